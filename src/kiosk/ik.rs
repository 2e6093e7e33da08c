//! Inverse kinematics for limb drags (bevy-free).
//!
//! A visitor drags the end bone of the selected limb (hand, foot, head); the limb follows the
//! finger. Two steps, each a plain function:
//!
//! 1. [`fabrik`] moves a chain of points (the limb's joints, root fixed) so that its last point
//!    reaches a target, keeping every segment length (FABRIK, Aristidou & Lasenby 2011). An
//!    unreachable target gives the chain stretched straight toward it.
//! 2. [`apply_chain_points`] turns the new points back into the skeleton's rotations (relative
//!    to the parent bone, as [`Skeleton`] stores them): each bone gets the **minimal swing**
//!    taking its current direction onto its new one, so its twist is kept; bones below the
//!    chain keep their relative rotations and are carried along.
//!
//! **Which bones move.** [`limb_bones`] gives the bones of a template chain that the drag moves:
//! every bone of the chain but the end bone, whose start (the wrist, the ankle, the base of the
//! head) is the effector; the end bone keeps its rotation relative to its parent, so the hand
//! follows the forearm. A one-bone chain moves its only bone, its tip being the effector.
//!
//! **Chain points.** [`chain_points`] gives `bones.len() + 1` points: the start of every bone,
//! then the end of the last one. A follower bone between two chain bones (the human
//! `neck_link` between `spine_upper` and `neck`) is rigid relative to its leader, so the
//! segment from the leader's start to the next chain bone's start is rigid too: its length is
//! kept by FABRIK and its direction turns with the leader.

use crate::anatomy::{Posed, Skeleton, Template};
use crate::geometry::frames::rotation_arc;
use crate::math::Vec3;

/// Stopping rule of [`fabrik`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IkOptions {
    /// Stop when the end point is closer than this to the target, as a fraction of the
    /// chain's total length.
    pub tolerance: f32,
    /// Forward-and-backward passes at most.
    pub max_iterations: usize,
}

impl Default for IkOptions {
    fn default() -> Self {
        IkOptions {
            tolerance: 1e-4,
            max_iterations: 64,
        }
    }
}

/// FABRIK: new positions of `joints` (the first one fixed) whose last point reaches `target`
/// when it can, segment lengths kept. When the target is farther than the chain's total
/// length the chain is laid straight toward it. Starting from the current positions makes
/// successive solves (one per frame of a drag) continuous.
pub fn fabrik(joints: &[Vec3], target: Vec3, options: &IkOptions) -> Vec<Vec3> {
    let mut p = joints.to_vec();
    let n = p.len();
    if n < 2 || !target.is_finite() {
        return p;
    }
    let lengths: Vec<f32> = p.windows(2).map(|w| (w[1] - w[0]).length()).collect();
    // Fallback directions for coincident points: the original segment directions.
    let dirs: Vec<Vec3> = p
        .windows(2)
        .map(|w| (w[1] - w[0]).normalize_or(Vec3::X))
        .collect();
    let total: f32 = lengths.iter().sum();
    let root = p[0];
    if total <= 0.0 {
        return p;
    }
    let to_target = target - root;
    if to_target.length() >= total {
        let dir = to_target.normalize_or(dirs[0]);
        for i in 0..n - 1 {
            p[i + 1] = p[i] + dir * lengths[i];
        }
        return p;
    }
    let tol = options.tolerance * total;
    for _ in 0..options.max_iterations {
        if (p[n - 1] - target).length() <= tol {
            break;
        }
        // Backward: from the target to the root.
        p[n - 1] = target;
        for i in (0..n - 1).rev() {
            let d = (p[i] - p[i + 1]).normalize_or(-dirs[i]);
            p[i] = p[i + 1] + d * lengths[i];
        }
        // Forward: from the root back out.
        p[0] = root;
        for i in 0..n - 1 {
            let d = (p[i + 1] - p[i]).normalize_or(dirs[i]);
            p[i + 1] = p[i] + d * lengths[i];
        }
    }
    p
}

/// The bones a drag of `chain`'s end bone moves (see the module docs): the chain without its
/// end bone, or the chain itself when it has one bone.
pub fn limb_bones(template: &Template, chain: usize) -> Vec<usize> {
    let Some(c) = template.chains.get(chain) else {
        return Vec::new();
    };
    if c.bones.len() > 1 {
        c.bones[..c.bones.len() - 1].to_vec()
    } else {
        c.bones.clone()
    }
}

/// The end bone of `chain` (the one a visitor drags), if the chain exists.
pub fn end_bone(template: &Template, chain: usize) -> Option<usize> {
    template
        .chains
        .get(chain)
        .and_then(|c| c.bones.last().copied())
}

/// The points of a chain of `bones` in a posed skeleton: the start of every bone, then the end
/// of the last one (`bones.len() + 1` points).
pub fn chain_points(posed: &Posed, bones: &[usize]) -> Vec<Vec3> {
    let mut out: Vec<Vec3> = bones.iter().map(|&b| posed.bones[b].c1).collect();
    if let Some(&last) = bones.last() {
        out.push(posed.bones[last].c2);
    }
    out
}

/// Writes new chain points (from [`fabrik`], same count as [`chain_points`]) into the
/// skeleton's relative rotations: each bone, parents first, is swung by the shortest arc from
/// its current segment direction to the new one (twist kept), and its rotation relative to
/// its parent recomputed. Lengths, radii and every other bone's relative rotation are
/// untouched, so the bones below the chain follow rigidly.
pub fn apply_chain_points(skeleton: &mut Skeleton, bones: &[usize], points: &[Vec3]) {
    if points.len() != bones.len() + 1 {
        return;
    }
    let template = skeleton.template.clone();
    let mut posed = skeleton.pose();
    for (i, &b) in bones.iter().enumerate() {
        let current = chain_points(&posed, bones);
        let old_dir = current[i + 1] - current[i];
        let new_dir = points[i + 1] - points[i];
        if !(old_dir.length_squared() > 0.0 && new_dir.length_squared() > 0.0) {
            continue;
        }
        let swing = rotation_arc(old_dir, new_dir);
        let frame = (swing * posed.frames[b]).normalize();
        let parent = template.bones[b]
            .parent
            .map(|p| posed.frames[p])
            .unwrap_or(skeleton.root_rotation);
        skeleton.bones[b].rotation = (parent.inverse() * frame).normalize();
        skeleton.pose_into(&mut posed);
    }
}

/// One drag step: the chain of `bones` in `skeleton` is solved toward `target` and written
/// back; returns the new chain points.
pub fn drag_chain(
    skeleton: &mut Skeleton,
    bones: &[usize],
    target: Vec3,
    options: &IkOptions,
) -> Vec<Vec3> {
    let points = chain_points(&skeleton.pose(), bones);
    let solved = fabrik(&points, target, options);
    apply_chain_points(skeleton, bones, &solved);
    solved
}
