//! The sphere-mesh bone: the convex hull of two spheres `(c1, r1)` and `(c2, r2)`, i.e. the
//! union of the spheres centred on the segment `[c1 c2]` whose radius varies linearly
//! (thesis §2.1, fig. 2.2; paper 001 appendix A). Its surface is a truncated cone (the
//! *cone part*) closed by two spherical *caps*.
//!
//! ## Notation (thesis §2.2.1, eq. 2.1–2.2)
//!
//! `l = |c1c2|`, axis `u = (c2 − c1)/l`, cone angle `α` with `sin α = (r2 − r1)/l` (signed here,
//! so the formulas need no `r1 ≤ r2` swap). For a point `p`, `x = (p − c1)·u` is its axial
//! coordinate, `y` its distance to the axis line and `v` the radial unit vector; `p*` is its
//! projection on the axis line. The two candidate axis points are `p*_{±α}` at axial
//! coordinate `x ± y tan α`, with `τ_{±α} = (x ± y tan α)/l`. The cone normal on the side of
//! `p` is `n_α = cos α v − sin α u`; on the opposite side `n_{−α} = −cos α v − sin α u`.
//!
//! * Orthogonal projection (closest surface point): `τ_α < 0` → cap of sphere 1,
//!   `τ_α > 1` → cap of sphere 2, otherwise the cone, at distance
//!   `|pp*_α| − r_α(p) = y / cos α − r(τ_α)` (eq. 2.1, first case; eq. 2.2). For points inside
//!   the bone the closest boundary point is the nearest of the cone line and the two cap arcs
//!   in the half-plane of `p` (exact, since the bone is convex and of revolution).
//! * Normal-constrained projection `p̃` (thesis §2.2.1, paper 001 appendix A):
//!   - `0 ≤ τ_α ≤ 1`: if `n_α · n_p > 0` take the orthogonal projection `p̃_α`; otherwise the
//!     far intersection `p̃_{−α}` of the line `p p*_{−α}` with the non-truncated cone, at
//!     distance `|pp*_{−α}| + r_{−α}(p) = y / cos α + r(τ_{−α})` (eq. 2.1, second case).
//!   - `τ_α < 0` (resp. `> 1`): the projection on sphere 1 (resp. 2) whose normal agrees with
//!     `n_p` — the near point, or the antipodal point at distance `|c p| + r`; if that
//!     antipodal point falls within the bone (not on its cap), `p̃ = p̃_{−α}` instead.
//!   - Far-away fallback (paper 001 appendix A): when `p̃_{−α}` is not on the bone surface
//!     (`τ_{−α}` outside `[0, 1]`, the point `q` of fig. 2.4), take the normal-consistent
//!     projections of `p` on the two spheres and keep the closest, preferring one that lies
//!     on the envelope (a cap) over one hidden inside the bone.
//!   - A zero normal `n_p` means "no normal": the orthogonal projection is returned.
//!
//! **Choices where the papers are open.** The fallback's sphere projections are the
//! normal-consistent ones (near point when its normal agrees with `n_p`, antipodal point
//! otherwise), and [`Projection::on_surface`] says whether the result lies on the bone's
//! envelope. The [`Projection::residual`] used by Levenberg–Marquardt is signed for
//! consistent projections (negative inside the bone, eq. 2.1 first case) and positive for
//! flipped ones (eq. 2.1 second case).
//!
//! ## Degenerate bones
//! * `r1 = r2`: a cylinder with hemispherical caps (`α = 0`).
//! * `|r2 − r1| ≥ l` (one sphere inside the other, including `l = 0`): the bone is the larger
//!   sphere; every projection is a sphere projection and reports the cap of that sphere.
//! * A point on the axis (`y = 0`): the radial direction is a fixed unit vector orthogonal to
//!   the axis, so the result is deterministic.
//!
//! All arithmetic is done relative to `c1` (or `c2` for cap 2) to keep `f32` precision for
//! statues far from the origin.

