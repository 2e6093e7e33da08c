//! Rotations and frames shared by the anatomy, FAKIR and skinning.

use crate::math::{Quat, Vec3};

/// The rotation taking the unit vector `from` to the unit vector `to` by the shortest arc.
pub fn rotation_between(from: Vec3, to: Vec3) -> Quat {
    Quat::from_rotation_arc(from.normalize_or(Vec3::X), to.normalize_or(Vec3::X))
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
