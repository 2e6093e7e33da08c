//! Levenberg–Marquardt over small groups of skeleton parameters (thesis §2.3, eq. 2.7–2.8 and
//! 2.12–2.13; paper 001 appendices B–C).
//!
//! One LM iteration for a parameter group `θ` (1 to 7 parameters; up to [`MAX_PARAMS`] for the
//! whole-chain fit) minimises the energy of the points assigned to a set of bones (the one-bone
//! energy eq. 2.3/2.6, the two-bone energy eq. 2.5/2.11, the root-block energy, or a whole
//! chain's) with the assignment held fixed:
//! `δθ = −[JᵀJ + λ diag(JᵀJ)]⁻¹ Jᵀ g(θ)`, the damping `λ` starting at 0.01 and divided by 10
//! after an accepted step, multiplied by 10 after a rejected one.
//!
//! **Stopping (our choice; the papers give none).** A loop ends when an accepted step lowers
//! the energy by less than `lm_tolerance` (relative, 10⁻⁶) or when the damping passes 10⁶.
//! A rejected step leaves the state unchanged, so its normal equations are kept and reused
//! with the new damping (on the papers' chain two thirds of the LM iterations are rejected
//! steps: `fakir/chain4_5k` 0.63 → 0.49 s, the same skeleton bit for bit). **Tried and
//! dropped twice** (README, *Stopping an LM loop on its model's promise*): stopping before a
//! trial whose linearised model promises a decrease (`−(2 δ·Jᵀr + δᵀJᵀJδ)`) under 10⁻⁶ or
//! 10⁻⁸ of the energy halves the chain's time, but the steps it skips at high damping still
//! gain: fewer synthetic statues end under 2% of the height in joint error.
//!
//! **One projection per state (exact).** Each pass over an energy's points keeps every
//! point's residual and gradient ([`PointRows`]); the next pass at the same state reads them
//! instead of projecting (the solver's row cache, keyed by the bones, their geometry and the
//! members): the normal equations after an accepted step (its trial's pass projected), the
//! next parameter group of the same fit, the first group after a round's energy was summed.
//! The same sums bit for bit (tests), so the same skeletons.
//!
//! **Derivatives.** Each residual's derivative is the chain rule of two factors:
//! * per point, analytic: the derivative of the residual with respect to its bone's
//!   `c1, c2, r1, r2` ([`crate::geometry::Projection::gradient`], envelope theorem);
//! * per parameter, the derivative of the bones' `c1, c2, r1, r2` with respect to the
//!   parameter, by central differences of the skeleton's forward kinematics (a handful of
//!   bones, not the points; step `1e-4` rad or `1e-4 ×` the statue scale).
//!
//! This gives the papers' derivatives (eq. 2.9–2.10 for the two angles, 2.14–2.15 for the two
//! lengths) for every parameterisation at once, including the block and follower
//! constraints; tests compare the resulting Jacobian with finite differences of the energy.
//!
//! **Choice:** loose proportion bounds (§2.4.1, §2.6.1) are enforced by clamping after each
//! step ([`Limits`]): lengths stay within `[0.5, 2.0] ×` the template's (scaled) length
//! (`[0.75, 1.33] ×` while a bone is calibrated by the chain's initial forward pass,
//! [`Limits::with_length_range`]) and the ratio of consecutive chain bones within `4 ×` of the
//! template's ratio either way, radii within `[0.3, 1.5] ×` the template's, and
//! `|r2 − r1| ≤ 0.9 l` so no sphere swallows its neighbour; the root block's scale stays
//! within `[0.6, 1.6] ×` the initial estimate. (A tighter `1.6 ×` length bound was tried and
//! dropped: it pushed more synthetic statues over 2% than it fixed; see the README.) The
//! energy is evaluated after clamping, so a clamped step is only accepted when
//! it still lowers the energy.

use super::assign::{Assignment, CHUNK};
use super::world::{End, RadiusClasses, WorldSkeleton};
use crate::anatomy::template::BoneKind;
use crate::cloud::grid::NearGrid;
use crate::geometry::{Bone, BoneGradient, PreparedBone};
use crate::math::{Quat, Vec3};
use rayon::prelude::*;

/// Largest parameter group (the whole-chain fit of [`super::solver::Solver::whole_chain`]
/// takes up to four parameters per bone; the papers' groups take 1 to 7).
///
/// Only a Jacobian row (on the stack) has this size: the sums ([`NormalEquations`]), the
/// geometry derivatives and the damped system are sized by the group, so the papers' small
/// groups do not pay for the whole-chain fit's room (with every sum held at `32 × 32`,
/// `fakir/human_10k` ran about 2% slower than at 7; see the README).
pub const MAX_PARAMS: usize = 32;

/// One scalar parameter of the skeleton, applied as an increment to the current state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Param {
    /// Rotation of `bone` about the world `axis` through its first joint; descendants follow.
    Swing { bone: usize, axis: Vec3 },
    /// Length of `bone`; descendants translate.
    Length { bone: usize },
    /// A radius (and every radius shared with it).
    Radius { bone: usize, end: End },
    /// Rotation of the joint between `a` and its child `b` about the axis through the outer
    /// joints, which stay fixed (thesis fig. 2.5).
    PairRotate { a: usize, b: usize },
    /// Length of `a` (`first`) or of `b`, the outer joints fixed (eq. 2.11–2.15).
    PairLength { a: usize, b: usize, first: bool },
    /// Translation of the root along a world axis; the whole skeleton follows.
    RootMove { axis: Vec3 },
    /// Rotation of the whole skeleton about the root joint.
    RootRotate { axis: Vec3 },
    /// Logarithm of the root block's scale.
    BlockScale,
    /// Translation of the first joint of a bone leaving the root (a free chain extremity), its
    /// second joint fixed.
    AnchorMove { bone: usize, axis: Vec3 },
}

