//! Heightfield skinning with anisotropic bend and twist weights (thesis ch. 3, Algorithm 2;
//! paper 001 §4.1).
//!
//! Each point is its base point on its bone plus a height: `p = p̃ + h n_p̃` (§3.1.1). The base
//! points are skinned, re-projected on the new sphere-mesh and lifted by their heights, scaled
//! by the bone's radius ratio at the base point (Algorithm 2 steps 2–5).
//!
//! **Twist first** (§3.2.2, eq. 3.3). A joint's twist change `β = τ_D` is spread linearly along
//! the two bones it joins: with `v = c_{k−1}` and `w = c_{k+1}` a point at arc position `x`
//! along the chain turns by `ω β`, `ω = |v − x| / (l_{k−1} + l_k)`. Written per bone in its own
//! frame this is a rotation about its axis by `a + b f` (`f` the base point's axial fraction,
//! coefficients in [`super::frame`]): the bone's frame already carries the whole twist, the
//! correction removes the part not yet reached. A chain's first bone (and a branch, e.g. the
//! upper arm's clavicle on the spine) takes its own twist alone, from 0 at `c1` to 1 at `c2`.
//!
//! **Then bend** (§3.2.1, eq. 3.2, paper 001 §4.1). The bend of angle `θ` about axis `a`
//! through the joint centre `J` is applied as `⌈θ / 5°⌉` small rotations; at each one a base
//! point near the joint turns about `a` by `ω_C δθ`, `ω_C` the child's weight from the
//! Gaussian of the point's distances to both bones (eq. 3.1) with the anisotropic width
//! `ε_r = |cos α_b| ε'_r` on the convex side (`cos α_b < 0`), and the weights are updated after
//! each step (the limit of the paper's iterated small linear-blend steps: a point keeps its
//! distance to the bend axis, as the iterated blend does for small steps). On the concave side
//! (`cos α_b ≥ 0`) the weights are 1 for the own bone and 0 for the other: the point follows
//! its bone and the bones may locally interpenetrate, as the thesis chooses. The anisotropy
//! angle is measured once, before the bend, between the point's radial direction about its own
//! bone's axis and the direction `a × u` towards which that bone's axis turns.
//! Finally the moved base point is re-projected (orthogonal projection) on the nearer of the
//! two new bones and lifted along that bone's normal.
//!
//! Points without a blend partner (away from every joint) move rigidly with their bone,
//! twist included; their base points never leave the bone, so the re-projection is exact.
//!
//! ## Speed
//!
//! The per-point iteration (a dozen distance evaluations per point, for the 40% of a statue's
//! points that lie in a joint's zone) and a per-point branch on the base point's part were
//! the cost; three choices of this crate remove them.
//!
//! * **The bend is tabulated per frame.** Everything the bend does to a base point — the
//!   iterated small rotations, the re-projection, the normal's rotation — depends only on
//!   where the base point sits on its bone (and on the frame). A base point is located by its
//!   **profile coordinate** `u` (arc length along the *fitted* bone's outline from the `c1`
//!   pole: cap 1 by polar angle, the cone by `s`, cap 2 by polar angle; frame-independent, so
//!   fixed at bind time) and its azimuth `ψ` about the bone's axis. Each side of each joint
//!   (the child's points partnered with the parent; the parent's points partnered with that
//!   child) gets a grid of `GRID_NU × GRID_NPSI` = 24 × 32 samples of `(u, ψ)` over the `u`
//!   range its bound points occupy. Per frame every sample is decoded on the new shape,
//!   twisted and bent exactly as above, eight samples at a time; a cell holds, in the bone's
//!   own new frame, the displacement `D` of the base point, the change `ΔN` of its normal and
//!   the angle of the normals' rotation about the side's (fixed) axis as `(cos, sin)`. A point
//!   keeps its own exactly decoded and twisted base point `b`, normal `n` and point normal `m`,
//!   reads four cells at a slot fixed at bind time (bilinear) and becomes
//!   `b + D + h (n + ΔN)/|n + ΔN|` with normal `R(axis, angle) m`. The three tabulated
//!   quantities vanish for a vanishing bend and on the concave side, so the fitted pose, a
//!   rigid motion, a bend-free pose and every point whose cells do not bend are exact, and the
//!   bending zone joins the rigid rest of the bone without a seam. Inside the zone the
//!   interpolation smooths: where the weights change faster than a cell (the Gaussian of
//!   eq. 3.1 is narrow, `σ = ε_r / 3`, and vanishes at the sides of the bend, where the
//!   per-point iteration itself jumps between following one bone and the other) the table
//!   gives a blend of the neighbouring samples. Against the per-point iteration
//!   ([`reference_point`], `tests/skinning.rs`) on the benchmark's worst case: 99% of the
//!   points within 10⁻³ of the height, rms 3·10⁻⁴; the largest differences (about 1%) sit on
//!   those jumps. Concave-side cells cost nothing; a joint that does not bend (`θ ≤ 10⁻⁵`) is
//!   skipped whole.
//! * **No branch on the part.** Writing `σ` = 0 (cap 1), `s` (cone), 1 (cap 2) and `κ` = 1 on
//!   the caps, 0 on the cone, a stored direction `d` (the cap direction or the cone's radial
//!   direction) decodes on the new shape as `n = (κ dₓ − (1 − κ) sin α, (κ + (1 − κ) cos α) d_yz)`,
//!   `b = σ l X + ((1 − σ) r₁ + σ r₂) n` — [`super::surface::BoneShape::decode`] for all three
//!   parts at once — with axial fraction `clamp(σ, 0, 1)`. The twist `cos`/`sin` come from
//!   polynomials (`twist_cs`), not a table.
//! * **Points grouped by bone.** At bind time the points of each block of `CHUNK` = 4096
//!   (consecutive in the output) are ordered by (bone, joint side) into runs, and their
//!   per-point data is stored in that order, structure of arrays. A run reads its bone's
//!   frame data once and handles eight points per step in [`super::lanes`] vectors; the block's
//!   results are then written to the caller's buffers in the original order. The layout is
//!   derived from the binding's arrays (at bind and at load), never saved.

