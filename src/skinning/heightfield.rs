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

use super::binding::{BoneBind, NONE, PointData};
use super::frame::BoneFrame;
use crate::geometry::bone::PreparedBone;
use crate::math::Vec3;

/// Bend step (radians): 5°.
pub const BEND_STEP: f32 = 5.0 * std::f32::consts::PI / 180.0;

/// Per-bone prepared bones for one frame, in the parent's new frame.
#[derive(Clone, Debug)]
pub struct JointBones {
    /// The bone itself in its own new frame (`c1` at the origin, along X).
    pub local: PreparedBone,
    /// The bone before its bend, in its parent's new frame (`c1` at `J`).
    pub pre: PreparedBone,
    /// The bone after its bend, in its parent's new frame.
    pub post: PreparedBone,
    /// `(cos, sin)` of the twist correction at `TWIST_SAMPLES` axial fractions.
    pub twist: [[f32; 2]; TWIST_SAMPLES],
}

/// Samples of the twist correction along a bone (it is linear in the axial fraction; the
/// normalised interpolation of neighbouring samples is exact in direction to 0.02° for a
/// correction of up to 180°).
pub const TWIST_SAMPLES: usize = 17;

impl JointBones {
    /// `(cos, sin)` of the twist correction at axial fraction `f ∈ [0, 1]`.
    #[inline]
    pub fn twist_at(&self, f: f32) -> (f32, f32) {
        let u = f.clamp(0.0, 1.0) * (TWIST_SAMPLES - 1) as f32;
        let i = (u as usize).min(TWIST_SAMPLES - 2);
        let t = u - i as f32;
        let [c0, s0] = self.twist[i];
        let [c1, s1] = self.twist[i + 1];
        let (c, s) = (c0 + (c1 - c0) * t, s0 + (s1 - s0) * t);
        let inv = 1.0 / (c * c + s * s).sqrt().max(1e-12);
        (c * inv, s * inv)
    }
}

/// Rotates `v` about X by the angle of cosine `c` and sine `s`.
#[inline]
fn rot_x(v: Vec3, c: f32, s: f32) -> Vec3 {
    Vec3::new(v.x, c * v.y - s * v.z, s * v.y + c * v.z)
}

/// `(sin x, cos x)` for `|x| ≤ 5°` (a bend step) by Taylor polynomials: error below 10⁻⁹.
#[inline]
fn small_sin_cos(x: f32) -> (f32, f32) {
    let x2 = x * x;
    (
        x * (1.0 - x2 * (1.0 / 6.0) * (1.0 - x2 * (1.0 / 20.0))),
        1.0 - x2 * 0.5 * (1.0 - x2 * (1.0 / 12.0)),
    )
}

/// Deforms point `i` (output: world position and normal).
#[inline]
pub fn deform_point(
    i: usize,
    pts: &PointData,
    frames: &[BoneFrame],
    bones: &[BoneBind],
    joint_bones: &[JointBones],
) -> (Vec3, Vec3) {
    let k = pts.bone[i] as usize;
    let fk = &frames[k];
    let part = pts.part[i];
    let (b, nb) = fk.shape.decode(part, pts.s[i], pts.dir[i]);
    let f = fk.shape.axial_fraction(part, pts.s[i]);
    let hs = fk.radius_ratio[0] + (fk.radius_ratio[1] - fk.radius_ratio[0]) * f;
    let h = pts.height[i] * hs;
    let (b, nb, nl) = if fk.twist_a != 0.0 || fk.twist_b != 0.0 {
        let (c, s) = joint_bones[k].twist_at(f);
        (rot_x(b, c, s), rot_x(nb, c, s), rot_x(pts.normal[i], c, s))
    } else {
        (b, nb, pts.normal[i])
    };
    let m = pts.partner[i];
    if m != NONE {
        let m = m as usize;
        // The joint's child carries the bend.
        let (pp, cc) = if bones[k].parent == Some(m) {
            (m, k)
        } else {
            (k, m)
        };
        let fc = &frames[cc];
        if fc.bend_angle > 1e-5
            && let Some(r) = bend(k == pp, b, nl, h, pp, cc, fc, bones, frames, joint_bones)
        {
            let fp = &frames[pp];
            return (fp.rot * r.0 + fp.origin, (fp.rot * r.1).normalize_or(r.1));
        }
    }
    let x = b + h * nb;
    (fk.rot * x + fk.origin, (fk.rot * nl).normalize_or(nl))
}

