//! The statue's **base** (plinth, socle, pedestal): found in the cloud so that registration
//! fits the figure only, and skinning leaves the base where it stands.
//!
//! The papers register clouds of figures alone; museum scans stand on plinths, and a plinth
//! is a large block under the feet that FAKIR would otherwise cover with the legs (the feet
//! reach into it) or, without an up hint, take for the shoulders. This module is ours.
//!
//! ## Method
//! A plinth's **top face** is a flat region whose normals point up, at one height, near the
//! bottom of the statue; a body has no such region (a lying figure's back is curved, and the
//! undersides of outstretched arms are narrow). For a direction `d` ([`find_along`]):
//! 1. heights `t = p·d`, extent `E` of the cloud along `d` (steps 1–6 look at every `k`-th
//!    point only, at most 16,384 of them; step 7 takes the base's points among all);
//! 2. *flat points*: normal within [`BaseOptions::flat_angle`] of `d` and height in the lowest
//!    [`BaseOptions::max_height`]`·E`;
//! 3. their heights are binned in bins of `E/200`; the window of three bins with the most
//!    flat points is the **top band**;
//! 4. `d` is replaced by the band's mean normal and steps 1–3 are done once more (a tilted
//!    scan: the top face gives the true up). The first time, step 2 accepts normals within
//!    [`BaseOptions::hint_angle`] instead, so that a direction up to that far from the top
//!    face's normal still finds it;
//! 5. the band is a base's top when it holds at least [`BaseOptions::min_share`] of all
//!    points and is wide in both directions of its plane: its smaller extent is at least
//!    [`BaseOptions::min_width`]`·E` (this rejects an arm's underside);
//! 6. what lies below the band is a plinth's body, a prism or a slab: at least
//!    [`BaseOptions::min_prism`] of the points more than `E/100` below it have side-wall or
//!    bottom normals (within 20° of horizontal, or of straight down). Measured on
//!    `../shared/data`: 84–99% on the eight plinths; 37% on a seated synthetic figure whose
//!    thighs' undersides passed steps 1–5;
//! 7. the base is every point below the band's mean height plus a margin of
//!    `max(3σ, E/200)` (σ the band's spread of heights), when that is at most
//!    [`BaseOptions::max_share`] of the points.
//!
//! Outward normals at the bottom of a cloud point down, so an upward-facing flat band near the
//! bottom along `d` is a step on which something stands: the plinth's top, not its bottom
//! face. Without an up hint ([`detect_base`]) the directions tried are `±` the cloud's
//! principal axes and the four peaks of a histogram of the normals (a cube map of 216 cells
//! of about 15°: a large flat face is such a peak), and the accepted band with the most
//! points wins; with a hint only the hint is tried, and the found up must stay within
//! [`BaseOptions::hint_angle`] of it. (The principal axes alone missed the plinth on 2 of 20
//! random synthetic poses: a bent figure on a plinth has no axis near the up.)
//!
//! On `../shared/data` (60k–100k points) the top band holds 2.4–12% of the points on the
//! plinth statues and at most 1.2% on the TOSCA shapes, the rigged meshes and synthetic
//! figures (measured while choosing `min_share` = 1.5%).

use crate::geometry::pca::pca;
use crate::math::{DVec3, Vec3};

/// Thresholds of the base detection (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct BaseOptions {
    /// Largest angle between a flat point's normal and the up direction (radians).
    pub flat_angle: f32,
    /// Part of the extent along up, from the bottom, where the top face may lie.
    pub max_height: f32,
    /// Least share of all points in the top band.
    pub min_share: f32,
    /// Least width of the top band in both directions, as a share of the extent along up.
    pub min_width: f32,
    /// Largest share of all points in the base.
    pub max_share: f32,
    /// Least share, among the base's points more than 1% of the extent below the top face,
    /// of side-wall or bottom normals (within 20° of horizontal, or of straight down).
    pub min_prism: f32,
    /// Largest angle between an up hint and the found up (radians).
    pub hint_angle: f32,
}