use crate::math::Vec3;
use crate::rng::Rng;
use serde::{Deserialize, Serialize};

/// A sphere-mesh bone: the convex hull of the spheres `(c1, r1)` and `(c2, r2)`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Bone {
    /// Centre of the first (proximal) sphere.
    pub c1: Vec3,
    /// Centre of the second (distal) sphere.
    pub c2: Vec3,
    /// Radius of the first sphere (≥ 0).
    pub r1: f32,
    /// Radius of the second sphere (≥ 0).
    pub r2: f32,
}

/// Which part of the bone surface a projection lies on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Part {
    /// The spherical cap around `c1`.
    Cap1,
    /// The conical part.
    Cone,
    /// The spherical cap around `c2`.
    Cap2,
}

/// The result of projecting a point on a bone.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Projection {
    /// The projected point `p̃`.
    pub point: Vec3,
    /// The outward unit normal of the bone surface at `p̃`.
    pub normal: Vec3,
    /// `|p − p̃|`.
    pub distance: f32,
    /// Signed residual for least squares: negative inside the bone for a consistent
    /// projection, `+distance` for a flipped (far-side) one.
    pub residual: f32,
    /// The part of the surface `p̃` belongs to (for off-surface far-side points, the part of
    /// the non-truncated cone: `Cone`).
    pub part: Part,
    /// Axial parameter of the sphere centre the projection comes from: `0` at `c1`, `1` at
    /// `c2` (outside `[0, 1]` only for off-surface far-side projections).
    pub tau: f32,
    /// True when `p̃` is on the far side of the bone with respect to the orthogonal
    /// projection (the normal of `p` disagreed with the closest point's normal).
    pub flipped: bool,
    /// True when `p̃` lies on the bone's envelope (always true for the orthogonal projection).
    pub on_surface: bool,
}

/// Derivatives of a projection's [`Projection::residual`] with respect to the bone's
/// geometry (see [`Projection::gradient`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoneGradient {
    /// `∂ residual / ∂ c1`.
    pub dc1: Vec3,
    /// `∂ residual / ∂ c2`.
    pub dc2: Vec3,
    /// `∂ residual / ∂ r1`.
    pub dr1: f32,
    /// `∂ residual / ∂ r2`.
    pub dr2: f32,
}

impl Projection {
    /// Derivatives of [`Projection::residual`] with respect to `c1`, `c2`, `r1`, `r2`, the
    /// point `p` and its projection case being fixed.
    ///
    /// The bone is the envelope of the spheres `(c(τ), r(τ))` with `c(τ) = (1 − τ) c1 + τ c2`
    /// and `r(τ) = (1 − τ) r1 + τ r2`, and the residual is stationary in `τ` at the projection
    /// (that is how `τ_{±α}` is defined), so by the envelope theorem only the explicit
    /// dependence remains: for a consistent projection `residual = (p − c(τ))·n − r(τ)`, for a
    /// flipped one `residual = −(p − c(τ))·n + r(τ)` (`n` the surface normal at `p̃`). Hence,
    /// with weights `w1 = 1 − τ`, `w2 = τ` and `s = +1` (consistent) or `−1` (flipped):
    /// `∂/∂c_i = −s w_i n` and `∂/∂r_i = −s w_i`. These reproduce the papers' one- and
    /// two-bone derivatives (eq. 2.9–2.10, 2.14–2.15) by the chain rule through any
    /// parameterisation of `c1, c2, r1, r2`; they are checked against finite differences.
    #[inline]
    pub fn gradient(&self) -> BoneGradient {
        let tau = self.tau.clamp(0.0, 1.0);
        let s = if self.flipped { -1.0 } else { 1.0 };
        let (w1, w2) = (1.0 - tau, tau);
        BoneGradient {
            dc1: -s * w1 * self.normal,
            dc2: -s * w2 * self.normal,
            dr1: -s * w1,
            dr2: -s * w2,
        }
    }
}

