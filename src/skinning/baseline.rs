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

use super::binding::{BoneBind, PointData};
use super::frame::BoneFrame;
use super::surface::{CAP1, CAP2};
use crate::math::{Mat3, Vec3};

/// The baseline encoding of one point.
#[derive(Clone, Copy, Debug, Default)]
pub struct PointBaseline {
    /// Baseline parameter (NaN: rigid with a free cap).
    pub t: f32,
    /// Azimuth `(cos ψ, sin ψ)` in the bone frame.
    pub cs: [f32; 2],
    /// Height along the detail direction.
    pub h: f32,
    /// Detail direction at the fitted pose (bone-local).
    pub n: Vec3,
    /// Residual displacement (bone-local).
    pub res: Vec3,
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

/// An arc from direction `d0` (radius `r0`) to `d1` (radius `r1`) around `centre`.
#[derive(Clone, Copy, Debug)]
struct Arc {
    centre: Vec3,
    d0: Vec3,
    w: Vec3,
    angle: f32,
    r0: f32,
    r1: f32,
    len: f32,
}

impl Arc {
    fn new(centre: Vec3, d0: Vec3, r0: f32, d1: Vec3, r1: f32) -> Arc {
        let c = d0.dot(d1).clamp(-1.0, 1.0);
        let perp = d1 - c * d0;
        let sn = perp.length();
        let angle = sn.atan2(c);
        let w = if sn > 1e-9 { perp / sn } else { Vec3::ZERO };
        Arc {
            centre,
            d0,
            w,
            angle,
            r0,
            r1,
            len: angle * 0.5 * (r0 + r1),
        }
    }
    /// Point and normal at fraction `f` (extrapolates outside `[0, 1]`).
    #[inline]
    fn at(&self, f: f32) -> (Vec3, Vec3) {
        let (s, c) = (self.angle * f).sin_cos();
        let d = self.d0 * c + self.w * s;
        let r = self.r0 + (self.r1 - self.r0) * f.clamp(0.0, 1.0);
        (self.centre + r * d, d)
    }
}

/// A point's baseline on bone `k`, in `k`'s frame.
#[derive(Clone, Copy, Debug)]
struct Curve {
    arc1: Option<Arc>,
    a: Vec3,
    na: Vec3,
    b: Vec3,
    nb: Vec3,
    seg: f32,
    arc2: Option<Arc>,
}

impl Curve {
    fn arc1_len(&self) -> f32 {
        self.arc1.map_or(0.0, |a| a.len)
    }
    fn arc2_len(&self) -> f32 {
        self.arc2.map_or(0.0, |a| a.len)
    }
    fn len(&self) -> f32 {
        self.arc1_len() + self.seg + self.arc2_len()
    }
    /// Base point and detail direction at arc length `lambda` from `S1`.
    #[inline]
    fn at(&self, lambda: f32) -> (Vec3, Vec3) {
        let l1 = self.arc1_len();
        if let Some(a) = &self.arc1
            && lambda < l1
            && a.len > 1e-12
        {
            // Arc 1 runs from S1 to U1, i.e. fraction 0 at S1.
            return a.at(lambda / a.len);
        }
        if let Some(a) = &self.arc2
            && lambda > l1 + self.seg
            && a.len > 1e-12
        {
            return a.at((lambda - l1 - self.seg) / a.len);
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

/// Builds bone `k`'s baseline for the bone-local azimuth `(c, s)` from the frames of a pose.
#[inline]
fn curve(k: usize, c: f32, s: f32, frames: &[BoneFrame], bones: &[BoneBind]) -> Curve {
    let fk = &frames[k];
    let sh = &fk.shape;
    let n_k = sh.cone_normal_cs(c, s);
    let u1 = sh.r1 * n_k;
    let c2 = Vec3::new(sh.length, 0.0, 0.0);
    let v2 = c2 + sh.r2 * n_k;
    let bb = &bones[k];
    let (mut arc1, mut a, mut na) = (None, u1, n_k);
    if let Some(p) = bb.c1_partner {
        // Parent-frame azimuth ψ_P = ψ + τ(R_new).
        let (st, ct) = fk.tau_new.sin_cos();
        let (cp, sp) = (c * ct - s * st, s * ct + c * st);
        let kp = key(&frames[p], fk, cp, sp);
        // Parent frame → this bone's frame: x_k = Rᵀ (x_p − J).
        let jp = Vec3::new(frames[p].shape.length, 0.0, 0.0);
        let rt = fk.rel_new.transpose();
        let s1 = rt * (kp.s - jp);
        let d1 = rt * kp.d;
        if kp.cross {
            a = s1;
            na = d1;
        } else {
            arc1 = Some(Arc::new(Vec3::ZERO, d1, kp.r, n_k, sh.r1));
        }
    }
    let (mut arc2, mut b, mut nb) = (None, v2, n_k);
    if let Some(ch) = bb.c2_partner {
        let kc = key(fk, &frames[ch], c, s);
        if kc.cross {
            b = kc.s;
            nb = kc.d;
        } else {
            arc2 = Some(Arc::new(c2, n_k, sh.r2, kc.d, kc.r));
        }
    }
    Curve {
        arc1,
        a,
        na,
        b,
        nb,
        seg: (b - a).length(),
        arc2,
    }
}

/// Cubic interpolation `α(t) = 3t² − 2t³` on `[0, 1]`.
#[inline]
fn alpha(t: f32) -> f32 {
    let t = t.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Encodes one point of bone `k` (base point `b` and point `p`, both bone-local) on its fitted
/// baseline; `frames` are the fitted pose analysed against itself.
pub fn bind(
    k: usize,
    part: u8,
    b: Vec3,
    p: Vec3,
    frames: &[BoneFrame],
    bones: &[BoneBind],
) -> PointBaseline {
    let bb = &bones[k];
    let radial = Vec3::new(0.0, b.y, b.z);
    let e = if part == CAP1 || part == CAP2 {
        Vec3::new(0.0, p.y, p.z).normalize_or(radial.normalize_or(Vec3::Y))
    } else {
        radial.normalize_or(Vec3::Y)
    };
    let (c, s) = (e.y, e.z);
    let free =
        (part == CAP1 && bb.c1_partner.is_none()) || (part == CAP2 && bb.c2_partner.is_none());
    if free {
        return PointBaseline {
            t: f32::NAN,
            cs: [c, s],
            ..Default::default()
        };
    }
    let cv = curve(k, c, s, frames, bones);
    let total = cv.len();
    if !(total > 1e-12) {
        return PointBaseline {
            t: f32::NAN,
            cs: [c, s],
            ..Default::default()
        };
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
    let arc_param = |arc: &Arc, q: Vec3, offset: f32| -> f32 {
        let d = (q - arc.centre).normalize_or(arc.d0);
        let ang = d.dot(arc.w).atan2(d.dot(arc.d0));
        if arc.angle > 1e-9 {
            offset + ang / arc.angle * arc.len
        } else {
            offset
        }
    };
    let mut lambda = match (part, &cv.arc1, &cv.arc2) {
        (CAP1, Some(a1), _) => arc_param(a1, b, 0.0),
        (CAP2, _, Some(a2)) => arc_param(a2, b, l1 + cv.seg),
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
    let (pb, nb) = cv.at(lambda);
    let h = (p - pb).dot(nb);
    PointBaseline {
        t: lambda / total,
        cs: [c, s],
        h,
        n: nb,
        res: p - pb - h * nb,
    }
}

/// Rotates `v` about X by the angle whose cosine and sine are `(c, s)`.
#[inline]
fn rot_x(v: Vec3, c: f32, s: f32) -> Vec3 {
    Vec3::new(v.x, c * v.y - s * v.z, s * v.y + c * v.z)
}

/// Rotates `v` by the shortest rotation taking the unit `a` to the unit `b`.
#[inline]
fn rotate_arc(v: Vec3, a: Vec3, b: Vec3) -> Vec3 {
    let w = a.cross(b);
    let c = a.dot(b);
    if c < -0.999_999 {
        return -v;
    }
    v * c + w.cross(v) + w * (w.dot(v) / (1.0 + c))
}

/// Deforms point `i` (output: world position and normal).
#[inline]
pub fn deform_point(
    i: usize,
    pts: &PointData,
    frames: &[BoneFrame],
    bones: &[BoneBind],
) -> (Vec3, Vec3) {
    let k = pts.bone[i] as usize;
    let fk = &frames[k];
    let t = pts.bl_t[i];
    let (x, n) = if t.is_nan() {
        let (b, nb) = fk.shape.decode(pts.part[i], pts.s[i], pts.dir[i]);
        let f = fk.shape.axial_fraction(pts.part[i], pts.s[i]);
        let hs = fk.radius_ratio[0] + (fk.radius_ratio[1] - fk.radius_ratio[0]) * f;
        (b + hs * pts.height[i] * nb, pts.normal[i])
    } else {
        let a = alpha(t);
        let off = -fk.off0 * (1.0 - a) + fk.off1 * a;
        let [c0, s0] = pts.bl_cs[i];
        let (so, co) = off.sin_cos();
        let (c, s) = (c0 * co - s0 * so, s0 * co + c0 * so);
        let cv = curve(k, c, s, frames, bones);
        let (pb, nb) = cv.at(t * cv.len());
        let tc = t.clamp(0.0, 1.0);
        let hs = fk.radius_ratio[0] + (fk.radius_ratio[1] - fk.radius_ratio[0]) * tc;
        let res = rot_x(pts.bl_res[i], co, so);
        let x = pb + hs * (pts.bl_h[i] * nb + res);
        let n_fit = rot_x(pts.bl_n[i], co, so);
        let n = rotate_arc(rot_x(pts.normal[i], co, so), n_fit, nb);
        (x, n)
    };
    (fk.rot * x + fk.origin, (fk.rot * n).normalize_or(n))
}
