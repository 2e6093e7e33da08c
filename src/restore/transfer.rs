//! Transferring a part from a donor statue (thesis ch. 5, "Stage 2: pose and anatomy
//! changes"): the donor's points bound to the part's bones — plus a margin on the bone the part
//! hangs on, for the overlap — are re-proportioned to the target's sizes (the thesis'
//! `Scale(l_t/l_c, r_t/r_c)`) and posed like the target (or like the donor for the joints the
//! target cannot tell), by point-set skinning, in the target's frame:
//! `p = Skinning(Scale(l_t/l_c, r_t/r_c) p)`.
//!
//! **How.** The donor's binding is deformed to a skeleton that is the target's (completed)
//! skeleton — root placement, every size, every rotation — except, with
//! [`PoseSource::Donor`], the relative rotations of the part's own bones, taken from the
//! donor. The part therefore hangs from the target's joint with the target's proportions.
//! Heightfield skinning is used by default, as in the thesis.

use crate::anatomy::{Skeleton, Template};
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::math::Vec3;
use crate::skinning::{Binding, Method};
use serde::Serialize;

/// Where the pose of the transferred part comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum PoseSource {
    /// The target's completed skeleton (its mirror limb, or the rest pose).
    Keep,
    /// The donor's own relative rotations for the part's bones.
    Donor,
}

/// A part to restore: a connected set of bones hanging from `attach`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Part {
    /// The part's bones (template indices, parents first).
    pub bones: Vec<usize>,
    /// The bone the part hangs on (its root's parent), if any.
    pub attach: Option<usize>,
    /// Where the part starts on its first bone, as a fraction of that bone's length from its
    /// first joint: 0 when the whole bone is missing ([`parts_of`]); a stump's end when the
    /// statue keeps that bone up to there ([`super::stump::start_at_stumps`]).
    pub from: f32,
}

impl Part {
    /// The part's missing bones: all of `bones`, but the first when the part grows from a
    /// stump of it ([`Part::from`] > 0: the statue keeps that bone, cut part-way).
    pub fn lost_bones(&self) -> &[usize] {
        let kept = usize::from(self.from > 0.0).min(self.bones.len());
        &self.bones[kept..]
    }
}

/// Groups the missing bones (`missing[k]`) into parts: each missing bone whose parent is
/// present starts a part, which takes every missing bone below it.
pub fn parts_of(t: &Template, missing: &[bool]) -> Vec<Part> {
    let mut parts = Vec::new();
    for (k, def) in t.bones.iter().enumerate() {
        if !missing[k] || def.parent.is_some_and(|p| missing[p]) {
            continue;
        }
        let mut bones = vec![k];
        let mut i = 0;
        while i < bones.len() {
            for &c in &t.bones[bones[i]].children {
                if missing[c] {
                    bones.push(c);
                }
            }
            i += 1;
        }
        bones.sort_unstable();
        parts.push(Part {
            bones,
            attach: def.parent,
            from: 0.0,
        });
    }
    parts
}

/// Options of a transfer.
#[derive(Clone, Copy, Debug)]
pub struct TransferOptions {
    pub pose: PoseSource,
    /// Fraction of the attach bone's length, from the joint, whose donor points come along for
    /// the overlap (for a part starting inside its first bone, [`Part::from`], the same
    /// fraction of that bone before the start).
    pub margin: f32,
    pub method: Method,
}

impl Default for TransferOptions {
    fn default() -> Self {
        TransferOptions {
            pose: PoseSource::Donor,
            margin: 0.3,
            method: Method::Heightfield,
        }
    }
}

/// The donor's points brought to the target.
#[derive(Clone, Debug)]
pub struct Transferred {
    /// Points (with normals) in the target's frame.
    pub cloud: PointCloud,
    /// Donor bone of each point.
    pub bones: Vec<u32>,
    /// True for the margin points, for the overlap: on the attach bone, or for a part growing
    /// from a stump on its first bone before [`Part::from`].
    pub margin: Vec<bool>,
    /// Donor point index of each point (where it came from, e.g. to animate it in).
    pub indices: Vec<u32>,
    /// The skeleton the donor was deformed to: the target's, with the donor's relative
    /// rotations for the part's lost bones ([`Part::lost_bones`]) under [`PoseSource::Donor`]
    /// (the part's points lie on it).
    pub skeleton: Skeleton,
}