/// The bend of a point near the joint between `pp` (parent) and `cc` (child), in the parent's
/// new frame: `None` when the point is on the concave side (it then follows its own bone).
#[allow(clippy::too_many_arguments)]
#[inline]
fn bend(
    on_parent: bool,
    b: Vec3,
    nl: Vec3,
    h: f32,
    pp: usize,
    cc: usize,
    fc: &BoneFrame,
    bones: &[BoneBind],
    frames: &[BoneFrame],
    jb: &[JointBones],
) -> Option<(Vec3, Vec3)> {
    let j = Vec3::new(frames[pp].shape.length, 0.0, 0.0);
    let a = fc.bend_axis;
    let (x0, u, nl) = if on_parent {
        (b, Vec3::X, nl)
    } else {
        let g = fc.pre_bend;
        (j + g * b, g * Vec3::X, g * nl)
    };
    // Anisotropy: radial direction of the point about its own bone's axis against the
    // direction the bones' axes turn towards.
    let rel = x0 - j;
    let radial = rel - rel.dot(u) * u;
    let inside = a.cross(u);
    let cos_ab = radial
        .normalize_or(Vec3::ZERO)
        .dot(inside.normalize_or(Vec3::ZERO));
    if cos_ab >= 0.0 {
        return None;
    }
    let ratio = 0.5 * (frames[pp].radius_ratio[1] + fc.radius_ratio[0]);
    let eps = bones[cc].eps * ratio * (-cos_ab);
    let sigma2 = (eps / 3.0).powi(2).max(1e-30);
    let theta = fc.bend_angle;
    let steps = (theta / BEND_STEP).ceil().max(1.0) as usize;
    let dt = theta / steps as f32;
    // The point turns on a circle about the axis `a` through J.
    let z = rel.dot(a);
    let w = rel - z * a;
    let aw = a.cross(w);
    let centre = j + z * a;
    // (cos, sin) of the point's angle φ and of φ − ψ (ψ the child's angle so far).
    let (mut cp, mut sp) = (1.0f32, 0.0f32);
    let (mut cq, mut sq) = (1.0f32, 0.0f32);
    let mut phi = 0.0f32;
    let parent = &jb[pp].local;
    let child = &jb[cc].pre;
    for _ in 0..steps {
        let pos_p = centre + w * cp + aw * sp;
        let pos_c = centre + w * cq + aw * sq;
        let dp = parent.sdf_fast(pos_p).max(0.0);
        let dc = child.sdf_fast(pos_c).max(0.0);
        let e = ((dc * dc - dp * dp) / (2.0 * sigma2)).clamp(-60.0, 60.0);
        let wc = 1.0 / (1.0 + e.exp());
        let step = wc * dt;
        phi += step;
        // φ += wc δ; φ − ψ += (wc − 1) δ.
        let (s1, c1) = small_sin_cos(step);
        (cp, sp) = (cp * c1 - sp * s1, sp * c1 + cp * s1);
        let back = step - dt;
        let (s2, c2) = small_sin_cos(back);
        (cq, sq) = (cq * c2 - sq * s2, sq * c2 + cq * s2);
    }
    let x1 = centre + w * cp + aw * sp;
    // Re-project on the nearer of the two new bones (one exact projection).
    let post = &jb[cc].post;
    let best = if parent.sdf_fast(x1) <= post.sdf_fast(x1) {
        parent.project(x1)
    } else {
        post.project(x1)
    };
    let rot = crate::math::Quat::from_axis_angle(a, phi);
    Some((best.point + h * best.normal, rot * nl))
}

/// Prepares the per-bone bones of one frame (allocation-free once `out` has grown).
pub fn prepare(bones: &[BoneBind], frames: &[BoneFrame], out: &mut Vec<JointBones>) {
    use crate::geometry::Bone;
    let zero = Bone::new(Vec3::ZERO, 0.0, Vec3::X, 0.0).prepare();
    out.resize(
        frames.len(),
        JointBones {
            local: zero,
            pre: zero,
            post: zero,
            twist: [[1.0, 0.0]; TWIST_SAMPLES],
        },
    );
    for (k, f) in frames.iter().enumerate() {
        let sh = &f.shape;
        let local = Bone::new(Vec3::ZERO, sh.r1, Vec3::new(sh.length, 0.0, 0.0), sh.r2).prepare();
        let (pre, post) = match bones[k].parent {
            Some(p) => {
                let j = Vec3::new(frames[p].shape.length, 0.0, 0.0);
                let axis_pre = f.pre_bend * Vec3::X;
                let axis_post = f.rel_new * Vec3::X;
                (
                    Bone::new(j, sh.r1, j + sh.length * axis_pre, sh.r2).prepare(),
                    Bone::new(j, sh.r1, j + sh.length * axis_post, sh.r2).prepare(),
                )
            }
            None => (local, local),
        };
        let mut twist = [[1.0, 0.0]; TWIST_SAMPLES];
        for (j, t) in twist.iter_mut().enumerate() {
            let f_ = j as f32 / (TWIST_SAMPLES - 1) as f32;
            let (s, c) = (f.twist_a + f.twist_b * f_).sin_cos();
            *t = [c, s];
        }
        out[k] = JointBones {
            local,
            pre,
            post,
            twist,
        };
    }
}
