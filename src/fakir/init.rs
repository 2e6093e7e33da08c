//! Initial placement of the template (thesis §2.4.2, §2.6.4).
//!
//! The papers need one click on the pelvis and note that the bounding-box centre fails on a
//! lying figure (fig. 2.25). We do this automatically and for any template:
//!
//! 1. **Principal frames.** The template's rest pose is sampled on its envelope and both it and
//!    the cloud get a PCA frame (centroid, axes by decreasing variance).
//! 2. **Scale**: the ratio of the extents along the first principal axis (the body axis for a
//!    standing human, the head–tail axis for a quadruped). With an up hint, the ratio of the
//!    extents along the up axis (cloud) and the template's `+Y`.
//! 3. **Candidate orientations**: every proper rotation taking the template's principal axes to
//!    the cloud's, up to the sign of each axis and the order of the two minor axes (8
//!    candidates); with an up hint, the template's up is sent to the hint and the facing
//!    direction takes 8 headings about it.
//!    **A facing hint** (our addition: a curator knows where a statue faces; `front` in
//!    [`candidates`]) keeps only the headings near it: with an up hint, three headings
//!    [`FRONT_SPREAD`] apart centred on the hint; without one, the principal-axis candidates
//!    whose facing lies within 60° of it (all of them when none does). On an armless figure
//!    (the *Venus de Milo*) the sphere-mesh trunk is round and nothing else tells its heading:
//!    the automatic choice turned it by 90°.
//!    **The breadth cue** (our addition) stands in for the hint when the registration knows
//!    the figure armless ([`armless_shoulders`]: the limbs of [`Template::bust`] that hang
//!    above the root are lost from the start, those below it are there; the pair hypothesis
//!    of [`super::pair`] and `register --missing l_upper_arm,r_upper_arm`). A chest is wider
//!    than it is deep: the major level axis of the points of a band just below the shoulders
//!    ([`breadth_axis`], when its spread is at least [`BREADTH_RATIO`] times the spread across
//!    it) is the figure's left-right axis, so it faces across it, one way or the other. With
//!    an up axis, three headings [`FRONT_SPREAD`] apart are tried about each way (6
//!    candidates; five about each way, 40° either side, gave the *Venus* the same fit);
//!    without one, the principal-axis candidates whose left-right axis lies within 45° of the
//!    breadth their own up finds. Which way remains the search's and the anatomy's to decide
//!    (steps 5 and 6). On the *Venus* (`register` with no hint, her pair fit; release,
//!    2026-12-03) the shoulders' line now faces 33° and the hips' 49° from her front (+Z),
//!    where they faced 51° and 90° (the arms were completed at her front and back); told
//!    `--front z`, 37° and −5°, at a lower mean distance (0.819% of her size against 0.932%).
//!    Measured on the chest bands (2026-12-03): the
//!    statues of `../shared/data` standing upright (the *Venus*, *Maria*, the *Dancing
//!    Girl*, *Theodoric*, *Zenobia*, the *Faun*) have ratios 1.3–2.4 with the breadth within
//!    30° of their left-right axis (the *Venus*' chest is turned 30° from her hips);
//!    synthetic Venuses (`synth --rigid --height 1.7`, both upper arms cut at 0.1–0.3) 1.32,
//!    1.32 and 1.53 with the breadth within 12° (seeds 22, 23, 27), and 1.06–1.18 on seeds
//!    24–26, where the cue stays silent (seed 24's band, 1.06, is the one whose axis is wrong).
//! 4. **Placement**: the root goes where the template's root sits relative to its centroid,
//!    mapped by the candidate and the scale, or at the given anchor.
//! 5. **Choice**: a short registration (one whole-skeleton iteration on a small subsample)
//!    from each candidate ranks them; the best few then get a full registration (see
//!    [`super::registration`]). Both are scored two-sidedly: the mean distance of the points to the model
//!    (eq. 2.16) plus the mean distance of the model's visible surface to the points
//!    ([`super::solver::Solver::occupancy`]); the lowest score wins, ties to the earlier
//!    candidate. The one-sided distance alone cannot tell a flipped skeleton whose bones
//!    still cover the points from the right one; the flipped one leaves bone surface in
//!    empty space.
//! 6. **Anatomy decides near-ties**: a figure registered facing backwards can fit as well as
//!    the right one (a human's sphere-mesh is nearly front/back symmetric; only feet, knees
//!    and elbows tell), which would swap left and right. Among the full registrations whose
//!    two-sided score is within 50% of the best, the one whose pose lies least outside the
//!    template's joint ranges ([`implausibility`]) wins.
//! 7. **Scale restarts** (our choice): the extent along the body axis is a crude scale —
//!    raised arms lengthen it, a crouch shortens it — and the trunk (pelvis block and spine)
//!    settles in the minimum nearest its start, which neither the chain passes nor the limb
//!    seeding leave. The chosen finalist's orientation is therefore registered again from
//!    `rescales` (default ×0.88 and ×1.12) of its scale ([`rescaled`]), and the lowest
//!    two-sided score wins (see [`super::registration`]). They start from the orientation
//!    already chosen, so they do not reopen the front/back question: started from the best
//!    short candidate instead, a backwards fit at another scale won on two statues of 32.