impl Default for BaseOptions {
    fn default() -> Self {
        BaseOptions {
            flat_angle: 15f32.to_radians(),
            max_height: 0.35,
            min_share: 0.015,
            min_width: 0.15,
            max_share: 0.6,
            min_prism: 0.7,
            hint_angle: 30f32.to_radians(),
        }
    }
}

/// A detected base.
#[derive(Clone, Debug, PartialEq)]
pub struct Base {
    /// Unit up direction: the normal of the base's top face, pointing to the figure.
    pub up: Vec3,
    /// Height `p·up` of the top face.
    pub top: f32,
    /// Points with `p·up` below this belong to the base (`top` plus the margin).
    pub cut: f32,
    /// Share of all points in the top band (the score that chose this direction).
    pub band_share: f32,
    /// Indices of the base's points, increasing.
    pub points: Vec<u32>,
}

impl Base {
    /// `true` for the points of the base, `false` for the figure's (`n` points).
    pub fn mask(&self, n: usize) -> Vec<bool> {
        let mut m = vec![false; n];
        for &i in &self.points {
            if let Some(v) = m.get_mut(i as usize) {
                *v = true;
            }
        }
        m
    }
}

/// Number of height bins over the extent along up.
const BINS: f32 = 200.0;

/// Cells per face edge of the cube map that bins the normals ([`normal_peaks`]).
const CUBE: usize = 6;
/// Directions taken from the normals' histogram.
const PEAKS: usize = 4;

/// The mean normals of the `PEAKS` fullest cells of a cube map of the normals (6 faces of
/// `CUBE × CUBE` cells, about 15° each): a flat face is a peak of this histogram, whatever the
/// figure's shape does to its principal axes.
fn normal_peaks(normals: &[Vec3]) -> Vec<Vec3> {
    let cells = 6 * CUBE * CUBE;
    let mut count = vec![0usize; cells];
    let mut sum = vec![DVec3::ZERO; cells];
    for n in normals {
        let a = n.abs();
        let (face, u, v, m) = if a.x >= a.y && a.x >= a.z {
            (if n.x > 0.0 { 0 } else { 1 }, n.y, n.z, a.x)
        } else if a.y >= a.z {
            (if n.y > 0.0 { 2 } else { 3 }, n.x, n.z, a.y)
        } else {
            (if n.z > 0.0 { 4 } else { 5 }, n.x, n.y, a.z)
        };
        if !(m > 0.0) {
            continue;
        }
        let cell = |t: f32| (((t / m + 1.0) * 0.5 * CUBE as f32) as usize).min(CUBE - 1);
        let k = face * CUBE * CUBE + cell(u) * CUBE + cell(v);
        count[k] += 1;
        sum[k] += n.as_dvec3();
    }
    let mut order: Vec<usize> = (0..cells).filter(|&k| count[k] > 0).collect();
    order.sort_by(|&a, &b| count[b].cmp(&count[a]).then(a.cmp(&b)));
    order
        .iter()
        .take(PEAKS)
        .filter_map(|&k| sum[k].normalize_or_zero().as_vec3().try_normalize())
        .collect()
}

/// The directions tried: the hint alone, or else `±` each principal axis of `positions` and
/// the peaks of the normals' histogram (see the module docs).
pub fn directions(positions: &[Vec3], normals: &[Vec3], up_hint: Option<Vec3>) -> Vec<Vec3> {
    if let Some(u) = up_hint.and_then(|u| u.try_normalize()) {
        return vec![u];
    }
    let mut dirs: Vec<Vec3> = match pca(positions) {
        Some(p) => p.axes.iter().flat_map(|&a| [a, -a]).collect(),
        None => Vec::new(),
    };
    dirs.extend(normal_peaks(normals));
    dirs
}