/// A bone with its per-bone constants precomputed (axis, length, cone angle), for projecting
/// many points.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PreparedBone {
    pub bone: Bone,
    /// Unit axis `c1 → c2` (a fixed unit vector when `l = 0`).
    pub axis: Vec3,
    /// A fixed unit vector orthogonal to the axis (radial direction for points on the axis).
    pub perp: Vec3,
    /// Length `l`.
    pub length: f32,
    /// `sin α = (r2 − r1)/l`.
    pub sin_a: f32,
    /// `cos α`.
    pub cos_a: f32,
    /// `tan α`.
    pub tan_a: f32,
    /// When one sphere contains the other: index (1 or 2) of the containing sphere.
    pub sphere_only: Option<u8>,
}

const TINY: f32 = 1e-12;

impl Bone {
    /// A bone from its two spheres.
    pub fn new(c1: Vec3, r1: f32, c2: Vec3, r2: f32) -> Self {
        Bone { c1, c2, r1, r2 }
    }

    /// Length `|c1c2|`.
    pub fn length(&self) -> f32 {
        (self.c2 - self.c1).length()
    }

    /// A sphere holding the whole bone: centred midway between `c1` and `c2`, of radius
    /// `l/2 + max(r1, r2)` (every sphere of the bone is centred on the segment, within `l/2` of
    /// its middle). Points outside it are outside the bone, and the distance to it is a lower
    /// bound of the distance to the bone's surface (the culling of the assignment and the
    /// seeding, the hidden-sample test of the occupancy term).
    pub fn bounding_sphere(&self) -> (Vec3, f32) {
        (
            0.5 * (self.c1 + self.c2),
            0.5 * self.length() + self.r1.max(self.r2),
        )
    }

    /// A size scale for tolerances: `l + r1 + r2`.
    pub fn size(&self) -> f32 {
        self.length() + self.r1 + self.r2
    }

    /// True when all coordinates and radii are finite and the radii are non-negative.
    pub fn is_valid(&self) -> bool {
        self.c1.is_finite()
            && self.c2.is_finite()
            && self.r1.is_finite()
            && self.r2.is_finite()
            && self.r1 >= 0.0
            && self.r2 >= 0.0
    }

    /// Precomputes the per-bone constants.
    pub fn prepare(&self) -> PreparedBone {
        let d = self.c2 - self.c1;
        let length = d.length();
        let axis = if length > TINY { d / length } else { Vec3::Y };
        let perp = axis.any_orthonormal_vector();
        let dr = self.r2 - self.r1;
        let sphere_only = if dr.abs() >= length {
            Some(if self.r2 > self.r1 { 2 } else { 1 })
        } else {
            None
        };
        let (sin_a, cos_a) = if sphere_only.is_some() {
            (0.0, 1.0)
        } else {
            let s = (dr / length).clamp(-1.0, 1.0);
            (s, (1.0 - s * s).max(0.0).sqrt())
        };
        PreparedBone {
            bone: *self,
            axis,
            perp,
            length,
            sin_a,
            cos_a,
            tan_a: if cos_a > TINY { sin_a / cos_a } else { 0.0 },
            sphere_only,
        }
    }

    /// The orthogonal projection (closest surface point), for points inside or outside.
    pub fn project(&self, p: Vec3) -> Projection {
        self.prepare().project(p)
    }

    /// The normal-constrained projection of `p` with normal `n` (thesis §2.2.1).
    pub fn project_constrained(&self, p: Vec3, n: Vec3) -> Projection {
        self.prepare().project_constrained(p, n)
    }

    /// Signed distance to the surface (negative inside).
    pub fn signed_distance(&self, p: Vec3) -> f32 {
        self.prepare().signed_distance(p)
    }

    /// Total surface area of the envelope (cone part + both caps).
    pub fn area(&self) -> f32 {
        let pb = self.prepare();
        let [a1, ac, a2] = pb.part_areas();
        a1 + ac + a2
    }
}