use crate::anatomy::{Skeleton, Template};
use crate::geometry::pca::{Pca, pca};
use crate::math::{Quat, Vec3};
use crate::rng::Rng;
use std::sync::Arc;

/// How to place the template before registration.
#[derive(Clone, Debug, Default)]
pub enum Init {
    /// Fully automatic (see the module docs).
    #[default]
    Auto,
    /// Automatic orientation, root at `anchor` (e.g. a tapped pelvis), optional up axis.
    Anchor { anchor: Vec3, up: Option<Vec3> },
    /// Automatic, with the statue's up axis known.
    Up(Vec3),
    /// Start from this skeleton as is.
    Given(Skeleton),
}

/// A candidate placement.
#[derive(Clone, Debug)]
pub struct Candidate {
    pub skeleton: Skeleton,
    /// Template units → statue units.
    pub scale: f32,
}

/// Rest-pose envelope samples of a template (deterministic).
pub fn template_samples(t: &Arc<Template>, n: usize) -> Vec<Vec3> {
    let rest = Skeleton::rest(t.clone()).pose();
    let mut rng = Rng::new(0x5eed);
    crate::synth::sample_envelope(&rest.bones, n, t.height, &mut rng).0
}

fn extent_along(points: &[Vec3], c: Vec3, axis: Vec3) -> f32 {
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for p in points {
        let x = (*p - c).dot(axis);
        lo = lo.min(x);
        hi = hi.max(x);
    }
    (hi - lo).max(0.0)
}

