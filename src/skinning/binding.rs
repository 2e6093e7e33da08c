//! [`Binding`]: every point of a statue attached to its fitted skeleton (Algorithm 2 step 1,
//! Algorithm 3 step 1), stored as structure-of-arrays and built in parallel.
//!
//! Per point: its bone (the bone whose surface is nearest, by signed distance, so points inside
//! overlapping bones go to the deepest one), its base point `p̃` (orthogonal projection on that
//! bone) encoded intrinsically ([`super::surface`]), its signed height `h` with
//! `p = p̃ + h n_p̃`, its normal in the bone frame, its **blend partner** (the neighbouring bone
//! across the nearer joint, when the base point lies within reach of that bone's bending
//! weights) with its eq. 3.1 weight, and its baseline parameters ([`super::baseline`]).
//!
//! **Joints that bend.** The joint at `c1` of a bone links it to its parent, except between two
//! bones of the same rigid block. The joint at `c2` used by baseline skinning links a bone to
//! its chain successor, or to its only child; where a chain branches (shoulders on the spine's
//! top, hips on the pelvis) the branching bone meets its parent at its own `c1` only.
//!
//! **The base** ([`Binding::with_base`]; our addition): the points of the statue's plinth
//! ([`crate::cloud::base`]) are bound like the others, so the arrays stay one per point, but
//! every deformation then puts them back where they stood, moved only by the root's rigid
//! placement (`Binding::place_base`): a plinth neither bends with the feet nor follows a
//! change of proportions.
//!
//! **Influence size** `ε'_r` of the joint between `B_p` and `B_k` (thesis §3.2.1):
//! `ε'_r = 0.2 · max(r_j / 4, min(r_j, l_p − r_p1 − r_j, l_k − r_j − r_k2))` — the thesis'
//! formula (the joint radius and the gaps between consecutive spheres) with a floor so that
//! strongly overlapping spheres keep a usable influence. A point is given a partner when its
//! base point is within `1.5 ε'_r` of the partner's surface (beyond, the Gaussian weight is
//! below 5·10⁻⁵).

use super::baseline;
use super::frame::{self, BoneFrame};
use super::heightfield;
use super::surface::{BoneShape, CAP1, CAP2, CONE, encode};
use crate::anatomy::{BoneKind, Skeleton};
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::geometry::Bone;
use crate::geometry::bone::{Part, PreparedBone};
use crate::math::{Quat, Vec3};
use rayon::prelude::*;

/// No partner / no bone.
pub const NONE: u16 = u16::MAX;

/// Per-bone data of a binding (fitted pose).
#[derive(Clone, Debug)]
pub struct BoneBind {
    /// Parent bone.
    pub parent: Option<usize>,
    /// The bone across the joint at `c1` (the parent, unless both are in a rigid block).
    pub c1_partner: Option<usize>,
    /// The bone across the joint at `c2` for baseline curves (chain successor or only child).
    pub c2_partner: Option<usize>,
    /// Share of this bone's twist change taken by the parent side of the joint at `c1`:
    /// `1/2` when this bone continues the parent's chain, else `0`.
    pub parent_share: f32,
    /// Fitted shape.
    pub shape: BoneShape,
    /// Fitted world frame.
    pub frame: Quat,
    /// Fitted world `c1`.
    pub c1: Vec3,
    /// `ε'_r` of the joint at `c1` (0 without a partner).
    pub eps: f32,
}

