//! A small software renderer for point clouds: still pictures and film frames from the command
//! line and in tests, with no GPU and no Bevy (the kiosk has its own GPU renderer).
//!
//! # Method
//!
//! [`render`] draws every point as a small screen-space disk ("splat") into a depth buffer:
//!
//! 1. **Projection** (parallel over points, order kept): each point goes through the
//!    [`Camera`] (orthographic or perspective). Points that are not finite, or that lie behind
//!    the camera, are skipped. The disk's radius comes from
//!    [`RenderOptions::point_size_px`], or, when that is 0, from the point density: the mean
//!    spacing is estimated as `s = sqrt(A / n)` with `A` half the surface area of the cloud's
//!    bounding box (a fair guess of the area of a closed surface inside it: exact for a
//!    sphere within 5%, about right for a standing statue) and `n` the number of points, and
//!    the splat's world radius is [`AUTO_RADIUS_FACTOR`]` · s`, projected to pixels (so it
//!    shrinks with depth in perspective). With randomly (area-uniformly) sampled points, a
//!    radius of 1.2 s leaves about `exp(-π · 1.2²)` ≈ 1% of a surface facing the camera
//!    uncovered. Radii are clamped to 0.5..=256 pixels.
//! 2. **Shading per point**: the colour is the point's own (`colors`) or
//!    [`RenderOptions::base_color`], times `ambient + (1 − ambient) · |n · l|` (two-sided
//!    Lambert: estimated normals are not always oriented consistently, and a statue should not
//!    turn black where they flip) when normals are given, and times 1 (flat) otherwise. The
//!    light direction is given in **camera space**, so the light turns with the camera in a
//!    turntable film and the visible side is always lit the same way.
//! 3. **Splats follow the surface** when normals are given: a splat is the ellipse that a
//!    disk of that radius in the point's tangent plane projects to (its minor axis is
//!    foreshortened by `|n · view|`, clamped at 1/4), and its depth follows the tangent plane
//!    across the ellipse. Overlapping splats of one smooth surface then give a smooth depth
//!    buffer instead of a staircase of flat disks, and splats seen edge-on do not overhang the
//!    silhouette. Without normals the splats are flat, screen-aligned disks.
//! 4. **Splatting** (parallel over horizontal bands of [`BAND_ROWS`] rows): a first pass bins
//!    the point indices by the bands their splats touch; then every band, independently, draws
//!    its points in index order into its own rows, in two passes (the "ε-z-buffer" of surface
//!    splatting): a *depth pass* keeps the nearest splat depth per pixel, and a *blending
//!    pass* averages the colour and the depth of all splats within one splat diameter (in
//!    depth) of that nearest surface, weighted by `1 − d²/r²` (`d`: distance from the splat's
//!    centre in its tangent plane). Blending hides the seams between splats and smooths the
//!    per-point Lambert shading into a continuous surface. A pixel is covered by a splat when
//!    its centre is inside it, and always by the splat whose centre lies in it. Each pixel's
//!    sums are taken in index order by a single task, so the result is a function of the
//!    input alone: the same bytes whatever the number of threads.
//! 5. **Hole filling** ([`RenderOptions::fill_holes`]): random sampling leaves small gaps
//!    between splats, through which the far side of the statue (or the background) shows —
//!    and which eye-dome lighting would turn into black specks. A pixel is a hole when, in at
//!    least 7 of the 8 directions, a pixel within reach (1.5 mean splat radii, 2..=16 pixels)
//!    is nearer by more than 4 pixel units (see below) per pixel of distance, i.e. when it is
//!    enclosed by a much nearer surface; it takes the mean colour and depth of those nearer
//!    pixels (one pass, reading the unfilled buffers). Concave parts of a surface are not
//!    that steep and stay; openings wider than the reach stay too.
//! 6. **Eye-dome lighting** ([`RenderOptions::edl`], after Boucheny's EDL as used by
//!    CloudCompare and Potree): a screen-space pass over the depth buffer that outlines depth
//!    discontinuities and shades slopes, which makes the shape readable even without normals.
//!    Depths are first turned into *pixel units* — depth times pixels per world unit for an
//!    orthographic camera, and `f · ln(depth)` for a perspective camera of focal length `f`
//!    pixels (Boucheny's log-depth, whose differences are depth differences in pixel units
//!    at that depth) — so the effect does not depend on the object's size, the image size or
//!    where the orthographic eye happens to be. For each covered pixel `p`, the response is
//!    `R = Σ max(0, v(p) − v(q)) / |p − q|` over the 16 neighbours `q` at 1 and 2 pixels in the
//!    8 directions (background neighbours count as far away, i.e. never darken), and the
//!    colour is multiplied by `exp(−edl_strength · R / 16)`. A surface facing the camera is
//!    left alone, a 45° slope is darkened by about `exp(−0.3 · edl_strength)`, and the far side
//!    of an occluding contour turns almost black: the drawing's outline.
//!
//! Overlays for registration pictures — bone axes ([`overlay_segments`]) and sphere outlines
//! ([`overlay_spheres`]) — are drawn afterwards on the finished image, without depth test,
//! with anti-aliased edges.
//!
//! # Choices
//!
//! * Splats rather than a surface reconstruction: the renderer is for looking at raw and
//!   skinned point sets as they are; noise and real gaps (wider than a few splats) show, only
//!   the sampling holes between neighbouring splats are filled.
//! * Colours are mixed in 8-bit sRGB values directly (no linear-light maths): these are
//!   diagnostic pictures.
//! * Pictures are PNG files written by the tiny encoder of [`png`] (stored deflate blocks; no
//!   dependency).
//!
//! [`mod@pictogram`] draws a different kind of picture: a small RGBA icon of a skeleton's
//! sphere-mesh figure in a pose (the kiosk's pose buttons), analytically from the bones rather
//! than from points.

