//! Point-set skinning: re-pose and re-proportion a registered statue without a mesh, keeping
//! every scanned point (thesis ch. 3 and 4; paper 001 §4).
//!
//! ## Pipeline
//!
//! ```text
//! cloud + fitted Skeleton ──Binding::new──► Binding (per point: bone, base point, height, …)
//! Binding + target Skeleton ──deform(method)──► positions + normals (caller's buffers)
//! ```
//!
//! A *target* is any skeleton of the same template: new relative rotations (a pose, see
//! [`crate::anatomy::pose`]), new lengths and radii (a morphology change), a new root
//! placement. The fitted skeleton itself gives every point back; a rigid motion of the root
//! moves the cloud rigidly.
//!
//! | stage | module |
//! |---|---|
//! | base points encoded per bone so they survive length/radius changes | [`surface`] |
//! | the binding (structure of arrays, built in parallel) | [`binding`] |
//! | per-frame analysis of the target: frames, twist/bend per joint | [`frame`] |
//! | baseline skinning (ch. 4, Algorithm 3) — the default | [`baseline`] |
//! | heightfield skinning with anisotropic bend + twist (ch. 3, Algorithm 2, eq. 3.1–3.3) | [`heightfield`] |
//! | LBS and DQS with the weights of eq. 3.1, for comparison (fig. 3.5–3.8) | [`blend`] |
//! | eight-lane `f32` vectors for the per-frame kernels | [`lanes`] |
//! | saving and loading a binding (kiosk cache) | [`store`] |
//!
//! ## Per frame
//!
//! [`Binding::deform`] analyses the target once per bone (into a reusable [`Scratch`]), then
//! runs over the points in parallel chunks, each point reading only its own arrays and its
//! bones' frame data and writing its own output slot: no allocation once the scratch (and, for
//! heightfield skinning, each worker thread's block buffer) has grown, and the output does not
//! depend on the thread count.
//!
//! Baseline and heightfield skinning tabulate per frame what depends only on the pose (the
//! baseline grid; the bend grid of each joint side) so that the per-point work is a few table
//! reads and a fixed sequence of arithmetic, done eight points at a time in [`lanes`] vectors;
//! the per-point layouts they read are derived from the binding's arrays at bind and at load
//! time and never saved (see each module's "Speed" notes). Measured with
//! `pygmalion bench --only skin` (500k points, every joint bent, twisted and lengthened).

pub mod baseline;
pub mod binding;
pub mod blend;
pub mod frame;
pub mod heightfield;
pub mod lanes;
pub mod store;
pub mod surface;

pub use binding::Binding;

use crate::anatomy::{Posed, Skeleton};
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::math::Vec3;
use frame::BoneFrame;
use rayon::prelude::*;
use std::fmt;
use std::str::FromStr;

/// A skinning method.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Baseline skinning (thesis ch. 4, Algorithm 3). The default.
    #[default]
    Baseline,
    /// Heightfield skinning with anisotropic bend and twist weights (thesis ch. 3, Algorithm 2).
    Heightfield,
    /// Linear blend skinning with the Gaussian weights of eq. 3.1 (comparison).
    Lbs,
    /// Dual-quaternion skinning with the Gaussian weights of eq. 3.1 (comparison).
    Dqs,
}

impl Method {
    /// Every method, the default first.
    pub const ALL: [Method; 4] = [
        Method::Baseline,
        Method::Heightfield,
        Method::Lbs,
        Method::Dqs,
    ];