use super::binding::{BoneBind, NONE, PointData};
use super::frame::BoneFrame;
use super::lanes::{F8, L, M8, V3, has_avx2};
use super::surface::{BoneShape, CAP1, CAP2};
use crate::math::{Mat3, Vec3};
use rayon::prelude::*;
use std::cell::RefCell;
use std::f32::consts::{PI, TAU};

/// Bend step (radians): 5°.
pub const BEND_STEP: f32 = 5.0 * std::f32::consts::PI / 180.0;

/// Bend grid samples along the profile coordinate `u`, per joint side.
pub const GRID_NU: usize = 24;
/// Bend grid samples around the bone (azimuth); a power of two, a multiple of the lanes.
pub const GRID_NPSI: usize = 64;
const PER_SIDE: usize = GRID_NU * GRID_NPSI;

/// Points per block of the bind-time layout (and per parallel task).
pub const CHUNK: usize = 4096;

/// No joint side: the point has no blend partner.
const NO_SIDE: u16 = u16::MAX;

/// What the points of one bone need from the frame.
#[derive(Clone, Copy, Debug, Default)]
struct BoneCoef {
    rot: Mat3,
    origin: Vec3,
    shape: BoneShape,
    /// Twist correction `a + b f` (eq. 3.3).
    twist: [f32; 2],
    /// Height scale `r1'/r1 + (r2'/r2 − r1'/r1) f`.
    hs: [f32; 2],
}

impl BoneCoef {
    fn new(f: &BoneFrame) -> BoneCoef {
        BoneCoef {
            rot: f.rot,
            origin: f.origin,
            shape: f.shape,
            twist: [f.twist_a, f.twist_b],
            hs: [f.radius_ratio[0], f.radius_ratio[1] - f.radius_ratio[0]],
        }
    }

    /// Eight base points `(σ, κ, d)` (see the module docs) with their point normals `nl`
    /// (bone-local, fitted) decoded on the new shape and twisted: the base points, their
    /// normals and the point normals in the bone's new frame, and the height scales.
    #[inline(always)]
    fn base(&self, sig: F8, cap: F8, d: V3, nl: V3) -> (V3, V3, V3, F8) {
        let sh = &self.shape;
        let f = sig.max(F8::splat(0.0)).min(F8::splat(1.0));
        let (c, s) = twist_cs(self.twist[0] + f * self.twist[1]);
        let k = cap + (1.0 - cap) * sh.cos_a;
        let n = V3 {
            x: cap * d.x + (cap - 1.0) * sh.sin_a,
            y: k * (c * d.y - s * d.z),
            z: k * (s * d.y + c * d.z),
        };
        let rad = (1.0 - sig) * sh.r1 + sig * sh.r2;
        let b = V3 {
            x: sig * sh.length + rad * n.x,
            y: rad * n.y,
            z: rad * n.z,
        };
        let m = V3 {
            x: nl.x,
            y: c * nl.y - s * nl.z,
            z: s * nl.y + c * nl.z,
        };
        (b, n, m, self.hs[0] + f * self.hs[1])
    }
}

/// `(cos t, sin t)` for twist corrections `|t| ≤ 3π` (see [`super::frame`]: `|a| ≤ π`,
/// `|b| ≤ 2π`): Taylor polynomials of `t/8` (error below 10⁻⁷), then three angle doublings.
/// Exact for `t = 0`.
#[inline(always)]
fn twist_cs(t: F8) -> (F8, F8) {
    let x = t * 0.125;
    let x2 = x * x;
    let mut s =
        x * (1.0 - x2 * (1.0 / 6.0) * (1.0 - x2 * (1.0 / 20.0) * (1.0 - x2 * (1.0 / 42.0))));
    let mut c = 1.0
        - x2 * 0.5
            * (1.0 - x2 * (1.0 / 12.0) * (1.0 - x2 * (1.0 / 30.0) * (1.0 - x2 * (1.0 / 56.0))));
    for _ in 0..3 {
        (c, s) = (c * c - s * s, (c + c) * s);
    }
    (c, s)
}

/// `(sin x, cos x)` for `|x| ≤ 5°` (a bend step) by Taylor polynomials: error below 10⁻⁹.
#[inline(always)]
fn small_sin_cos(x: F8) -> (F8, F8) {
    let x2 = x * x;
    (
        x * (1.0 - x2 * (1.0 / 6.0) * (1.0 - x2 * (1.0 / 20.0))),
        1.0 - x2 * 0.5 * (1.0 - x2 * (1.0 / 12.0)),
    )
}

/// `(σ, κ)` of a base point (see the module docs).
#[inline]
fn sigma_cap(part: u8, s: f32) -> (f32, f32) {
    match part {
        CAP1 => (0.0, 1.0),
        CAP2 => (1.0, 1.0),
        _ => (s, 0.0),
    }
}

/// The joint of a point of bone `k` with blend partner `m`: `(side, on_parent, pp, cc)` with
/// `pp` the joint's parent, `cc` its child, and the side index `2 cc` (the child's points) or
/// `2 cc + 1` (the parent's points).
#[inline]
fn joint_of(k: usize, m: usize, bones: &[BoneBind]) -> (usize, bool, usize, usize) {
    if bones[k].parent == Some(m) {
        (2 * k, false, m, k)
    } else {
        (2 * m + 1, true, k, m)
    }
}

