//! Merging a transferred part into the target (thesis ch. 5, eq. 5.1): in the overlap around
//! the joint the part hangs from, points of both statues are expressed as heights above their
//! base points on the target's (completed) sphere-mesh; for each point `p`, `Q_p` gathers the
//! points whose base points lie within `3δ` of `p`'s, `H_p ⊂ Q_p` keeps the upper layer (heights
//! above `h_max − ρ`), and `p`'s height becomes the Gaussian-weighted mean of `H_p`'s
//! (eq. 5.1, weights `exp(−‖p − q‖² / (2 (3δ)²))`): the lower layer — the fracture face of the
//! stump, the inside of the donor's margin — is lifted onto the upper one, leaving a single
//! layer. A second pass smooths the seam: each height becomes the Gaussian-weighted mean of
//! the first pass's heights within `3δ`. `ρ` is the mean nearest-neighbour spacing of the
//! overlap's points and `3δ = 10ρ` by default (thesis).
//!
//! **The overlap** (the thesis assumes the parts "slightly overlap"): points of either
//! statue within `r_J + margin · l_attach` of the joint centre `J` whose nearest bone is the
//! attach bone or a bone of the part (the donor's margin points, the target's stump and
//! shoulder around it). Points elsewhere are not touched. For a part growing from a stump
//! ([`Part::from`] > 0, [`super::stump`]) `J` is the point of the part's first bone's axis at
//! the stump's end, `r_J` the bone's radius there, and `margin` is of that bone's length.

use super::transfer::Part;
use crate::anatomy::Skeleton;
use crate::geometry::Bone;
use crate::geometry::bone::PreparedBone;
use crate::math::Vec3;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;

/// Options of a merge.
#[derive(Clone, Copy, Debug)]
pub struct MergeOptions {
    /// `3δ` as a multiple of the overlap's mean spacing `ρ` (thesis: 10).
    pub three_delta_over_rho: f32,
    /// Smoothing pass across the seam.
    pub smooth: bool,
}

impl Default for MergeOptions {
    fn default() -> Self {
        MergeOptions {
            three_delta_over_rho: 10.0,
            smooth: true,
        }
    }
}

/// What a merge measured.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct MergeStats {
    /// Points in the overlap.
    pub overlap_points: usize,
    /// Mean spacing ρ of the overlap.
    pub rho: f32,
    /// `3δ` used.
    pub three_delta: f32,
    /// Mean |height change| of the overlap's points.
    pub mean_lift: f32,
}

/// The nearest bone (by signed distance) of `p` and its orthogonal projection.
fn base(p: Vec3, bones: &[PreparedBone]) -> (usize, Vec3, Vec3, f32) {
    let (best, _) = crate::geometry::bone::nearest_bone(bones, p);
    let pr = bones[best].project(p);
    let h = (p - pr.point).dot(pr.normal);
    (best, pr.point, pr.normal, h)
}

