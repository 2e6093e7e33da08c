//! Baseline skinning (thesis ch. 4, Algorithm 3).
//!
//! Every point `p` of bone `B_k` lies above a **baseline**: a curve on the sphere-mesh made of
//! an arc on the joint sphere at `c1`, a segment on `B_k`'s cone (a generatrix) and an arc on
//! the joint sphere at `c2` (§4.1). The curve lives in the point's azimuthal half-plane `ψ`
//! around the bone's axis; its ends are the **key points** `S1`, `S2` of the two joints. The
//! point is encoded by the baseline parameter `t` (arc length from `S1` over the total
//! length, §4.3), its height `h` along the detail direction `n_b` (§4.2) and a residual that
//! makes the decomposition exact. After a pose or anatomy change the baseline is rebuilt on the
//! new sphere-mesh and the point is placed at the same `t`: `p' = p'_b + h n'_b` (Algorithm 3).
//!
//! **Key point of a joint** between a parent `P` and a child `C`, for an azimuth `ψ_P` of the
//! parent (§4.1, §4.4). The azimuths of the two bones correspond through the swing of the
//! joint: `ψ_C = ψ_P − τ(R)` where `R = S·T(τ)` is the child's relative rotation. The two
//! generatrices (`P`'s ending at its tangent point `U_P = J + r n_P` on the joint sphere, `C`'s
//! starting at `U_C = J + r n_C`) either
//! * **cross** on the cone parts (the concave side of a bend): `S` is their intersection (the
//!   midpoint of their closest points when the bend is out of the point's plane) and the
//!   detail direction at `S` points from the joint centre to `S` (§4.2, "if a segment on `B_k`
//!   is incident to another segment on `B_{k+1}`"); or
//! * are joined by an **arc** of the joint sphere (the convex side): `S` is the arc's midpoint
//!   (§4.1, "the point S is the midpoint of the arc").
//!
//! Both bones compute the same `S` for corresponding azimuths, so the deformed surface stays
//! continuous across the joint. This replaces the thesis' pencil of cutting planes through the
//! two cone apices by the plane of each bone's generatrix, which coincides with it in the bend
//! plane and, for points off that plane, joins the same generatrices; the thesis itself
//! rebuilds the plane after deformation as a bisector (§4.4.2), which this construction gives
//! by symmetry.
//!
//! **Twist** (§4.2.1, interpolation of the plane with `α_p(t)`). A change `Δτ` of a joint's
//! twist is distributed along the baselines of the two bones: the parent takes `Δτ/2` at its
//! `c2` end when the child continues its chain (none at a branch), the child the rest at its
//! `c1` end, and along a bone the azimuth offset is
//! `off(t) = −o0 (1 − α(t)) + o1 α(t)` with the cubic `α(t) = 3t² − 2t³` (the thesis' cubic
//! `α_p`). The detail direction along a segment is the linear interpolation (normalised) of the
//! directions at its ends (§4.2: `n_b = (1 − t) n_u + t n_v`); on arcs it is the sphere normal.
//!
//! **Where the thesis is silent.**
//! * Branches: the key point at a bone's `c2` joint is built with its chain successor (or its
//!   only child); other children (the shoulders on the spine's top, the hips on the pelvis)
//!   meet it at their own `c1` key points only.
//! * Free ends (chain extremities, bones without a bending partner at an end): the baseline
//!   stops at the cone's tangent point and points on that cap move rigidly with the bone.
//! * Points beyond a key point (on the joint sphere, past the arc midpoint, or hidden past a
//!   crossing) get `t < 0` or `t > 1`: the arc or segment is extended.
//! * Heights are scaled by the bone's radius ratio at `t` (radius-scaled heights).
//!
//! **Speed.** Per frame, each joint's key points are tabulated over `TABLE` = 128 azimuths,
//! each bone's baseline over the same azimuths, and then, per bone, a grid of
//! `GRID_NT × GRID_NPSI` = 25 × 32 samples of `(t, ψ)` (`t ∈ [−0.25, 1.25]`, the twist offset
//! folded in) holds the world base point, detail direction, detail-frame rotation and height
//! scale. A point reads four cells (bilinear) at a slot fixed at bind time — no trigonometry
//! and no bone transform per point. The binding encodes every point against the same grid at
//! the fitted pose, so the fitted pose gives every point back exactly; between samples the
//! interpolation replaces the baseline by chords (for a human of height 1 the sag is about
//! 3·10⁻⁴ across `ψ` and below 10⁻³ across `t` at the joint arcs). Points outside the grid's
//! `t` range (about 3%, far past a key point, mostly hidden inside the neighbouring bone) move
//! rigidly with their bone, like the free caps.
//!
//! Per frame the tables are built in parallel (joint sides and curves per bone, the grid per
//! bone; a grid sample interpolates only the part of the curve that holds it). Per point the
//! pass reads 40 bytes (slot, height, residual, normal) and four 48-byte cells: eight points
//! at a time, each point's cells are blended as 12-float vectors, then the eight detail-frame
//! rotations and compositions run in [`super::lanes`] vectors. The rigidly moving points are
//! copied at bind time into a stream of their own ([`Rigid`], derived, not saved), so that
//! the pass does not fetch them from arrays it otherwise never touches.