/// Moves the joint at the end of `a` to `target`, the first joint of `a` and the second joint
/// of `b` (a's child, possibly through a follower) staying where they are.
fn move_pair_joint(w: &mut WorldSkeleton, a: usize, b: usize, target: Vec3) {
    let posed = w.pose();
    let c_k = posed.bones[a].c1;
    let c_k2 = posed.bones[b].c2;
    w.aim(a, c_k, target);
    w.enforce();
    let c1_b = w.pose().bones[b].c1;
    w.aim(b, c1_b, c_k2);
    w.enforce();
}

/// Applies `value` of parameter `p` to `w` (an increment from the current state).
pub fn apply(w: &mut WorldSkeleton, classes: &RadiusClasses, p: &Param, value: f32) {
    match *p {
        Param::Swing { bone, axis } => {
            w.rotate_subtree(bone, Quat::from_axis_angle(axis, value));
            w.enforce();
        }
        Param::Length { bone } => {
            w.lengths[bone] = (w.lengths[bone] + value).max(1e-6);
            w.enforce();
        }
        Param::Radius { bone, end } => {
            let r = (w.radius(bone, end) + value).max(1e-6);
            w.set_radius(classes, bone, end, r);
        }
        Param::PairRotate { a, b } => {
            let posed = w.pose();
            let (c_k, j, c_k2) = (posed.bones[a].c1, posed.bones[a].c2, posed.bones[b].c2);
            let axis = (c_k2 - c_k).normalize_or(Vec3::Z);
            let target = c_k + Quat::from_axis_angle(axis, value) * (j - c_k);
            move_pair_joint(w, a, b, target);
        }
        Param::PairLength { a, b, first } => {
            let posed = w.pose();
            let (c_k, j, c1_b, c_k2) = (
                posed.bones[a].c1,
                posed.bones[a].c2,
                posed.bones[b].c1,
                posed.bones[b].c2,
            );
            let dir = if first {
                (j - c_k).normalize_or(Vec3::X)
            } else {
                (c1_b - c_k2).normalize_or(Vec3::X)
            };
            move_pair_joint(w, a, b, j + value * dir);
        }
        Param::RootMove { axis } => w.root_position += value * axis,
        Param::RootRotate { axis } => w.rotate_all(Quat::from_axis_angle(axis, value)),
        Param::BlockScale => w.scale_block(value.exp()),
        Param::AnchorMove { bone, axis } => {
            let c2 = w.pose().bones[bone].c2;
            w.root_position += value * axis;
            let root = w.root_position;
            w.aim(bone, root, c2);
            w.enforce();
        }
    }
}

/// Finite-difference step of a parameter (see the module docs).
fn fd_step(p: &Param, scale: f32) -> f32 {
    match p {
        Param::Swing { .. }
        | Param::PairRotate { .. }
        | Param::RootRotate { .. }
        | Param::BlockScale => 1e-3,
        _ => 1e-3 * scale,
    }
}

/// Loose bounds on lengths and radii (see the module docs).
#[derive(Clone, Debug)]
pub struct Limits {
    pub min_len: Vec<f32>,
    pub max_len: Vec<f32>,
    pub min_r: Vec<[f32; 2]>,
    pub max_r: Vec<[f32; 2]>,
    /// Template length ratio of each bone to its chain predecessor (None for chain heads).
    pub prev_ratio: Vec<Option<(usize, f32)>>,
    /// Bounds of the root block's scale.
    pub block_scale: (f32, f32),
}

impl Limits {
    /// Loose bounds for a template scaled by `scale` (template units → statue units).
    pub fn new(w: &WorldSkeleton, scale: f32) -> Self {
        Self::with_length_range(w, scale, 0.5, 2.0)
    }

    /// Bounds with lengths within `[lo, hi] ×` the scaled template lengths.
    pub fn with_length_range(w: &WorldSkeleton, scale: f32, lo: f32, hi: f32) -> Self {
        let t = &w.template;
        let n = t.bones.len();
        let mut l = Limits {
            min_len: vec![0.0; n],
            max_len: vec![f32::INFINITY; n],
            min_r: vec![[0.0; 2]; n],
            max_r: vec![[f32::INFINITY; 2]; n],
            prev_ratio: vec![None; n],
            block_scale: (0.6 * scale, 1.6 * scale),
        };
        for (i, def) in t.bones.iter().enumerate() {
            let rest = w.rest_length(i) * scale;
            l.min_len[i] = lo * rest;
            l.max_len[i] = hi * rest;
            l.min_r[i] = [0.3 * def.r1 * scale, 0.3 * def.r2 * scale];
            l.max_r[i] = [1.5 * def.r1 * scale, 1.5 * def.r2 * scale];
            if let Some((c, pos)) = def.chain
                && pos > 0
            {
                let prev = t.chains[c].bones[pos - 1];
                l.prev_ratio[i] = Some((prev, w.rest_length(i) / w.rest_length(prev)));
            }
        }
        l
    }

    /// Clamps the lengths and radii of `bones` (and what shares their radii).
    pub fn clamp(&self, w: &mut WorldSkeleton, classes: &RadiusClasses, bones: &[usize]) {
        let t = w.template.clone();
        let k = w.block_scale.clamp(self.block_scale.0, self.block_scale.1) / w.block_scale;
        if k != 1.0 && k.is_finite() {
            w.scale_block(k);
        }
        for &b in bones {
            if t.bones[b].kind != BoneKind::Free {
                continue;
            }
            let mut len = w.lengths[b];
            if let Some((prev, ratio)) = self.prev_ratio[b] {
                let lp = w.lengths[prev];
                len = len.clamp(0.25 * ratio * lp, 4.0 * ratio * lp);
            }
            // The absolute bounds win over the ratio bound.
            w.lengths[b] = len.clamp(self.min_len[b], self.max_len[b]);
            for (k, end) in [(0, End::First), (1, End::Second)] {
                let r = w.radius(b, end);
                let c = r.clamp(self.min_r[b][k], self.max_r[b][k]);
                if c != r {
                    w.set_radius(classes, b, end, c);
                }
            }
            let (r1, r2) = (w.r1[b], w.r2[b]);
            let max_dr = 0.9 * w.lengths[b];
            if (r2 - r1).abs() > max_dr {
                // Shrink the larger radius.
                if r2 > r1 {
                    w.set_radius(classes, b, End::Second, r1 + max_dr);
                } else {
                    w.set_radius(classes, b, End::First, r2 + max_dr);
                }
            }
        }
        w.enforce();
    }
}