/// The candidate placements for `points` (see the module docs).
///
/// `lost` flags the bones known to be lost from the start (empty: none); when they leave the
/// trunk armless and no facing hint is given, the breadth cue applies (step 3).
pub fn candidates(
    t: &Arc<Template>,
    points: &[Vec3],
    init: &Init,
    front: Option<Vec3>,
    lost: &[bool],
) -> Vec<Candidate> {
    let samples = template_samples(t, 4000);
    let (Some(tp), Some(cp)) = (pca(&samples), pca(points)) else {
        return Vec::new();
    };
    // The breadth cue: where the shoulders of an armless figure lie (share of its height).
    let shoulders = if front.is_none() {
        armless_shoulders(t, &samples, lost)
    } else {
        None
    };
    let root_rest = t.joints[t.root].rest;
    let up_hint = match init {
        Init::Up(u) => Some(*u),
        Init::Anchor { up, .. } => *up,
        _ => None,
    };
    let anchor = match init {
        Init::Anchor { anchor, .. } => Some(*anchor),
        _ => None,
    };
    let mut rotations: Vec<Quat> = Vec::new();
    let scale;
    match up_hint {
        Some(up) if up.length() > 1e-9 => {
            let up = up.normalize();
            scale = extent_along(points, cp.centroid, up)
                / extent_along(&samples, tp.centroid, Vec3::Y).max(1e-9);
            let base = crate::geometry::frames::rotation_arc(Vec3::Y, up);
            // The facing hint, level with the up axis.
            let facing = front
                .map(|f| f - f.dot(up) * up)
                .filter(|f| f.length() > 1e-3 * front.map_or(1.0, |g| g.length()));
            // An armless figure faces across its breadth, one way or the other.
            let across = shoulders
                .and_then(|f| breadth_axis(points, up, f))
                .map(|m| up.cross(m).normalize());
            match (facing, across) {
                (Some(f), _) => rotations.extend(headings_around(base, up, f)),
                (None, Some(f)) => {
                    rotations.extend(headings_around(base, up, f));
                    rotations.extend(headings_around(base, up, -f));
                }
                (None, None) => {
                    for k in 0..8 {
                        let heading =
                            Quat::from_axis_angle(up, k as f32 * std::f32::consts::TAU / 8.0);
                        rotations.push((heading * base).normalize());
                    }
                }
            }
        }
        _ => {
            scale = extent_along(points, cp.centroid, cp.axes[0])
                / extent_along(&samples, tp.centroid, tp.axes[0]).max(1e-9);
            rotations = axis_alignments(&tp, &cp);
            if let Some(f) = shoulders {
                // Each alignment's own up tells where its shoulders are.
                let across: Vec<Quat> = rotations
                    .iter()
                    .copied()
                    .filter(|q| {
                        breadth_axis(points, *q * Vec3::Y, f)
                            .is_some_and(|m| (*q * Vec3::X).dot(m).abs() >= ACROSS_COS)
                    })
                    .collect();
                if !across.is_empty() {
                    rotations = across;
                }
            }
            if let Some(f) = front.filter(|f| f.length() > 1e-9) {
                let f = f.normalize();
                let near: Vec<Quat> = rotations
                    .iter()
                    .copied()
                    .filter(|q| (*q * Vec3::Z).dot(f) >= 0.5)
                    .collect();
                if !near.is_empty() {
                    rotations = near;
                }
            }
        }
    }
    rotations
        .into_iter()
        .map(|q| {
            let root = match anchor {
                Some(a) => a,
                None => cp.centroid + q * ((root_rest - tp.centroid) * scale),
            };
            Candidate {
                skeleton: Skeleton::rest_placed(t.clone(), root, q, scale),
                scale,
            }
        })
        .collect()
}

/// Angle between the headings tried around a facing hint ([`candidates`]): 20°.
pub const FRONT_SPREAD: f32 = 20.0 * std::f32::consts::PI / 180.0;

/// Three headings about `up`, [`FRONT_SPREAD`] apart, centred on facing `f` (level with `up`),
/// for the template placed upright by `base`.
fn headings_around(base: Quat, up: Vec3, f: Vec3) -> [Quat; 3] {
    let (now, f) = (base * Vec3::Z, f.normalize());
    let angle = now.cross(f).dot(up).atan2(now.dot(f));
    [-1.0f32, 0.0, 1.0].map(|k| {
        let heading = Quat::from_axis_angle(up, angle + k * FRONT_SPREAD);
        (heading * base).normalize()
    })
}

/// Least ratio of the major to the minor spread (standard deviations) of the points of the
/// breadth band for the band to tell the figure's breadth ([`breadth_axis`]).
pub const BREADTH_RATIO: f32 = 1.2;

/// Height of the breadth band, as a share of the figure's extent along its up: the band ends
/// [`BREADTH_GAP`] below the shoulders.
pub const BREADTH_BAND: f32 = 0.1;

/// Gap between the breadth band's top and the shoulders (share of the extent).
pub const BREADTH_GAP: f32 = 0.02;

/// Least `|cos|` between a principal-axis candidate's left-right axis and the breadth for the
/// candidate to be kept by the breadth cue (45°).
pub const ACROSS_COS: f32 = std::f32::consts::FRAC_1_SQRT_2;