use super::binding::{BoneBind, PointData};
use super::frame::BoneFrame;
use super::lanes::{F8, L, V3, has_avx2};
use super::surface::{CAP1, CAP2};
use crate::geometry::frames::rotation_arc;
use crate::math::{Mat3, Quat, Vec3};
use rayon::prelude::*;

/// The baseline encoding of one point.
#[derive(Clone, Copy, Debug, Default)]
pub struct PointBaseline {
    /// Grid cell ([`NO_CELL`]: the point moves rigidly with its bone).
    pub cell: u32,
    /// Bilinear fractions within the cell.
    pub uv: [f32; 2],
    /// Height along the (interpolated) detail direction.
    pub h: f32,
    /// Residual displacement, in the cell's detail frame.
    pub res: Vec3,
    /// The point's normal, in the cell's detail frame.
    pub n: Vec3,
}

/// No grid cell: the point moves rigidly with its bone.
pub const NO_CELL: u32 = u32::MAX;

impl PointBaseline {
    fn rigid() -> PointBaseline {
        PointBaseline {
            cell: NO_CELL,
            ..Default::default()
        }
    }
}

/// A key point in the parent's frame.
#[derive(Clone, Copy, Debug)]
struct Key {
    s: Vec3,
    d: Vec3,
    r: f32,
    cross: bool,
}

/// The key point of the joint at `c1` of `child` (its parent's frame is the reference), for
/// the parent-frame azimuth `(c, s)`.
#[inline]
fn key(parent: &BoneFrame, child: &BoneFrame, c: f32, s: f32) -> Key {
    let sp = &parent.shape;
    let sc = &child.shape;
    let j = Vec3::new(sp.length, 0.0, 0.0);
    let n_p = sp.cone_normal_cs(c, s);
    let g_p = Vec3::new(sp.cos_a, sp.sin_a * c, sp.sin_a * s);
    let sw: &Mat3 = &child.swing_new;
    let n_c = *sw * sc.cone_normal_cs(c, s);
    let g_c = *sw * Vec3::new(sc.cos_a, sc.sin_a * c, sc.sin_a * s);
    let u_p = j + sp.r2 * n_p;
    let u_c = j + sc.r1 * n_c;
    let w0 = u_p - u_c;
    let b = g_p.dot(g_c);
    let den = 1.0 - b * b;
    if den > 1e-8 {
        let d = g_p.dot(w0);
        let e = g_c.dot(w0);
        let sig_p = (b * e - d) / den;
        let sig_c = (e - b * d) / den;
        let len_p = sp.length * sp.cos_a;
        let len_c = sc.length * sc.cos_a;
        if sig_p < 0.0 && sig_c > 0.0 && -sig_p < len_p && sig_c < len_c {
            let m = 0.5 * ((u_p + sig_p * g_p) + (u_c + sig_c * g_c));
            let v = m - j;
            let r = v.length();
            if r > 1e-12 {
                return Key {
                    s: m,
                    d: v / r,
                    r,
                    cross: true,
                };
            }
        }
    }
    let d = (n_p + n_c).normalize_or(n_p);
    let r = 0.5 * (sp.r2 + sc.r1);
    Key {
        s: j + r * d,
        d,
        r,
        cross: false,
    }
}

/// Azimuth samples per joint table.
pub const TABLE: usize = 128;

/// One side of a joint for one azimuth sample: the segment end on that bone, its detail
/// direction, and the arc on the joint sphere between the bone's tangent point and the key
/// point (empty when the generatrices cross).
#[derive(Clone, Copy, Debug, Default)]
pub struct Side {
    /// Segment end (`U` for an arc, `S` for a crossing).
    p: Vec3,
    /// Detail direction at `p`.
    n: Vec3,
    /// Arc start direction (from the joint centre).
    d0: Vec3,
    /// Unit vector completing `d0` in the arc's plane (towards the arc's end).
    w: Vec3,
    /// Arc angle.
    angle: f32,
    /// Radius at the arc's start and end.
    r0: f32,
    r1: f32,
    /// Arc length.
    len: f32,
}