impl PreparedBone {
    /// Local coordinates of `p`: axial `x`, radial distance `y`, radial unit vector `v`.
    #[inline]
    pub fn local(&self, p: Vec3) -> (f32, f32, Vec3) {
        let d = p - self.bone.c1;
        let x = d.dot(self.axis);
        let w = d - x * self.axis;
        let y = w.length();
        // The first test settles the common case without `|d|` (a square root): with
        // `|d|² < 10¹⁴`, `TINY (1 + |d|)` is at most about 10⁻⁵, below `y ≥ 10⁻⁴`.
        let v = if (y >= 1e-4 && d.length_squared() < 1e14) || y > TINY * (1.0 + d.length()) {
            w / y
        } else {
            self.perp
        };
        (x, y, v)
    }

    /// Areas of `[cap 1, cone, cap 2]`.
    pub fn part_areas(&self) -> [f32; 3] {
        use std::f32::consts::PI;
        let b = &self.bone;
        match self.sphere_only {
            Some(1) => [4.0 * PI * b.r1 * b.r1, 0.0, 0.0],
            Some(_) => [0.0, 0.0, 4.0 * PI * b.r2 * b.r2],
            None => [
                2.0 * PI * b.r1 * b.r1 * (1.0 - self.sin_a),
                PI * (b.r1 + b.r2) * self.cos_a * self.cos_a * self.length,
                2.0 * PI * b.r2 * b.r2 * (1.0 + self.sin_a),
            ],
        }
    }

    /// Radius of the sphere centred at axial coordinate `t` (linear in `t`).
    #[inline]
    fn radius_at(&self, t: f32) -> f32 {
        let b = &self.bone;
        if self.length > TINY {
            b.r1 + (b.r2 - b.r1) * (t / self.length)
        } else {
            b.r1
        }
    }

    /// True when the outward sphere direction `dir` (unit) of sphere `which` lies on that
    /// sphere's cap (i.e. on the envelope).
    #[inline]
    fn on_cap(&self, which: u8, dir: Vec3) -> bool {
        match self.sphere_only {
            Some(s) => s == which,
            None => {
                let c = dir.dot(self.axis);
                if which == 1 {
                    c <= -self.sin_a
                } else {
                    c >= -self.sin_a
                }
            }
        }
    }

    #[inline]
    fn sphere_projection(&self, which: u8, p: Vec3, n: Option<Vec3>) -> Projection {
        let b = &self.bone;
        let (c, r) = if which == 1 {
            (b.c1, b.r1)
        } else {
            (b.c2, b.r2)
        };
        let e = p - c;
        let le = e.length();
        let fallback_dir = if which == 1 { -self.axis } else { self.axis };
        let dir = if le > TINY * (1.0 + c.abs().max_element()) {
            e / le
        } else {
            fallback_dir
        };
        let part = if which == 1 { Part::Cap1 } else { Part::Cap2 };
        let tau = if which == 1 { 0.0 } else { 1.0 };
        match n {
            Some(n) if dir.dot(n) <= 0.0 => Projection {
                point: c - r * dir,
                normal: -dir,
                distance: le + r,
                residual: le + r,
                part,
                tau,
                flipped: true,
                on_surface: self.on_cap(which, -dir),
            },
            _ => Projection {
                point: c + r * dir,
                normal: dir,
                distance: (le - r).abs(),
                residual: le - r,
                part,
                tau,
                flipped: false,
                on_surface: self.on_cap(which, dir),
            },
        }
    }