/// The data an LM iteration reads: the assignment and the members of each energy bone.
pub struct EnergyTerms<'a> {
    pub assignment: &'a Assignment,
    /// Point indices (into the assignment) of each bone.
    pub members: &'a [Vec<u32>],
    /// Bones whose points make up the energy.
    pub bones: &'a [usize],
    /// Optional occupancy term (model → data).
    pub occupancy: Option<OccupancyTerm<'a>>,
    /// Optional joint-range prior.
    pub prior: Option<&'a RangePrior>,
}

/// The joint-range prior (our addition): a bone whose direction relative to its parent leaves
/// the template's joint range (`bend`, `swing`) by more than `margin` pays
/// `weight · (excess − margin)` as one residual. The thesis has no such term; without it a
/// short bone whose points are few (a hand, the neck) can fold inside its neighbour, where no
/// point and no occupancy sample holds it, and stay there. **Choice:** margin 45° (statue
/// poses beyond the generator's ranges cost nothing), weight `√(n_b) · r̄_b` (`n_b` the points
/// the bone would carry at the mean density, `r̄_b` its mean radius), so one radian beyond the
/// margin costs like every point of the bone lying one radius off.
///
/// It also holds the **proportion prior** (the "loose proportion constraints between
/// consecutive bones" of §2.4.1, made soft): a bone whose length ratio to its chain
/// predecessor leaves the template's ratio by more than a factor [`RATIO_MARGIN`] either way
/// pays `weight · (|ln(ratio / template ratio)| − ln RATIO_MARGIN)`, with the same weight as
/// the range term. Within the margin (statues are stylised; the generator draws ±30% per
/// bone) it costs nothing; beyond it, it stops a joint from sliding along a straight limb
/// (a wrist sliding to the elbow, a skull base sliding down the neck), where the surface
/// alone cannot tell where the joint is.
#[derive(Clone, Debug)]
pub struct RangePrior {
    /// Bones and their weights.
    pub bones: Vec<(usize, f64)>,
    /// Free angle beyond the range (radians).
    pub margin: f32,
    /// Length-ratio terms: (bone, chain predecessor, template ratio, weight).
    pub ratios: Vec<(usize, usize, f32, f64)>,
}

/// Factor by which a length ratio may leave the template's before the proportion prior acts.
pub const RATIO_MARGIN: f32 = 1.8;

/// Margin of the joint-range prior (radians).
pub const PRIOR_MARGIN: f32 = std::f32::consts::FRAC_PI_4;

impl RangePrior {
    /// The residuals of the prior for `w`, in the order of `bones`.
    pub fn residuals(&self, w: &WorldSkeleton) -> Vec<f64> {
        self.bones
            .iter()
            .map(|&(b, wgt)| {
                let excess = super::init::range_excess(
                    &w.template,
                    &w.rest_frames,
                    b,
                    w.direction_at_rest(b),
                );
                wgt * (excess - self.margin).max(0.0) as f64
            })
            .chain(self.ratios.iter().map(|&(b, prev, ratio, wgt)| {
                let r = w.lengths[b] / (ratio * w.lengths[prev]).max(1e-30);
                wgt * (r.max(1e-30).ln().abs() - RATIO_MARGIN.ln()).max(0.0) as f64
            }))
            .collect()
    }

    /// Energy of the prior.
    pub fn energy(&self, w: &WorldSkeleton) -> f64 {
        self.residuals(w).iter().map(|r| r * r).sum()
    }
}

/// The occupancy term (model → data): samples on the visible surface of a bone must lie on
/// the data. The thesis names this remedy (§2.5.1: "adding a bone occupancy term to the
/// one-bone energy", "a term corresponding to the distance of the free caps to the data
/// points") for bones whose free end escapes the data; without it a bone can grow into empty
/// space, or swell, while its points still fit. **Choice:** it is carried by the chain tips
/// (bones without children, and bones leaving a free root), as the thesis proposes, and by
/// every **trunk** bone ([`super::solver::trunk_bones`]: the root block and the chains other
/// chains hang from). With the data term alone a trunk bone swells and stretches to swallow
/// the points of the limbs that hang from it (on 16 posed synthetic statues, tips only: trunk
/// radii up to 1.5× and spine lengths up to 1.7× the truth, mean joint error ≤ 2% of the
/// height on 4 of 16; trunk too: 6 of 16, 13 better, 3 worse, mean of the errors 4.5% →
/// 3.6%). A limb's mid-chain bones do not carry it: over a legitimate gap (a missing middle
/// portion, fig. 2.12, a test) it would pull the bone off its points, and the two-bone fits
/// already hold mid-chain joints. It is left out of the initial forward pass, where bones
/// start far from the data and it would only pull them towards the nearest surface.
///
/// **Choice:** 32 samples per bone, fixed in the bone's own parameterisation so they move
/// smoothly with it (24 on the cone: 4 stations along the axis × 6 around it; 4 on each cap:
/// its pole and 3 directions 50° off it). A sample hidden inside another bone is skipped.
/// Each visible sample contributes `weight · max(0, |s − q| − slack)` with `q` the nearest
/// data point (k-d tree, re-queried at every evaluation; a sample that the solver's
/// [`NearGrid`] finds within the slack skips the query, since its term is zero either way)
/// and `slack` [`OCCUPANCY_SLACK`] times the data's median nearest-neighbour spacing, so a
/// bone lying on the data pays nothing (no pull towards dense spots);
/// `weight² = density × area / 32`, the number of points the sample's share of the bone would
/// carry at the statue's average density, so a bone fully off the data costs like that many
/// points at that distance.
pub struct OccupancyTerm<'a> {
    pub bones: &'a [usize],
    /// `weight` of each bone's samples (same order as `bones`).
    pub weights: &'a [f64],
    pub tree: &'a kiddo::ImmutableKdTree<f32, 3>,
    /// The same points in a grid ([`NearGrid`]): a sample with a point of the grid near it
    /// is within the slack without a query of the tree (the same residuals bit for bit).
    pub grid: Option<&'a NearGrid>,
    pub positions: &'a [Vec3],
    /// Distance under which a sample counts as lying on the data.
    pub slack: f32,
}