pub mod camera;
pub mod image;
pub mod pictogram;
pub mod png;

pub use camera::Camera;
pub use image::Image;
pub use pictogram::{Pictogram, PictogramOptions, pictogram, pose_pictogram};

use rayon::prelude::*;

use crate::math::{Vec2, Vec3};
use camera::View;

/// Rows per band of the parallel splatting pass.
pub const BAND_ROWS: usize = 16;

/// Automatic splat radius in units of the estimated mean point spacing (see the module docs).
pub const AUTO_RADIUS_FACTOR: f32 = 1.2;

/// Smallest and largest splat radius, in pixels.
const RADIUS_PX: (f32, f32) = (0.5, 256.0);

/// Largest depth slope (depth per unit of screen distance) of a tilted splat.
const MAX_SLOPE: f32 = 4.0;

/// Splats within this many of their own diameters (in depth) behind the nearest surface at a
/// pixel blend into it.
const BLEND_DEPTH: f32 = 1.0;

/// Smallest blending weight (for the pixel holding a splat's centre outside its disk).
const MIN_WEIGHT: f32 = 1.0 / 16.0;

/// Hole filling: least and most pixels to look in each of the 8 directions (1.5 mean splat
/// radii in between), ...
const HOLE_REACH: (i64, i64) = (2, 16);
/// ... how much nearer (pixel units per pixel of distance) a pixel must be to close a
/// direction, ...
const HOLE_STEP: f32 = 4.0;
/// ... and how many of the 8 directions must be closed.
const HOLE_SECTORS: usize = 7;

/// Options of [`render`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderOptions {
    /// Picture width in pixels.
    pub width: u32,
    /// Picture height in pixels.
    pub height: u32,
    /// Colour of pixels no point covers.
    pub background: [u8; 3],
    /// Diameter of a point's disk in pixels (for a perspective camera: at the target's
    /// distance, scaled by depth); 0 (or anything not positive) chooses it from the point
    /// density (see the module docs).
    pub point_size_px: f32,
    /// Direction *towards* the light in camera space: x to the right, y up, z towards the
    /// viewer. Need not be unit; a zero vector means light from the viewer.
    pub light_dir: Vec3,
    /// Colour of points when the cloud has no colours.
    pub base_color: [u8; 3],
    /// Fraction of the colour a point keeps when its normal is perpendicular to the light
    /// (0..=1).
    pub ambient: f32,
    /// Eye-dome lighting: darken slopes and depth discontinuities (see the module docs).
    pub edl: bool,
    /// Strength of the eye-dome lighting (1 is the default look; 0 disables it).
    pub edl_strength: f32,
    /// Fill small holes between splats (see the module docs).
    pub fill_holes: bool,
}