/// The profile coordinate `u` (arc length along the bone's outline from the `c1` pole, for
/// the shape `shape`) and the azimuth `ψ` of a base point encoded as `(part, s, dir)`.
fn profile(shape: &BoneShape, part: u8, s: f32, dir: Vec3) -> (f32, f32) {
    let gb = shape.sin_a.clamp(-1.0, 1.0).acos();
    let u1 = shape.r1 * gb;
    let lc = shape.length * shape.cos_a;
    let polar = (-dir.x).clamp(-1.0, 1.0).acos();
    let u = match part {
        CAP1 => shape.r1 * polar,
        CAP2 => u1 + lc + shape.r2 * (polar - gb),
        _ => u1 + s.clamp(0.0, 1.0) * lc,
    };
    (u, dir.z.atan2(dir.y))
}

/// The inverse of [`profile`] for one `u`: `(σ, κ, dₓ, d_r)` with the stored direction
/// `d = (dₓ, d_r cos ψ, d_r sin ψ)` at azimuth `ψ`.
fn profile_row(shape: &BoneShape, u: f32) -> (f32, f32, f32, f32) {
    let gb = shape.sin_a.clamp(-1.0, 1.0).acos();
    let u1 = shape.r1 * gb;
    let lc = shape.length * shape.cos_a;
    if u < u1 {
        let (sg, cg) = (u / shape.r1).sin_cos();
        (0.0, 1.0, -cg, sg)
    } else if u <= u1 + lc && lc > 0.0 {
        ((u - u1) / lc, 0.0, 0.0, 1.0)
    } else {
        let g = gb + (u - u1 - lc).max(0.0) / shape.r2.max(1e-12);
        let (sg, cg) = g.min(PI).sin_cos();
        (1.0, 1.0, -cg, sg)
    }
}

/// A run of points of one bone (and one joint side, or none) in the bind-time layout.
#[derive(Clone, Copy, Debug)]
struct Run {
    start: u32,
    end: u32,
    bone: u16,
    side: u16,
}

/// The bind-time layout of heightfield skinning (see the module docs): derived from the
/// binding's per-point arrays, not saved.
#[derive(Clone, Debug, Default)]
pub struct Slots {
    /// Per joint side: lowest profile coordinate and grid steps per unit of it (`0`: no point
    /// on that side).
    range: Vec<[f32; 2]>,
    /// Runs, block after block; `block_runs[c]..block_runs[c + 1]` are block `c`'s.
    runs: Vec<Run>,
    block_runs: Vec<u32>,
    /// Per point, in output order: its place in its block's layout.
    place: Vec<u16>,
    /// Per place: `σ`, `κ`, stored direction, height, point normal (bone-local).
    sig: Vec<f32>,
    cap: Vec<f32>,
    d: [Vec<f32>; 3],
    h: Vec<f32>,
    nl: [Vec<f32>; 3],
    /// Per place (joint points): lower bend-grid cell and bilinear fractions.
    cell: Vec<u32>,
    uv: Vec<[f32; 2]>,
}

impl Slots {
    /// The layout of the points `pts` bound to `bones` (robust to out-of-range indices, which
    /// are checked later by the loader).
    pub fn new(bones: &[BoneBind], pts: &PointData) -> Slots {
        let nb = bones.len().max(1);
        let n = pts.bone.len();
        // Per point: bone, joint side, (u, ψ).
        let prof: Vec<(u16, u16, f32, f32)> = (0..n)
            .into_par_iter()
            .map(|i| {
                let k = (pts.bone[i] as usize).min(nb - 1);
                let m = pts.partner[i];
                if m == NONE || m as usize >= bones.len() || k >= bones.len() {
                    return (k as u16, NO_SIDE, 0.0, 0.0);
                }
                let (side, ..) = joint_of(k, m as usize, bones);
                let (u, psi) = profile(&bones[k].shape, pts.part[i], pts.s[i], pts.dir[i]);
                if u.is_finite() && psi.is_finite() {
                    (k as u16, side as u16, u, psi)
                } else {
                    (k as u16, NO_SIDE, 0.0, 0.0)
                }
            })
            .collect();
        let mut lo = vec![f32::INFINITY; 2 * nb];
        let mut hi = vec![f32::NEG_INFINITY; 2 * nb];
        for &(_, side, u, _) in &prof {
            if side != NO_SIDE {
                lo[side as usize] = lo[side as usize].min(u);
                hi[side as usize] = hi[side as usize].max(u);
            }
        }
        let range: Vec<[f32; 2]> = lo
            .iter()
            .zip(&hi)
            .map(|(&l, &h)| {
                if l <= h {
                    [l, (GRID_NU - 1) as f32 / (h - l).max(1e-9)]
                } else {
                    [0.0, 0.0]
                }
            })
            .collect();
        // Per block: the order by (bone, side), stable, and its runs.
        let mut order: Vec<u32> = (0..n as u32).collect();
        order.par_chunks_mut(CHUNK).for_each(|c| {
            let mut keys: Vec<u64> = c
                .iter()
                .map(|&i| {
                    let (k, side, ..) = prof[i as usize];
                    (k as u64) << 48 | (side as u64) << 32 | i as u64
                })
                .collect();
            keys.sort_unstable();
            for (o, k) in c.iter_mut().zip(keys) {
                *o = k as u32;
            }
        });
        let mut place = vec![0u16; n];
        let block_runs: Vec<Vec<Run>> = order
            .par_chunks(CHUNK)
            .zip(place.par_chunks_mut(CHUNK))
            .enumerate()
            .map(|(c, (block, place))| {
                let base = c * CHUNK;
                let mut runs: Vec<Run> = Vec::new();
                for (j, &i) in block.iter().enumerate() {
                    let (k, side, _, _) = prof[i as usize];
                    place[i as usize - base] = j as u16;
                    let at = (base + j) as u32;
                    match runs.last_mut() {
                        Some(r) if r.bone == k && r.side == side => r.end = at + 1,
                        _ => runs.push(Run {
                            start: at,
                            end: at + 1,
                            bone: k,
                            side,
                        }),
                    }
                }
                runs
            })
            .collect();
        let mut s = Slots {
            range,
            place,
            ..Default::default()
        };
        for runs in block_runs {
            s.block_runs.push(s.runs.len() as u32);
            s.runs.extend(runs);
        }
        s.block_runs.push(s.runs.len() as u32);
        fn gather(order: &[u32], f: impl Fn(usize) -> f32 + Sync) -> Vec<f32> {
            order.par_iter().map(|&i| f(i as usize)).collect()
        }
        s.sig = gather(&order, |i| sigma_cap(pts.part[i], pts.s[i]).0);
        s.cap = gather(&order, |i| sigma_cap(pts.part[i], pts.s[i]).1);
        s.d = [0, 1, 2].map(|a| gather(&order, |i| pts.dir[i][a]));
        s.nl = [0, 1, 2].map(|a| gather(&order, |i| pts.normal[i][a]));
        s.h = gather(&order, |i| pts.height[i]);
        (s.cell, s.uv) = order
            .par_iter()
            .map(|&i| {
                let (_, side, u, psi) = prof[i as usize];
                if side == NO_SIDE {
                    return (0, [0.0, 0.0]);
                }
                let [u0, scale] = s.range[side as usize];
                let t = ((u - u0) * scale).clamp(0.0, (GRID_NU - 1) as f32);
                let j = (t as usize).min(GRID_NU - 2);
                let v = psi * (GRID_NPSI as f32 / TAU) + (4 * GRID_NPSI) as f32;
                let m0 = v as usize;
                let c = side as usize * PER_SIDE + j * GRID_NPSI + m0 % GRID_NPSI;
                (c as u32, [t - j as f32, v - m0 as f32])
            })
            .unzip();
        s
    }
}

