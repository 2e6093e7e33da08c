//! Which bones of a fitted statue are really there: **support** (issue: "how much of its
//! surface is covered by scan points, relative to the local sampling density") and the
//! completion of missing bones to a plausible size and pose (thesis ch. 5).
//!
//! **Why the fitted size is not enough.** FAKIR shrinks the bones of a missing limb onto the
//! stump (their lengths and radii collapse to the solver's lower limits), and a collapsed bone
//! is "covered" by the stump's points. So each bone is judged at its **expected size**: its
//! mirror bone's fitted size when the mirror limb is itself healthy, otherwise the template's
//! proportions scaled to the statue (the median ratio of fitted to template lengths over the
//! healthy bones). A bone whose fitted length is below [`SHRUNK`] × the expected one is
//! examined at the expected size, along its fitted direction, or — when it collapsed to
//! nothing — along its mirror's (mirrored) or rest direction.
//!
//! **Coverage.** [`SAMPLES`] area-uniform samples of the bone's surface, keeping only the
//! *visible* ones (outside every other bone), are each covered when a scan point lies within
//! `2.5 ρ` (ρ the mean nearest-neighbour spacing of the scan) or half the bone's mean radius
//! (fitted radii are rarely better than that),
//! whichever is larger. `coverage` is the covered fraction; `reach` the axial fraction (from
//! `c1`) up to which the bone is covered (last of [`BINS`] axial bins with ≥ 50% coverage,
//! counted from `c1` without a gap). A bone is **missing** below [`MISSING`] = 0.4 coverage and
//! **partial** below [`PARTIAL`] (tested on synthetic statues with cut limbs).
//!
//! **Completion.** Missing bones get their expected size and the pose of their mirror
//! (reflected across the statue's sagittal plane, the fitted root frame's YZ plane) when the
//! mirror is healthy, else the template's rest pose relative to the bone they hang on.

use crate::anatomy::{Skeleton, Template};
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::geometry::Bone;
use crate::geometry::frames::rotation_arc;
use crate::math::{Quat, Vec3};
use crate::rng::Rng;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;
use serde::Serialize;

/// Surface samples per bone.
pub const SAMPLES: usize = 600;

/// Samples examined together by one parallel task ([`coverage_of`]).
const SAMPLE_CHUNK: usize = 100;

/// Axial bins for `reach`.
pub const BINS: usize = 10;
/// Coverage below which a bone is missing.
pub const MISSING: f32 = 0.4;
/// Coverage below which a bone is partial.
pub const PARTIAL: f32 = 0.75;
/// A fitted length below this fraction of the expected one means the bone collapsed.
pub const SHRUNK: f32 = 0.7;

/// The support of one bone.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BoneSupport {
    pub bone: String,
    /// Fraction of the visible surface (at the expected size) covered by scan points.
    pub coverage: f32,
    /// Axial fraction from `c1` up to which the bone is covered.
    pub reach: f32,
    pub missing: bool,
    pub partial: bool,
    /// The fitted length had collapsed below [`SHRUNK`] × the expected length.
    pub shrunk: bool,
}

/// Mean nearest-neighbour spacing of a cloud (over at most 20k points): [`add_spacings`] over
/// every sampled point, divided by their number.
pub fn mean_spacing(points: &[Vec3], tree: &ImmutableKdTree<f32, 3>) -> f32 {
    let n = spacing_samples(points.len());
    let mut sum = 0.0;
    add_spacings(points, tree, 0..n, &mut sum);
    (sum / n.max(1) as f64) as f32
}

/// How many points [`mean_spacing`] averages over: every `(n / 20 000).max(1)`-th point.
pub fn spacing_samples(n: usize) -> usize {
    n.div_ceil(spacing_step(n))
}

fn spacing_step(n: usize) -> usize {
    (n / 20_000).max(1)
}

/// Sampled points per parallel chunk of [`add_spacings`].
pub const SPACING_CHUNK: usize = 256;