impl Side {
    #[inline]
    fn lerp(a: &Side, b: &Side, f: f32) -> Side {
        let g = 1.0 - f;
        Side {
            p: a.p * g + b.p * f,
            n: a.n * g + b.n * f,
            d0: a.d0 * g + b.d0 * f,
            w: a.w * g + b.w * f,
            angle: a.angle * g + b.angle * f,
            r0: a.r0 * g + b.r0 * f,
            r1: a.r1 * g + b.r1 * f,
            len: a.len * g + b.len * f,
        }
    }
    fn arc(p: Vec3, n: Vec3, d0: Vec3, r0: f32, d1: Vec3, r1: f32) -> Side {
        let c = d0.dot(d1).clamp(-1.0, 1.0);
        let perp = d1 - c * d0;
        let sn = perp.length();
        let angle = sn.atan2(c);
        Side {
            p,
            n,
            d0,
            w: if sn > 1e-9 { perp / sn } else { Vec3::ZERO },
            angle,
            r0,
            r1,
            len: angle * 0.5 * (r0 + r1),
        }
    }
    /// Point and normal at fraction `f` of the arc (extrapolated outside `[0, 1]`).
    #[inline]
    fn at(&self, centre: Vec3, f: f32) -> (Vec3, Vec3) {
        let (s, c) = (self.angle * f).sin_cos();
        let d = (self.d0 * c + self.w * s).normalize_or(self.d0);
        let r = self.r0 + (self.r1 - self.r0) * f.clamp(0.0, 1.0);
        (centre + r * d, d)
    }
}

/// The joint tables of one pose: for the joint at `c1` of every bone `k` with a partner,
/// `TABLE` azimuth samples of the child side (in `k`'s frame, indexed by `k`'s azimuth) and of
/// the parent side (in the parent's frame, indexed by the parent's azimuth).
#[derive(Clone, Debug, Default)]
pub struct Tables {
    child: Vec<Side>,
    parent: Vec<Side>,
    curves: Vec<Curve>,
    cs: Vec<[f32; 2]>,
    grid: Vec<Cell>,
    /// The grid's detail directions in the bones' frames.
    local_n: Vec<Vec3>,
}

/// Baseline parameters covered by the per-frame grid: `t ∈ [GRID_T0, GRID_T1]`.
pub const GRID_T0: f32 = -0.25;
/// Upper end of the grid's `t` range.
pub const GRID_T1: f32 = 1.25;
/// Grid samples along `t`.
pub const GRID_NT: usize = 25;
/// Grid samples around the bone (azimuth).
pub const GRID_NPSI: usize = 32;

/// One grid cell, in world coordinates of the pose: the base point, the (unnormalised)
/// detail direction, the rotation that carries a point's detail frame from the fitted pose to
/// this one (bone frame, twist offset, shortest arc from the fitted detail direction to the
/// new one) and the height scale (the bone's radius ratio at `t`), as
/// `[p (3), n (3), q (x, y, z, w), hs, 0]`: 48 bytes, three 16-byte groups.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
pub struct Cell([f32; 12]);

impl Cell {
    fn new(p: Vec3, n: Vec3, q: Quat, hs: f32) -> Cell {
        Cell([p.x, p.y, p.z, n.x, n.y, n.z, q.x, q.y, q.z, q.w, hs, 0.0])
    }
    #[inline(always)]
    fn p(&self) -> Vec3 {
        Vec3::new(self.0[0], self.0[1], self.0[2])
    }
    #[inline(always)]
    fn n(&self) -> Vec3 {
        Vec3::new(self.0[3], self.0[4], self.0[5])
    }
    #[inline(always)]
    fn q(&self) -> Quat {
        Quat::from_xyzw(self.0[6], self.0[7], self.0[8], self.0[9])
    }
}

impl Default for Cell {
    fn default() -> Self {
        Cell::new(Vec3::ZERO, Vec3::X, Quat::IDENTITY, 1.0)
    }
}

impl Tables {
    /// The detail directions of the grid (to keep from the fitted pose, see [`build_tables`]).
    pub fn grid_normals(&self) -> Vec<Vec3> {
        self.local_n.clone()
    }
}