/// Samples per bone of the occupancy term.
pub const OCCUPANCY_SAMPLES: usize = 32;

/// The occupancy term's slack in median nearest-neighbour spacings (see [`OccupancyTerm`]).
///
/// **Choice: 2, knowing it biases a fit lying on the data.** Points scattered at random over
/// a surface at density `ρ` leave a spot farther than `x` from every point with probability
/// `exp(−πρx²)`; their median nearest-neighbour spacing is `√(ln 2 / πρ)`, so a spot lies
/// farther than `k` spacings from the data with probability `2^(−k²)`: 1 in 16 at 2
/// spacings, 1 in 512 at 3, 1 in 65,536 at 4. At 2, one sample in 16 of a bone lying exactly
/// on the data pays and pulls: the papers' chain (`synth::chain4`, 5k points, no noise)
/// registered from its own truth drifts to a mean distance of 0.0145 with joints up to 0.14
/// off (length 140); at 3 and 4 it stays (mean distance 4·10⁻⁶). But on the 16 posed humans
/// of `fakir/accuracy_posed` the larger slacks fit fewer statues well: under 2% of the
/// height 15 at 2, 14 at 3, 13 at 4 (medians 0.55%, 0.53%, 0.44%; 90th percentiles 1.4%,
/// 3.1%, 4.4%). The pull of the spots between points seems to help hold bones on a figure
/// more than the bias costs (not checked further).
pub const OCCUPANCY_SLACK: f32 = 2.0;

/// World positions of the occupancy samples of bone `b` of `w` (see [`OccupancyTerm`]).
pub fn occupancy_samples(w: &WorldSkeleton, bones: &[Bone], b: usize) -> [Vec3; OCCUPANCY_SAMPLES] {
    let bone = bones[b];
    let f = w.frames[b];
    let (x, y, z) = (f * Vec3::X, f * Vec3::Y, f * Vec3::Z);
    let l = bone.length();
    let sin_a = if l > 1e-12 {
        ((bone.r2 - bone.r1) / l).clamp(-0.99, 0.99)
    } else {
        0.0
    };
    let cos_a = (1.0 - sin_a * sin_a).sqrt();
    let mut out = [Vec3::ZERO; OCCUPANCY_SAMPLES];
    let mut k = 0;
    for u in [0.125f32, 0.375, 0.625, 0.875] {
        for j in 0..6 {
            let phi = (j as f32 + 0.5 * (u * 8.0).round() % 2.0) * std::f32::consts::TAU / 6.0;
            let v = phi.cos() * y + phi.sin() * z;
            let n = cos_a * v - sin_a * x;
            let r = bone.r1 + u * (bone.r2 - bone.r1);
            out[k] = bone.c1 + (u * l) * x + r * n;
            k += 1;
        }
    }
    let (s50, c50) = 50f32.to_radians().sin_cos();
    for (c, r, sign) in [(bone.c2, bone.r2, 1.0f32), (bone.c1, bone.r1, -1.0)] {
        out[k] = c + r * sign * x;
        k += 1;
        for j in 0..3 {
            let phi = j as f32 * std::f32::consts::TAU / 3.0;
            out[k] = c + r * (sign * c50 * x + s50 * (phi.cos() * y + phi.sin() * z));
            k += 1;
        }
    }
    out
}

impl OccupancyTerm<'_> {
    fn nearest(&self, s: Vec3) -> Vec3 {
        let nn = self
            .tree
            .query(&s.to_array())
            .nearest_one::<kiddo::SquaredEuclidean<f32>>()
            .execute();
        self.positions[nn.item as usize]
    }

    /// Weighted residuals and unit directions of every sample (zero for hidden samples and
    /// samples within the slack), bone by bone.
    fn residuals(&self, w: &WorldSkeleton) -> Vec<(f64, Vec3, f64)> {
        let bones = w.bones();
        let prepared: Vec<_> = bones.iter().map(|b| b.prepare()).collect();
        // Bounding spheres (centre, squared radius): a sample outside one is not inside that
        // bone (its signed distance is positive, far above `-tol`).
        let spheres: Vec<(Vec3, f32)> = bones
            .iter()
            .map(|b| {
                let (c, r) = b.bounding_sphere();
                (c, r * r)
            })
            .collect();
        let mut out = Vec::with_capacity(self.bones.len() * OCCUPANCY_SAMPLES);
        for (bi, &b) in self.bones.iter().enumerate() {
            let tol = 1e-4 * (bones[b].length() + bones[b].r1 + bones[b].r2);
            for s in occupancy_samples(w, &bones, b) {
                let hidden = prepared
                    .iter()
                    .zip(&spheres)
                    .enumerate()
                    .any(|(o, (pb, c))| {
                        o != b && (s - c.0).length_squared() <= c.1 && pb.sdf_fast(s) < -tol
                    });
                if hidden || self.grid.is_some_and(|g| g.within_below(s, self.slack)) {
                    out.push((0.0, Vec3::ZERO, 0.0));
                    continue;
                }
                let d = s - self.nearest(s);
                let l = d.length();
                if l <= self.slack {
                    out.push((0.0, Vec3::ZERO, 0.0));
                } else {
                    let wgt = self.weights[bi];
                    out.push((wgt * (l - self.slack) as f64, d / l, wgt));
                }
            }
        }
        out
    }

    /// Energy of the term.
    pub fn energy(&self, w: &WorldSkeleton) -> f64 {
        self.residuals(w).iter().map(|(r, _, _)| r * r).sum()
    }

    /// All samples of the term's bones, concatenated.
    fn all_samples(&self, w: &WorldSkeleton) -> Vec<Vec3> {
        let bones = w.bones();
        self.bones
            .iter()
            .flat_map(|&b| occupancy_samples(w, &bones, b))
            .collect()
    }
}