/// One joint side for one frame: whether its points bend, and the axis (in the side's bone's
/// own new frame) about which their normals turn.
#[derive(Clone, Copy, Debug, Default)]
struct SideFrame {
    active: bool,
    axis: Vec3,
    /// `(y, z)` of the direction towards which the bones' axes turn, in the side's bone's
    /// own frame: a point is on the convex side when its base point's radial part points
    /// away from it.
    inside: [f32; 2],
}

/// A bend cell: displacement of the base point, change of its normal, `(cos, sin)` of the
/// normals' rotation angle — all in the side's bone's own new frame.
type Cell = [f32; 8];
const IDENTITY: Cell = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0];

/// The per-frame tables of heightfield skinning (reuse between frames; they only grow).
#[derive(Default)]
pub struct Tables {
    coef: Vec<BoneCoef>,
    sides: Vec<SideFrame>,
    cells: Vec<Cell>,
}

/// `(cos ψ, sin ψ)` of the grid's azimuths, lane blocks.
fn psi_lanes() -> [(F8, F8); GRID_NPSI / L] {
    std::array::from_fn(|g| {
        let a: [(f32, f32); L] =
            std::array::from_fn(|l| (TAU * (g * L + l) as f32 / GRID_NPSI as f32).sin_cos());
        (
            F8(std::array::from_fn(|l| a[l].1)),
            F8(std::array::from_fn(|l| a[l].0)),
        )
    })
}

/// Fills the tables for the pose analysed in `frames` (allocation-free once grown).
pub fn build_tables(bones: &[BoneBind], frames: &[BoneFrame], slots: &Slots, out: &mut Tables) {
    out.coef.clear();
    out.coef.extend(frames.iter().map(BoneCoef::new));
    let nb = bones.len();
    out.sides.resize(2 * nb, SideFrame::default());
    for (c, fc) in frames.iter().enumerate() {
        let bends = bones[c].c1_partner.is_some() && fc.bend_angle > 1e-5;
        let a = fc.bend_axis;
        let in_child = (fc.pre_bend.transpose() * a).cross(Vec3::X);
        let in_parent = a.cross(Vec3::X);
        out.sides[2 * c] = SideFrame {
            active: bends && slots.range[2 * c][1] > 0.0,
            axis: fc.rel_new.transpose() * a,
            inside: [in_child.y, in_child.z],
        };
        out.sides[2 * c + 1] = SideFrame {
            active: bends && slots.range[2 * c + 1][1] > 0.0,
            axis: a,
            inside: [in_parent.y, in_parent.z],
        };
    }
    out.cells.resize(2 * nb * PER_SIDE, IDENTITY);
    let psi = psi_lanes();
    let (sides, coef) = (&out.sides, &out.coef);
    out.cells
        .par_chunks_mut(GRID_NPSI)
        .enumerate()
        .for_each(|(row_index, row)| {
            let (side, j) = (row_index / GRID_NU, row_index % GRID_NU);
            if !sides[side].active {
                return;
            }
            #[cfg(target_arch = "x86_64")]
            if has_avx2() {
                // SAFETY: the processor runs AVX2.
                return unsafe { table_row_avx2(side, j, row, &psi, bones, frames, slots, coef) };
            }
            table_row(side, j, row, &psi, bones, frames, slots, coef)
        });
}

/// [`table_row`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
fn table_row_avx2(
    side: usize,
    j: usize,
    row: &mut [Cell],
    psi: &[(F8, F8); GRID_NPSI / L],
    bones: &[BoneBind],
    frames: &[BoneFrame],
    slots: &Slots,
    coef: &[BoneCoef],
) {
    table_row(side, j, row, psi, bones, frames, slots, coef)
}