/// Fills `out` for the pose analysed in `frames` (allocation-free once grown).
pub fn build_tables(
    frames: &[BoneFrame],
    bones: &[BoneBind],
    fit_normals: Option<&[Vec3]>,
    out: &mut Tables,
) {
    let n = frames.len();
    out.child.resize(n * TABLE, Side::default());
    out.parent.resize(n * TABLE, Side::default());
    if out.cs.len() != TABLE {
        out.cs = (0..TABLE)
            .map(|i| {
                let (s, c) = (i as f32 * std::f32::consts::TAU / TABLE as f32).sin_cos();
                [c, s]
            })
            .collect();
    }
    let cs = &out.cs;
    out.child
        .par_chunks_mut(TABLE)
        .zip(out.parent.par_chunks_mut(TABLE))
        .enumerate()
        .for_each(|(k, (child, parent))| {
            let Some(p) = bones[k].c1_partner else {
                return;
            };
            let fk = &frames[k];
            let fp = &frames[p];
            let jp = Vec3::new(fp.shape.length, 0.0, 0.0);
            let rt = fk.rel_new.transpose();
            let (st, ct) = fk.tau_new.sin_cos();
            for (i, (child, parent)) in child.iter_mut().zip(parent.iter_mut()).enumerate() {
                let [c, s] = cs[i];
                // Child side: azimuth ψ of k ↔ ψ + τ of the parent.
                let (cp, sp) = (c * ct - s * st, s * ct + c * st);
                let kp = key(fp, fk, cp, sp);
                let d1 = rt * kp.d;
                let n_k = fk.shape.cone_normal_cs(c, s);
                *child = if kp.cross {
                    Side {
                        p: rt * (kp.s - jp),
                        n: d1,
                        d0: d1,
                        r0: kp.r,
                        r1: kp.r,
                        ..Default::default()
                    }
                } else {
                    Side::arc(fk.shape.r1 * n_k, n_k, d1, kp.r, n_k, fk.shape.r1)
                };
                // Parent side: azimuth ψ of p.
                let kc = key(fp, fk, c, s);
                let n_p = fp.shape.cone_normal_cs(c, s);
                *parent = if kc.cross {
                    Side {
                        p: kc.s,
                        n: kc.d,
                        d0: kc.d,
                        r0: kc.r,
                        r1: kc.r,
                        ..Default::default()
                    }
                } else {
                    Side::arc(jp + fp.shape.r2 * n_p, n_p, n_p, fp.shape.r2, kc.d, kc.r)
                };
            }
        });
    let mut curves = std::mem::take(&mut out.curves);
    curves.resize(n * TABLE, Curve::default());
    let sides: &Tables = out;
    curves
        .par_chunks_mut(TABLE)
        .enumerate()
        .for_each(|(k, row)| {
            for (i, c) in row.iter_mut().enumerate() {
                *c = curve_sample(k, i, frames, bones, sides);
            }
        });
    out.curves = curves;
    // The (t, ψ) grid, one block per bone, in parallel.
    let per_bone = GRID_NT * GRID_NPSI;
    let mut grid = std::mem::take(&mut out.grid);
    let mut local_n = std::mem::take(&mut out.local_n);
    grid.resize(n * per_bone, Cell::default());
    local_n.resize(n * per_bone, Vec3::X);
    let tables: &Tables = out;
    grid.par_chunks_mut(per_bone)
        .zip(local_n.par_chunks_mut(per_bone))
        .enumerate()
        .for_each(|(k, (cells, normals))| {
            let fk = &frames[k];
            for (j, (row, nrow)) in cells
                .chunks_mut(GRID_NPSI)
                .zip(normals.chunks_mut(GRID_NPSI))
                .enumerate()
            {
                let t = GRID_T0 + (GRID_T1 - GRID_T0) * j as f32 / (GRID_NT - 1) as f32;
                let a = alpha(t);
                let off = -fk.off0 * (1.0 - a) + fk.off1 * a;
                let twist = Quat::from_rotation_x(off);
                let tc = t.clamp(0.0, 1.0);
                let hs = fk.radius_ratio[0] + (fk.radius_ratio[1] - fk.radius_ratio[0]) * tc;
                for (m, (cell, nl)) in row.iter_mut().zip(nrow.iter_mut()).enumerate() {
                    let psi = std::f32::consts::TAU * m as f32 / GRID_NPSI as f32;
                    let (p, nb) = curve_at(k, psi + off, t, tables);
                    let q = match fit_normals {
                        Some(fit) => {
                            let n_fit = twist * fit[k * per_bone + j * GRID_NPSI + m];
                            arc_quat(n_fit, nb) * twist
                        }
                        None => twist,
                    };
                    if fit_normals.is_none() {
                        *nl = nb;
                    }
                    *cell = Cell::new(
                        fk.rot * p + fk.origin,
                        fk.rot * nb,
                        (fk.rot_q * q).normalize(),
                        hs,
                    );
                }
            }
        });
    out.grid = grid;
    out.local_n = local_n;
}

/// A point's baseline on bone `k`, in `k`'s frame: arc 1 (from `S1` to the segment start;
/// empty at a crossing or a free end), the segment `a → b` with its end detail directions,
/// and arc 2 (from the segment end to `S2`).
#[derive(Clone, Copy, Debug, Default)]
pub struct Curve {
    arc1: Side,
    a: Vec3,
    na: Vec3,
    b: Vec3,
    nb: Vec3,
    seg: f32,
    c2: Vec3,
    arc2: Side,
}