/// The top band along `d` (steps 1–3 of the module docs): its mean normal, mean height,
/// spread of heights, point count and the extent of the cloud along `d`.
struct Band {
    normal: Vec3,
    height: f64,
    spread: f64,
    count: usize,
    extent: f64,
    members: Vec<u32>,
}

fn band_along(
    positions: &[Vec3],
    normals: &[Vec3],
    d: Vec3,
    angle: f32,
    opts: &BaseOptions,
) -> Option<Band> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for p in positions {
        let t = p.dot(d) as f64;
        lo = lo.min(t);
        hi = hi.max(t);
    }
    let extent = hi - lo;
    if !(extent > 0.0) {
        return None;
    }
    let w = extent / BINS as f64;
    let cos = angle.cos();
    let limit = opts.max_height as f64 * extent;
    let n_bins = (limit / w).ceil() as usize + 1;
    let mut hist = vec![0usize; n_bins];
    for (p, n) in positions.iter().zip(normals) {
        let t = p.dot(d) as f64 - lo;
        if n.dot(d) > cos && t < limit {
            hist[((t / w) as usize).min(n_bins - 1)] += 1;
        }
    }
    if n_bins < 3 {
        return None;
    }
    let mut best = (0usize, 0usize);
    for k in 0..n_bins - 2 {
        let s = hist[k] + hist[k + 1] + hist[k + 2];
        if s > best.1 {
            best = (k, s);
        }
    }
    if best.1 == 0 {
        return None;
    }
    let (b0, b1) = (lo + best.0 as f64 * w, lo + (best.0 + 3) as f64 * w);
    let mut members = Vec::with_capacity(best.1);
    let (mut nsum, mut tsum, mut t2sum) = (DVec3::ZERO, 0.0f64, 0.0f64);
    for (i, (p, n)) in positions.iter().zip(normals).enumerate() {
        let t = p.dot(d) as f64;
        if n.dot(d) > cos && t >= b0 && t < b1 {
            members.push(i as u32);
            nsum += n.as_dvec3();
            tsum += t;
            t2sum += t * t;
        }
    }
    let count = members.len();
    if count == 0 {
        return None;
    }
    let mean = tsum / count as f64;
    Some(Band {
        normal: nsum.normalize_or_zero().as_vec3(),
        height: mean,
        spread: (t2sum / count as f64 - mean * mean).max(0.0).sqrt(),
        count,
        extent,
        members,
    })
}

/// Smaller width of `members` in the plane orthogonal to `d` (extent along the minor
/// principal axis of the projected points).
fn band_width(positions: &[Vec3], members: &[u32], d: Vec3) -> f32 {
    let projected: Vec<Vec3> = members
        .iter()
        .map(|&i| {
            let p = positions[i as usize];
            p - d * p.dot(d)
        })
        .collect();
    let Some(frame) = pca(&projected) else {
        return 0.0;
    };
    // The smallest-variance axis is `d` itself (zero spread); the in-plane minor axis is the
    // second one.
    let axis = frame.axes[1];
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for p in &projected {
        let x = p.dot(axis);
        lo = lo.min(x);
        hi = hi.max(x);
    }
    (hi - lo).max(0.0)
}

/// Points looked at to find the base (a stride through the cloud): the shares and widths
/// it measures need no more, and each direction tried then stays well inside a
/// registration's work unit on 100k points.
const SAMPLE_POINTS: usize = 16_384;

/// Every `k`-th point and normal, `k` the least stride leaving at most `SAMPLE_POINTS`.
fn sample(positions: &[Vec3], normals: &[Vec3]) -> (Vec<Vec3>, Vec<Vec3>) {
    let k = positions.len().div_ceil(SAMPLE_POINTS).max(1);
    (
        positions.iter().step_by(k).copied().collect(),
        normals.iter().step_by(k).copied().collect(),
    )
}