/// Per-point data, structure of arrays.
#[derive(Clone, Debug, Default)]
pub struct PointData {
    /// Bone index.
    pub bone: Vec<u16>,
    /// Part of the base point ([`super::surface::CAP1`], `CONE`, `CAP2`).
    pub part: Vec<u8>,
    /// Fraction along the generatrix (cone points).
    pub s: Vec<f32>,
    /// Cap direction or cone radial direction, bone-local.
    pub dir: Vec<Vec3>,
    /// Signed height above the base point.
    pub height: Vec<f32>,
    /// The point's normal, bone-local.
    pub normal: Vec<Vec3>,
    /// Fitted world position (LBS / DQS).
    pub position: Vec<Vec3>,
    /// Blend partner bone or [`NONE`].
    pub partner: Vec<u16>,
    /// Eq. 3.1 weight of the partner (LBS / DQS).
    pub weight: Vec<f32>,
    /// Baseline grid cell ([`super::baseline::NO_CELL`]: the point moves rigidly with its
    /// bone — free caps, or far past a key point).
    pub bl_cell: Vec<u32>,
    /// Bilinear fractions in the baseline grid cell.
    pub bl_uv: Vec<[f32; 2]>,
    /// Baseline height along the detail direction.
    pub bl_h: Vec<f32>,
    /// What the baseline decomposition leaves over, in the detail frame (usually tiny).
    pub bl_res: Vec<Vec3>,
    /// The point's normal in the baseline detail frame.
    pub bl_n: Vec<Vec3>,
}

/// A statue's points bound to its fitted skeleton.
#[derive(Clone, Debug)]
pub struct Binding {
    pub(crate) fitted: Skeleton,
    pub(crate) bones: Vec<BoneBind>,
    pub(crate) points: PointData,
    /// Detail directions of the baseline grid at the fitted pose.
    pub(crate) fit_grid_normals: Vec<Vec3>,
    /// Heightfield skinning's layout (derived from `points`, not saved).
    pub(crate) hf: heightfield::Slots,
    /// Baseline skinning's rigid points (derived from `points`, not saved).
    pub(crate) bl_rigid: baseline::Rigid,
    /// The base's points, increasing (see the module docs).
    pub(crate) base: Vec<u32>,
    /// The bones left out ([`Binding::new_without`]), one flag per bone; empty for none.
    pub(crate) lost: Vec<bool>,
}

/// One point's binding, before splitting into arrays.
#[derive(Clone, Copy, Default)]
struct Rec {
    bone: u16,
    part: u8,
    s: f32,
    dir: Vec3,
    height: f32,
    normal: Vec3,
    position: Vec3,
    partner: u16,
    weight: f32,
    bl: baseline::PointBaseline,
}

fn part_code(p: Part) -> u8 {
    match p {
        Part::Cap1 => CAP1,
        Part::Cone => CONE,
        Part::Cap2 => CAP2,
    }
}

/// Checks that `skel` can drive a binding: finite, positive lengths, non-negative radii.
pub(crate) fn check_skeleton(skel: &Skeleton, what: &str) -> Result<()> {
    if !skel.root_position.is_finite() || !skel.root_rotation.is_finite() {
        return Err(Error::input(format!(
            "{what}: the root placement is not finite"
        )));
    }
    for (i, b) in skel.bones.iter().enumerate() {
        let name = &skel.template.bones[i].name;
        if !b.rotation.is_finite() || !(b.rotation.length_squared() > 1e-12) {
            return Err(Error::input(format!(
                "{what}: bone '{name}' has an invalid rotation"
            )));
        }
        if !(b.length > 0.0) || !b.length.is_finite() {
            return Err(Error::input(format!(
                "{what}: bone '{name}' has length {} (must be positive and finite)",
                b.length
            )));
        }
        if !(b.r1 >= 0.0) || !(b.r2 >= 0.0) || !b.r1.is_finite() || !b.r2.is_finite() {
            return Err(Error::input(format!(
                "{what}: bone '{name}' has radii {} and {} (must be non-negative and finite)",
                b.r1, b.r2
            )));
        }
    }
    Ok(())
}

impl Binding {
    /// Binds every point of `cloud` to the skeleton `fitted` (the statue's fitted pose).
    /// Errors: an empty cloud, non-finite coordinates, a skeleton with non-finite or
    /// non-positive sizes, more than 65,534 bones.
    pub fn new(cloud: &PointCloud, fitted: &Skeleton) -> Result<Binding> {
        Binding::new_without(cloud, fitted, &[])
    }