    /// The method's name on the command line and in configuration files.
    pub fn name(self) -> &'static str {
        match self {
            Method::Baseline => "baseline",
            Method::Heightfield => "heightfield",
            Method::Lbs => "lbs",
            Method::Dqs => "dqs",
        }
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Method {
    type Err = Error;
    fn from_str(s: &str) -> Result<Method> {
        Method::ALL
            .into_iter()
            .find(|m| m.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| {
                Error::input(format!(
                    "unknown skinning method '{s}' (expected baseline, heightfield, lbs or dqs)"
                ))
            })
    }
}

/// Per-frame working memory of [`Binding::deform`]; reuse it between calls (it only grows).
#[derive(Default)]
pub struct Scratch {
    posed: Option<Posed>,
    frames: Vec<BoneFrame>,
    tables: baseline::Tables,
    hf: heightfield::Tables,
}

impl Binding {
    /// Writes the points (and normals) of the statue re-posed as `target` (same template as
    /// the fitted skeleton; new rotations, lengths and radii allowed) into the caller's buffers
    /// (each of length [`Binding::len`]). Allocation-free once `scratch` has grown; parallel
    /// over points.
    ///
    /// Errors: a target of another template, non-finite or non-positive sizes, buffers of the
    /// wrong length.
    pub fn deform(
        &self,
        target: &Skeleton,
        method: Method,
        scratch: &mut Scratch,
        out_positions: &mut [Vec3],
        out_normals: &mut [Vec3],
    ) -> Result<()> {
        let n = self.len();
        if out_positions.len() != n || out_normals.len() != n {
            return Err(Error::input(format!(
                "deform: output buffers hold {} positions and {} normals for {n} points",
                out_positions.len(),
                out_normals.len()
            )));
        }
        if !std::sync::Arc::ptr_eq(&target.template, &self.fitted.template)
            && (target.template.name != self.fitted.template.name
                || target.bones.len() != self.fitted.bones.len())
        {
            return Err(Error::input(format!(
                "deform: the pose is for template '{}' but the statue is fitted with '{}'",
                target.template.name, self.fitted.template.name
            )));
        }
        if target.bones.len() != self.fitted.bones.len() {
            return Err(Error::input(
                "deform: the pose has the wrong number of bones",
            ));
        }
        binding::check_skeleton(target, "pose")?;
        let posed = scratch.posed.get_or_insert_with(|| Posed {
            bones: Vec::new(),
            frames: Vec::new(),
            joints: Vec::new(),
        });
        target.pose_into(posed);
        frame::analyse(
            &self.bones,
            &self.fitted,
            target,
            posed,
            &mut scratch.frames,
        );
        let frames = &scratch.frames;
        let pts = &self.points;
        let bones = &self.bones;
        let (op, on) = (out_positions, out_normals);
        match method {
            Method::Lbs => run(op, on, |i| blend::lbs_point(i, pts, frames)),
            Method::Dqs => run(op, on, |i| blend::dqs_point(i, pts, frames)),
            Method::Baseline => {
                baseline::build_tables(
                    frames,
                    bones,
                    Some(&self.fit_grid_normals),
                    &mut scratch.tables,
                );
                baseline::deform(pts, &self.bl_rigid, frames, &scratch.tables, op, on);
            }
            Method::Heightfield => {
                heightfield::build_tables(bones, frames, &self.hf, &mut scratch.hf);
                heightfield::deform(&self.hf, &scratch.hf, op, on);
            }
        }
        self.place_base(target, op, on);
        Ok(())
    }

    /// Heightfield skinning evaluated point by point with the bend iteration of Algorithm 2
    /// (no bend tables, slow): the reference that [`Method::Heightfield`]'s tables approximate
    /// (see [`heightfield`]), for tests. Same errors as [`Binding::deform`].
    pub fn deform_heightfield_reference(&self, target: &Skeleton) -> Result<PointCloud> {
        let mut pos = vec![Vec3::ZERO; self.len()];
        let mut nrm = vec![Vec3::ZERO; self.len()];
        let mut scratch = Scratch::default();
        self.deform(
            target,
            Method::Heightfield,
            &mut scratch,
            &mut pos,
            &mut nrm,
        )?;
        let (pts, bones, frames, tb) = (&self.points, &self.bones, &scratch.frames, &scratch.hf);
        run(&mut pos, &mut nrm, |i| {
            heightfield::reference_point(i, pts, bones, frames, tb)
        });
        self.place_base(target, &mut pos, &mut nrm);
        Ok(PointCloud::with_normals(pos, nrm))
    }

    /// Convenience: [`Binding::deform`] into a new cloud (colours are the caller's to copy).
    pub fn deform_cloud(&self, target: &Skeleton, method: Method) -> Result<PointCloud> {
        let mut pos = vec![Vec3::ZERO; self.len()];
        let mut nrm = vec![Vec3::ZERO; self.len()];
        self.deform(target, method, &mut Scratch::default(), &mut pos, &mut nrm)?;
        Ok(PointCloud::with_normals(pos, nrm))
    }
}

/// Runs `f` over every point in parallel chunks, writing position and normal.
fn run<F: Fn(usize) -> (Vec3, Vec3) + Sync>(positions: &mut [Vec3], normals: &mut [Vec3], f: F) {
    const CHUNK: usize = 4096;
    positions
        .par_chunks_mut(CHUNK)
        .zip(normals.par_chunks_mut(CHUNK))
        .enumerate()
        .for_each(|(c, (ps, ns))| {
            let base = c * CHUNK;
            for (j, (p, n)) in ps.iter_mut().zip(ns.iter_mut()).enumerate() {
                (*p, *n) = f(base + j);
            }
        });
}