impl EnergyTerms<'_> {
    /// Number of points in the energy.
    pub fn count(&self) -> usize {
        self.bones.iter().map(|&b| self.members[b].len()).sum()
    }

    /// Energy (sum of squared residuals) for the given world bones, in a fixed order.
    pub fn energy(&self, bones: &[Bone]) -> f64 {
        let mut acc = EnergyAccumulator::new(bones.to_vec());
        while !acc.feed(self, usize::MAX) {}
        acc.data
    }

    /// Data energy plus the occupancy term, for a world skeleton.
    pub fn total_energy(&self, w: &WorldSkeleton) -> f64 {
        self.energy(&w.bones())
            + self.occupancy.as_ref().map_or(0.0, |c| c.energy(w))
            + self.prior.as_ref().map_or(0.0, |p| p.energy(w))
    }
}

/// Points of a slice of a sliced accumulation over an energy's members ([`NormalAccumulator`],
/// [`EnergyAccumulator`]): the registration makes each slice a work unit of its own, so no
/// unit projects more than this many points, however many points the fitted bones carry
/// (tens of thousands on a 100k-point level 1). A whole number of chunks, so slicing keeps
/// the chunks, and therefore the sums, of an unsliced pass.
pub const SLICE_POINTS: usize = 4 * CHUNK;

/// Where a sliced pass over the members of an energy's bones stands: bone `bone` of the
/// energy's bones (prepared once, when the pass reaches it), its members from `offset` on (a
/// multiple of [`CHUNK`]), `done` members of the bones before it visited.
#[derive(Clone, Debug, Default)]
struct Cursor {
    bone: usize,
    offset: usize,
    done: usize,
    prepared: Option<PreparedBone>,
}

impl Cursor {
    /// Visits the next runs of members, at most `budget` points rounded up to whole chunks,
    /// in the fixed order (bone by bone, each bone's members in order): `f(b, bone, run, at,
    /// last)` gets the bone's index `b`, its world bone from `bones` prepared, the members'
    /// run, the run's position in the whole pass (the index of its first member in a
    /// [`PointRows`] of the pass), and whether the run ends the bone's members. Returns true
    /// when every member has been visited.
    fn advance(
        &mut self,
        terms: &EnergyTerms,
        bones: &[Bone],
        budget: usize,
        mut f: impl FnMut(usize, &PreparedBone, &[u32], usize, bool),
    ) -> bool {
        let mut chunks = budget.div_ceil(CHUNK).max(1);
        while self.bone < terms.bones.len() {
            if chunks == 0 {
                return false;
            }
            let b = terms.bones[self.bone];
            let pb = self.prepared.get_or_insert_with(|| bones[b].prepare());
            let members = &terms.members[b];
            let end = members
                .len()
                .min(self.offset.saturating_add(chunks.saturating_mul(CHUNK)));
            let last = end == members.len();
            let start = self.offset.min(end);
            f(b, pb, &members[start..end], self.done + start, last);
            chunks -= (end - start).div_ceil(CHUNK);
            if last {
                self.bone += 1;
                self.offset = 0;
                self.done += members.len();
                self.prepared = None;
            } else {
                self.offset = end;
            }
        }
        true
    }
}

/// One point of a pass over an energy's members: its residual and the residual's gradient
/// with respect to its bone ([`crate::geometry::Projection::gradient`]).
pub type PointRow = (f32, BoneGradient);

/// The [`PointRow`]s of a whole pass over an energy's members, in the pass's order (bone by
/// bone, each bone's members in order): what a pass at one state leaves for the next pass at
/// the same state, bones and assignment (the solver's LM loop), which then projects nothing
/// and sums exactly the same numbers.
pub type PointRows = Vec<PointRow>;

/// Where a sliced pass finds its points' rows: `read`, rows of an earlier pass at the same
/// state (nothing is projected; `write` is then left alone); else `write`, room for the
/// rows it projects (as many as the members); neither, rows projected and dropped.
#[derive(Default)]
pub struct Rows<'r> {
    pub read: Option<&'r [PointRow]>,
    pub write: Option<&'r mut [PointRow]>,
}

/// The zero row (room for a pass's rows before it writes them).
pub const NO_ROW: PointRow = (
    0.0,
    BoneGradient {
        dc1: Vec3::ZERO,
        dc2: Vec3::ZERO,
        dr1: 0.0,
        dr2: 0.0,
    },
);

/// The rows of the points `run` (whose first member is row `at` of the pass) of bone `pb`,
/// chunk by chunk in parallel: `f` folds each chunk's rows into a partial sum, in order; the
/// rows are read from `rows.read` or projected (into `rows.write`, or a chunk on the stack).
fn chunk_rows<T: Send>(
    a: &Assignment,
    pb: &PreparedBone,
    run: &[u32],
    at: usize,
    rows: &mut Rows,
    f: impl Fn(&[PointRow]) -> T + Sync,
) -> Vec<T> {
    let project = |c: &[u32], out: &mut [PointRow]| {
        for (&i, o) in c.iter().zip(out.iter_mut()) {
            let proj = pb.project_constrained(a.positions[i as usize], a.normals[i as usize]);
            *o = (proj.residual, proj.gradient());
        }
    };
    let read = rows.read.map(|r| &r[at..at + run.len()]);
    let write = rows
        .write
        .as_deref_mut()
        .map(|w| &mut w[at..at + run.len()]);
    match (read, write) {
        (Some(r), _) => r.par_chunks(CHUNK).map(&f).collect(),
        (None, Some(w)) => run
            .par_chunks(CHUNK)
            .zip(w.par_chunks_mut(CHUNK))
            .map(|(c, out)| {
                project(c, out);
                f(out)
            })
            .collect(),
        (None, None) => run
            .par_chunks(CHUNK)
            .map(|c| {
                let mut out = [NO_ROW; CHUNK];
                project(c, &mut out);
                f(&out[..c.len()])
            })
            .collect(),
    }
}

