//! Pose pictograms: a small RGBA picture of a template's sphere-mesh figure in a pose, for the
//! kiosk's pose buttons (and anything else that wants an icon of a pose). Made from the pose
//! data itself, so a museum that adds a pose file gets its pictogram for free.
//!
//! # Inputs and output
//!
//! * [`pose_pictogram`]`(pose, template, options)`: the template's rest skeleton put in `pose`
//!   ([`Pose::apply`]), then drawn by [`pictogram`]. Fails only when the pose does not fit the
//!   template (an unknown or constrained bone: the pose's own error).
//! * [`pictogram`]`(skeleton, options)`: any skeleton (a fitted statue's too), seen in its own
//!   **template frame** — the root's placement and orientation are undone, so the figure stands
//!   upright and faces the viewer whatever the statue's orientation in its scan.
//! * Out comes a [`Pictogram`]: `width × height` pixels, RGBA, 8 bits per channel, sRGB, *not*
//!   premultiplied, row-major from the top-left corner, with a transparent background (alpha is
//!   the share of the pixel the figure covers). [`Pictogram::frame`] maps template-frame points
//!   to pixels (for tests and overlays); [`Pictogram::to_image`] lays it over a background.
//!
//! # How it is drawn
//!
//! * **View** ([`PictogramOptions::yaw_deg`], [`PictogramOptions::pitch_deg`]): orthographic,
//!   from the front turned by `yaw` about the vertical (default −30°: a three-quarter view from
//!   the figure's right front, so forward and backward moves — a stride, a seated figure's
//!   thighs — show, which a view straight from the front hides) and raised by `pitch` (10°).
//! * **Scale**: one scale for every pose of a skeleton, so poses compare: the figure's
//!   *standing height* (its own bone sizes in the template's rest rotations) takes
//!   `1 / frame_heights` of the picture's height less the margins (default 1.35: room for
//!   raised arms). A seated figure therefore comes out shorter than a standing one. Only a pose
//!   that would not fit (wider than the picture, or taller than the frame) is shrunk to fit.
//! * **Placement**: the figure's lowest point on the bottom margin (it stands on the ground),
//!   centred horizontally.
//! * **Shapes**: each bone is exactly what the fitting uses, the convex hull of its two spheres.
//!   That hull is also the union of the spheres `(c(τ), r(τ))` interpolated linearly along the
//!   bone, so for each sample the bone's front surface is `max_τ z(τ) + √(r(τ)² − ρ(τ)²)`
//!   (`ρ`: the sample's distance to the projected centre). The expression under the root is
//!   a quadratic in `τ`, concave when the projected bone is longer than its radius change, and
//!   the maximum then has a closed form; bones seen nearly end-on are sampled at nine `τ`. The
//!   nearest bone wins (a z-buffer), and the sphere `τ` gives the normal.
//! * **Shading**: the figure's colour ([`PictogramOptions::color`], light stone) times
//!   `ambient + (1 − ambient) · max(0, n · l)` with the light from the upper left front;
//!   where a part passes in front of another (the sample's neighbour one pixel away is nearer
//!   by more than 4% of the standing height) the far side is darkened into an outline, so a
//!   forearm across the chest reads. No outline around the figure: the button's colour behind
//!   it is the contrast.
//! * **Antialiasing**: `supersample²` samples per pixel (default 4 × 4); a pixel's alpha is
//!   the share of its samples the figure covers and its colour their mean. Colours are mixed
//!   in 8-bit sRGB values directly, as in the point renderer.
//!
//! Each bone visits only the samples of its bounding box: the seven built-in poses at 64 × 64
//! take a few milliseconds together (`tests/render.rs` prints the time).

use std::sync::Arc;

use super::image::Image;
use crate::anatomy::{Pose, Skeleton, Template};
use crate::error::Result;
use crate::math::{Vec2, Vec3};