/// Row `j` of joint side `side` of the bend grid.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn table_row(
    side: usize,
    j: usize,
    row: &mut [Cell],
    psi: &[(F8, F8); GRID_NPSI / L],
    bones: &[BoneBind],
    frames: &[BoneFrame],
    slots: &Slots,
    coef: &[BoneCoef],
) {
    let (cc, on_parent) = (side / 2, side % 2 == 1);
    let Some(pp) = bones[cc].c1_partner else {
        return;
    };
    let own = if on_parent { pp } else { cc };
    let [u0, scale] = slots.range[side];
    let (sig, cap, dx, dr) = profile_row(&bones[own].shape, u0 + j as f32 / scale);
    for (block, &(cp, sp)) in row.chunks_mut(L).zip(psi) {
        let d = V3 {
            x: F8::splat(dx),
            y: cp * dr,
            z: sp * dr,
        };
        let (b, n, _, _) = coef[own].base(F8::splat(sig), F8::splat(cap), d, d);
        let (convex, p, m, ang) = bend(on_parent, b, pp, cc, bones, frames);
        if !convex.contains(&true) {
            block.fill(IDENTITY);
            continue;
        }
        let (dp, dn) = (p - b, m - n);
        for (l, cell) in block.iter_mut().enumerate() {
            let (s, c) = ang.0[l].sin_cos();
            *cell = [
                dp.x.0[l], dp.y.0[l], dp.z.0[l], dn.x.0[l], dn.y.0[l], dn.z.0[l], c, s,
            ];
        }
    }
}

/// Bilinear interpolation of the bend grid at a slot.
#[inline(always)]
fn fetch(cell: u32, [fu, fv]: [f32; 2], cells: &[Cell]) -> Cell {
    const _: () = assert!(GRID_NPSI.is_power_of_two() && GRID_NPSI.is_multiple_of(L));
    let c = cell as usize;
    let m0 = c & (GRID_NPSI - 1);
    let c01 = c - m0 + ((m0 + 1) & (GRID_NPSI - 1));
    let (a, b, d, e) = (
        &cells[c],
        &cells[c01],
        &cells[c + GRID_NPSI],
        &cells[c01 + GRID_NPSI],
    );
    let w00 = (1.0 - fu) * (1.0 - fv);
    let w01 = (1.0 - fu) * fv;
    let w10 = fu * (1.0 - fv);
    let w11 = fu * fv;
    let mut r = [0.0; 8];
    for (i, ri) in r.iter_mut().enumerate() {
        *ri = a[i] * w00 + b[i] * w01 + d[i] * w10 + e[i] * w11;
    }
    r
}

thread_local! {
    /// Per worker: one block's results in layout order (six arrays of `CHUNK`).
    static BLOCK: RefCell<Vec<f32>> = const { RefCell::new(Vec::new()) };
}

/// Deforms every point into `out_p` (world positions) and `out_n` (world normals), in
/// parallel blocks.
pub fn deform(slots: &Slots, tables: &Tables, out_p: &mut [Vec3], out_n: &mut [Vec3]) {
    out_p
        .par_chunks_mut(CHUNK)
        .zip(out_n.par_chunks_mut(CHUNK))
        .enumerate()
        .for_each(|(c, (ps, ns))| {
            BLOCK.with(|tmp| {
                let mut tmp = tmp.borrow_mut();
                if tmp.len() < 6 * CHUNK {
                    tmp.resize(6 * CHUNK, 0.0);
                }
                #[cfg(target_arch = "x86_64")]
                if has_avx2() {
                    // SAFETY: the processor runs AVX2.
                    return unsafe { deform_block_avx2(c, slots, tables, &mut tmp, ps, ns) };
                }
                deform_block(c, slots, tables, &mut tmp, ps, ns)
            })
        });
}

/// [`deform_block`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn deform_block_avx2(
    c: usize,
    slots: &Slots,
    tables: &Tables,
    tmp: &mut [f32],
    out_p: &mut [Vec3],
    out_n: &mut [Vec3],
) {
    deform_block(c, slots, tables, tmp, out_p, out_n)
}

