//! Rotations and frames shared by the anatomy, FAKIR and skinning.

use crate::math::{Quat, Vec3};

/// The rotation taking the direction `from` to the direction `to` by the shortest arc.
///
/// Unlike `Quat::from_rotation_arc`, which returns the identity for angles below about
/// `7e-4` rad in `f32`, this keeps small rotations exact (the angle comes from the cross
/// product through `atan2`), which Levenberg–Marquardt steps and finite differences need.
pub fn rotation_arc(from: Vec3, to: Vec3) -> Quat {
    let a = from.normalize_or(Vec3::X);
    let b = to.normalize_or(Vec3::X);
    let axis = a.cross(b);
    let s = axis.length();
    let c = a.dot(b);
    if s < 1e-20 {
        if c > 0.0 {
            return Quat::IDENTITY;
        }
        // Opposite directions: half a turn about any orthogonal axis.
        return Quat::from_axis_angle(a.any_orthonormal_vector(), std::f32::consts::PI);
    }
    Quat::from_axis_angle(axis / s, s.atan2(c))
}

/// A right-handed orthonormal frame whose X axis is `axis` and whose Y axis is the part of
/// `reference` orthogonal to it (or of a fallback when `reference` is nearly parallel).
/// Bones use X as their axis (paper 001 appendix B: "x-axis aligned with c1c2").
pub fn frame_from_axis(axis: Vec3, reference: Vec3, fallback: Vec3) -> Quat {
    let x = axis.normalize_or(Vec3::X);
    let mut y = reference - reference.dot(x) * x;
    if y.length_squared() < 1e-6 {
        y = fallback - fallback.dot(x) * x;
        if y.length_squared() < 1e-6 {
            y = x.any_orthonormal_vector();
        }
    }
    let y = y.normalize();
    let z = x.cross(y);
    Quat::from_mat3(&crate::math::Mat3::from_cols(x, y, z)).normalize()
}