/// Adds to `sum` the nearest-neighbour distances of the sampled points `range` (indices among
/// the [`spacing_samples`] points that [`mean_spacing`] averages over), so that a caller can
/// cut the pass into work units. The distances are summed in fixed chunks of
/// [`SPACING_CHUNK`] sampled points (counted from 0), and the chunks' sums are added to `sum`
/// in order: slices whose bounds are multiples of the chunk give the same bytes as one call
/// over everything, on any number of threads.
pub fn add_spacings(
    points: &[Vec3],
    tree: &ImmutableKdTree<f32, 3>,
    range: std::ops::Range<usize>,
    sum: &mut f64,
) {
    let step = spacing_step(points.len());
    let end = range.end.min(spacing_samples(points.len()));
    let start = range.start.min(end);
    let chunk_sums: Vec<f64> = (start / SPACING_CHUNK..end.div_ceil(SPACING_CHUNK))
        .into_par_iter()
        .map(|c| {
            let from = (c * SPACING_CHUNK).max(start);
            let to = ((c + 1) * SPACING_CHUNK).min(end);
            (from..to)
                .map(|k| {
                    let r = tree
                        .query(&points[k * step].to_array())
                        .nearest_n::<SquaredEuclidean<f32>>(
                            std::num::NonZero::new(2).expect("2 > 0"),
                        )
                        .execute();
                    r.get(1).map_or(0.0, |n| n.distance.sqrt() as f64)
                })
                .sum::<f64>()
        })
        .collect();
    for c in chunk_sums {
        *sum += c;
    }
}

/// The statue's scale relative to its template: the median ratio of fitted to template lengths
/// over the bones known to be there (all of them when none is known lost: a collapsed or lost
/// bone says nothing of the statue's proportions); the root block's scale without any.
fn statue_scale(fitted: &Skeleton, healthy: Option<&[bool]>) -> f32 {
    let rest = Skeleton::rest(fitted.template.clone());
    let mut ratios: Vec<f32> = fitted
        .bones
        .iter()
        .zip(&rest.bones)
        .enumerate()
        .filter(|(k, _)| healthy.is_none_or(|h| h[*k]))
        .map(|(_, (f, r))| f.length / r.length.max(1e-12))
        .collect();
    if ratios.is_empty() {
        ratios.push(fitted.block_scale);
    }
    ratios.sort_by(f32::total_cmp);
    ratios[ratios.len() / 2]
}

/// Expected length and radii of every bone (see the module docs), and whether the fitted
/// bone had collapsed.
fn expected_sizes(
    fitted: &Skeleton,
    healthy: Option<&[bool]>,
) -> (Vec<(f32, f32, f32)>, Vec<bool>) {
    let t = &fitted.template;
    let rest = Skeleton::rest(t.clone());
    let scale = statue_scale(fitted, healthy);
    let templ: Vec<(f32, f32, f32)> = rest
        .bones
        .iter()
        .map(|b| (b.length * scale, b.r1 * scale, b.r2 * scale))
        .collect();
    let shrunk: Vec<bool> = fitted
        .bones
        .iter()
        .zip(&templ)
        .map(|(f, e)| f.length < SHRUNK * e.0)
        .collect();
    let mir = t.mirror_bones();
    let sizes = (0..t.bones.len())
        .map(|k| match mir[k] {
            Some(m) if healthy.map_or(!shrunk[m], |h| h[m]) => {
                let b = &fitted.bones[m];
                (b.length, b.r1, b.r2)
            }
            _ => templ[k],
        })
        .collect();
    (sizes, shrunk)
}

/// Reflects a world direction across the statue's sagittal plane (the root frame's YZ plane).
fn reflect(d: Vec3, root: Quat) -> Vec3 {
    let x = root * Vec3::X;
    d - 2.0 * d.dot(x) * x
}

/// A copy of `fitted` where every bone flagged in `redo` gets its expected size and the pose of
/// its healthy mirror (reflected) or its rest pose relative to its parent.
pub fn complete(fitted: &Skeleton, redo: &[bool]) -> Skeleton {
    complete_with(fitted, redo, None)
}

/// [`complete`] where the mirror bones known to be there are `healthy` (the registration
/// knows which limbs it found lost; a healthy limb 30% shorter than the template's
/// proportions is not shrunk). `None`: a mirror is healthy when it is neither redone nor
/// shrunk.
pub fn complete_with(fitted: &Skeleton, redo: &[bool], healthy: Option<&[bool]>) -> Skeleton {
    let t = &fitted.template;
    let (sizes, shrunk) = expected_sizes(fitted, healthy);
    let mir = t.mirror_bones();
    let rest = Skeleton::rest(t.clone());
    let fitted_pose = fitted.pose();
    let mut s = fitted.clone();
    for k in 0..t.bones.len() {
        if !redo[k] {
            continue;
        }
        let (l, r1, r2) = sizes[k];
        s.bones[k].length = l;
        s.bones[k].r1 = r1;
        s.bones[k].r2 = r2;
        // Pose: parents come first, so the parent's world frame is final.
        let posed = s.pose();
        let parent_frame = t.bones[k]
            .parent
            .map(|p| posed.frames[p])
            .unwrap_or(s.root_rotation);
        match mir[k] {
            Some(m) if healthy.map_or(!shrunk[m] && !redo[m], |h| h[m]) => {
                let want = reflect(fitted_pose.frames[m] * Vec3::X, fitted.root_rotation);
                let world_now = parent_frame * (rest.bones[k].rotation * Vec3::X);
                let world = rotation_arc(world_now, want) * parent_frame * rest.bones[k].rotation;
                s.bones[k].rotation = (parent_frame.inverse() * world).normalize();
            }
            _ => s.bones[k].rotation = rest.bones[k].rotation,
        }
    }
    s.enforce_constraints();
    s
}