/// One block: its runs into `tmp` (layout order), then `tmp` into the output (point order).
#[inline(always)]
fn deform_block(
    c: usize,
    slots: &Slots,
    tables: &Tables,
    tmp: &mut [f32],
    out_p: &mut [Vec3],
    out_n: &mut [Vec3],
) {
    let base = c * CHUNK;
    let runs = &slots.runs[slots.block_runs[c] as usize..slots.block_runs[c + 1] as usize];
    let [t0, t1, t2, t3, t4, t5] = tmp
        .get_disjoint_mut([
            0..CHUNK,
            CHUNK..2 * CHUNK,
            2 * CHUNK..3 * CHUNK,
            3 * CHUNK..4 * CHUNK,
            4 * CHUNK..5 * CHUNK,
            5 * CHUNK..6 * CHUNK,
        ])
        .expect("disjoint");
    for run in runs {
        let (a, e) = (run.start as usize, run.end as usize);
        let bc = &tables.coef[run.bone as usize];
        let side = tables
            .sides
            .get(run.side as usize)
            .filter(|s| s.active && run.side != NO_SIDE);
        let mut i = a;
        while i < e {
            let m = (e - i).min(L);
            let r = i..i + m;
            let (b, n, nl, hs) = bc.base(
                F8::load(&slots.sig[r.clone()]),
                F8::load(&slots.cap[r.clone()]),
                V3 {
                    x: F8::load(&slots.d[0][r.clone()]),
                    y: F8::load(&slots.d[1][r.clone()]),
                    z: F8::load(&slots.d[2][r.clone()]),
                },
                V3 {
                    x: F8::load(&slots.nl[0][r.clone()]),
                    y: F8::load(&slots.nl[1][r.clone()]),
                    z: F8::load(&slots.nl[2][r.clone()]),
                },
            );
            let h = F8::load(&slots.h[r.clone()]) * hs;
            let (x, nl) = match side {
                None => (b + n.scale(h), nl),
                Some(sf) => {
                    let mut tc = [IDENTITY; L];
                    for (l, tc) in tc.iter_mut().enumerate().take(m) {
                        *tc = fetch(slots.cell[i + l], slots.uv[i + l], &tables.cells);
                    }
                    let t: [[f32; L]; 8] =
                        std::array::from_fn(|q| std::array::from_fn(|l| tc[l][q]));
                    let dn = V3 {
                        x: F8(t[3]),
                        y: F8(t[4]),
                        z: F8(t[5]),
                    };
                    let n2 = (n + dn).normalize_or(n);
                    let dp = V3 {
                        x: F8(t[0]),
                        y: F8(t[1]),
                        z: F8(t[2]),
                    };
                    let (c, s) = (F8(t[6]), F8(t[7]));
                    let inv = 1.0 / (c * c + s * s).sqrt().max(F8::splat(1e-12));
                    let bent_x = b + dp + n2.scale(h);
                    let bent_n = rot_axis(nl, sf.axis, c * inv, s * inv);
                    // Concave side: the point follows its own bone (exactly).
                    let convex = (b.y * sf.inside[0] + b.z * sf.inside[1]).lt(F8::splat(0.0));
                    let rigid_x = b + n.scale(h);
                    (
                        V3 {
                            x: F8::select(convex, bent_x.x, rigid_x.x),
                            y: F8::select(convex, bent_x.y, rigid_x.y),
                            z: F8::select(convex, bent_x.z, rigid_x.z),
                        },
                        V3 {
                            x: F8::select(convex, bent_n.x, nl.x),
                            y: F8::select(convex, bent_n.y, nl.y),
                            z: F8::select(convex, bent_n.z, nl.z),
                        },
                    )
                }
            };
            let p = V3::mat(&bc.rot, x).add_c(bc.origin);
            let q = V3::mat(&bc.rot, nl);
            let o = i - base;
            p.x.store(&mut t0[o..o + m]);
            p.y.store(&mut t1[o..o + m]);
            p.z.store(&mut t2[o..o + m]);
            q.x.store(&mut t3[o..o + m]);
            q.y.store(&mut t4[o..o + m]);
            q.z.store(&mut t5[o..o + m]);
            i += m;
        }
    }
    let place = &slots.place[base..base + out_p.len()];
    for ((op, on), &j) in out_p.iter_mut().zip(out_n.iter_mut()).zip(place) {
        let j = j as usize;
        *op = Vec3::new(t0[j], t1[j], t2[j]);
        *on = Vec3::new(t3[j], t4[j], t5[j]);
    }
}

/// Rotates `v` about the unit axis `k` by the angle of cosine `c` and sine `s` (Rodrigues).
#[inline(always)]
fn rot_axis(v: V3, k: Vec3, c: F8, s: F8) -> V3 {
    let kv = v.dot_c(k) * (1.0 - c);
    let kx = v.cross_from(k);
    V3 {
        x: v.x * c + kx.x * s + kv * k.x,
        y: v.y * c + kx.y * s + kv * k.y,
        z: v.z * c + kx.z * s + kv * k.z,
    }
}

/// Point `i` deformed with the bend evaluated at its own base point (no bend tables): the
/// reference the tables approximate (for tests). `tables` must have been built for `frames`.
pub fn reference_point(
    i: usize,
    pts: &PointData,
    bones: &[BoneBind],
    frames: &[BoneFrame],
    tables: &Tables,
) -> (Vec3, Vec3) {
    let k = pts.bone[i] as usize;
    let bc = &tables.coef[k];
    let (sig, cap) = sigma_cap(pts.part[i], pts.s[i]);
    let (b, n, nl, hs) = bc.base(
        F8::splat(sig),
        F8::splat(cap),
        V3::splat(pts.dir[i]),
        V3::splat(pts.normal[i]),
    );
    let (b, n, nl, h) = (b.lane(0), n.lane(0), nl.lane(0), pts.height[i] * hs.0[0]);
    let m = pts.partner[i];
    if m != NONE {
        let (side, on_parent, pp, cc) = joint_of(k, m as usize, bones);
        if tables.sides[side].active
            && let (convex, p, n, ang) = bend(on_parent, V3::splat(b), pp, cc, bones, frames)
            && convex[0]
        {
            let (p, n, ang) = (p.lane(0), n.lane(0), ang.0[0]);
            let (s, c) = ang.sin_cos();
            let m = rot_axis(
                V3::splat(nl),
                tables.sides[side].axis,
                F8::splat(c),
                F8::splat(s),
            );
            return (bc.rot * (p + h * n) + bc.origin, bc.rot * m.lane(0));
        }
    }
    (bc.rot * (b + h * n) + bc.origin, bc.rot * nl)
}

/// A bone in its own frame (`c1` at the origin, along X) as
/// [`crate::geometry::bone::PreparedBone`] describes it, for
/// eight points at a time.
#[derive(Clone, Copy, Debug)]
struct LocalBone {
    l: f32,
    r1: f32,
    r2: f32,
    sin_a: f32,
    cos_a: f32,
    tan_a: f32,
    /// 0, or the containing sphere (1 or 2) when one sphere contains the other.
    sphere_only: u8,
}

/// A projection on a [`LocalBone`]: point, normal, distance, residual, on the envelope.
#[derive(Clone, Copy)]
struct Proj {
    p: V3,
    n: V3,
    dist: F8,
    res: F8,
    on: M8,
}

