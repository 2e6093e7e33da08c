//! The registration's working units (our choice; the papers are silent): the cloud is brought to a
//! size between 1 and 2 by a power of two, and shifted to the origin when it lies far from it,
//! before anything is fitted; the fit is mapped back at the end.
//!
//! FAKIR's numbers are not all relative to the statue: the projection's degenerate cases, the
//! solver's guards and its tolerances hold absolute constants, and `f32` squares overflow past
//! about 10¹⁹. Measured before this frame on one synthetic statue (seed 5, 6000 points,
//! `synth --rigid --height 1.7`, joint error 0.29% of its height) written in other units:
//! ×10⁻⁶ 6.4%, ×10⁻⁹ 6.8% (a hand taken lost), ×10⁻¹² 11.3%, ×10¹⁸ no end in 5 minutes;
//! random points near 10³⁰, whose squares pass `f32`'s range, made it panic. In the working
//! units: 0.72%, 0.69%, 0.41% and 0.51% (these scales are not powers of two, so the cloud
//! differs from the metre one by rounding, and FAKIR's path with it). Scaled by a power of
//! two, a cloud registers bit for bit like the original (a test checks it at 2⁻⁴⁰ and 2¹⁰⁰);
//! at everyday scales the fits are as before this frame (the bust and *Zenobia* at ×2, the
//! *Venus* at ×½, TOSCA *Victoria 0* at ×2⁻⁷: the same `FIT.json` bytes; the *Dancing Faun*
//! in millimetres: the same mean distance and lost set; the papers' chain of length 140: the
//! same work units and joint error).
//!
//! **Choices.**
//! - The scale is a power of two, `2⁻ᵏ` with the largest bounding-box edge times it in `[1, 2)`
//!   (`k` kept within ±125, so the scale stays a normal `f32`: only clouds smaller than about 2⁻¹²⁴
//!   or larger than 2¹²⁶ keep a working size outside `[1, 2)`). Multiplying by it is exact in
//!   floating point, so a cloud already of that size (every synthetic statue of height 1.7 the
//!   tests and benchmarks use: their largest edges lie between 1.2 and 1.9) is registered bit for
//!   bit as before, and mapping the fit back loses nothing.
//! - The shift is the bounding box's centre, applied only when that centre lies farther from the
//!   origin than [`FAR`] (2¹⁴) times the largest edge: there `f32` steps are coarser than about
//!   2⁻¹⁰ of the statue's size, and the bones' joints, held in the cloud's coordinates, cannot move
//!   by less. The same statue (seed 5) moved 10⁵ along each axis (about 1.1 × 10⁵ times its size)
//!   had fitted with 29% joint error, and fits with 0.84% shifted; moved 10⁴ it had fitted with
//!   0.68% unshifted. Nearer clouds are not shifted: a shift is not exact in floating point, and
//!   FAKIR's path through its many starts and checks turns rounding differences into different fits
//!   (moved 10³ and shifted for a trial, the same statue came out at 5.4% instead of 1.0%).
//! - The options that hold positions or sizes (a given anchor, a given skeleton) are mapped in, and
//!   everything of the fit that is a length or a position is mapped out: the skeleton, the mean
//!   distance, the candidates' scores and the base's heights.

use super::Init;
use super::registration::{Fit, RegistrationOptions};
use crate::anatomy::Skeleton;
use crate::cloud::{Aabb, PointCloud};
use crate::math::Vec3;

/// A cloud whose bounding-box centre lies farther from the origin than this many times its
/// largest edge is shifted to the origin (see the module docs).
pub const FAR: f64 = 16384.0;

/// The map from a cloud's units to the registration's: `x ↦ (x − shift) · scale`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorkingFrame {
    /// Subtracted first (zero unless the cloud lies far from the origin).
    pub shift: Vec3,
    /// A power of two.
    pub scale: f32,
}

impl WorkingFrame {
    /// The frame of a cloud of these positions (see the module docs). `None` when there is
    /// nothing to map: no point, a coordinate that is not finite, all points at one place
    /// (the registration reports these itself).
    pub fn of(positions: &[Vec3]) -> Option<WorkingFrame> {
        if !positions.iter().all(|p| p.is_finite()) {
            return None;
        }
        let bb = Aabb::of(positions)?;
        // In f64: the edges of a box spanning most of f32's range overflow f32.
        let (lo, hi) = (bb.min.as_dvec3(), bb.max.as_dvec3());
        let size = (hi - lo).max_element();
        if !(size > 0.0) {
            return None;
        }
        // 2^-k with size · 2^-k in [1, 2); within f32's normal exponents.
        let k = size.log2().floor().clamp(-125.0, 125.0) as i32;
        let mut scale = 2f64.powi(-k);
        // log2 may round across a power of two.
        if size * scale >= 2.0 {
            scale *= 0.5;
        } else if size * scale < 1.0 {
            scale *= 2.0;
        }
        let centre = 0.5 * (lo + hi);
        let shift = if centre.length() > FAR * size {
            centre.as_vec3()
        } else {
            Vec3::ZERO
        };
        Some(WorkingFrame {
            shift,
            scale: scale as f32,
        })
    }

    /// True when the map changes nothing.
    pub fn is_identity(&self) -> bool {
        self.shift == Vec3::ZERO && self.scale == 1.0
    }

    /// A position in the registration's units.
    pub fn to_working(&self, p: Vec3) -> Vec3 {
        (p - self.shift) * self.scale
    }

    /// A position back in the cloud's units.
    pub fn from_working(&self, p: Vec3) -> Vec3 {
        p / self.scale + self.shift
    }

    /// The cloud in the registration's units (normals and colours as they are).
    pub fn cloud_to_working(&self, cloud: &PointCloud) -> PointCloud {
        PointCloud {
            positions: cloud
                .positions
                .iter()
                .map(|&p| self.to_working(p))
                .collect(),
            normals: cloud.normals.clone(),
            colors: None,
        }
    }

    /// A skeleton in the registration's units.
    pub fn skeleton_to_working(&self, s: &Skeleton) -> Skeleton {
        let mut s = s.clone();
        s.root_position = self.to_working(s.root_position);
        s.scale_sizes(self.scale);
        s
    }

    /// A skeleton back in the cloud's units.
    pub fn skeleton_from_working(&self, s: &Skeleton) -> Skeleton {
        let mut s = s.clone();
        s.root_position = self.from_working(s.root_position);
        s.scale_sizes(1.0 / self.scale);
        s
    }

    /// The options with their positions and sizes in the registration's units.
    pub fn options_to_working(&self, opts: &RegistrationOptions) -> RegistrationOptions {
        let mut o = opts.clone();
        o.init = match &opts.init {
            Init::Anchor { anchor, up } => Init::Anchor {
                anchor: self.to_working(*anchor),
                up: *up,
            },
            Init::Given(s) => Init::Given(self.skeleton_to_working(s)),
            other => other.clone(),
        };
        o
    }

    /// A fit made in the registration's units, back in the cloud's.
    pub fn fit_from_working(&self, mut fit: Fit) -> Fit {
        let back = 1.0 / self.scale as f64;
        fit.skeleton = self.skeleton_from_working(&fit.skeleton);
        fit.mean_distance *= back;
        for d in &mut fit.candidate_distances {
            *d *= back;
        }
        if let Some(b) = &mut fit.base {
            let lift = self.shift.dot(b.up);
            b.top = b.top / self.scale + lift;
            b.cut = b.cut / self.scale + lift;
        }
        fit
    }
}