/// Merges in place: `positions` (and `normals`) hold both statues' points; the ones in the
/// overlap where `part` starts (the joint at `c1` of its first bone, or its stump's end) are
/// moved. Returns the indices of the overlap's points and the statistics.
pub fn merge(
    skeleton: &Skeleton,
    part: &Part,
    margin: f32,
    positions: &mut [Vec3],
    opts: &MergeOptions,
) -> (Vec<usize>, MergeStats) {
    let posed = skeleton.pose();
    let prepared: Vec<PreparedBone> = posed.bones.iter().map(Bone::prepare).collect();
    let Some(&part_root) = part.bones.first() else {
        return (Vec::new(), MergeStats::default());
    };
    let zone_bones = &part.bones;
    let root = &posed.bones[part_root];
    let f = part.from.clamp(0.0, 1.0);
    let j = root.c1.lerp(root.c2, f);
    let attach = part.attach;
    let l_margin = if f > 0.0 {
        skeleton.bones[part_root].length
    } else {
        attach.map_or(0.0, |a| skeleton.bones[a].length)
    };
    let radius = root.r1 + (root.r2 - root.r1) * f + margin * l_margin;
    // The overlap's points with their base points.
    // Only points near the joint can be in the overlap: base points for those alone.
    let near: Vec<usize> = (0..positions.len())
        .filter(|&i| (positions[i] - j).length() <= radius)
        .collect();
    let based: Vec<(usize, (usize, Vec3, Vec3, f32))> = near
        .par_iter()
        .map(|&i| (i, base(positions[i], &prepared)))
        .filter(|(_, (b, _, _, _))| zone_bones.contains(b) || Some(*b) == attach)
        .collect();
    let zone: Vec<usize> = based.iter().map(|(i, _)| *i).collect();
    let info: Vec<(usize, Vec3, Vec3, f32)> = based.iter().map(|(_, x)| *x).collect();
    if zone.len() < 2 {
        return (zone, MergeStats::default());
    }
    let zp: Vec<[f32; 3]> = zone.iter().map(|&i| positions[i].to_array()).collect();
    let zb: Vec<[f32; 3]> = info.iter().map(|x| x.1.to_array()).collect();
    let (Ok(tree_p), Ok(tree_b)) = (
        ImmutableKdTree::<f32, 3>::new_from_slice(&zp),
        ImmutableKdTree::<f32, 3>::new_from_slice(&zb),
    ) else {
        return (zone, MergeStats::default());
    };
    let two = std::num::NonZero::new(2).expect("2 > 0");
    let rho = zp
        .iter()
        .map(|p| {
            tree_p
                .query(p)
                .nearest_n::<SquaredEuclidean<f32>>(two)
                .execute()
                .get(1)
                .map_or(0.0, |n| n.distance.sqrt())
        })
        .sum::<f32>()
        / zp.len() as f32;
    let td = (opts.three_delta_over_rho * rho).max(1e-9);
    let heights: Vec<f32> = info.iter().map(|x| x.3).collect();
    // Pass 1 (eq. 5.1): the upper layer's Gaussian-weighted height.
    let pass1: Vec<f32> = (0..zone.len())
        .into_par_iter()
        .map(|a| {
            let q = tree_b
                .query(&zb[a])
                .within::<SquaredEuclidean<f32>>(td * td)
                .execute();
            let hmax = q
                .iter()
                .map(|n| heights[n.item as usize])
                .fold(f32::MIN, f32::max);
            let (mut s, mut w) = (0.0f64, 0.0f64);
            let pa = positions[zone[a]];
            for n in &q {
                let b = n.item as usize;
                if heights[b] > hmax - rho {
                    let d2 = (pa - positions[zone[b]]).length_squared();
                    let g = (-(d2 / (2.0 * td * td)) as f64).exp();
                    s += g * heights[b] as f64;
                    w += g;
                }
            }
            if w > 0.0 { (s / w) as f32 } else { heights[a] }
        })
        .collect();
    // Pass 2: smooth across the seam.
    let pass2: Vec<f32> = if opts.smooth {
        (0..zone.len())
            .into_par_iter()
            .map(|a| {
                let q = tree_b
                    .query(&zb[a])
                    .within::<SquaredEuclidean<f32>>(td * td)
                    .execute();
                let (mut s, mut w) = (0.0f64, 0.0f64);
                for n in &q {
                    let g = (-(n.distance / (2.0 * td * td)) as f64).exp();
                    s += g * pass1[n.item as usize] as f64;
                    w += g;
                }
                if w > 0.0 { (s / w) as f32 } else { pass1[a] }
            })
            .collect()
    } else {
        pass1
    };
    let mut lift = 0.0f64;
    for (a, &i) in zone.iter().enumerate() {
        let (_, b, n, h) = info[a];
        positions[i] = b + pass2[a] * n;
        lift += (pass2[a] - h).abs() as f64;
    }
    let stats = MergeStats {
        overlap_points: zone.len(),
        rho,
        three_delta: td,
        mean_lift: (lift / zone.len() as f64) as f32,
    };
    (zone, stats)
}
