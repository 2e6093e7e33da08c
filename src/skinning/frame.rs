//! Per-frame analysis of a target pose against the fitted one: each bone's new frame and
//! shape, the rigid map fitted → new, and per joint the decomposition of the pose change into
//! twist and bend (thesis §3.2, "the motion between two bones at a joint is the combination of
//! a twisting rotation around the axis of one of the bones and a bending rotation").
//!
//! Joint conventions: the joint at `c1` of bone `k` links `k` to its parent `p`; everything
//! about it is expressed in `p`'s **new** local frame, where the joint centre is
//! `J = (l'_p, 0, 0)` and the child's relative rotation is `R` (`R_fit` at the fitted pose,
//! `R_new` at the target).
//! * **Twist/swing about the bone's own axis** (baseline skinning): `R = S·T` with `T` a
//!   rotation about X by `τ(R)` and `S` the shortest arc from X to `R·X`.
//! * **Change decomposition** (heightfield skinning): `D = R_new R_fit⁻¹ = S_D T_D`, with `T_D`
//!   a rotation by `τ_D` about the child's fitted axis `u = R_fit X` and `S_D` a bend of angle
//!   `θ` about an axis `a ⊥ u`. The child before bending is `G = T_D R_fit`; `S_D G = R_new`.

use super::binding::BoneBind;
use super::surface::BoneShape;
use crate::anatomy::Skeleton;
use crate::geometry::frames::rotation_arc;
use crate::math::{Mat3, Quat, Vec3};
use std::f32::consts::PI;

/// What [`super::Binding::deform`] needs to know about one bone for one target pose.
#[derive(Clone, Copy, Debug, Default)]
pub struct BoneFrame {
    /// New world frame `F'_k` (columns: bone X, Y, Z).
    pub rot: Mat3,
    /// The same as a quaternion.
    pub rot_q: Quat,
    /// New world position of `c1`.
    pub origin: Vec3,
    /// New shape (length, radii).
    pub shape: BoneShape,
    /// `r1'/r1` and `r2'/r2`: heights are scaled by the radius ratio at their base point.
    pub radius_ratio: [f32; 2],
    /// Rigid map of the fitted bone onto the new one: `x' = q x + t` (world).
    pub rigid_q: Quat,
    /// Translation of the rigid map.
    pub rigid_t: Vec3,
    /// `R_new` as a matrix (child-local → parent-local rotation), identity without a parent.
    pub rel_new: Mat3,
    /// Twist `τ(R_new)` and its cosine/sine.
    pub tau_new: f32,
    /// `S(R_new)`: the swing part of the new relative rotation.
    pub swing_new: Mat3,
    /// Heightfield: twist change `τ_D` at the joint at `c1`.
    pub change_twist: f32,
    /// Heightfield: bend axis `a` (parent-local, unit) of the joint at `c1`.
    pub bend_axis: Vec3,
    /// Heightfield: bend angle `θ ≥ 0` of the joint at `c1`.
    pub bend_angle: f32,
    /// Heightfield: the child's rotation before bending, `G = T_D R_fit` (parent-local).
    pub pre_bend: Mat3,
    /// Heightfield twist correction about the bone's own axis: `a + b f` radians at axial
    /// fraction `f` (eq. 3.3 written per bone, see [`super::heightfield`]).
    pub twist_a: f32,
    /// Slope of the twist correction.
    pub twist_b: f32,
    /// Baseline: twist offset `off(t) = −o0 (1 − α(t)) + o1 α(t)` (see [`super::baseline`]).
    pub off0: f32,
    /// Baseline: twist offset at the `c2` end.
    pub off1: f32,
}

/// Twist angle of `q` about the local X axis, in `(−π, π]`.
pub fn twist_x(q: Quat) -> f32 {
    let q = if q.w < 0.0 { -q } else { q };
    wrap(2.0 * q.x.atan2(q.w))
}

/// Twist angle of `q` about the unit axis `u`, in `(−π, π]`.
pub fn twist_about(q: Quat, u: Vec3) -> f32 {
    let q = if q.w < 0.0 { -q } else { q };
    wrap(2.0 * Vec3::new(q.x, q.y, q.z).dot(u).atan2(q.w))
}

/// Wraps an angle to `(−π, π]`.
pub fn wrap(a: f32) -> f32 {
    let mut a = a % (2.0 * PI);
    if a > PI {
        a -= 2.0 * PI;
    } else if a <= -PI {
        a += 2.0 * PI;
    }
    a
}