/// Options of [`pictogram`] and [`pose_pictogram`]. See the [module documentation](self).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PictogramOptions {
    /// Picture width in pixels.
    pub width: u32,
    /// Picture height in pixels.
    pub height: u32,
    /// The viewer turned about the vertical from the front, degrees; positive moves the viewer
    /// towards the figure's left (`+X` of the template frame). 0: straight from the front.
    pub yaw_deg: f32,
    /// The viewer raised above the horizontal, degrees.
    pub pitch_deg: f32,
    /// The picture's height (less the margins) in standing heights of the figure: the one
    /// scale of every pose (poses that would not fit are shrunk).
    pub frame_heights: f32,
    /// Empty pixels kept on every side.
    pub margin_px: f32,
    /// Factor on every bone radius: the template's radii are generous (the fitting prefers
    /// to shrink them), and slimmer limbs read better in a small picture.
    pub radius_scale: f32,
    /// The figure's colour where fully lit (sRGB).
    pub color: [u8; 3],
    /// Share of the colour kept where the light grazes (0..=1).
    pub ambient: f32,
    /// Samples per pixel along each axis (1..=8).
    pub supersample: u32,
}

impl Default for PictogramOptions {
    /// 64 × 64, three-quarter view from the figure's right front, light stone colour.
    fn default() -> Self {
        PictogramOptions {
            width: 64,
            height: 64,
            yaw_deg: -40.0,
            pitch_deg: 12.0,
            frame_heights: 1.3,
            margin_px: 2.0,
            radius_scale: 0.8,
            color: [238, 233, 222],
            ambient: 0.42,
            supersample: 4,
        }
    }
}

/// Where template-frame points land in a [`Pictogram`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PictogramFrame {
    /// Screen right, up and towards the viewer, in the template frame (unit vectors).
    pub right: Vec3,
    pub up: Vec3,
    pub toward_viewer: Vec3,
    /// Pixels per template-frame unit.
    pub scale: f32,
    /// Pixel position (x right, y down, from the top-left corner of the picture) of the
    /// template frame's origin.
    pub origin: Vec2,
    /// The figure's standing height (template-frame units) the scale was chosen for.
    pub standing_height: f32,
}

impl PictogramFrame {
    /// The pixel position (x right, y down; pixel `(i, j)` spans `i..i + 1`, `j..j + 1`) of a
    /// template-frame point.
    pub fn to_pixel(&self, p: Vec3) -> Vec2 {
        Vec2::new(
            self.origin.x + self.scale * p.dot(self.right),
            self.origin.y - self.scale * p.dot(self.up),
        )
    }
}

/// A pictogram: RGBA pixels (see the [module documentation](self) for the layout).
#[derive(Clone, Debug, PartialEq)]
pub struct Pictogram {
    pub width: u32,
    pub height: u32,
    /// `rgba[4 * (y * width + x) + c]` is channel `c` of pixel (`x`, `y`); sRGB, straight
    /// (not premultiplied) alpha.
    pub rgba: Vec<u8>,
    /// How the figure was placed.
    pub frame: PictogramFrame,
}

impl Pictogram {
    /// The alpha of pixel (`x`, `y`) (0 outside the picture).
    pub fn alpha(&self, x: u32, y: u32) -> u8 {
        if x >= self.width || y >= self.height {
            return 0;
        }
        self.rgba[4 * (y as usize * self.width as usize + x as usize) + 3]
    }

    /// The smallest box `(x0, y0, x1, y1)` (inclusive) holding every pixel of at least
    /// `min_alpha`, or `None` when there is none: the figure's extent in pixels.
    pub fn ink_bounds(&self, min_alpha: u8) -> Option<(u32, u32, u32, u32)> {
        let mut b: Option<(u32, u32, u32, u32)> = None;
        for y in 0..self.height {
            for x in 0..self.width {
                if self.alpha(x, y) >= min_alpha.max(1) {
                    b = Some(match b {
                        None => (x, y, x, y),
                        Some((x0, y0, x1, y1)) => (x0.min(x), y0.min(y), x1.max(x), y1.max(y)),
                    });
                }
            }
        }
        b
    }