impl Curve {
    #[inline]
    fn lerp(x: &Curve, y: &Curve, f: f32) -> Curve {
        let g = 1.0 - f;
        Curve {
            arc1: Side::lerp(&x.arc1, &y.arc1, f),
            a: x.a * g + y.a * f,
            na: x.na * g + y.na * f,
            b: x.b * g + y.b * f,
            nb: x.nb * g + y.nb * f,
            seg: x.seg * g + y.seg * f,
            c2: x.c2,
            arc2: Side::lerp(&x.arc2, &y.arc2, f),
        }
    }
    #[inline]
    fn arc1_len(&self) -> f32 {
        self.arc1.len
    }
    #[inline]
    fn len(&self) -> f32 {
        self.arc1.len + self.seg + self.arc2.len
    }
    /// Base point and detail direction at arc length `lambda` from `S1`.
    #[inline]
    fn at(&self, lambda: f32) -> (Vec3, Vec3) {
        let l1 = self.arc1.len;
        if lambda < l1 && l1 > 1e-12 {
            // Arc 1 runs from S1 (fraction 0) to U1.
            return self.arc1.at(Vec3::ZERO, lambda / l1);
        }
        let l2 = l1 + self.seg;
        if lambda > l2 && self.arc2.len > 1e-12 {
            return self.arc2.at(self.c2, (lambda - l2) / self.arc2.len);
        }
        let f = if self.seg > 1e-12 {
            (lambda - l1) / self.seg
        } else {
            0.0
        };
        let fc = f.clamp(0.0, 1.0);
        (
            self.a + (self.b - self.a) * f,
            (self.na + (self.nb - self.na) * fc).normalize_or(self.na),
        )
    }
}

/// Builds bone `k`'s baseline for azimuth sample `i` from the joint sides.
fn curve_sample(k: usize, i: usize, frames: &[BoneFrame], bones: &[BoneBind], t: &Tables) -> Curve {
    let [c, s] = t.cs[i];
    let sh = &frames[k].shape;
    let n_k = sh.cone_normal_cs(c, s);
    let c2 = Vec3::new(sh.length, 0.0, 0.0);
    let bb = &bones[k];
    let (arc1, a, na) = if bb.c1_partner.is_some() {
        let side = t.child[k * TABLE + i];
        (side, side.p, side.n)
    } else {
        (Side::default(), sh.r1 * n_k, n_k)
    };
    let (arc2, b, nb) = if let Some(ch) = bb.c2_partner {
        let side = t.parent[ch * TABLE + i];
        (side, side.p, side.n)
    } else {
        (Side::default(), c2 + sh.r2 * n_k, n_k)
    };
    Curve {
        arc1,
        a,
        na,
        b,
        nb,
        seg: (b - a).length(),
        c2,
        arc2,
    }
}

/// Bone `k`'s baseline for the bone-local azimuth `psi`: linear interpolation between the two
/// nearest of the pose's `TABLE` samples.
#[inline]
fn curve(k: usize, psi: f32, tables: &Tables) -> Curve {
    // ψ ∈ (−π − 2π, π + 2π) at most (azimuth plus a twist offset): shift to positive before
    // truncating, so truncation is the floor.
    let u = psi * (TABLE as f32 / std::f32::consts::TAU) + (4 * TABLE) as f32;
    let fl = u as usize;
    let f = u - fl as f32;
    let i0 = fl % TABLE;
    let i1 = (i0 + 1) % TABLE;
    Curve::lerp(
        &tables.curves[k * TABLE + i0],
        &tables.curves[k * TABLE + i1],
        f,
    )
}

/// `curve(k, psi).at(t · len)`, interpolating only the part of the curve that holds the
/// point (the same values, fewer operations).
#[inline]
fn curve_at(k: usize, psi: f32, t: f32, tables: &Tables) -> (Vec3, Vec3) {
    let u = psi * (TABLE as f32 / std::f32::consts::TAU) + (4 * TABLE) as f32;
    let fl = u as usize;
    let f = u - fl as f32;
    let i0 = fl % TABLE;
    let i1 = (i0 + 1) % TABLE;
    let (x, y) = (
        &tables.curves[k * TABLE + i0],
        &tables.curves[k * TABLE + i1],
    );
    let g = 1.0 - f;
    let l1 = x.arc1.len * g + y.arc1.len * f;
    let seg = x.seg * g + y.seg * f;
    let l2 = x.arc2.len * g + y.arc2.len * f;
    let lambda = t * (l1 + seg + l2);
    if lambda < l1 && l1 > 1e-12 {
        return Side::lerp(&x.arc1, &y.arc1, f).at(Vec3::ZERO, lambda / l1);
    }
    let l12 = l1 + seg;
    if lambda > l12 && l2 > 1e-12 {
        return Side::lerp(&x.arc2, &y.arc2, f).at(x.c2, (lambda - l12) / l2);
    }
    let (a, b) = (x.a * g + y.a * f, x.b * g + y.b * f);
    let (na, nb) = (x.na * g + y.na * f, x.nb * g + y.nb * f);
    let fs = if seg > 1e-12 {
        (lambda - l1) / seg
    } else {
        0.0
    };
    let fc = fs.clamp(0.0, 1.0);
    (a + (b - a) * fs, (na + (nb - na) * fc).normalize_or(na))
}