impl Default for RenderOptions {
    /// An 800 × 800 picture of a light stone-coloured statue on a dark grey background, lit
    /// from the upper left front, points sized automatically, with eye-dome lighting.
    fn default() -> Self {
        RenderOptions {
            width: 800,
            height: 800,
            background: [40, 42, 48],
            point_size_px: 0.0,
            light_dir: Vec3::new(-0.4, 0.6, 0.7),
            base_color: [235, 228, 214],
            ambient: 0.3,
            edl: true,
            edl_strength: 1.0,
            fill_holes: true,
        }
    }
}

/// One projected point, ready to be drawn.
#[derive(Clone, Copy, Debug)]
struct Splat {
    /// Centre in pixels.
    x: f32,
    y: f32,
    /// Depth at the centre (world units along the viewing direction).
    depth: f32,
    /// Radius in pixels.
    r: f32,
    /// Depth change per pixel to the right and per pixel down (tangent plane; 0 when flat).
    gx: f32,
    gy: f32,
    /// Unit screen direction (x right, y down) of the normal's projection, and the inverse of
    /// the normal's (clamped) component along the viewing direction: the disk is the ellipse
    /// that a world disk of radius `r` in the tangent plane projects to (a circle when flat).
    mx: f32,
    my: f32,
    inv_nd: f32,
    /// Depth (world units) behind the nearest surface within which the splat still blends in.
    tolerance: f32,
    /// Shaded colour.
    color: [u8; 3],
}

impl Splat {
    /// Inclusive pixel rows the disk may touch (unclamped).
    fn rows(&self) -> (f32, f32) {
        ((self.y - self.r).floor(), (self.y + self.r).floor())
    }
    fn cols(&self) -> (f32, f32) {
        ((self.x - self.r).floor(), (self.x + self.r).floor())
    }
}

/// The automatic world-space splat radius for the finite points of `positions` (see the
/// module docs), or 0 when there are none.
pub fn auto_point_radius(positions: &[Vec3]) -> f32 {
    let (lo, hi, n) = positions
        .par_iter()
        .filter(|p| p.is_finite())
        .fold(
            || {
                (
                    Vec3::splat(f32::INFINITY),
                    Vec3::splat(f32::NEG_INFINITY),
                    0usize,
                )
            },
            |(lo, hi, n), &p| (lo.min(p), hi.max(p), n + 1),
        )
        .reduce(
            || {
                (
                    Vec3::splat(f32::INFINITY),
                    Vec3::splat(f32::NEG_INFINITY),
                    0usize,
                )
            },
            |a, b| (a.0.min(b.0), a.1.max(b.1), a.2 + b.2),
        );
    if n == 0 {
        return 0.0;
    }
    let s = hi - lo;
    let half_area = s.x * s.y + s.y * s.z + s.z * s.x;
    AUTO_RADIUS_FACTOR * (half_area / n as f32).sqrt()
}