impl Proj {
    #[inline(always)]
    fn select(m: M8, a: &Proj, b: &Proj) -> Proj {
        let v = |x: V3, y: V3| V3 {
            x: F8::select(m, x.x, y.x),
            y: F8::select(m, x.y, y.y),
            z: F8::select(m, x.z, y.z),
        };
        Proj {
            p: v(a.p, b.p),
            n: v(a.n, b.n),
            dist: F8::select(m, a.dist, b.dist),
            res: F8::select(m, a.res, b.res),
            on: std::array::from_fn(|i| if m[i] { a.on[i] } else { b.on[i] }),
        }
    }
}

const TINY: f32 = 1e-12;

impl LocalBone {
    /// As [`crate::geometry::Bone::prepare`] for the bone of shape `sh` along X.
    fn new(sh: &BoneShape) -> LocalBone {
        let (l, r1, r2) = (sh.length, sh.r1, sh.r2);
        let dr = r2 - r1;
        let sphere_only = if dr.abs() >= l {
            if r2 > r1 { 2 } else { 1 }
        } else {
            0
        };
        let (sin_a, cos_a) = if sphere_only != 0 {
            (0.0, 1.0)
        } else {
            let s = (dr / l).clamp(-1.0, 1.0);
            (s, (1.0 - s * s).max(0.0).sqrt())
        };
        LocalBone {
            l,
            r1,
            r2,
            sin_a,
            cos_a,
            tan_a: if cos_a > TINY { sin_a / cos_a } else { 0.0 },
            sphere_only,
        }
    }

    /// Signed distance as [`crate::geometry::bone::PreparedBone::sdf_fast`].
    #[inline(always)]
    fn sdf(&self, p: V3) -> F8 {
        let d1 = p.dot(p).sqrt() - self.r1;
        let q = p.add_c(Vec3::new(-self.l, 0.0, 0.0));
        let d2 = q.dot(q).sqrt() - self.r2;
        match self.sphere_only {
            1 => return d1,
            2 => return d2,
            _ => {}
        }
        let y = (p.y * p.y + p.z * p.z).sqrt();
        let t = p.x + y * self.tan_a;
        let cone = y / self.cos_a - (self.r1 + (self.r2 - self.r1) * (t / self.l));
        let tau = t / self.l;
        F8::select(
            tau.lt(F8::splat(0.0)),
            d1,
            F8::select(F8::splat(1.0).lt(tau), d2, cone),
        )
    }

    /// Projection on sphere `which` as [`crate::geometry::bone::PreparedBone`]'s (no normal constraint).
    #[inline(always)]
    fn sphere(&self, which: u8, p: V3) -> Proj {
        let (cx, r, fallback) = if which == 1 {
            (0.0, self.r1, -1.0)
        } else {
            (self.l, self.r2, 1.0)
        };
        let e = p.add_c(Vec3::new(-cx, 0.0, 0.0));
        let le = e.dot(e).sqrt();
        let ok = F8::splat(TINY * (1.0 + cx.abs())).lt(le);
        let inv = 1.0 / le;
        let dir = V3 {
            x: F8::select(ok, e.x * inv, F8::splat(fallback)),
            y: F8::select(ok, e.y * inv, F8::splat(0.0)),
            z: F8::select(ok, e.z * inv, F8::splat(0.0)),
        };
        let on = match self.sphere_only {
            0 if which == 1 => std::array::from_fn(|i| dir.x.0[i] <= -self.sin_a),
            0 => std::array::from_fn(|i| dir.x.0[i] >= -self.sin_a),
            s => [s == which; L],
        };
        let res = le - r;
        Proj {
            p: dir.scale(F8::splat(r)).add_c(Vec3::new(cx, 0.0, 0.0)),
            n: dir,
            dist: res.map(f32::abs),
            res,
            on,
        }
    }

    /// The orthogonal projection, as [`crate::geometry::bone::PreparedBone::project`]: `(point, normal)`.
    #[inline(always)]
    fn project(&self, p: V3) -> (V3, V3) {
        if self.sphere_only != 0 {
            let s = self.sphere(self.sphere_only, p);
            return (s.p, s.n);
        }
        let (s1, s2) = (self.sphere(1, p), self.sphere(2, p));
        // The cone line in p's half-plane.
        let y = (p.y * p.y + p.z * p.z).sqrt();
        let pl = (p.x * p.x + y * y).sqrt();
        let ok: M8 = std::array::from_fn(|i| y.0[i] > TINY * (1.0 + pl.0[i]));
        let inv = 1.0 / y;
        let (vy, vz) = (
            F8::select(ok, p.y * inv, F8::splat(1.0)),
            F8::select(ok, p.z * inv, F8::splat(0.0)),
        );
        let t = p.x + y * self.tan_a;
        let r = self.r1 + (self.r2 - self.r1) * (t / self.l);
        let n = V3 {
            x: F8::splat(-self.sin_a),
            y: vy * self.cos_a,
            z: vz * self.cos_a,
        };
        let tau = t / self.l;
        let res = y / self.cos_a - r;
        let cone = Proj {
            p: n.scale(r).add_c(Vec3::ZERO)
                + V3 {
                    x: t,
                    y: F8::splat(0.0),
                    z: F8::splat(0.0),
                },
            n,
            dist: res.map(f32::abs),
            res,
            on: std::array::from_fn(|i| (0.0..=1.0).contains(&tau.0[i]) && r.0[i] >= 0.0),
        };
        let region = Proj::select(
            tau.lt(F8::splat(0.0)),
            &s1,
            &Proj::select(F8::splat(1.0).lt(tau), &s2, &cone),
        );
        // Inside: the nearest of the cone line and the two cap arcs that lie on the envelope.
        let mut best = region;
        let mut best_d = F8::splat(f32::INFINITY);
        for c in [&cone, &s1, &s2] {
            let take: M8 = std::array::from_fn(|i| c.on[i] && c.dist.0[i] < best_d.0[i]);
            best = Proj::select(take, c, &best);
            best_d = F8::select(take, c.dist, best_d);
        }
        let inside = region.res.lt(F8::splat(0.0));
        let r = Proj::select(inside, &best, &region);
        (r.p, r.n)
    }
}