/// The data energy of [`EnergyTerms`] for given bones, summed slice by slice
/// ([`SLICE_POINTS`]) with exactly the sums of an unsliced pass: per bone, the chunks' partial
/// sums in order; then the bones in order.
pub struct EnergyAccumulator {
    bones: Vec<Bone>,
    cursor: Cursor,
    bone_sum: f64,
    /// The data energy summed so far (all of it once [`EnergyAccumulator::feed`] returned true).
    pub data: f64,
}

impl EnergyAccumulator {
    /// An accumulation for the world bones `bones` (indexed like the template's).
    pub fn new(bones: Vec<Bone>) -> Self {
        EnergyAccumulator {
            bones,
            cursor: Cursor::default(),
            bone_sum: 0.0,
            data: 0.0,
        }
    }

    /// Adds the next `budget` points (whole chunks); true when every point is in.
    pub fn feed(&mut self, terms: &EnergyTerms, budget: usize) -> bool {
        self.feed_rows(terms, budget, &mut Rows::default())
    }

    /// [`EnergyAccumulator::feed`], the points' rows read from or written to `rows`.
    pub fn feed_rows(&mut self, terms: &EnergyTerms, budget: usize, rows: &mut Rows) -> bool {
        let a = terms.assignment;
        let (bone_sum, data) = (&mut self.bone_sum, &mut self.data);
        self.cursor
            .advance(terms, &self.bones, budget, |_, pb, run, at, last| {
                let parts = chunk_rows(a, pb, run, at, rows, |c| {
                    c.iter()
                        .map(|(r, _)| {
                            let r = *r as f64;
                            r * r
                        })
                        .sum::<f64>()
                });
                for p in parts {
                    *bone_sum += p;
                }
                if last {
                    *data += *bone_sum;
                    *bone_sum = 0.0;
                }
            })
    }

    /// The total energy (data, occupancy, prior) of the world skeleton `w` whose bones were
    /// fed, once [`EnergyAccumulator::feed`] returned true.
    pub fn finish(&self, terms: &EnergyTerms, w: &WorldSkeleton) -> f64 {
        self.data
            + terms.occupancy.as_ref().map_or(0.0, |c| c.energy(w))
            + terms.prior.as_ref().map_or(0.0, |p| p.energy(w))
    }
}

/// Outcome of one LM iteration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LmStep {
    pub energy_before: f64,
    pub energy_after: f64,
    pub accepted: bool,
    /// Norm of the step taken (0 when rejected).
    pub step_norm: f64,
}

/// Per-bone derivatives of `(c1, c2, r1, r2)` with respect to one parameter.
#[derive(Clone, Copy, Debug, Default)]
struct GeoDeriv {
    dc1: Vec3,
    dc2: Vec3,
    dr1: f32,
    dr2: f32,
}

/// The normal-equation sums of a group of `k` parameters: `JᵀJ` (`k × k`, row-major, upper
/// triangle and diagonal filled), `Jᵀr` and the energy `rᵀr`.
///
/// Sized by the group, not by [`MAX_PARAMS`]: the papers' groups (1 to 7 parameters) do not
/// pay for the whole-chain fit's room.
#[derive(Clone, Debug, PartialEq)]
pub struct NormalEquations {
    /// `JᵀJ`, row-major with stride `k` (upper triangle and diagonal).
    pub jtj: Vec<f64>,
    /// `Jᵀr`.
    pub jtr: Vec<f64>,
    /// `rᵀr`.
    pub energy: f64,
}

impl NormalEquations {
    /// Zero sums for `k` parameters.
    pub fn zeros(k: usize) -> Self {
        NormalEquations {
            jtj: vec![0.0; k * k],
            jtr: vec![0.0; k],
            energy: 0.0,
        }
    }

    /// Number of parameters.
    pub fn k(&self) -> usize {
        self.jtr.len()
    }

    /// Adds one residual `r` with its Jacobian row (`k` entries): `r²` to the energy, the
    /// row to `JᵀJ` (upper triangle) and `Jᵀr`.
    #[inline]
    pub fn add_row(&mut self, row: &[f64], r: f64) {
        self.energy += r * r;
        let k = self.k();
        let row = &row[..k];
        for (j, (&rj, tr)) in row.iter().zip(&mut self.jtr).enumerate() {
            *tr += rj * r;
            let upper = &mut self.jtj[j * k + j..(j + 1) * k];
            for (x, &rm) in upper.iter_mut().zip(&row[j..]) {
                *x += rj * rm;
            }
        }
    }

    /// [`NormalEquations::add_row`] for a row whose only entries that may be nonzero are those
    /// of the parameters `active` (increasing), `row[a]` being parameter `active[a]`'s. The
    /// other entries are zeros (of either sign), whose products the dense row would add:
    /// adding `±0` to a sum that started at `+0` changes no bit of it (a sum of such terms
    /// cannot become `−0`), so the sums are the dense row's, bit for bit, as long as the row
    /// holds no infinity or NaN (an infinite entry times a zero would have made a NaN).
    #[inline]
    pub fn add_sparse_row(&mut self, active: &[usize], row: &[f64], r: f64) {
        self.energy += r * r;
        let k = self.k();
        for (a, (&j, &rj)) in active.iter().zip(row).enumerate() {
            self.jtr[j] += rj * r;
            let upper = &mut self.jtj[j * k..(j + 1) * k];
            for (&m, &rm) in active[a..].iter().zip(&row[a..]) {
                upper[m] += rj * rm;
            }
        }
    }