/// Renders a point cloud: `positions`, with optional unit `normals` (two-sided Lambert
/// shading and tilted splats) and per-point `colors` (else [`RenderOptions::base_color`]).
///
/// See the module docs for the method. Never panics on bad input: an empty cloud gives the
/// background, points that are not finite or lie behind the camera are skipped, a normal that
/// is missing (a `normals` slice shorter than `positions`) or not finite shades that point
/// flat, and a missing colour is the base colour. A zero width or height gives an empty image.
/// The output is the same, byte for byte, whatever the number of rayon threads.
pub fn render(
    positions: &[Vec3],
    normals: Option<&[Vec3]>,
    colors: Option<&[[u8; 3]]>,
    camera: &Camera,
    opts: &RenderOptions,
) -> Image {
    let (w, h) = (opts.width as usize, opts.height as usize);
    let mut img = Image::new(opts.width, opts.height, opts.background);
    if w == 0 || h == 0 || positions.is_empty() {
        return img;
    }
    let view = View::new(camera, opts.width, opts.height);
    let splats = project_points(positions, normals, colors, &view, opts);

    // Binning: point indices per band, in index order.
    let bands = h.div_ceil(BAND_ROWS);
    let mut bins: Vec<Vec<u32>> = vec![Vec::new(); bands];
    for (i, s) in splats.iter().enumerate() {
        let Some(s) = s else { continue };
        let (y0, y1) = s.rows();
        let (x0, x1) = s.cols();
        if y1 < 0.0 || y0 >= h as f32 || x1 < 0.0 || x0 >= w as f32 {
            continue;
        }
        let b0 = y0.max(0.0) as usize / BAND_ROWS;
        let b1 = (y1 as usize).min(h - 1) / BAND_ROWS;
        for bin in &mut bins[b0..=b1] {
            bin.push(i as u32);
        }
    }

    // Splatting, one band per task: a depth pass, then the blending pass.
    let mut depth = vec![f32::INFINITY; w * h];
    img.rgb
        .par_chunks_mut(BAND_ROWS * w * 3)
        .zip(depth.par_chunks_mut(BAND_ROWS * w))
        .zip(bins.par_iter())
        .enumerate()
        .for_each(|(b, ((rgb, zbuf), bin))| {
            let band = Band {
                row0: b * BAND_ROWS,
                rows: zbuf.len() / w,
                width: w,
            };
            let splats = || {
                bin.iter()
                    .map(|&i| splats[i as usize].as_ref().expect("binned splats exist"))
            };
            for s in splats() {
                band.cover(s, |j, d, _| {
                    if d < zbuf[j] {
                        zbuf[j] = d;
                    }
                });
            }
            // Sums of weight, weight × depth and weight × colour per pixel.
            let mut acc = vec![[0.0f32; 5]; zbuf.len()];
            for s in splats() {
                band.cover(s, |j, d, weight| {
                    if d <= zbuf[j] + s.tolerance {
                        let a = &mut acc[j];
                        a[0] += weight;
                        a[1] += weight * d;
                        for c in 0..3 {
                            a[2 + c] += weight * s.color[c] as f32;
                        }
                    }
                });
            }
            for (j, a) in acc.iter().enumerate() {
                if a[0] > 0.0 {
                    zbuf[j] = a[1] / a[0];
                    for c in 0..3 {
                        rgb[3 * j + c] = (a[2 + c] / a[0]).round().clamp(0.0, 255.0) as u8;
                    }
                }
            }
        });

    if opts.fill_holes {
        // Reach: 1.5 times the mean splat radius (a sequential sum, so that the result does
        // not depend on the thread count).
        let (sum, n) = splats
            .iter()
            .flatten()
            .fold((0.0f64, 0usize), |(sum, n), s| (sum + s.r as f64, n + 1));
        let mean_r = if n > 0 { sum / n as f64 } else { 0.0 };
        let reach = ((1.5 * mean_r).ceil() as i64).clamp(HOLE_REACH.0, HOLE_REACH.1);
        fill_holes(&mut img, &mut depth, &view, reach);
    }
    if opts.edl && opts.edl_strength > 0.0 {
        eye_dome(&mut img, &depth, &view, opts.edl_strength);
    }
    img
}