/// The breadth cue's shoulder height (share of the template's rest extent along `+Y`, from
/// its lowest sample) when `lost` leaves the figure **armless**: the bones of
/// [`Template::bust`] that start above the template's root (a human's upper arms) are all
/// lost, and those that start below it (its thighs) are all there. `None` otherwise, or when
/// the template names no such bones (`samples`: [`template_samples`]).
pub fn armless_shoulders(t: &Template, samples: &[Vec3], lost: &[bool]) -> Option<f32> {
    let root_y = t.joints[t.root].rest.y;
    let bust: Vec<usize> = t.bust.iter().filter_map(|n| t.bone_index(n)).collect();
    let (upper, lower): (Vec<usize>, Vec<usize>) = bust
        .iter()
        .partition(|&&b| t.joints[t.bones[b].from].rest.y > root_y);
    let is_lost = |b: &usize| lost.get(*b).copied().unwrap_or(false);
    if upper.is_empty() || !upper.iter().all(is_lost) || lower.iter().any(is_lost) {
        return None;
    }
    let (lo, hi) = samples.iter().fold((f32::MAX, f32::MIN), |(lo, hi), p| {
        (lo.min(p.y), hi.max(p.y))
    });
    let y = upper
        .iter()
        .map(|&b| t.joints[t.bones[b].from].rest.y)
        .sum::<f32>()
        / upper.len() as f32;
    (hi > lo).then(|| (y - lo) / (hi - lo))
}

/// The figure's **breadth**: the major axis, level with `up`, of the points lying between
/// `shoulders − BREADTH_GAP − BREADTH_BAND` and `shoulders − BREADTH_GAP` of their extent
/// along `up` (the chest below the shoulders), when its spread there is at least
/// [`BREADTH_RATIO`] times the spread across it; `None` otherwise (a round band, too few
/// points, a degenerate `up`). The sign of the axis is arbitrary.
pub fn breadth_axis(points: &[Vec3], up: Vec3, shoulders: f32) -> Option<Vec3> {
    let up = up.try_normalize()?;
    let (lo, hi) = points.iter().fold((f32::MAX, f32::MIN), |(lo, hi), p| {
        let h = p.dot(up);
        (lo.min(h), hi.max(h))
    });
    if hi <= lo {
        return None;
    }
    let top = lo + (shoulders - BREADTH_GAP) * (hi - lo);
    let bottom = top - BREADTH_BAND * (hi - lo);
    let e1 = up.any_orthonormal_vector();
    let e2 = up.cross(e1);
    let band: Vec<(f64, f64)> = points
        .iter()
        .filter(|p| (bottom..=top).contains(&p.dot(up)))
        .map(|p| (p.dot(e1) as f64, p.dot(e2) as f64))
        .collect();
    if band.len() < 10 {
        return None;
    }
    let n = band.len() as f64;
    let (mx, my) = band
        .iter()
        .fold((0.0, 0.0), |(x, y), &(a, b)| (x + a, y + b));
    let (mx, my) = (mx / n, my / n);
    let (mut sxx, mut sxy, mut syy) = (0.0f64, 0.0f64, 0.0f64);
    for &(a, b) in &band {
        let (dx, dy) = (a - mx, b - my);
        sxx += dx * dx;
        sxy += dx * dy;
        syy += dy * dy;
    }
    // Eigenvalues of the 2 × 2 covariance.
    let (tr, det) = (sxx + syy, sxx * syy - sxy * sxy);
    let disc = (0.25 * tr * tr - det).max(0.0).sqrt();
    let (major, minor) = (0.5 * tr + disc, (0.5 * tr - disc).max(0.0));
    if major <= 0.0 || major < (BREADTH_RATIO as f64).powi(2) * minor {
        return None;
    }
    // Eigenvector of `major`: (sxy, major − sxx) or (major − syy, sxy), the longer one.
    let (a, b) = if (major - sxx).abs() > (major - syy).abs() {
        (sxy, major - sxx)
    } else {
        (major - syy, sxy)
    };
    (e1 * a as f32 + e2 * b as f32).try_normalize()
}