    /// Adds the sums of `other` (same `k`) entry by entry.
    pub fn add(&mut self, other: &NormalEquations) {
        let k = self.k();
        for j in 0..k {
            let upper = j * k + j..(j + 1) * k;
            for (x, y) in self.jtj[upper.clone()].iter_mut().zip(&other.jtj[upper]) {
                *x += y;
            }
            self.jtr[j] += other.jtr[j];
        }
        self.energy += other.energy;
    }
}

/// Normal-equation terms of a parameter group at the current state (see
/// [`NormalEquations`]).
pub fn normal_equations(
    w: &WorldSkeleton,
    classes: &RadiusClasses,
    params: &[Param],
    terms: &EnergyTerms,
    size: f32,
) -> NormalEquations {
    let mut acc = NormalAccumulator::new(w, classes, params, terms, size);
    while !acc.feed(terms, usize::MAX) {}
    acc.finish(w, terms)
}

/// [`normal_equations`] summed slice by slice ([`SLICE_POINTS`] points of the members at a
/// time), with exactly the sums of an unsliced pass: `new` takes the geometry Jacobian,
/// `feed` adds the members' rows in order, `finish` adds the occupancy and prior rows.
pub struct NormalAccumulator {
    k: usize,
    bones: Vec<Bone>,
    /// `geo[b * k + j]`: the derivatives of bone `b` with respect to parameter `j`.
    geo: Vec<GeoDeriv>,
    /// `active[b]`: the parameters (increasing) whose derivatives of bone `b` are not all
    /// zero. The whole-chain fit's parameters move only the bones from theirs on, so the
    /// rows of a chain's first bones are mostly zeros ([`NormalEquations::add_sparse_row`]).
    active: Vec<Vec<usize>>,
    occ_deriv: Vec<Vec<Vec3>>,
    prior_deriv: Vec<Vec<f64>>,
    cursor: Cursor,
    sums: NormalEquations,
}

impl NormalAccumulator {
    /// Starts the normal equations of `params` at the state `w`: the derivatives of the bones
    /// (and of the occupancy samples and prior residuals) with respect to each parameter.
    pub fn new(
        w: &WorldSkeleton,
        classes: &RadiusClasses,
        params: &[Param],
        terms: &EnergyTerms,
        size: f32,
    ) -> Self {
        let k = params.len();
        assert!(k > 0 && k <= MAX_PARAMS);
        let bones = w.bones();
        // Geometry Jacobian by central differences of the forward kinematics.
        let mut geo = vec![GeoDeriv::default(); bones.len() * k];
        let mut occ_deriv: Vec<Vec<Vec3>> = vec![Vec::new(); k];
        let mut prior_deriv: Vec<Vec<f64>> = vec![Vec::new(); k];
        for (j, p) in params.iter().enumerate() {
            let h = fd_step(p, size);
            let mut plus = w.clone();
            apply(&mut plus, classes, p, h);
            let mut minus = w.clone();
            apply(&mut minus, classes, p, -h);
            let (bp, bm) = (plus.bones(), minus.bones());
            if let Some(occ) = &terms.occupancy {
                let (sp, sm) = (occ.all_samples(&plus), occ.all_samples(&minus));
                occ_deriv[j] = sp
                    .iter()
                    .zip(&sm)
                    .map(|(a, b)| (*a - *b) / (2.0 * h))
                    .collect();
            }
            if let Some(prior) = &terms.prior {
                let (rp, rm) = (prior.residuals(&plus), prior.residuals(&minus));
                prior_deriv[j] = rp
                    .iter()
                    .zip(&rm)
                    .map(|(a, b)| (a - b) / (2.0 * h as f64))
                    .collect();
            }
            for &b in terms.bones {
                let inv = 1.0 / (2.0 * h);
                geo[b * k + j] = GeoDeriv {
                    dc1: (bp[b].c1 - bm[b].c1) * inv,
                    dc2: (bp[b].c2 - bm[b].c2) * inv,
                    dr1: (bp[b].r1 - bm[b].r1) * inv,
                    dr2: (bp[b].r2 - bm[b].r2) * inv,
                };
            }
        }
        let mut active = vec![Vec::new(); bones.len()];
        for &b in terms.bones {
            active[b] = (0..k)
                .filter(|&j| {
                    let d = &geo[b * k + j];
                    d.dc1 != Vec3::ZERO || d.dc2 != Vec3::ZERO || d.dr1 != 0.0 || d.dr2 != 0.0
                })
                .collect();
        }
        NormalAccumulator {
            k,
            bones,
            geo,
            active,
            occ_deriv,
            prior_deriv,
            cursor: Cursor::default(),
            sums: NormalEquations::zeros(k),
        }
    }

    /// Adds the rows of the next `budget` member points (whole chunks) to `JᵀJ`, `Jᵀr` and
    /// the energy; true when every member is in.
    pub fn feed(&mut self, terms: &EnergyTerms, budget: usize) -> bool {
        self.feed_rows(terms, budget, &mut Rows::default())
    }

    /// [`NormalAccumulator::feed`], the points' rows read from or written to `rows`.
    pub fn feed_rows(&mut self, terms: &EnergyTerms, budget: usize, rows: &mut Rows) -> bool {
        let a = terms.assignment;
        let k = self.k;
        let (geo, active, sums) = (&self.geo, &self.active, &mut self.sums);
        self.cursor
            .advance(terms, &self.bones, budget, |b, pb, run, at, _| {
                let g = &geo[b * k..(b + 1) * k];
                let act = &active[b];
                let entry = |grad: &BoneGradient, d: &GeoDeriv| {
                    (grad.dc1.dot(d.dc1)
                        + grad.dc2.dot(d.dc2)
                        + grad.dr1 * d.dr1
                        + grad.dr2 * d.dr2) as f64
                };
                let parts = chunk_rows(a, pb, run, at, rows, |c| {
                    let mut part = NormalEquations::zeros(k);
                    let mut row = [0.0f64; MAX_PARAMS];
                    // Every parameter active (the papers' one- and two-bone groups): the
                    // plain row, without the indirection through `act`.
                    if act.len() == k {
                        for (r, grad) in c {
                            for (x, d) in row.iter_mut().zip(g) {
                                *x = entry(grad, d);
                            }
                            part.add_row(&row[..k], *r as f64);
                        }
                    } else {
                        for (r, grad) in c {
                            for (x, &j) in row.iter_mut().zip(act) {
                                *x = entry(grad, &g[j]);
                            }
                            part.add_sparse_row(act, &row[..act.len()], *r as f64);
                        }
                    }
                    part
                });
                for part in &parts {
                    sums.add(part);
                }
            })
    }