    /// Projection on the cone line on the side of `p` (`flipped = false`) or on the opposite
    /// side (`flipped = true`), with the non-truncated cone: may be off the surface.
    #[inline]
    fn cone_projection(&self, x: f32, y: f32, v: Vec3, flipped: bool) -> Projection {
        let b = &self.bone;
        let (sign, t) = if flipped {
            (-1.0, x - y * self.tan_a)
        } else {
            (1.0, x + y * self.tan_a)
        };
        let r = self.radius_at(t);
        let normal = sign * self.cos_a * v - self.sin_a * self.axis;
        let point = b.c1 + t * self.axis + r * normal;
        let tau = if self.length > TINY {
            t / self.length
        } else {
            0.0
        };
        let on_segment = (0.0..=1.0).contains(&tau);
        let (distance, residual) = if flipped {
            let d = y / self.cos_a + r;
            (d.abs(), d)
        } else {
            let d = y / self.cos_a - r;
            (d.abs(), d)
        };
        Projection {
            point,
            normal,
            distance,
            residual,
            part: Part::Cone,
            tau,
            flipped,
            on_surface: on_segment && r >= 0.0,
        }
    }

    /// The orthogonal projection: the closest point of the bone surface to `p`, for points
    /// outside or inside the bone.
    pub fn project(&self, p: Vec3) -> Projection {
        if let Some(s) = self.sphere_only {
            return self.sphere_projection(s, p, None);
        }
        let (x, y, v) = self.local(p);
        let tau_a = (x + y * self.tan_a) / self.length;
        let region = if tau_a < 0.0 {
            self.sphere_projection(1, p, None)
        } else if tau_a > 1.0 {
            self.sphere_projection(2, p, None)
        } else {
            self.cone_projection(x, y, v, false)
        };
        if region.residual >= 0.0 {
            return region;
        }
        // Inside: nearest of the cone line segment and the two cap arcs in p's half-plane.
        let candidates = [
            self.cone_projection(x, y, v, false),
            self.sphere_projection(1, p, None),
            self.sphere_projection(2, p, None),
        ];
        let mut best = region;
        let mut best_d = f32::INFINITY;
        for c in candidates {
            if c.on_surface && c.distance < best_d {
                best_d = c.distance;
                best = c;
            }
        }
        // Depth is measured to the nearest boundary point: the residual is minus it.
        best.residual = -best.distance;
        best.on_surface = true;
        best
    }

    /// Signed distance to the surface (negative inside).
    #[inline]
    pub fn signed_distance(&self, p: Vec3) -> f32 {
        self.project(p).residual
    }

    /// Fast signed "outside" distance used by the inside test: exact outside, a lower bound of
    /// the depth inside (negative inside, zero on the surface).
    #[inline]
    pub fn sdf_fast(&self, p: Vec3) -> f32 {
        let b = &self.bone;
        match self.sphere_only {
            Some(1) => (p - b.c1).length() - b.r1,
            Some(_) => (p - b.c2).length() - b.r2,
            None => {
                let (x, y, _) = self.local(p);
                let tau_a = (x + y * self.tan_a) / self.length;
                if tau_a < 0.0 {
                    (p - b.c1).length() - b.r1
                } else if tau_a > 1.0 {
                    (p - b.c2).length() - b.r2
                } else {
                    y / self.cos_a - self.radius_at(x + y * self.tan_a)
                }
            }
        }
    }

    /// The normal-constrained projection of `p` whose (approximate, unit) normal is `n`
    /// (thesis §2.2.1 and paper 001 appendix A; see the module docs for every case). A zero
    /// `n` gives the orthogonal projection.
    #[inline]
    pub fn project_constrained(&self, p: Vec3, n: Vec3) -> Projection {
        if n == Vec3::ZERO {
            return self.project(p);
        }
        if let Some(s) = self.sphere_only {
            return self.sphere_projection(s, p, Some(n));
        }
        let (x, y, v) = self.local(p);
        let tau_a = (x + y * self.tan_a) / self.length;
        let cap = if tau_a < 0.0 {
            Some(1u8)
        } else if tau_a > 1.0 {
            Some(2u8)
        } else {
            None
        };
        match cap {
            None => {
                let near = self.cone_projection(x, y, v, false);
                if near.normal.dot(n) > 0.0 {
                    return near;
                }
            }
            Some(which) => {
                let s = self.sphere_projection(which, p, Some(n));
                if s.on_surface {
                    return s;
                }
            }
        }
        let far = self.cone_projection(x, y, v, true);
        if far.on_surface {
            return far;
        }
        // Far-away fallback: the closest normal-consistent sphere projection, preferring one
        // that lies on the envelope (a cap) over one hidden inside the bone.
        let a = self.sphere_projection(1, p, Some(n));
        let b = self.sphere_projection(2, p, Some(n));
        match (a.on_surface, b.on_surface) {
            (true, false) => a,
            (false, true) => b,
            _ if a.distance <= b.distance => a,
            _ => b,
        }
    }