/// [`complete_with`] for a restoration, with each bone cut part-way given back its length (our
/// choice; `crate::restore` and the kiosk's part swapping use it, while the registration's fit
/// keeps the bone as fitted, its support telling where the break is).
///
/// **Which bones.** A limb bone kept (not in `redo`, not a trunk bone) whose children are all
/// redone, fitted shorter than [`SHRUNK`] × the template's proportions at the statue's scale:
/// FAKIR shrank it onto its stump. It gets its mirror's fitted length when that mirror is kept
/// and not shrunk itself, along its fitted direction (radii kept); without such a mirror it
/// stays as fitted — the template's proportions alone would take the *Venus de Milo*'s
/// clavicles, whole but fitted at half the template's length, for shrunk ones and double them.
/// The lost bones then hang where the limb's joint was, not at the stump's end, and the
/// restored part grows from the stump ([`crate::restore::stump`]); their expected sizes are
/// [`complete_with`]'s over the lengthened skeleton.
///
/// **Measured** on 40 held-out synthetic statues cut part-way through a bone (`synth --rigid
/// --height 1.7 --cut bone:B@F`, registered by `register`): of the 20 cut bones kept with their
/// children lost, 16 were fitted at 0.49–0.88 of their true length, 10 of them flagged shrunk;
/// one whole bone with a lost child was flagged (seed 338, whose fit lost the wrong limb). It
/// acted on 9 of the 10 (one had no usable mirror): the cut bone's far joint moved nearer its
/// truth on 6 and farther on 3, the mean distance from 12.2% to 10.2% of the height (the
/// synthetic statues' left and right bones differ by up to ±30% each, so the mirror's length is
/// only a plausible one).
pub fn complete_cut(fitted: &Skeleton, redo: &[bool], healthy: Option<&[bool]>) -> Skeleton {
    let t = &fitted.template;
    let (_, shrunk) = expected_sizes(fitted, healthy);
    let trunk = super::solver::trunk_bones(t);
    let mir = t.mirror_bones();
    let kept = |k: usize| !redo.get(k).copied().unwrap_or(false);
    let mut s = fitted.clone();
    for (k, def) in t.bones.iter().enumerate() {
        if !kept(k) || trunk[k] || !shrunk[k] || def.children.is_empty() {
            continue;
        }
        if def.children.iter().any(|&c| kept(c)) {
            continue;
        }
        // Only a mirror tells: the template's proportions do not (the armless *Venus de
        // Milo*'s clavicles, whole, are fitted at half the template's).
        if let Some(m) = mir[k].filter(|&m| kept(m) && !shrunk[m]) {
            s.bones[k].length = s.bones[k].length.max(fitted.bones[m].length);
        }
    }
    complete_with(&s, redo, healthy)
}

/// The bones named in `names` and every bone they carry (a limb the statue is known to have
/// lost, [`super::RegistrationOptions::lost`]), flagged by index. Errors name the bone: an
/// unknown name (with the closest names), or a bone that is not a limb bone (the root block
/// and the trunk carry the rest of the figure and cannot be left out).
pub fn lost_from_names(t: &Template, names: &[String]) -> Result<Vec<bool>> {
    let trunk = super::solver::trunk_bones(t);
    let mut lost = vec![false; t.bones.len()];
    for name in names {
        let name = name.trim();
        let Some(b) = t.bone_index(name) else {
            let limbs: Vec<usize> = (0..t.bones.len()).filter(|&b| !trunk[b]).collect();
            return Err(Error::input(crate::anatomy::pose::unknown_bone(
                "missing bones",
                name,
                t,
                &limbs,
            )));
        };
        if trunk[b] {
            return Err(Error::input(format!(
                "missing bones: '{name}' is part of the trunk of template '{}'; only limb \
                 bones can be missing",
                t.name
            )));
        }
        for x in t.subtree(b) {
            lost[x] = true;
        }
    }
    Ok(lost)
}

