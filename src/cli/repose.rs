//! `pygmalion repose`: a registered statue re-posed (and optionally re-proportioned) by
//! point-set skinning, written as a PLY file with a one-line summary.
//!
//! Everything cheap that can fail on bad input (the method, the pose, the proportions, the
//! fitted skeleton) is checked before the cloud is read and bound, so a typo in a pose file is
//! reported at once, naming the file.

use crate::anatomy::{Pose, Proportions, Skeleton, Template};
use crate::cloud::ply::{WriteOptions, write_ply};
use crate::error::{Error, Result};
use crate::skinning::{Binding, Method};
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

/// The command's arguments.
pub struct Args<'a> {
    /// The statue (PLY).
    pub input: &'a Path,
    /// The fitted skeleton (JSON written by `register --out`).
    pub fit: &'a Path,
    /// A built-in pose name or a pose file.
    pub pose: &'a str,
    /// The skinning method's name.
    pub method: &'a str,
    /// A proportions file.
    pub proportions: Option<&'a Path>,
    /// A template name or file, when the fit's template is not built in.
    pub template: Option<&'a str>,
    /// The output PLY.
    pub out: &'a Path,
    /// Drop points with NaN/inf coordinates instead of refusing the file.
    pub drop_non_finite: bool,
}

/// The target skeleton: the fit at `fit` re-posed by `pose` and re-proportioned by
/// `proportions`. Returns the fitted skeleton too.
pub fn target(
    fit: &Path,
    pose: &str,
    proportions: Option<&Path>,
    template: Option<&str>,
) -> Result<(Skeleton, Skeleton)> {
    let pose_source = Pose::source_path(pose);
    let pose = Pose::resolve(pose)?;
    let proportions = proportions
        .map(|p| Proportions::load(p).map(|x| (x, p)))
        .transpose()?;
    let template = template
        .map(|t| Template::resolve(t).map(Arc::new))
        .transpose()?;
    let fitted = Skeleton::load_json(fit, template)?;
    let mut target = pose.apply(&fitted, &pose_source)?;
    if let Some((p, source)) = proportions {
        target = p.apply(&target, source)?;
    }
    Ok((fitted, target))
}

/// Runs the command.
pub fn run(args: &Args) -> Result<()> {
    let method: Method = args.method.parse()?;
    let (fitted, target) = target(args.fit, args.pose, args.proportions, args.template)?;
    let (cloud, estimated) = super::read_with_normals(args.input, args.drop_non_finite)?;
    let start = Instant::now();
    let binding = Binding::new_on_base(&cloud, &fitted)
        .map_err(|e| Error::input(format!("{}: cannot bind: {e}", args.input.display())))?;
    let bind_secs = start.elapsed().as_secs_f64();
    let start = Instant::now();
    let mut out = binding.deform_cloud(&target, method)?;
    let deform_secs = start.elapsed().as_secs_f64();
    out.colors = cloud.colors.clone();
    write_ply(args.out, &out, &WriteOptions::default())?;
    println!(
        "{}: {} points{} re-posed to '{}' with {method} (bind {bind_secs:.3} s, deform {deform_secs:.3} s) → {}",
        args.input.display(),
        out.len(),
        if estimated {
            " (normals estimated)"
        } else {
            ""
        },
        args.pose,
        args.out.display()
    );
    Ok(())
}