/// `c` placed again at `f` times its scale, with the same orientation: its root moves away
/// from (or towards) `pivot` by `f` — the cloud's centroid, which the automatic placement
/// maps the template's centroid to, or the given anchor, which then stays where it is.
/// Used for the registration's scale restarts (see [`super::registration`]).
pub fn rescaled(c: &Candidate, pivot: Vec3, f: f32) -> Candidate {
    let s = &c.skeleton;
    let root = pivot + (s.root_position - pivot) * f;
    Candidate {
        skeleton: Skeleton::rest_placed(s.template.clone(), root, s.root_rotation, c.scale * f),
        scale: c.scale * f,
    }
}

/// Rotations sending the template's major principal axis onto the cloud's, either way, each
/// followed by 8 turns (45° apart) about the cloud's major axis: 16 candidates. (Aligning the
/// minor axes too, as a first version did, gives only 90° steps; a figure whose arms or legs
/// spread diagonally has minor axes that say little about its facing.)
fn axis_alignments(tp: &Pca, cp: &Pca) -> Vec<Quat> {
    let mut out = Vec::new();
    for s0 in [1.0f32, -1.0] {
        let target = s0 * cp.axes[0];
        let base = crate::geometry::frames::rotation_arc(tp.axes[0], target);
        // Start the turns from the alignment of the second axes, so the first candidate of
        // each sign is the plain principal-frame alignment.
        let second = base * tp.axes[1];
        let want = cp.axes[1] - cp.axes[1].dot(target) * target;
        let start = if want.length() > 1e-6 && second.length() > 1e-6 {
            let (a, b) = (second.normalize(), want.normalize());
            a.cross(b).dot(target).atan2(a.dot(b))
        } else {
            0.0
        };
        for k in 0..8 {
            let turn =
                Quat::from_axis_angle(target, start + k as f32 * std::f32::consts::TAU / 8.0);
            out.push((turn * base).normalize());
        }
    }
    out
}

/// How far the direction `dir` of bone `b`, expressed in the template's rest frame (its
/// parent at rest), lies outside the bone's joint range (radians): the angle to the nearest
/// direction of the hinge arc `bend` about `bend_axis` (or to the rest direction), minus the
/// `swing` cone. Zero for bones without a range.
pub fn range_excess(t: &Template, rest_frames: &[Quat], b: usize, dir: Vec3) -> f32 {
    let def = &t.bones[b];
    if def.kind != crate::anatomy::BoneKind::Free || (def.bend.is_none() && def.swing_deg <= 0.0) {
        return 0.0;
    }
    let axis = rest_frames[b] * Vec3::X;
    let angle_to = |d: Vec3| -> f32 { d.dot(dir).clamp(-1.0, 1.0).acos() };
    let best = match def.bend {
        Some((bend_axis, lo, hi)) => (0..=12)
            .map(|k| {
                angle_to(
                    Quat::from_axis_angle(
                        bend_axis,
                        (lo + (hi - lo) * k as f32 / 12.0).to_radians(),
                    ) * axis,
                )
            })
            .fold(f32::INFINITY, f32::min),
        None => angle_to(axis),
    };
    (best - def.swing_deg.to_radians()).max(0.0)
}

/// How far a skeleton's pose lies outside the template's joint ranges (radians, summed over
/// bones, [`range_excess`] of each bone's direction relative to its parent, compared at the
/// rest pose), measured on the skeleton untwisted
/// ([`super::world::WorldSkeleton::untwisted`]): a fit's twists are left to chance, and a
/// hinge's range is stated in its parent's frame. Nearly zero for any pose the synthetic
/// generator can draw; a figure fitted facing backwards pays for its feet and knees.
pub fn implausibility(s: &Skeleton) -> f64 {
    let s = &super::world::WorldSkeleton::from_skeleton(s)
        .untwisted()
        .to_skeleton();
    let t = &s.template;
    let rest = Skeleton::rest(s.template.clone());
    let frames = crate::anatomy::skeleton::rest_frames(t);
    let mut total = 0.0f64;
    for i in 0..t.bones.len() {
        let local = rest.bones[i].rotation.inverse() * s.bones[i].rotation;
        let world_at_rest = frames[i] * local * frames[i].inverse();
        let dir = world_at_rest * (frames[i] * Vec3::X);
        total += range_excess(t, &frames, i, dir) as f64;
    }
    total
}