    /// The picture laid over `background` (for PNG files).
    pub fn to_image(&self, background: [u8; 3]) -> Image {
        let mut img = Image::new(self.width, self.height, background);
        for y in 0..self.height {
            for x in 0..self.width {
                let i = 4 * (y as usize * self.width as usize + x as usize);
                let c = [self.rgba[i], self.rgba[i + 1], self.rgba[i + 2]];
                img.blend(x, y, c, self.rgba[i + 3] as f32 / 255.0);
            }
        }
        img
    }
}

/// The pictogram of `pose` on `template`'s rest skeleton (see the [module
/// documentation](self)). Errors are the pose's own ([`Pose::apply`]: a bone the template
/// lacks, or one that cannot be posed).
pub fn pose_pictogram(
    pose: &Pose,
    template: Arc<Template>,
    options: &PictogramOptions,
) -> Result<Pictogram> {
    let rest = Skeleton::rest(template);
    let posed = pose.apply(&rest, &Pose::source_path(&pose.name))?;
    Ok(pictogram(&posed, options))
}

/// Darkening of the far side of an occluding contour (outline), as a colour factor.
const OUTLINE_SHADE: f32 = 0.38;
/// A neighbour nearer by this share of the standing height makes an outline.
const OUTLINE_DEPTH: f32 = 0.04;
/// Samples along a bone seen nearly end-on.
const END_ON_SAMPLES: usize = 9;

/// One bone in sample units: projected centres, depths (towards the viewer) and radii.
struct FlatBone {
    a: Vec2,
    g: Vec2,
    za: f32,
    dz: f32,
    ra: f32,
    dr: f32,
    /// Sample-space bounding box (inclusive-exclusive), clamped to the picture.
    x0: usize,
    x1: usize,
    y0: usize,
    y1: usize,
}

impl FlatBone {
    /// The bone's front depth at sample `p` and the interpolation parameter of the sphere
    /// that gives it, or `None` where the bone does not cover `p`.
    fn front(&self, p: Vec2) -> Option<(f32, f32)> {
        // Q(τ) = r(τ)² − |e + τ g|² = −A τ² + B τ + C, with e = a − p.
        let e = self.a - p;
        let a = self.g.length_squared() - self.dr * self.dr;
        let b = 2.0 * (self.ra * self.dr - e.dot(self.g));
        let c = self.ra * self.ra - e.length_squared();
        let q = |t: f32| -a * t * t + b * t + c;
        let f = |t: f32| {
            let v = q(t);
            (v >= 0.0).then(|| self.za + self.dz * t + v.sqrt())
        };
        let best = |ts: &mut dyn Iterator<Item = f32>| {
            ts.filter_map(|t| f(t).map(|z| (z, t)))
                .max_by(|x, y| x.0.total_cmp(&y.0))
        };
        if a > 1e-6 * (self.g.length_squared() + self.dr * self.dr + 1e-12) {
            // Concave: where Q peaks tells whether p is covered, and the depth's stationary
            // point (d/dτ [z + √Q] = 0) is in closed form.
            let t_q = (b / (2.0 * a)).clamp(0.0, 1.0);
            if q(t_q) < 0.0 {
                return None;
            }
            let dz2 = self.dz * self.dz;
            let mid = b / (2.0 * a);
            let disc = mid * mid - (b * b / 4.0 - dz2 * c) / (a * (a + dz2));
            let t_z = if dz2 > 0.0 && disc >= 0.0 {
                (mid + self.dz.signum() * disc.sqrt()).clamp(0.0, 1.0)
            } else {
                t_q
            };
            // Rounding can put the clamped stationary point just outside the domain.
            best(&mut [t_z, t_q].into_iter())
        } else {
            // Seen nearly end-on (one projected disc holds the other): sample.
            best(&mut (0..END_ON_SAMPLES).map(|i| i as f32 / (END_ON_SAMPLES - 1) as f32))
        }
    }
}