    /// [`Binding::new`] where no point is bound to (or blended with) a bone flagged in `lost`
    /// (the lost limbs of a broken statue, [`crate::fakir::Fit::missing`]: completed to a
    /// plausible pose, they may pass through parts that are there). An empty `lost` flags
    /// none.
    pub fn new_without(cloud: &PointCloud, fitted: &Skeleton, lost: &[bool]) -> Result<Binding> {
        if cloud.is_empty() {
            return Err(Error::input("cannot bind an empty point cloud"));
        }
        let bad = cloud.positions.iter().filter(|p| !p.is_finite()).count();
        if bad > 0 {
            return Err(Error::input(format!(
                "cannot bind a cloud with {bad} non-finite point(s)"
            )));
        }
        check_skeleton(fitted, "fitted skeleton")?;
        let t = &fitted.template;
        if t.bones.len() >= NONE as usize {
            return Err(Error::input("too many bones for a binding"));
        }
        if !lost.is_empty() && lost.len() != t.bones.len() {
            return Err(Error::input(format!(
                "{} lost-bone flags for the {} bones of template '{}'",
                lost.len(),
                t.bones.len(),
                t.name
            )));
        }
        if !lost.is_empty() && lost.iter().all(|&l| l) {
            return Err(Error::input(
                "every bone is lost: nothing to bind the points to",
            ));
        }
        let (bones, prepared, tables) = prepare(fitted);
        let fit_grid_normals = tables.grid_normals();
        let normals = cloud.normals.as_deref();
        let recs: Vec<Rec> = cloud
            .positions
            .par_iter()
            .enumerate()
            .map(|(i, &p)| {
                bind_point(
                    p,
                    normals.map(|n| n[i]),
                    &prepared,
                    &bones,
                    &tables,
                    t.bones.as_slice(),
                    lost,
                )
            })
            .collect();
        let mut points = PointData::default();
        let m = recs.len();
        macro_rules! take {
            ($field:ident) => {
                points.$field = recs.iter().map(|r| r.$field).collect::<Vec<_>>();
            };
        }
        take!(bone);
        take!(part);
        take!(s);
        take!(dir);
        take!(height);
        take!(normal);
        take!(position);
        take!(partner);
        take!(weight);
        points.bl_cell = recs.iter().map(|r| r.bl.cell).collect();
        points.bl_uv = recs.iter().map(|r| r.bl.uv).collect();
        points.bl_h = recs.iter().map(|r| r.bl.h).collect();
        points.bl_n = recs.iter().map(|r| r.bl.n).collect();
        points.bl_res = recs.iter().map(|r| r.bl.res).collect();
        debug_assert_eq!(points.bone.len(), m);
        Ok(Binding {
            fitted: fitted.clone(),
            hf: heightfield::Slots::new(&bones, &points),
            bl_rigid: baseline::Rigid::new(&points),
            bones,
            points,
            fit_grid_normals,
            base: Vec::new(),
            lost: if lost.iter().any(|&l| l) {
                lost.to_vec()
            } else {
                Vec::new()
            },
        })
    }

    /// The bones this binding leaves out (given to [`Binding::new_without`]: a statue's lost
    /// limbs), one flag per bone; empty when none is.
    pub fn lost(&self) -> &[bool] {
        &self.lost
    }

    /// [`Binding::lost`] as one flag per bone of the fitted template, also when none is lost.
    pub fn lost_bones(&self) -> Vec<bool> {
        let n = self.fitted.template.bones.len();
        if self.lost.len() == n {
            self.lost.clone()
        } else {
            vec![false; n]
        }
    }

    /// The same binding with the points `base` (indices, e.g. [`crate::cloud::base::Base`]'s)
    /// held as the statue's base (see the module docs). Errors: an index out of range.
    pub fn with_base(mut self, base: &[u32]) -> Result<Binding> {
        if let Some(&bad) = base.iter().find(|&&i| i as usize >= self.len()) {
            return Err(Error::input(format!(
                "base point {bad} is not one of the {} bound points",
                self.len()
            )));
        }
        let mut v = base.to_vec();
        v.sort_unstable();
        v.dedup();
        self.base = v;
        Ok(self)
    }