/// The swing part of `q` (shortest arc from X to `q X`).
pub fn swing_x(q: Quat) -> Quat {
    rotation_arc(Vec3::X, q * Vec3::X)
}

/// Fills `out` (one entry per bone) for the target skeleton `target` against the fitted one.
pub fn analyse(
    bones: &[BoneBind],
    fitted: &Skeleton,
    target: &Skeleton,
    target_posed: &crate::anatomy::Posed,
    out: &mut Vec<BoneFrame>,
) {
    let n = bones.len();
    out.resize(n, BoneFrame::default());
    for k in 0..n {
        let bb = &bones[k];
        let st = &target.bones[k];
        let shape = BoneShape::new(st.length, st.r1, st.r2);
        let q_new = target_posed.frames[k];
        let origin = target_posed.bones[k].c1;
        let rigid_q = (q_new * bb.frame.inverse()).normalize();
        let ratio = |new: f32, old: f32| if old > 1e-12 { new / old } else { 1.0 };
        let r_fit = fitted.bones[k].rotation;
        let r_new = st.rotation;
        let tau_new = twist_x(r_new);
        // Change at the joint at c1, in parent-local coordinates.
        let d = (r_new * r_fit.inverse()).normalize();
        let u = r_fit * Vec3::X;
        let change_twist = twist_about(d, u);
        let t_d = Quat::from_axis_angle(u, change_twist);
        let s_d = (d * t_d.inverse()).normalize();
        let (axis, angle) = s_d.to_axis_angle();
        let (bend_axis, bend_angle) = if angle.is_finite() && angle > 1e-6 {
            let a = if angle > PI { -axis } else { axis };
            (
                a.normalize_or(Vec3::Y),
                if angle > PI { 2.0 * PI - angle } else { angle },
            )
        } else {
            (u.any_orthonormal_vector(), 0.0)
        };
        out[k] = BoneFrame {
            rot: Mat3::from_quat(q_new),
            rot_q: q_new,
            origin,
            shape,
            radius_ratio: [ratio(st.r1, bb.shape.r1), ratio(st.r2, bb.shape.r2)],
            rigid_q,
            rigid_t: origin - rigid_q * bb.c1,
            rel_new: Mat3::from_quat(r_new),
            tau_new,
            swing_new: Mat3::from_quat(swing_x(r_new)),
            change_twist: if bb.c1_partner.is_some() {
                change_twist
            } else {
                0.0
            },
            bend_axis,
            bend_angle: if bb.c1_partner.is_some() {
                bend_angle
            } else {
                0.0
            },
            pre_bend: Mat3::from_quat((t_d * r_fit).normalize()),
            twist_a: 0.0,
            twist_b: 0.0,
            off0: 0.0,
            off1: 0.0,
        };
    }
    // Twist distributions need the neighbours' twists: a second pass.
    for k in 0..n {
        let bb = &bones[k];
        let l_k = out[k].shape.length;
        let (mut a, mut b) = (0.0, 0.0);
        let (mut o0, mut o1) = (0.0, 0.0);
        if let Some(p) = bb.c1_partner {
            let tau = out[k].change_twist;
            if bb.parent_share > 0.0 {
                // Chain continuation: the twist spreads linearly from c1 of the parent
                // (eq. 3.3 with v = c_{k−1}, w = c_{k+1}); this bone holds the part from
                // l_p/(l_p + l_k) to 1.
                let l_p = out[p].shape.length;
                let s0 = if l_p + l_k > 1e-12 {
                    l_p / (l_p + l_k)
                } else {
                    0.5
                };
                a += (s0 - 1.0) * tau;
                b -= (s0 - 1.0) * tau;
            } else {
                // Branch (or first bone of a chain): the twist spreads over the bone alone.
                a -= tau;
                b += tau;
            }
            let dtau = wrap(twist_x(target.bones[k].rotation) - twist_x(fitted.bones[k].rotation));
            o0 = (1.0 - bb.parent_share) * dtau;
        }
        if let Some(c) = bb.c2_partner {
            let share = bones[c].parent_share;
            if share > 0.0 {
                let l_c = out[c].shape.length;
                let f = if l_k + l_c > 1e-12 {
                    l_k / (l_k + l_c)
                } else {
                    0.5
                };
                b += f * out[c].change_twist;
                let dtau =
                    wrap(twist_x(target.bones[c].rotation) - twist_x(fitted.bones[c].rotation));
                o1 = share * dtau;
            }
        }
        out[k].twist_a = a;
        out[k].twist_b = b;
        out[k].off0 = o0;
        out[k].off1 = o1;
    }
}