/// The pictogram of `skeleton`, seen in its template frame (see the [module
/// documentation](self)).
pub fn pictogram(skeleton: &Skeleton, options: &PictogramOptions) -> Pictogram {
    let o = options;
    let (w, h) = (o.width.max(1), o.height.max(1));
    let ss = o.supersample.clamp(1, 8) as usize;
    let (sw, sh) = (w as usize * ss, h as usize * ss);

    // The view.
    let (yaw, pitch) = (o.yaw_deg.to_radians(), o.pitch_deg.to_radians());
    let toward = Vec3::new(
        pitch.cos() * yaw.sin(),
        pitch.sin(),
        pitch.cos() * yaw.cos(),
    );
    let right = Vec3::new(yaw.cos(), 0.0, -yaw.sin());
    let up = toward.cross(right);

    // The figure in its template frame.
    let inv = skeleton.root_rotation.inverse();
    let bones: Vec<_> = skeleton
        .pose()
        .bones
        .into_iter()
        .map(|b| {
            (
                inv * (b.c1 - skeleton.root_position),
                b.r1 * o.radius_scale.max(0.0),
                inv * (b.c2 - skeleton.root_position),
                b.r2 * o.radius_scale.max(0.0),
            )
        })
        .collect();
    let standing = standing_height(skeleton);

    // Scale: the standing height fills 1 / frame_heights of the usable height, unless the
    // pose does not fit.
    let (mut lo, mut hi) = (Vec2::splat(f32::INFINITY), Vec2::splat(f32::NEG_INFINITY));
    for &(c1, r1, c2, r2) in &bones {
        for (c, r) in [(c1, r1), (c2, r2)] {
            let v = Vec2::new(c.dot(right), c.dot(up));
            lo = lo.min(v - Vec2::splat(r));
            hi = hi.max(v + Vec2::splat(r));
        }
    }
    let usable = Vec2::new(
        (w as f32 - 2.0 * o.margin_px).max(1.0),
        (h as f32 - 2.0 * o.margin_px).max(1.0),
    );
    let extent = (hi - lo).max(Vec2::splat(1e-6));
    let mut scale = usable.y / (o.frame_heights.max(0.1) * standing.max(1e-6));
    if !bones.is_empty() {
        scale = scale.min(usable.x / extent.x).min(usable.y / extent.y);
    } else {
        (lo, hi) = (Vec2::ZERO, Vec2::ZERO);
    }
    let origin = Vec2::new(
        w as f32 / 2.0 - scale * (lo.x + hi.x) / 2.0,
        h as f32 - o.margin_px + scale * lo.y,
    );
    let frame = PictogramFrame {
        right,
        up,
        toward_viewer: toward,
        scale,
        origin,
        standing_height: standing,
    };

    // Bones in sample units (x right, y down, z towards the viewer).
    let k = ss as f32;
    let flat: Vec<FlatBone> = bones
        .iter()
        .map(|&(c1, r1, c2, r2)| {
            let a = frame.to_pixel(c1) * k;
            let b = frame.to_pixel(c2) * k;
            let (ra, rb) = (r1 * scale * k, r2 * scale * k);
            let (za, zb) = (c1.dot(toward) * scale * k, c2.dot(toward) * scale * k);
            let r = ra.max(rb) + 1.0;
            let clamp = |v: f32, n: usize| (v.max(0.0) as usize).min(n);
            FlatBone {
                a,
                g: b - a,
                za,
                dz: zb - za,
                ra,
                dr: rb - ra,
                x0: clamp((a.x.min(b.x) - r).floor(), sw),
                x1: clamp((a.x.max(b.x) + r).ceil(), sw),
                y0: clamp((a.y.min(b.y) - r).floor(), sh),
                y1: clamp((a.y.max(b.y) + r).ceil(), sh),
            }
        })
        .collect();

    // Z-buffer of the samples: nearest front depth and its normal's shade.
    let light = Vec3::new(-0.45, 0.6, 0.75).normalize();
    let mut depth = vec![f32::NEG_INFINITY; sw * sh];
    let mut shade = vec![0.0f32; sw * sh];
    for fb in &flat {
        for y in fb.y0..fb.y1 {
            for x in fb.x0..fb.x1 {
                let p = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                let Some((z, t)) = fb.front(p) else { continue };
                let i = y * sw + x;
                if z <= depth[i] {
                    continue;
                }
                depth[i] = z;
                let centre = fb.a + fb.g * t;
                let r = (fb.ra + fb.dr * t).max(1e-6);
                let zc = fb.za + fb.dz * t;
                // Normal in view space (x right, y up, z towards the viewer).
                let n = Vec3::new(p.x - centre.x, centre.y - p.y, z - zc) / r;
                let lit = n.normalize_or_zero().dot(light).max(0.0);
                shade[i] = o.ambient.clamp(0.0, 1.0) + (1.0 - o.ambient.clamp(0.0, 1.0)) * lit;
            }
        }
    }

    // Outlines: the far side of an occluding contour.
    let step = (ss as f32 * 0.75).round().max(1.0) as isize;
    let jump = OUTLINE_DEPTH * standing * scale * k;
    let mut dark = vec![false; sw * sh];
    for y in 0..sh {
        for x in 0..sw {
            let d = depth[y * sw + x];
            if d == f32::NEG_INFINITY {
                continue;
            }
            dark[y * sw + x] =
                [(step, 0), (-step, 0), (0, step), (0, -step)]
                    .iter()
                    .any(|&(dx, dy)| {
                        let (nx, ny) = (x as isize + dx, y as isize + dy);
                        nx >= 0
                            && ny >= 0
                            && (nx as usize) < sw
                            && (ny as usize) < sh
                            && depth[ny as usize * sw + nx as usize] > d + jump
                    });
        }
    }

    // Down to pixels.
    let mut rgba = vec![0u8; w as usize * h as usize * 4];
    for py in 0..h as usize {
        for px in 0..w as usize {
            let (mut n, mut sum) = (0usize, 0.0f32);
            for sy in 0..ss {
                for sx in 0..ss {
                    let i = (py * ss + sy) * sw + px * ss + sx;
                    if depth[i] == f32::NEG_INFINITY {
                        continue;
                    }
                    n += 1;
                    sum += shade[i] * if dark[i] { OUTLINE_SHADE } else { 1.0 };
                }
            }
            if n == 0 {
                continue;
            }
            let s = sum / n as f32;
            let out = &mut rgba[4 * (py * w as usize + px)..][..4];
            for (c, &base) in out.iter_mut().zip(&o.color) {
                *c = (base as f32 * s).round().clamp(0.0, 255.0) as u8;
            }
            out[3] = ((n * 255) as f32 / (ss * ss) as f32).round() as u8;
        }
    }
    Pictogram {
        width: w,
        height: h,
        rgba,
        frame,
    }
}

/// The skeleton's height standing: its own bone sizes in the template's rest rotations,
/// radii included (template-frame units).
pub fn standing_height(skeleton: &Skeleton) -> f32 {
    let rest = Skeleton::rest(skeleton.template.clone());
    let mut standing = skeleton.clone();
    standing.root_rotation = rest.root_rotation;
    standing.root_position = rest.root_position;
    for (b, r) in standing.bones.iter_mut().zip(&rest.bones) {
        b.rotation = r.rotation;
    }
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for b in standing.pose().bones {
        lo = lo.min(b.c1.y - b.r1).min(b.c2.y - b.r2);
        hi = hi.max(b.c1.y + b.r1).max(b.c2.y + b.r2);
    }
    if hi > lo { hi - lo } else { 0.0 }
}

/// Reads a pose by name or file ([`Pose::resolve`]) and draws it on `template`: the kiosk's
/// pose buttons in one call.
pub fn named_pose_pictogram(
    name_or_path: &str,
    template: Arc<Template>,
    options: &PictogramOptions,
) -> Result<Pictogram> {
    let pose = Pose::resolve(name_or_path)?;
    pose_pictogram(&pose, template, options)
}