    /// Adds the occupancy and prior rows (at the state `w` given to `new`) and returns the
    /// sums, once [`NormalAccumulator::feed`] returned true.
    pub fn finish(self, w: &WorldSkeleton, terms: &EnergyTerms) -> NormalEquations {
        let (k, mut sums) = (self.k, self.sums);
        let mut row = [0.0f64; MAX_PARAMS];
        if let Some(occ) = &terms.occupancy {
            for (q, (r, e, wgt)) in occ.residuals(w).iter().enumerate() {
                for (x, d) in row.iter_mut().zip(&self.occ_deriv) {
                    *x = wgt * e.dot(d[q]) as f64;
                }
                sums.add_row(&row[..k], *r);
            }
        }
        if let Some(prior) = &terms.prior {
            for (q, r) in prior.residuals(w).iter().enumerate() {
                for (x, d) in row.iter_mut().zip(&self.prior_deriv) {
                    *x = d[q];
                }
                sums.add_row(&row[..k], *r);
            }
        }
        sums
    }
}

/// The damped step of one Levenberg–Marquardt iteration from the normal equations `ne` of
/// the state `w`: the trial state (clamped to `limits`) and the step's norm, or `None` when
/// the damped system is singular (the damping is then raised tenfold: a rejected step). The
/// trial's energy is then summed (sliced, [`EnergyAccumulator`]) and [`lm_decide`] accepts or
/// rejects it.
#[allow(clippy::too_many_arguments)]
pub fn lm_trial(
    w: &WorldSkeleton,
    classes: &RadiusClasses,
    limits: &Limits,
    params: &[Param],
    ne: &NormalEquations,
    lambda: &mut f64,
    clamp_bones: &[usize],
) -> Option<(WorldSkeleton, f64)> {
    let k = params.len();
    debug_assert_eq!(ne.k(), k);
    // Damped normal equations (the lower triangle mirrored from the upper).
    let mut mat = vec![0.0f64; k * k];
    let mut rhs = [0.0f64; MAX_PARAMS];
    for j in 0..k {
        for m in 0..k {
            mat[j * k + m] = if m < j {
                ne.jtj[m * k + j]
            } else {
                ne.jtj[j * k + m]
            };
        }
        let d = ne.jtj[j * k + j];
        mat[j * k + j] = d + *lambda * d.max(1e-12);
        rhs[j] = -ne.jtr[j];
    }
    let Some(delta) = solve(&mut mat, &mut rhs, k) else {
        *lambda *= 10.0;
        return None;
    };
    let mut trial = w.clone();
    for (j, p) in params.iter().enumerate() {
        apply(&mut trial, classes, p, delta[j] as f32);
    }
    limits.clamp(&mut trial, classes, clamp_bones);
    let norm = delta[..k].iter().map(|d| d * d).sum::<f64>().sqrt();
    Some((trial, norm))
}

/// Ends an LM iteration: the trial state (from [`lm_trial`], total energy `after`) replaces
/// `w` when it lowers the energy of the normal equations `cache` (which are then dropped,
/// and the damping divided by 10); otherwise `w` and `cache` stay (a rejected step keeps its
/// normal equations) and the damping is multiplied by 10.
pub fn lm_decide(
    w: &mut WorldSkeleton,
    trial: WorldSkeleton,
    norm: f64,
    after: f64,
    lambda: &mut f64,
    cache: &mut Option<NormalEquations>,
) -> LmStep {
    let energy = cache.as_ref().map_or(f64::INFINITY, |ne| ne.energy);
    if after < energy {
        *w = trial;
        *cache = None;
        *lambda = (*lambda / 10.0).max(1e-9);
        LmStep {
            energy_before: energy,
            energy_after: after,
            accepted: true,
            step_norm: norm,
        }
    } else {
        *lambda = (*lambda * 10.0).min(1e12);
        LmStep {
            energy_before: energy,
            energy_after: energy,
            accepted: false,
            step_norm: 0.0,
        }
    }
}

/// Solves the `k × k` system `m` (row-major, stride `k`) in place by Gaussian elimination
/// with partial pivoting.
fn solve(m: &mut [f64], rhs: &mut [f64; MAX_PARAMS], k: usize) -> Option<[f64; MAX_PARAMS]> {
    for col in 0..k {
        let piv =
            (col..k).max_by(|&x, &y| m[x * k + col].abs().total_cmp(&m[y * k + col].abs()))?;
        if !(m[piv * k + col].abs() > 1e-300) {
            return None;
        }
        if piv != col {
            for c in 0..k {
                m.swap(piv * k + c, col * k + c);
            }
            rhs.swap(piv, col);
        }
        for r in col + 1..k {
            let f = m[r * k + col] / m[col * k + col];
            for c in col..k {
                m[r * k + c] -= f * m[col * k + c];
            }
            rhs[r] -= f * rhs[col];
        }
    }
    let mut x = [0.0f64; MAX_PARAMS];
    for r in (0..k).rev() {
        let mut s = rhs[r];
        for c in r + 1..k {
            s -= m[r * k + c] * x[c];
        }
        x[r] = s / m[r * k + r];
        if !x[r].is_finite() {
            return None;
        }
    }
    Some(x)
}