/// Length of a collapsed bone, as a fraction of its length ([`collapse`]).
pub const COLLAPSED: f32 = 0.02;

/// Collapses the bones flagged in `lost` into the joint they hang from: a length of
/// [`COLLAPSED`] times theirs and a far radius of half their smaller one (the near radius is
/// the joint's, shared with the parent). A registration that knows a limb is lost starts
/// from this, so the lost bones neither stick out into empty space (the occupancy term) nor
/// hide other bones' surface; [`complete_with`] gives them their expected size at the end.
pub fn collapse(s: &mut Skeleton, lost: &[bool]) {
    let t = s.template.clone();
    for (k, def) in t.bones.iter().enumerate() {
        if !lost.get(k).copied().unwrap_or(false) {
            continue;
        }
        let parent_lost = def.parent.is_some_and(|p| lost[p]);
        let b = &mut s.bones[k];
        b.length *= COLLAPSED;
        let small = 0.5 * b.r1.min(b.r2);
        if parent_lost {
            b.r1 = small;
        }
        b.r2 = small;
    }
    // A lost bone's children are lost too: their near radius follows the collapsed joint.
    for (k, def) in t.bones.iter().enumerate() {
        if lost.get(k).copied().unwrap_or(false)
            && let Some(p) = def.parent
            && lost[p]
        {
            s.bones[k].r1 = s.bones[p].r2;
        }
    }
}

/// Support of every bone of `fitted` in `cloud`. Errors: an empty cloud.
pub fn support(cloud: &PointCloud, fitted: &Skeleton) -> Result<Vec<BoneSupport>> {
    let pts: Vec<[f32; 3]> = cloud.positions.iter().map(|p| p.to_array()).collect();
    if pts.is_empty() {
        return Err(Error::input("support: the cloud is empty"));
    }
    let tree = ImmutableKdTree::<f32, 3>::new_from_slice(&pts)
        .map_err(|e| Error::input(format!("support: k-d tree: {e:?}")))?;
    let rho = mean_spacing(&cloud.positions, &tree);
    let exam = SupportExam::new(&tree, rho, fitted);
    Ok((0..fitted.template.bones.len())
        .into_par_iter()
        .map(|k| exam.bone(k))
        .collect())
}

/// The support of a fit, bone by bone ([`SupportExam::bone`]), over points whose k-d tree
/// is given: the registration examines its own points one bone per work unit.
pub struct SupportExam<'a> {
    fitted: &'a Skeleton,
    tree: &'a ImmutableKdTree<f32, 3>,
    /// Mean nearest-neighbour spacing of the points.
    rho: f32,
    shrunk: Vec<bool>,
    /// The fit as it is, the fit with shrunk bones at their expected size, the fit with
    /// shrunk bones completed: each posed and prepared.
    exams: Vec<(
        crate::anatomy::Posed,
        Vec<crate::geometry::bone::PreparedBone>,
    )>,
}

impl<'a> SupportExam<'a> {
    /// Prepares the examination of `fitted` against the points of `tree` (non-empty), whose
    /// mean nearest-neighbour spacing is `rho` ([`mean_spacing`]).
    pub fn new(
        tree: &'a ImmutableKdTree<f32, 3>,
        rho: f32,
        fitted: &'a Skeleton,
    ) -> SupportExam<'a> {
        let (sizes, shrunk) = expected_sizes(fitted, None);
        // Shrunk bones are examined at their expected size, along their fitted direction and
        // along their completion direction (mirror or rest); the better coverage counts.
        let mut along_fit = fitted.clone();
        for (k, sh) in shrunk.iter().enumerate() {
            if *sh {
                (
                    along_fit.bones[k].length,
                    along_fit.bones[k].r1,
                    along_fit.bones[k].r2,
                ) = sizes[k];
            }
        }
        along_fit.enforce_constraints();
        let along_completion = complete(fitted, &shrunk);
        let exams = [fitted.clone(), along_fit, along_completion]
            .iter()
            .map(|s| {
                let posed = s.pose();
                let prepared = posed.bones.iter().map(Bone::prepare).collect();
                (posed, prepared)
            })
            .collect();
        SupportExam {
            fitted,
            tree,
            rho,
            shrunk,
            exams,
        }
    }

    /// The support of bone `k`: the best of its [`SupportExam::tries`].
    pub fn bone(&self, k: usize) -> BoneSupport {
        let best = self
            .tries(k)
            .iter()
            .fold((0.0, 0.0), |best, &e| better(best, self.coverage(k, e)));
        self.support(k, best)
    }

    /// The examinations bone `k` goes through (indices for [`SupportExam::coverage`]): a bone
    /// that is not shrunk is examined as fitted (resizing another bone would move it); a
    /// shrunk one at its expected size, along its fitted direction and along its completion.
    pub fn tries(&self, k: usize) -> &'static [usize] {
        if self.shrunk[k] { &[1, 2] } else { &[0] }
    }

    /// Coverage and reach of bone `k` in examination `e` (one of its [`SupportExam::tries`]).
    /// The registration makes each one a work unit.
    pub fn coverage(&self, k: usize, e: usize) -> (f32, f32) {
        coverage_of(k, &self.exams[e].0, &self.exams[e].1, self.tree, self.rho)
    }

    /// The support of bone `k` from the best (coverage, reach) of its tries, folded from
    /// `(0, 0)` with [`better`].
    pub fn support(&self, k: usize, (coverage, reach): (f32, f32)) -> BoneSupport {
        BoneSupport {
            bone: self.fitted.template.bones[k].name.clone(),
            coverage,
            reach,
            missing: coverage < MISSING,
            partial: (MISSING..PARTIAL).contains(&coverage),
            shrunk: self.shrunk[k],
        }
    }
}