    /// [`Binding::new`] holding as base the plinth that [`crate::cloud::base::detect_base`]
    /// finds along the fitted skeleton's up (its root frame's `+Y`): for fits that come
    /// without their base (a `FIT.json`, a restorer's skeleton). A cloud without normals gets
    /// no base.
    pub fn new_on_base(cloud: &PointCloud, fitted: &Skeleton) -> Result<Binding> {
        let b = Binding::new(cloud, fitted)?;
        let Some(normals) = cloud.normals.as_deref() else {
            return Ok(b);
        };
        let up = fitted.up();
        match crate::cloud::base::detect_base(
            &cloud.positions,
            normals,
            Some(up),
            &crate::cloud::base::BaseOptions::default(),
        ) {
            Some(base) => b.with_base(&base.points),
            None => Ok(b),
        }
    }

    /// The base's points (increasing; empty without a base).
    pub fn base(&self) -> &[u32] {
        &self.base
    }

    /// Writes the base's points for `target`: their fitted positions and normals moved by the
    /// rigid motion from the fitted root placement to the target's.
    pub(crate) fn place_base(
        &self,
        target: &Skeleton,
        positions: &mut [Vec3],
        normals: &mut [Vec3],
    ) {
        if self.base.is_empty() {
            return;
        }
        let f = &self.fitted;
        let turn = (target.root_rotation * f.root_rotation.inverse()).normalize();
        let pts = &self.points;
        for &i in &self.base {
            let i = i as usize;
            positions[i] = target.root_position + turn * (pts.position[i] - f.root_position);
            let frame = self.bones[pts.bone[i] as usize].frame;
            normals[i] = turn * (frame * pts.normal[i]);
        }
    }

    /// A binding from a fitted skeleton and its per-point arrays (the per-bone part and the
    /// baseline tables are recomputed from the skeleton).
    pub(crate) fn from_parts(fitted: Skeleton, points: PointData) -> Binding {
        let (bones, _, tables) = prepare(&fitted);
        Binding {
            fit_grid_normals: tables.grid_normals(),
            hf: heightfield::Slots::new(&bones, &points),
            bl_rigid: baseline::Rigid::new(&points),
            fitted,
            bones,
            points,
            base: Vec::new(),
            lost: Vec::new(),
        }
    }

    /// Number of bound points.
    pub fn len(&self) -> usize {
        self.points.bone.len()
    }

    /// True when no point is bound (never: binding an empty cloud is an error).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The fitted skeleton the binding was made on.
    pub fn fitted(&self) -> &Skeleton {
        &self.fitted
    }

    /// The per-point arrays.
    pub fn points(&self) -> &PointData {
        &self.points
    }

    /// Number of points with a blend partner (in a joint's bending zone).
    pub fn joint_points(&self) -> usize {
        self.points.partner.iter().filter(|&&p| p != NONE).count()
    }
}

/// The per-bone part of a binding (topology, joint sizes) with the fitted pose's prepared
/// bones and baseline tables: a pure function of the fitted skeleton.
fn prepare(fitted: &Skeleton) -> (Vec<BoneBind>, Vec<PreparedBone>, baseline::Tables) {
    let t = &fitted.template;
    let posed = fitted.pose();
    let n = t.bones.len();
    // Per-bone topology.
    let successor = |k: usize| -> Option<usize> {
        let (c, i) = t.bones[k].chain?;
        t.chains[c]
            .bones
            .get(i + 1)
            .copied()
            .filter(|&s| t.bones[s].parent == Some(k))
    };
    let is_block = |k: usize| matches!(t.bones[k].kind, BoneKind::Block);
    let mut bones: Vec<BoneBind> = (0..n)
        .map(|k| {
            let def = &t.bones[k];
            let c1_partner = def.parent.filter(|&p| !(is_block(p) && is_block(k)));
            let st = &fitted.bones[k];
            BoneBind {
                parent: def.parent,
                c1_partner,
                c2_partner: None,
                parent_share: match c1_partner {
                    Some(p) if successor(p) == Some(k) => 0.5,
                    _ => 0.0,
                },
                shape: BoneShape::new(st.length, st.r1, st.r2),
                frame: posed.frames[k],
                c1: posed.bones[k].c1,
                eps: 0.0,
            }
        })
        .collect();
    for k in 0..n {
        let children: Vec<usize> = t.bones[k]
            .children
            .iter()
            .copied()
            .filter(|&c| bones[c].c1_partner == Some(k))
            .collect();
        bones[k].c2_partner =
            successor(k)
                .filter(|s| children.contains(s))
                .or(if children.len() == 1 {
                    Some(children[0])
                } else {
                    None
                });
        if let Some(p) = bones[k].c1_partner {
            let rj = fitted.bones[p].r2;
            let gap_p = fitted.bones[p].length - fitted.bones[p].r1 - rj;
            let gap_k = fitted.bones[k].length - rj - fitted.bones[k].r2;
            bones[k].eps = 0.2 * (0.25 * rj).max(rj.min(gap_p).min(gap_k));
        }
    }
    let prepared: Vec<PreparedBone> = posed.bones.iter().map(Bone::prepare).collect();
    // The fitted pose analysed against itself: the baseline curves at bind time come from
    // the very code that evaluates them at deform time.
    let mut frames: Vec<BoneFrame> = Vec::new();
    frame::analyse(&bones, fitted, fitted, &posed, &mut frames);
    let mut tables = baseline::Tables::default();
    baseline::build_tables(&frames, &bones, None, &mut tables);
    (bones, prepared, tables)
}