/// The shortest-arc rotation between unit vectors without trigonometry (half-way vector
/// form); the rare near-opposite case falls back to [`rotation_arc`].
#[inline]
fn arc_quat(a: Vec3, b: Vec3) -> Quat {
    let c = a.dot(b);
    if c < -0.999 {
        return rotation_arc(a, b);
    }
    let w = a.cross(b);
    Quat::from_xyzw(w.x, w.y, w.z, 1.0 + c).normalize()
}

/// The grid slot of a point of bone `k` at `(t, ψ)`: the index of its lower cell and the
/// bilinear fractions; `None` outside the grid's `t` range.
pub fn grid_slot(k: usize, t: f32, psi: f32) -> Option<(u32, [f32; 2])> {
    let u = (t - GRID_T0) * ((GRID_NT - 1) as f32 / (GRID_T1 - GRID_T0));
    if !(u >= 0.0 && u < (GRID_NT - 1) as f32) {
        return None;
    }
    let j = u as usize;
    let v = psi * (GRID_NPSI as f32 / std::f32::consts::TAU) + (4 * GRID_NPSI) as f32;
    let m0 = v as usize;
    let fv = v - m0 as f32;
    let cell = k * GRID_NT * GRID_NPSI + j * GRID_NPSI + m0 % GRID_NPSI;
    Some((cell as u32, [u - j as f32, fv]))
}

/// A cell with the identity rotation (filler for points without a cell).
const IDENTITY_CELL: [f32; 12] = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.0];

/// Bilinear interpolation of the grid at a slot.
#[inline(always)]
fn grid_fetch(cell: u32, [fu, fv]: [f32; 2], grid: &[Cell]) -> Cell {
    const _: () = assert!(GRID_NPSI.is_power_of_two());
    let c = cell as usize;
    let m0 = c & (GRID_NPSI - 1);
    let c01 = c - m0 + ((m0 + 1) & (GRID_NPSI - 1));
    let (c00, c01, c10, c11) = (
        &grid[c].0,
        &grid[c01].0,
        &grid[c + GRID_NPSI].0,
        &grid[c01 + GRID_NPSI].0,
    );
    let w00 = (1.0 - fu) * (1.0 - fv);
    let w01 = (1.0 - fu) * fv;
    let w10 = fu * (1.0 - fv);
    let w11 = fu * fv;
    // Quaternions of neighbouring cells are close (same hemisphere): plain blend.
    let mut r = [0.0; 12];
    for (i, ri) in r.iter_mut().enumerate() {
        *ri = c00[i] * w00 + c01[i] * w01 + c10[i] * w10 + c11[i] * w11;
    }
    Cell(r)
}

/// Cubic interpolation `α(t) = 3t² − 2t³` on `[0, 1]`.
#[inline]
fn alpha(t: f32) -> f32 {
    crate::anatomy::pose::ease(t)
}

