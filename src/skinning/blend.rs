//! The comparison methods of thesis fig. 3.5–3.8: linear blend skinning (LBS) and
//! dual-quaternion skinning (DQS, Kavan et al. 2007) applied directly to the points, with the
//! Gaussian weights of eq. 3.1 (isotropic `ε'_r`, computed at the base points, so the two
//! methods and ours differ only in how the weights are used).
//!
//! Each bone moves rigidly from its fitted frame to its new one (`x ↦ q x + t`); a point blends
//! its own bone's motion with its partner's. A change of a bone's length moves its children but
//! does not stretch its own points, and radii changes are ignored: these are the classic
//! methods, without the sphere-mesh's intrinsic parameters.

use super::binding::{NONE, PointData};
use super::frame::BoneFrame;
use crate::math::{Quat, Vec3};

/// LBS for point `i`.
#[inline]
pub fn lbs_point(i: usize, pts: &PointData, frames: &[BoneFrame]) -> (Vec3, Vec3) {
    let k = pts.bone[i] as usize;
    let p = pts.position[i];
    let fk = &frames[k];
    let n = fk.rot * pts.normal[i];
    let xk = fk.rigid_q * p + fk.rigid_t;
    let m = pts.partner[i];
    let w = pts.weight[i];
    if m == NONE || w <= 0.0 {
        return (xk, n);
    }
    let fm = &frames[m as usize];
    let xm = fm.rigid_q * p + fm.rigid_t;
    // The point's normal in world at the fitted pose, moved by the partner.
    let n_world = fk.rigid_q.inverse() * n;
    let nm = fm.rigid_q * n_world;
    (
        xk * (1.0 - w) + xm * w,
        (n * (1.0 - w) + nm * w).normalize_or(n),
    )
}

/// A unit dual quaternion `(real, dual)` of the rigid map `x ↦ q x + t`.
#[inline]
fn dual(q: Quat, t: Vec3) -> (Quat, Quat) {
    let tq = Quat::from_xyzw(t.x, t.y, t.z, 0.0);
    (q, (tq * q) * 0.5)
}

/// DQS for point `i`.
#[inline]
pub fn dqs_point(i: usize, pts: &PointData, frames: &[BoneFrame]) -> (Vec3, Vec3) {
    let k = pts.bone[i] as usize;
    let p = pts.position[i];
    let fk = &frames[k];
    let m = pts.partner[i];
    let w = pts.weight[i];
    let n_world = fk.rigid_q.inverse() * (fk.rot * pts.normal[i]);
    if m == NONE || w <= 0.0 {
        return (fk.rigid_q * p + fk.rigid_t, fk.rigid_q * n_world);
    }
    let fm = &frames[m as usize];
    let (r0, d0) = dual(fk.rigid_q, fk.rigid_t);
    let (mut r1, mut d1) = dual(fm.rigid_q, fm.rigid_t);
    // Shortest path: blend quaternions in the same hemisphere.
    if r0.dot(r1) < 0.0 {
        r1 = -r1;
        d1 = -d1;
    }
    let r = r0 * (1.0 - w) + r1 * w;
    let d = d0 * (1.0 - w) + d1 * w;
    let len = r.length();
    if !(len > 1e-12) {
        return (fk.rigid_q * p + fk.rigid_t, fk.rigid_q * n_world);
    }
    let (r, d) = (r / len, d / len);
    // Translation t = 2 d r*.
    let tq = (d * r.conjugate()) * 2.0;
    let t = Vec3::new(tq.x, tq.y, tq.z);
    (r * p + t, r * n_world)
}