fn bind_point(
    p: Vec3,
    normal: Option<Vec3>,
    prepared: &[PreparedBone],
    bones: &[BoneBind],
    tables: &baseline::Tables,
    defs: &[crate::anatomy::template::BoneDef],
    lost: &[bool],
) -> Rec {
    let is_lost = |b: usize| lost.get(b).copied().unwrap_or(false);
    // Nearest bone by (fast) signed distance (lost bones left out), then the exact
    // projection on it.
    let (k, _) = crate::geometry::bone::nearest_bone_where(prepared, p, |b| !is_lost(b));
    let proj = prepared[k].project(p);
    let bb = &bones[k];
    let inv = bb.frame.inverse();
    let b_loc = inv * (proj.point - bb.c1);
    let n_loc = (inv * proj.normal).normalize_or(Vec3::X);
    let part = part_code(proj.part);
    let (s, dir) = encode(&bb.shape, part, b_loc, n_loc);
    let height = (p - proj.point).dot(proj.normal);
    let point_normal = normal
        .filter(|n| n.is_finite() && n.length_squared() > 1e-12)
        .map(|n| (inv * n).normalize())
        .unwrap_or(n_loc);
    // Blend partner: the neighbour across a joint whose surface is nearest the base point.
    let mut partner = NONE;
    let mut weight = 0.0;
    let mut best_m: Option<(usize, f32, f32)> = None;
    let mut consider = |m: usize, eps: f32| {
        if eps <= 0.0 || is_lost(m) {
            return;
        }
        let d = prepared[m].sdf_fast(proj.point).max(0.0);
        if d < 1.5 * eps && best_m.is_none_or(|(_, bd, _)| d < bd) {
            best_m = Some((m, d, eps));
        }
    };
    if let Some(pp) = bb.c1_partner {
        consider(pp, bb.eps);
    }
    for &c in &defs[k].children {
        if bones[c].c1_partner == Some(k) {
            consider(c, bones[c].eps);
        }
    }
    if let Some((m, d, eps)) = best_m {
        partner = m as u16;
        let sigma = eps / 3.0;
        // Eq. 3.1 with the own bone at distance 0.
        let g = (-(d * d) / (2.0 * sigma * sigma)).exp();
        weight = g / (1.0 + g);
    }
    let world_normal = bb.frame * point_normal;
    let bl = baseline::bind(
        k,
        part,
        b_loc,
        p_local(p, bb),
        (p, world_normal),
        bones,
        tables,
    );
    Rec {
        bone: k as u16,
        part,
        s,
        dir,
        height,
        normal: point_normal,
        position: p,
        partner,
        weight,
        bl,
    }
}

fn p_local(p: Vec3, bb: &BoneBind) -> Vec3 {
    bb.frame.inverse() * (p - bb.c1)
}
