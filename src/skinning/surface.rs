//! Base points in a bone's own frame, encoded intrinsically so that they can be placed again
//! on the same bone after its length and radii change (Algorithm 2, step 4: "re-project on the
//! sphere-mesh" — for a base point that stays on its bone this is exact and free).
//!
//! Bone-local coordinates: origin at `c1`, X along `c1c2`, `(Y, Z)` the bone frame's other
//! axes (see [`crate::anatomy::skeleton`]). A base point is
//! * on a cap: `c_i + r_i d` with a unit direction `d`;
//! * on the cone: `(1 − s)(c1 + r1 n) + s(c2 + r2 n)` with `n = cos α e − sin α X` the cone
//!   normal for the radial unit vector `e ⊥ X` and `s ∈ [0, 1]` the fraction along the
//!   generatrix (the tangent points `c_i + r_i n` are where the cone touches the spheres).

use crate::math::Vec3;

/// The shape of a bone in its own frame: length and radii, with the cone angle.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct BoneShape {
    /// Length `|c1c2|`.
    pub length: f32,
    /// Radius at `c1`.
    pub r1: f32,
    /// Radius at `c2`.
    pub r2: f32,
    /// `sin α = (r2 − r1)/l`, clamped to `[−1, 1]`.
    pub sin_a: f32,
    /// `cos α ≥ 0`.
    pub cos_a: f32,
}

/// Which part of a bone a base point lies on (same order as [`crate::geometry::bone::Part`]).
pub const CAP1: u8 = 0;
/// The cone part.
pub const CONE: u8 = 1;
/// The cap around `c2`.
pub const CAP2: u8 = 2;

impl BoneShape {
    /// The shape of a bone of length `length` and radii `r1`, `r2`. When one sphere contains
    /// the other the cone degenerates (`cos α = 0`) and cone points collapse onto the spheres'
    /// tangent circle, which stays continuous.
    pub fn new(length: f32, r1: f32, r2: f32) -> BoneShape {
        let s = if length > 1e-12 {
            ((r2 - r1) / length).clamp(-1.0, 1.0)
        } else if r2 > r1 {
            1.0
        } else {
            -1.0
        };
        BoneShape {
            length,
            r1,
            r2,
            sin_a: s,
            cos_a: (1.0 - s * s).max(0.0).sqrt(),
        }
    }

    /// The cone normal for the radial unit vector `e` (orthogonal to X).
    #[inline]
    pub fn cone_normal(&self, e: Vec3) -> Vec3 {
        Vec3::new(-self.sin_a, self.cos_a * e.y, self.cos_a * e.z)
    }

    /// The cone normal for the azimuth `(cos ψ, sin ψ)`.
    #[inline]
    pub fn cone_normal_cs(&self, c: f32, s: f32) -> Vec3 {
        Vec3::new(-self.sin_a, self.cos_a * c, self.cos_a * s)
    }

    /// Radius of the spheres along the axis at fraction `f` of the length.
    #[inline]
    pub fn radius_at(&self, f: f32) -> f32 {
        self.r1 + (self.r2 - self.r1) * f
    }

    /// Decodes a base point: `(position, outward unit normal)` in bone-local coordinates.
    #[inline]
    pub fn decode(&self, part: u8, s: f32, dir: Vec3) -> (Vec3, Vec3) {
        match part {
            CAP1 => (self.r1 * dir, dir),
            CAP2 => (Vec3::new(self.length, 0.0, 0.0) + self.r2 * dir, dir),
            _ => {
                let n = self.cone_normal(dir);
                let a = self.r1 * n;
                let b = Vec3::new(self.length, 0.0, 0.0) + self.r2 * n;
                (a + (b - a) * s, n)
            }
        }
    }

    /// The axial fraction of a base point (0 at `c1`, 1 at `c2`, clamped), used to scale heights
    /// and to distribute twists.
    #[inline]
    pub fn axial_fraction(&self, part: u8, s: f32) -> f32 {
        match part {
            CAP1 => 0.0,
            CAP2 => 1.0,
            _ => s.clamp(0.0, 1.0),
        }
    }
}

/// Encodes a surface point `b` of the bone `shape` with outward unit normal `n` (both
/// bone-local) lying on `part`: `(s, dir)` such that [`BoneShape::decode`] gives `b` back.
pub fn encode(shape: &BoneShape, part: u8, b: Vec3, n: Vec3) -> (f32, Vec3) {
    match part {
        CAP1 | CAP2 => (0.0, n.normalize_or(Vec3::X)),
        _ => {
            let e = Vec3::new(0.0, n.y, n.z).normalize_or(Vec3::Y);
            let nc = shape.cone_normal(e);
            let a = shape.r1 * nc;
            let g = Vec3::new(shape.length, 0.0, 0.0) + shape.r2 * nc - a;
            let len2 = g.length_squared();
            let s = if len2 > 1e-24 {
                (b - a).dot(g) / len2
            } else {
                0.0
            };
            (s, e)
        }
    }
}