/// The base whose top face faces `d` (steps 1–7 of the module docs), if any.
pub fn find_along(
    positions: &[Vec3],
    normals: &[Vec3],
    d: Vec3,
    opts: &BaseOptions,
) -> Option<Base> {
    if positions.is_empty() || normals.len() != positions.len() {
        return None;
    }
    let (sp, sn) = sample(positions, normals);
    find_in(positions, (&sp, &sn), d, opts)
}

/// [`find_along`] measuring the band on `sample` (points and normals of `positions`).
fn find_in(
    positions: &[Vec3],
    (sp, sn): (&[Vec3], &[Vec3]),
    d: Vec3,
    opts: &BaseOptions,
) -> Option<Base> {
    let n = positions.len();
    let d0 = d.try_normalize()?;
    // A first look with the hint's tolerance (a tilted direction still sees the top face's
    // normals), then the band along the mean normal found.
    let wide = opts.flat_angle.max(opts.hint_angle);
    let first = band_along(sp, sn, d0, wide, opts)?;
    let up = first.normal.try_normalize()?;
    let band = band_along(sp, sn, up, opts.flat_angle, opts)?;
    let share = band.count as f32 / sp.len() as f32;
    if share < opts.min_share {
        return None;
    }
    if band_width(sp, &band.members, up) < opts.min_width * band.extent as f32 {
        return None;
    }
    let top = band.height;
    let (sin20, cos20) = (20f32.to_radians().sin(), 20f32.to_radians().cos());
    let (mut below, mut prism) = (0usize, 0usize);
    for (p, nrm) in sp.iter().zip(sn) {
        if (p.dot(up) as f64) < top - 0.01 * band.extent {
            below += 1;
            let c = nrm.dot(up);
            if c.abs() < sin20 || c < -cos20 {
                prism += 1;
            }
        }
    }
    if (prism as f32) < opts.min_prism * below as f32 {
        return None;
    }
    let cut = top + (3.0 * band.spread).max(band.extent / BINS as f64);
    let points: Vec<u32> = (0..n as u32)
        .filter(|&i| (positions[i as usize].dot(up) as f64) < cut)
        .collect();
    if points.len() as f32 > opts.max_share * n as f32 {
        return None;
    }
    Some(Base {
        up,
        top: top as f32,
        cut: cut as f32,
        band_share: share,
        points,
    })
}

/// The statue's base, if it has one (see the module docs). `up_hint`, when given, is the
/// only direction tried, and a base whose top faces more than
/// [`BaseOptions::hint_angle`] away from it is refused.
pub fn detect_base(
    positions: &[Vec3],
    normals: &[Vec3],
    up_hint: Option<Vec3>,
    opts: &BaseOptions,
) -> Option<Base> {
    let r: Result<_, std::convert::Infallible> =
        detect_base_stepwise(positions, normals, up_hint, opts, || Ok(()));
    r.unwrap_or_else(|never| match never {})
}

/// [`detect_base`] calling `between` once the directions are chosen and after each direction
/// tried (a registration's work unit, which may stop it with an error).
pub fn detect_base_stepwise<E>(
    positions: &[Vec3],
    normals: &[Vec3],
    up_hint: Option<Vec3>,
    opts: &BaseOptions,
    mut between: impl FnMut() -> Result<(), E>,
) -> Result<Option<Base>, E> {
    if positions.is_empty() || normals.len() != positions.len() {
        return Ok(None);
    }
    let (sp, sn) = sample(positions, normals);
    let mut best: Option<Base> = None;
    let dirs = directions(&sp, &sn, up_hint);
    between()?;
    for d in dirs {
        let found = find_in(positions, (&sp, &sn), d, opts)
            .filter(|b| up_hint.is_none() || b.up.dot(d) >= opts.hint_angle.cos());
        if let Some(b) = found
            && best.as_ref().is_none_or(|x| b.band_share > x.band_share)
        {
            best = Some(b);
        }
        between()?;
    }
    Ok(best)
}