/// Transfers `part` from the donor (`donor_cloud`, bound to its fit as `binding` — bind a
/// donor once for all the parts it gives) to the target whose completed skeleton is `target`.
pub fn transfer(
    target: &Skeleton,
    donor_cloud: &PointCloud,
    binding: &Binding,
    part: &Part,
    opts: &TransferOptions,
) -> Result<Transferred> {
    let donor_fit = binding.fitted();
    if binding.len() != donor_cloud.len() {
        return Err(Error::input(
            "transfer: the binding is not the donor cloud's",
        ));
    }
    if donor_fit.template.name != target.template.name
        || donor_fit.bones.len() != target.bones.len()
    {
        return Err(Error::input(format!(
            "the donor is fitted with template '{}' and the target with '{}'",
            donor_fit.template.name, target.template.name
        )));
    }
    if part.bones.is_empty() {
        return Err(Error::input("nothing to transfer: the part has no bone"));
    }
    let mut goal = target.clone();
    if opts.pose == PoseSource::Donor {
        // A part growing from a stump keeps the stump's direction: the statue tells it.
        for &k in part.lost_bones() {
            goal.bones[k].rotation = donor_fit.bones[k].rotation;
        }
        goal.enforce_constraints();
    }
    let moved = binding.deform_cloud(&goal, opts.method)?;
    let labels = &binding.points().bone;
    let donor_posed = donor_fit.pose();
    let mut keep = Vec::new();
    let mut margin = Vec::new();
    // The donor's base (plinth) is not a limb, whatever bone it is bound to.
    let mut on_base = binding.base().iter().peekable();
    // Axial fraction of a donor point along donor bone `b`, from its first joint.
    let fraction = |i: usize, b: usize| {
        let bone = &donor_posed.bones[b];
        let axis = bone.c2 - bone.c1;
        let l2 = axis.length_squared().max(1e-24);
        (donor_cloud.positions[i] - bone.c1).dot(axis) / l2
    };
    let first = part.bones[0];
    for (i, &b) in labels.iter().enumerate() {
        if on_base.next_if_eq(&&(i as u32)).is_some() {
            continue;
        }
        let b = b as usize;
        if part.from > 0.0 && b == first {
            // A part growing from a stump: the first bone beyond the stump's end, and the
            // `margin` before it for the overlap.
            let f = fraction(i, b);
            if f >= part.from - opts.margin {
                keep.push(i);
                margin.push(f < part.from);
            }
        } else if part.bones.contains(&b) {
            keep.push(i);
            margin.push(false);
        } else if part.from <= 0.0 && Some(b) == part.attach {
            // Near the joint the part hangs from: the last `margin` of the attach bone.
            if fraction(i, b) >= 1.0 - opts.margin {
                keep.push(i);
                margin.push(true);
            }
        }
    }
    if part.from > 0.0 {
        // Skinned onto the statue, a few of the first bone's points near the donor's joints
        // land before the margin (on the joint sphere the stump's part carries): left out, as
        // the stump has them.
        let bone = goal.pose().bones[first];
        let axis = bone.c2 - bone.c1;
        let l2 = axis.length_squared().max(1e-24);
        let lands_before =
            |i: usize| (moved.positions[i] - bone.c1).dot(axis) / l2 < part.from - opts.margin;
        (keep, margin) = keep
            .iter()
            .zip(&margin)
            .filter(|&(&i, _)| labels[i] as usize != first || !lands_before(i))
            .map(|(&i, &m)| (i, m))
            .unzip();
    }
    let on_part = margin.iter().filter(|m| !**m).count();
    if on_part == 0 {
        let names: Vec<&str> = part
            .bones
            .iter()
            .map(|&k| target.template.bones[k].name.as_str())
            .collect();
        return Err(Error::input(format!(
            "the donor has no points on {} (is that part missing on the donor too?)",
            names.join(", ")
        )));
    }
    let positions: Vec<Vec3> = keep.iter().map(|&i| moved.positions[i]).collect();
    let normals: Vec<Vec3> = keep
        .iter()
        .map(|&i| moved.normals.as_ref().map_or(Vec3::Y, |n| n[i]))
        .collect();
    let mut cloud = PointCloud::with_normals(positions, normals);
    if let Some(c) = &donor_cloud.colors {
        cloud.colors = Some(keep.iter().map(|&i| c[i]).collect());
    }
    Ok(Transferred {
        cloud,
        bones: keep.iter().map(|&i| labels[i] as u32).collect(),
        margin,
        indices: keep.iter().map(|&i| i as u32).collect(),
        skeleton: goal,
    })
}