/// Projects and shades every point (`None` for skipped points), in parallel, in order.
fn project_points(
    positions: &[Vec3],
    normals: Option<&[Vec3]>,
    colors: Option<&[[u8; 3]]>,
    view: &View,
    opts: &RenderOptions,
) -> Vec<Option<Splat>> {
    let fixed = opts.point_size_px > 0.0 && opts.point_size_px.is_finite();
    let world_radius = if fixed {
        0.0
    } else {
        auto_point_radius(positions)
    };
    let light = opts.light_dir.try_normalize().unwrap_or(Vec3::Z);
    // The light in world space, so that it is dotted with world normals directly. Camera
    // space has z towards the viewer, i.e. −fwd.
    let light = view.right * light.x + view.up * light.y - view.fwd * light.z;
    let ambient = if opts.ambient.is_finite() {
        opts.ambient.clamp(0.0, 1.0)
    } else {
        0.0
    };
    positions
        .par_iter()
        .enumerate()
        .map(|(i, &p)| {
            let c = view.camera_coords(p);
            if !(c.z > view.near) || !c.is_finite() {
                return None;
            }
            let s: Vec2 = view.screen_coords(c);
            if !s.is_finite() {
                return None;
            }
            let k = view.pixels_per_unit(c.z);
            let r = if fixed {
                let scale = if view.ortho {
                    1.0
                } else {
                    view.target_depth / c.z
                };
                0.5 * opts.point_size_px * scale
            } else {
                world_radius * k
            };
            let r = if r.is_finite() {
                r.clamp(RADIUS_PX.0, RADIUS_PX.1)
            } else {
                RADIUS_PX.1
            };
            let color = colors
                .and_then(|cs| cs.get(i).copied())
                .unwrap_or(opts.base_color);
            let normal = normals
                .and_then(|ns| ns.get(i).copied())
                .filter(|n| n.is_finite() && n.length_squared() > 1e-12);
            let (mut gx, mut gy, mut shade) = (0.0, 0.0, 1.0);
            let (mut mx, mut my, mut inv_nd) = (0.0, 0.0, 1.0);
            if let Some(n) = normal {
                let n = n.normalize();
                shade = ambient + (1.0 - ambient) * n.dot(light).abs();
                let (nx, ny, nd) = (n.dot(view.right), n.dot(view.up), n.dot(view.fwd));
                let nd = if nd.abs() < 1.0 / MAX_SLOPE {
                    (1.0 / MAX_SLOPE).copysign(nd)
                } else {
                    nd
                };
                // Tangent plane: Δdepth = −(nx Δx + ny Δy) / nd, with Δx = Δcol / k and
                // Δy = −Δrow / k.
                gx = -nx / (nd * k);
                gy = ny / (nd * k);
                if let Some(m) = Vec2::new(nx, -ny).try_normalize() {
                    (mx, my, inv_nd) = (m.x, m.y, 1.0 / nd.abs());
                }
            }
            let color = color.map(|v| (v as f32 * shade).round().clamp(0.0, 255.0) as u8);
            Some(Splat {
                x: s.x,
                y: s.y,
                depth: c.z,
                r,
                gx,
                gy,
                mx,
                my,
                inv_nd,
                tolerance: BLEND_DEPTH * r / k,
                color,
            })
        })
        .collect()
}

/// A horizontal band of the picture: `rows` rows from `row0`, `width` pixels wide.
struct Band {
    row0: usize,
    rows: usize,
    width: usize,
}

impl Band {
    /// Calls `f(j, depth, weight)` for every pixel of the band the splat covers, `j` being the
    /// pixel's index within the band, `depth` the splat's depth there and `weight` its blending
    /// weight (`1 − d²/r²` at distance `d` from the centre, at least [`MIN_WEIGHT`]).
    fn cover(&self, s: &Splat, mut f: impl FnMut(usize, f32, f32)) {
        let (y0, y1) = s.rows();
        let (x0, x1) = s.cols();
        let ya = (y0.max(self.row0 as f32) as usize).max(self.row0);
        let yb = (y1.min((self.row0 + self.rows - 1) as f32)) as i64;
        let xa = x0.max(0.0) as usize;
        let xb = x1.min((self.width - 1) as f32) as i64;
        if yb < ya as i64 || xb < xa as i64 {
            return;
        }
        let (cx, cy) = (s.x.floor(), s.y.floor());
        let inv_r2 = 1.0 / (s.r * s.r);
        for y in ya..=yb as usize {
            let dy = y as f32 + 0.5 - s.y;
            let line = (y - self.row0) * self.width;
            for x in xa..=xb as usize {
                let dx = x as f32 + 0.5 - s.x;
                // Distance in the tangent plane: the offset along the projected normal is
                // foreshortened by |n · view|.
                let along = (dx * s.mx + dy * s.my) * (s.inv_nd - 1.0);
                let (ex, ey) = (dx + along * s.mx, dy + along * s.my);
                let q = (ex * ex + ey * ey) * inv_r2;
                if q > 1.0 && !(x as f32 == cx && y as f32 == cy) {
                    continue;
                }
                let d = s.depth + s.gx * dx + s.gy * dy;
                f(line + x, d, (1.0 - q).max(MIN_WEIGHT));
            }
        }
    }
}