/// The better of two (coverage, reach) examinations of a bone: the higher coverage, the
/// first on a tie.
pub fn better(a: (f32, f32), b: (f32, f32)) -> (f32, f32) {
    if b.0 > a.0 { b } else { a }
}

/// Coverage and reach of bone `k` of a posed skeleton (see the module docs). The samples
/// are drawn in sequence from the bone's own seed and examined in parallel; the counts are
/// integers, so their sum does not depend on the order.
fn coverage_of(
    k: usize,
    posed: &crate::anatomy::Posed,
    prepared: &[crate::geometry::bone::PreparedBone],
    tree: &ImmutableKdTree<f32, 3>,
    rho: f32,
) -> (f32, f32) {
    let pb = &prepared[k];
    let b = &posed.bones[k];
    let radius = 0.5 * (b.r1 + b.r2);
    let tol = (2.5 * rho).max(0.5 * radius);
    let mut rng = Rng::new(0x5u64.wrapping_add(k as u64 * 7919));
    let samples: Vec<Vec3> = (0..SAMPLES)
        .map(|_| pb.sample_surface(&mut rng).0)
        .collect();
    let examine = |chunk: &[Vec3]| {
        let mut bins = [(0u32, 0u32); BINS];
        let (mut visible, mut covered) = (0u32, 0u32);
        for &p in chunk {
            let inside_other = prepared
                .iter()
                .enumerate()
                .any(|(j, o)| j != k && o.sdf_fast(p) < -0.02 * radius);
            if inside_other {
                continue;
            }
            visible += 1;
            let near = tree
                .query(&p.to_array())
                .nearest_n::<SquaredEuclidean<f32>>(std::num::NonZero::new(1).expect("1 > 0"))
                .execute()
                .first()
                .is_some_and(|n| n.distance.sqrt() <= tol);
            let axial = if pb.length > 1e-12 {
                ((p - b.c1).dot(pb.axis) / pb.length).clamp(0.0, 0.9999)
            } else {
                0.0
            };
            let bin = (axial * BINS as f32) as usize;
            bins[bin].0 += 1;
            if near {
                covered += 1;
                bins[bin].1 += 1;
            }
        }
        (bins, visible, covered)
    };
    let (bins, visible, covered) = samples.par_chunks(SAMPLE_CHUNK).map(examine).reduce(
        || ([(0u32, 0u32); BINS], 0u32, 0u32),
        |mut a, b| {
            for (x, y) in a.0.iter_mut().zip(&b.0) {
                x.0 += y.0;
                x.1 += y.1;
            }
            (a.0, a.1 + b.1, a.2 + b.2)
        },
    );
    // Entirely hidden inside other bones: nothing to see, nothing missing.
    let coverage = if visible > 0 {
        covered as f32 / visible as f32
    } else {
        1.0
    };
    let mut reach = 0.0;
    for (i, (v, c)) in bins.iter().enumerate() {
        if *v > 0 && (*c as f32) < 0.5 * *v as f32 {
            break;
        }
        reach = (i + 1) as f32 / BINS as f32;
    }
    (coverage, reach)
}