/// The bend of eight (twisted) base points `b` of a bone near the joint between `pp` (parent)
/// and `cc` (child), in the bone's own new frame: per point the re-projected base point, its
/// normal and the angle by which the point's normal turns about the side's axis, or `None` on
/// the concave side (the point follows its own bone).
#[inline(always)]
fn bend(
    on_parent: bool,
    b: V3,
    pp: usize,
    cc: usize,
    bones: &[BoneBind],
    frames: &[BoneFrame],
) -> (M8, V3, V3, F8) {
    let fc = &frames[cc];
    let j = Vec3::new(frames[pp].shape.length, 0.0, 0.0);
    let a = fc.bend_axis;
    let g = fc.pre_bend;
    let (x0, u) = if on_parent {
        (b, Vec3::X)
    } else {
        (V3::mat(&g, b).add_c(j), g * Vec3::X)
    };
    // Anisotropy: radial direction of the point about its own bone's axis against the
    // direction the bones' axes turn towards.
    let rel = x0.add_c(-j);
    let radial = rel - V3::splat(u).scale(rel.dot_c(u));
    let inside = a.cross(u).normalize_or(Vec3::ZERO);
    let cos_ab = radial.normalize_or(V3::default()).dot_c(inside);
    let convex: M8 = cos_ab.lt(F8::splat(0.0));
    if !convex.contains(&true) {
        return (convex, b, b, F8::splat(0.0));
    }
    let ratio = 0.5 * (frames[pp].radius_ratio[1] + fc.radius_ratio[0]);
    let eps = cos_ab.map(f32::abs) * (bones[cc].eps * ratio);
    let sig = eps * (1.0 / 3.0);
    let inv_2s2 = 1.0 / ((sig * sig).max(F8::splat(1e-30)) * 2.0);
    let theta = fc.bend_angle;
    let steps = (theta / BEND_STEP).ceil().max(1.0) as usize;
    let dt = theta / steps as f32;
    // The point turns on a circle about the axis `a` through J; the child's side of the
    // iteration is evaluated in the child's own frame before its bend (`x ↦ Gᵀ (x − J)`).
    let z = rel.dot_c(a);
    let w = rel - V3::splat(a).scale(z);
    let aw = w.cross_from(a);
    let centre = V3::splat(a).scale(z).add_c(j);
    let (zc, wc, awc) = (
        V3::mat_t(&g, V3::splat(a).scale(z)),
        V3::mat_t(&g, w),
        V3::mat_t(&g, aw),
    );
    let (bp, bc) = (LocalBone::new(&frames[pp].shape), LocalBone::new(&fc.shape));
    // (cos, sin) of the point's angle φ and of φ − ψ (ψ the child's angle so far).
    let (one, zero) = (F8::splat(1.0), F8::splat(0.0));
    let (mut cp, mut sp, mut cq, mut sq, mut phi) = (one, zero, one, zero, zero);
    for _ in 0..steps {
        let pos_p = centre + w.scale(cp) + aw.scale(sp);
        let pos_c = zc + wc.scale(cq) + awc.scale(sq);
        let dp = bp.sdf(pos_p).max(zero);
        let dc = bc.sdf(pos_c).max(zero);
        let e = ((dc * dc - dp * dp) * inv_2s2)
            .max(F8::splat(-60.0))
            .min(F8::splat(60.0));
        let step = dt / (1.0 + e.exp());
        phi = phi + step;
        // φ += wc δ; φ − ψ += (wc − 1) δ.
        let (s1, c1) = small_sin_cos(step);
        (cp, sp) = (cp * c1 - sp * s1, sp * c1 + cp * s1);
        let (s2, c2) = small_sin_cos(step - dt);
        (cq, sq) = (cq * c2 - sq * s2, sq * c2 + cq * s2);
    }
    let x1 = centre + w.scale(cp) + aw.scale(sp);
    // Re-project on the nearer of the two new bones: the parent in its frame (the one we are
    // in), the child after its bend in its own new frame, `x ↦ R_newᵀ (x − J)`.
    let r = &fc.rel_new;
    let x1c = V3::mat_t(r, x1.add_c(-j));
    let use_parent = {
        let (dp, dc) = (bp.sdf(x1), bc.sdf(x1c));
        std::array::from_fn(|i| dp.0[i] <= dc.0[i])
    };
    // Usually all eight agree: project on that bone only.
    let (pp_p, pp_n, pc_p, pc_n) = if use_parent.iter().all(|&u| u) {
        let (p, n) = bp.project(x1);
        (p, n, p, n)
    } else if !use_parent.contains(&true) {
        let (p, n) = bc.project(x1c);
        (p, n, p, n)
    } else {
        let (a, b) = (bp.project(x1), bc.project(x1c));
        (a.0, a.1, b.0, b.1)
    };
    let sel = |m: M8, a: V3, b: V3| V3 {
        x: F8::select(m, a.x, b.x),
        y: F8::select(m, a.y, b.y),
        z: F8::select(m, a.z, b.z),
    };
    // Into the own bone's new frame; the child's normals turn by φ − θ.
    let (p, n, ang) = if on_parent {
        (
            sel(use_parent, pp_p, V3::mat(r, pc_p).add_c(j)),
            sel(use_parent, pp_n, V3::mat(r, pc_n)),
            phi,
        )
    } else {
        (
            sel(use_parent, V3::mat_t(r, pp_p.add_c(-j)), pc_p),
            sel(use_parent, V3::mat_t(r, pp_n), pc_n),
            phi - theta,
        )
    };
    (convex, p, n, ang)
}