/// Depths in pixel units (see the module docs); background stays +∞.
fn pixel_depths(depth: &[f32], view: &View) -> Vec<f32> {
    depth
        .par_iter()
        .map(|&d| {
            if !d.is_finite() {
                f32::INFINITY
            } else if view.ortho {
                d * view.scale
            } else {
                view.scale * d.max(f32::MIN_POSITIVE).ln()
            }
        })
        .collect()
}

/// The 8 neighbour directions.
const DIRS: [(i64, i64); 8] = [
    (-1, -1),
    (0, -1),
    (1, -1),
    (-1, 0),
    (1, 0),
    (-1, 1),
    (0, 1),
    (1, 1),
];

/// The hole-filling pass (see the module docs).
fn fill_holes(img: &mut Image, depth: &mut [f32], view: &View, reach: i64) {
    let (w, h) = (img.width as usize, img.height as usize);
    let v = pixel_depths(depth, view);
    let (rgb, old_depth) = (&img.rgb, &*depth);
    let fills: Vec<Vec<(usize, [u8; 3], f32)>> = (0..h)
        .into_par_iter()
        .map(|y| {
            let mut out = Vec::new();
            for x in 0..w {
                let vp = v[y * w + x];
                let (mut closed, mut sum, mut sum_d) = (0, [0.0f32; 3], 0.0f32);
                for (dx, dy) in DIRS {
                    for step in 1..=reach {
                        let (qx, qy) = (x as i64 + dx * step, y as i64 + dy * step);
                        if qx < 0 || qy < 0 || qx >= w as i64 || qy >= h as i64 {
                            break;
                        }
                        let q = qy as usize * w + qx as usize;
                        if v[q] < vp - HOLE_STEP * step as f32 {
                            closed += 1;
                            for c in 0..3 {
                                sum[c] += rgb[3 * q + c] as f32;
                            }
                            sum_d += old_depth[q];
                            break;
                        }
                    }
                }
                if closed >= HOLE_SECTORS {
                    let n = closed as f32;
                    let color = sum.map(|c| (c / n).round() as u8);
                    out.push((y * w + x, color, sum_d / n));
                }
            }
            out
        })
        .collect();
    for (j, color, d) in fills.into_iter().flatten() {
        img.rgb[3 * j..3 * j + 3].copy_from_slice(&color);
        depth[j] = d;
    }
}

/// The eye-dome lighting pass (see the module docs).
fn eye_dome(img: &mut Image, depth: &[f32], view: &View, strength: f32) {
    let (w, h) = (img.width as usize, img.height as usize);
    let v = pixel_depths(depth, view);
    let k = strength / 16.0;
    img.rgb
        .par_chunks_mut(w * 3)
        .enumerate()
        .for_each(|(y, row)| {
            for x in 0..w {
                let vp = v[y * w + x];
                if !vp.is_finite() {
                    continue;
                }
                let mut response = 0.0f32;
                for step in [1i64, 2] {
                    for (dx, dy) in DIRS {
                        let (qx, qy) = (x as i64 + dx * step, y as i64 + dy * step);
                        if qx < 0 || qy < 0 || qx >= w as i64 || qy >= h as i64 {
                            continue;
                        }
                        let vq = v[qy as usize * w + qx as usize];
                        if vq < vp {
                            let dist = if dx != 0 && dy != 0 {
                                std::f32::consts::SQRT_2
                            } else {
                                1.0
                            } * step as f32;
                            response += (vp - vq) / dist;
                        }
                    }
                }
                if response > 0.0 {
                    let f = (-k * response).exp();
                    for c in &mut row[3 * x..3 * x + 3] {
                        *c = (*c as f32 * f).round() as u8;
                    }
                }
            }
        });
}

/// Line width of [`overlay_spheres`] outlines, in pixels.
pub const OUTLINE_PX: f32 = 1.5;