/// Encodes one point of bone `k` (base point `b` and point `p`, both bone-local) on its fitted
/// baseline; `frames` are the fitted pose analysed against itself.
pub fn bind(
    k: usize,
    part: u8,
    b: Vec3,
    p: Vec3,
    (world, normal): (Vec3, Vec3),
    bones: &[BoneBind],
    tables: &Tables,
) -> PointBaseline {
    let bb = &bones[k];
    let radial = Vec3::new(0.0, b.y, b.z);
    let e = if part == CAP1 || part == CAP2 {
        Vec3::new(0.0, p.y, p.z).normalize_or(radial.normalize_or(Vec3::Y))
    } else {
        radial.normalize_or(Vec3::Y)
    };
    let psi = e.z.atan2(e.y);
    let free =
        (part == CAP1 && bb.c1_partner.is_none()) || (part == CAP2 && bb.c2_partner.is_none());
    if free {
        return PointBaseline::rigid();
    }
    let cv = curve(k, psi, tables);
    let total = cv.len();
    if !(total > 1e-12) {
        return PointBaseline::rigid();
    }
    let l1 = cv.arc1_len();
    // Initial guess from the base point's position.
    let seg_param = |q: Vec3| -> f32 {
        let g = cv.b - cv.a;
        let len2 = g.length_squared();
        if len2 > 1e-24 {
            l1 + (q - cv.a).dot(g) / len2 * cv.seg
        } else {
            l1
        }
    };
    let arc_param = |arc: &Side, centre: Vec3, q: Vec3, offset: f32| -> f32 {
        let d = (q - centre).normalize_or(arc.d0);
        let ang = d.dot(arc.w).atan2(d.dot(arc.d0));
        if arc.angle > 1e-9 {
            offset + ang / arc.angle * arc.len
        } else {
            offset
        }
    };
    let mut lambda = match part {
        CAP1 if cv.arc1.len > 0.0 => arc_param(&cv.arc1, Vec3::ZERO, b, 0.0),
        CAP2 if cv.arc2.len > 0.0 => arc_param(&cv.arc2, cv.c2, b, l1 + cv.seg),
        _ => seg_param(b),
    };
    // Along segments whose detail directions vary (a crossing end), the base point is where
    // the detail direction through p meets the segment: a few fixed-point steps.
    let on_segment = lambda >= l1 && lambda <= l1 + cv.seg;
    if on_segment && (cv.na - cv.nb).length_squared() > 1e-12 {
        for _ in 0..8 {
            let (pb, nb) = cv.at(lambda);
            let h = (p - pb).dot(nb);
            lambda = seg_param(p - h * nb).clamp(l1, l1 + cv.seg);
        }
    }
    // Encode against the grid exactly as deform will read it, so the fitted pose gives p back.
    let Some((cell, uv)) = grid_slot(k, lambda / total, psi) else {
        return PointBaseline::rigid();
    };
    let c = grid_fetch(cell, uv, &tables.grid);
    let (cp, cn) = (c.p(), c.n());
    let q = c.q().normalize();
    let n2 = cn.length_squared().max(1e-30);
    let h = (world - cp).dot(cn) / n2;
    let inv = q.inverse();
    PointBaseline {
        cell,
        uv,
        h,
        res: inv * (world - cp - h * cn),
        n: inv * normal,
    }
}

/// The points without a grid cell (they move rigidly with their bone), gathered at bind time
/// in point order so that the per-frame pass reads them as a stream: for each block of
/// [`CHUNK`] points the index of its first one, then per point its bone, part, base point
/// encoding, height and normal. Derived from the per-point arrays, not saved.
#[derive(Clone, Debug, Default)]
pub struct Rigid {
    block_start: Vec<u32>,
    rec: Vec<RigidPoint>,
}

#[derive(Clone, Copy, Debug)]
struct RigidPoint {
    bone: u16,
    part: u8,
    s: f32,
    dir: Vec3,
    height: f32,
    normal: Vec3,
}

/// Points per block of the per-frame pass (and per parallel task).
pub const CHUNK: usize = 4096;

impl Rigid {
    /// The rigid points of `pts`.
    pub fn new(pts: &PointData) -> Rigid {
        let mut r = Rigid::default();
        for (i, &c) in pts.bl_cell.iter().enumerate() {
            if i % CHUNK == 0 {
                r.block_start.push(r.rec.len() as u32);
            }
            if c == NO_CELL {
                r.rec.push(RigidPoint {
                    bone: pts.bone[i],
                    part: pts.part[i],
                    s: pts.s[i],
                    dir: pts.dir[i],
                    height: pts.height[i],
                    normal: pts.normal[i],
                });
            }
        }
        r
    }
}

/// `v ↦ q v q*` for unit quaternions `q = (x, y, z, w)`: `v + 2w (u × v) + 2 u × (u × v)`.
#[inline(always)]
fn rotate([qx, qy, qz, qw]: [F8; 4], v: V3) -> V3 {
    let c = V3 {
        x: qy * v.z - qz * v.y,
        y: qz * v.x - qx * v.z,
        z: qx * v.y - qy * v.x,
    };
    let cc = V3 {
        x: qy * c.z - qz * c.y,
        y: qz * c.x - qx * c.z,
        z: qx * c.y - qy * c.x,
    };
    v + (c.scale(qw) + cc).scale(F8::splat(2.0))
}

