//! Parts that grow from a bone cut part-way (our addition; the thesis restores whole limbs
//! from a joint).
//!
//! An arm broken through the upper arm keeps a stump: the registration keeps the upper arm
//! (partial) and loses the forearm and hand ([`crate::fakir::support`]). A part made of the
//! lost bones alone hangs from the elbow, and the donor's margin covers only the end of the
//! upper arm (`TransferOptions::margin`, 0.3 of it): between the stump's end and the margin
//! the restored statue had a hole. Measured on a synthetic statue (`synth --seed 5 --points
//! 20000 --cut bone:l_upper_arm@F`, restored from seed 9 with both truths as fits), the share of
//! the upper arm's visible surface within 3ρ of a point, per tenth of its length from the
//! shoulder: cut at 0.2, 0.53 0.13 0.08 0.08 over its third to sixth tenths; at 0.5, 0.54 over
//! its sixth.
//!
//! **What.** [`stump_end`] measures how far along a bone the statue's points reach: the
//! [`QUANTILE`] of the axial fractions (from the bone's first joint) of the points whose
//! nearest bone it is, the lost part's bones left out. [`start_at_stumps`] makes a part grow from its attach bone's stump when
//! that reach ends before [`WHOLE`]: the attach bone becomes the part's first bone, with
//! [`Part::from`] its stump's end; the donor gives that bone's points beyond it, its margin
//! lies on the same bone before it, and the merge is centred on the cut
//! ([`super::merge::merge`]).
//!
//! **Our choices.** Only a limb bone (not the root block nor a bone carrying other chains,
//! [`crate::fakir::solver::trunk_bones`]) whose children all belong to the part; the stump's
//! direction is the fit's (its points tell it), so the donor's pose never turns that bone;
//! at least [`MIN_POINTS`] points, else nothing is measured. A bone lost whole keeps the
//! thesis' part from the joint: the registration completed it along its mirror or rest
//! direction, which a stump of it need not follow.

use super::transfer::Part;
use crate::anatomy::Skeleton;
use crate::geometry::Bone;
use crate::geometry::bone::{PreparedBone, nearest_bone_where};
use crate::math::Vec3;
use rayon::prelude::*;

/// Quantile of the axial fractions taken as a stump's end (a few stray points past the break
/// do not move it).
pub const QUANTILE: f32 = 0.98;

/// A bone whose points reach this fraction of its length is whole.
pub const WHOLE: f32 = 0.9;

/// Fewest points for a stump's end to be measured.
pub const MIN_POINTS: usize = 20;

/// How far along bone `bone` of `skeleton` the points reach: the [`QUANTILE`] of the axial
/// fractions `(p − c₁)·(c₂ − c₁) / ‖c₂ − c₁‖²` of the points `positions` whose nearest bone
/// (by signed distance, [`crate::geometry::bone::nearest_bone_where`]) is `bone` once the
/// bones `absent` are left out — the lost part's bones, which have no points: completed at the
/// joint, they would take the points round its sphere from a whole bone — and that lie within
/// the bone's mean radius of its surface (a plinth under a lost foot is nearest the shin, but
/// not on it). `None` with fewer
/// than [`MIN_POINTS`] such points or a degenerate bone. The fraction can pass 1 (the points
/// round the end sphere) or be negative.
pub fn stump_end(
    positions: &[Vec3],
    skeleton: &Skeleton,
    bone: usize,
    absent: &[usize],
) -> Option<f32> {
    let posed = skeleton.pose();
    let b = *posed.bones.get(bone)?;
    let axis = b.c2 - b.c1;
    let l2 = axis.length_squared();
    if !(l2 > 1e-20) {
        return None;
    }
    let prepared: Vec<PreparedBone> = posed.bones.iter().map(Bone::prepare).collect();
    let band = 0.5 * (b.r1 + b.r2);
    let mut f: Vec<f32> = positions
        .par_iter()
        .filter(|p| {
            let (k, d) = nearest_bone_where(&prepared, **p, |k| !absent.contains(&k));
            k == bone && d <= band
        })
        .map(|p| (*p - b.c1).dot(axis) / l2)
        .filter(|x| x.is_finite())
        .collect();
    if f.len() < MIN_POINTS {
        return None;
    }
    let k = ((f.len() - 1) as f32 * QUANTILE).round() as usize;
    let (_, x, _) = f.select_nth_unstable_by(k, f32::total_cmp);
    Some(*x)
}

/// Makes each part whose attach bone is a cut limb bone grow from that bone's stump (see the
/// module docs): the attach bone is put first in `bones`, `attach` becomes its parent and
/// `from` its [`stump_end`] (the part's bones left out). Parts left as they are: a part
/// already starting inside a bone, no attach bone, a trunk attach bone, an attach bone carrying
/// a bone outside the part, or one whose points reach [`WHOLE`] of it, end at or before its
/// first joint, or are too few to tell.
pub fn start_at_stumps(parts: &mut [Part], positions: &[Vec3], skeleton: &Skeleton) {
    let t = &skeleton.template;
    let trunk = crate::fakir::solver::trunk_bones(t);
    for part in parts.iter_mut() {
        let Some(a) = part.attach else { continue };
        if part.from > 0.0 || trunk[a] || part.bones.contains(&a) {
            continue;
        }
        if !t.bones[a].children.iter().all(|c| part.bones.contains(c)) {
            continue;
        }
        let Some(end) = stump_end(positions, skeleton, a, &part.bones) else {
            continue;
        };
        // An end at or before the joint says the fitted bone does not follow its points:
        // the part stays as it was.
        if !(end > 0.0) || end >= WHOLE {
            continue;
        }
        part.bones.insert(0, a);
        part.attach = t.bones[a].parent;
        part.from = end;
    }
}