/// Draws the segments (bone axes, say) on top of `img` as anti-aliased lines `width_px` wide,
/// with no depth test. A segment partly behind the camera is cut at the near plane; one
/// entirely behind it, or with a non-finite end, is skipped. A segment whose ends coincide is
/// a dot.
pub fn overlay_segments(
    img: &mut Image,
    camera: &Camera,
    segments: &[(Vec3, Vec3)],
    color: [u8; 3],
    width_px: f32,
) {
    let view = View::new(camera, img.width, img.height);
    let half = if width_px.is_finite() {
        0.5 * width_px.clamp(0.0, 1024.0)
    } else {
        0.5
    };
    // Cut at a near plane strictly in front of the eye (also for an orthographic camera).
    let near = view.near.max(1e-6 * view.target_depth.abs()).max(1e-30);
    for &(a, b) in segments {
        let (mut ca, mut cb) = (view.camera_coords(a), view.camera_coords(b));
        if !ca.is_finite() || !cb.is_finite() || (ca.z <= near && cb.z <= near) {
            continue;
        }
        if ca.z < near {
            ca = ca + (cb - ca) * ((near - ca.z) / (cb.z - ca.z));
        } else if cb.z < near {
            cb = cb + (ca - cb) * ((near - cb.z) / (ca.z - cb.z));
        }
        let (pa, pb) = (view.screen_coords(ca), view.screen_coords(cb));
        if !pa.is_finite() || !pb.is_finite() {
            continue;
        }
        let lo = pa.min(pb) - Vec2::splat(half + 1.0);
        let hi = pa.max(pb) + Vec2::splat(half + 1.0);
        let ab = pb - pa;
        let len2 = ab.length_squared();
        for_pixels(img, lo, hi, |p| {
            let t = if len2 > 0.0 {
                ((p - pa).dot(ab) / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let dist = (p - (pa + ab * t)).length();
            (half + 0.5 - dist).clamp(0.0, 1.0)
        })
        .into_iter()
        .for_each(|(x, y, alpha)| img.blend(x, y, color, alpha));
    }
}

/// Draws the outline of each sphere (centre, radius in world units) on top of `img`, in
/// `color`, [`OUTLINE_PX`] wide, with no depth test. The outline is the circle of the
/// sphere's radius at the centre's depth (exact for an orthographic camera; for perspective
/// it ignores the slight elongation of off-centre spheres). Spheres behind the camera, or
/// with a non-finite centre or radius, are skipped; a sphere smaller than a pixel is a dot.
pub fn overlay_spheres(
    img: &mut Image,
    camera: &Camera,
    centers_radii: &[(Vec3, f32)],
    color: [u8; 3],
) {
    let view = View::new(camera, img.width, img.height);
    let half = 0.5 * OUTLINE_PX;
    for &(c, radius) in centers_radii {
        let Some((p, depth)) = view.project(c) else {
            continue;
        };
        if !radius.is_finite() {
            continue;
        }
        let r = radius.abs() * view.pixels_per_unit(depth);
        if !r.is_finite() {
            continue;
        }
        let ext = Vec2::splat(r + half + 1.0);
        for_pixels(img, p - ext, p + ext, |q| {
            let dist = ((q - p).length() - r).abs();
            (half + 0.5 - dist).clamp(0.0, 1.0)
        })
        .into_iter()
        .for_each(|(x, y, alpha)| img.blend(x, y, color, alpha));
    }
}

/// The pixels in the box `lo`..`hi` (pixel coordinates, clamped to the image) with the
/// opacity `coverage` gives their centres, leaving out those with none.
fn for_pixels(
    img: &Image,
    lo: Vec2,
    hi: Vec2,
    coverage: impl Fn(Vec2) -> f32 + Sync,
) -> Vec<(u32, u32, f32)> {
    let (w, h) = (img.width as f32, img.height as f32);
    if w == 0.0 || h == 0.0 || hi.x < 0.0 || hi.y < 0.0 || lo.x >= w || lo.y >= h {
        return Vec::new();
    }
    let x0 = lo.x.max(0.0).floor() as u32;
    let y0 = lo.y.max(0.0).floor() as u32;
    let x1 = hi.x.min(w - 1.0).floor() as u32;
    let y1 = hi.y.min(h - 1.0).floor() as u32;
    (y0..=y1)
        .into_par_iter()
        .flat_map_iter(|y| {
            let coverage = &coverage;
            (x0..=x1).filter_map(move |x| {
                let a = coverage(Vec2::new(x as f32 + 0.5, y as f32 + 0.5));
                (a > 0.0).then_some((x, y, a))
            })
        })
        .collect()
}