    /// Samples a point of the surface area-uniformly, with its outward normal.
    pub fn sample_surface(&self, rng: &mut Rng) -> (Vec3, Vec3) {
        let areas = self.part_areas();
        let total = areas[0] + areas[1] + areas[2];
        let pick = rng.f32() * total;
        let b = &self.bone;
        let u = self.axis;
        let w = self.perp;
        let w2 = u.cross(w);
        let phi = rng.range(0.0, std::f32::consts::TAU);
        let radial = phi.cos() * w + phi.sin() * w2;
        let part = match self.sphere_only {
            Some(1) => 0,
            Some(_) => 2,
            None if pick < areas[0] => 0,
            None if pick < areas[0] + areas[1] => 1,
            None => 2,
        };
        if part == 0 {
            // Cap 1: directions with dir·u ≤ −sin α; by Archimedes z = dir·u is uniform.
            let zmax = if self.sphere_only.is_some() {
                1.0
            } else {
                -self.sin_a
            };
            let z = rng.range(-1.0, zmax);
            let dir = z * u + (1.0 - z * z).max(0.0).sqrt() * radial;
            (b.c1 + b.r1 * dir, dir)
        } else if part == 1 {
            // Cone: generatrix parameter s with density ∝ the circle radius.
            let (rho1, rho2) = (b.r1, b.r2);
            let q = rng.f32();
            let s = if (rho2 - rho1).abs() < 1e-6 * (rho1 + rho2).max(TINY) {
                q
            } else {
                // Inverse CDF of density ∝ rho1 + (rho2 − rho1) s on [0, 1].
                let a = rho2 - rho1;
                let c = rho1;
                let target = q * (c + 0.5 * a);
                (-c + (c * c + 2.0 * a * target).max(0.0).sqrt()) / a
            };
            let t = s * self.length;
            let normal = self.cos_a * radial - self.sin_a * u;
            let r = self.radius_at(t);
            (b.c1 + t * u + r * normal, normal)
        } else {
            let zmin = if self.sphere_only.is_some() {
                -1.0
            } else {
                -self.sin_a
            };
            let z = rng.range(zmin, 1.0);
            let dir = z * u + (1.0 - z * z).max(0.0).sqrt() * radial;
            (b.c2 + b.r2 * dir, dir)
        }
    }
}

/// The bone of `bones` whose surface is nearest to `p` by (fast) signed distance — for a point
/// inside overlapping bones, the deepest one — with that distance. `(0, ∞)` without bones.
pub fn nearest_bone(bones: &[PreparedBone], p: Vec3) -> (usize, f32) {
    nearest_bone_where(bones, p, |_| true)
}

/// [`nearest_bone`] among the bones `k` for which `keep(k)` holds (`(0, ∞)` when none does).
pub fn nearest_bone_where(
    bones: &[PreparedBone],
    p: Vec3,
    keep: impl Fn(usize) -> bool,
) -> (usize, f32) {
    let mut best = (0, f32::INFINITY);
    for (k, b) in bones.iter().enumerate() {
        if !keep(k) {
            continue;
        }
        let d = b.sdf_fast(p);
        if d < best.1 {
            best = (k, d);
        }
    }
    best
}