/// A rigid point moved with its bone.
#[cold]
fn rigid_point(r: &RigidPoint, frames: &[BoneFrame]) -> (Vec3, Vec3) {
    let Some(fk) = frames.get(r.bone as usize) else {
        return (Vec3::ZERO, Vec3::X);
    };
    let (b, nb) = fk.shape.decode(r.part, r.s, r.dir);
    let f = fk.shape.axial_fraction(r.part, r.s);
    let hs = fk.radius_ratio[0] + (fk.radius_ratio[1] - fk.radius_ratio[0]) * f;
    let x = b + hs * r.height * nb;
    (fk.rot * x + fk.origin, fk.rot * r.normal)
}

/// Deforms every point into `out_p` (world positions) and `out_n` (world normals), in
/// parallel blocks of [`CHUNK`].
pub fn deform(
    pts: &PointData,
    rigid: &Rigid,
    frames: &[BoneFrame],
    tables: &Tables,
    out_p: &mut [Vec3],
    out_n: &mut [Vec3],
) {
    out_p
        .par_chunks_mut(CHUNK)
        .zip(out_n.par_chunks_mut(CHUNK))
        .enumerate()
        .for_each(|(c, (ps, ns))| {
            #[cfg(target_arch = "x86_64")]
            if has_avx2() {
                // SAFETY: the processor runs AVX2.
                return unsafe { deform_block_avx2(c, pts, rigid, frames, tables, ps, ns) };
            }
            deform_block(c, pts, rigid, frames, tables, ps, ns)
        });
}

/// [`deform_block`] compiled for AVX2 (same results, see [`super::lanes::has_avx2`]).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn deform_block_avx2(
    c: usize,
    pts: &PointData,
    rigid: &Rigid,
    frames: &[BoneFrame],
    tables: &Tables,
    out_p: &mut [Vec3],
    out_n: &mut [Vec3],
) {
    deform_block(c, pts, rigid, frames, tables, out_p, out_n)
}

/// One block: eight points at a time, each reading its four grid cells, then the
/// detail-frame rotation and the composition in [`super::lanes`] vectors.
#[inline(always)]
fn deform_block(
    c: usize,
    pts: &PointData,
    rigid: &Rigid,
    frames: &[BoneFrame],
    tables: &Tables,
    out_p: &mut [Vec3],
    out_n: &mut [Vec3],
) {
    let grid = &tables.grid[..];
    let base = c * CHUNK;
    let n = out_p.len();
    let mut next_rigid = rigid
        .block_start
        .get(c)
        .map_or(rigid.rec.len(), |&s| s as usize);
    let (cells, uvs) = (&pts.bl_cell[base..base + n], &pts.bl_uv[base..base + n]);
    let (hs_, res, nd) = (
        &pts.bl_h[base..base + n],
        &pts.bl_res[base..base + n],
        &pts.bl_n[base..base + n],
    );
    let mut i = 0;
    while i < n {
        let m = (n - i).min(L);
        let mut tc = [IDENTITY_CELL; L];
        let (mut r, mut d) = (V3::default(), V3::default());
        let mut any_rigid = false;
        for l in 0..m {
            let cell = cells[i + l];
            let (rv, dv) = (res[i + l], nd[i + l]);
            (r.x.0[l], r.y.0[l], r.z.0[l]) = (rv.x, rv.y, rv.z);
            (d.x.0[l], d.y.0[l], d.z.0[l]) = (dv.x, dv.y, dv.z);
            if cell == NO_CELL {
                any_rigid = true;
                continue;
            }
            tc[l] = grid_fetch(cell, uvs[i + l], grid).0;
        }
        let t: [[f32; L]; 11] = std::array::from_fn(|q| std::array::from_fn(|l| tc[l][q]));
        let h = F8::load(&hs_[i..i + m]);
        let (qx, qy, qz, qw) = (F8(t[6]), F8(t[7]), F8(t[8]), F8(t[9]));
        let inv = 1.0 / (qx * qx + qy * qy + qz * qz + qw * qw).sqrt();
        let (qx, qy, qz, qw) = (qx * inv, qy * inv, qz * inv, qw * inv);
        let (cp, cn) = (
            V3 {
                x: F8(t[0]),
                y: F8(t[1]),
                z: F8(t[2]),
            },
            V3 {
                x: F8(t[3]),
                y: F8(t[4]),
                z: F8(t[5]),
            },
        );
        let q = [qx, qy, qz, qw];
        let p = cp + (cn.scale(h) + rotate(q, r)).scale(F8(t[10]));
        let nn = rotate(q, d);
        for l in 0..m {
            out_p[i + l] = p.lane(l);
            out_n[i + l] = nn.lane(l);
        }
        if any_rigid {
            for l in 0..m {
                if cells[i + l] == NO_CELL {
                    if let Some(rp) = rigid.rec.get(next_rigid) {
                        (out_p[i + l], out_n[i + l]) = rigid_point(rp, frames);
                    }
                    next_rigid += 1;
                }
            }
        }
        i += m;
    }
}
