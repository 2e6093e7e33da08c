//! `pygmalion register`: FAKIR on a PLY file, with a progress line on a terminal, a one-line
//! summary, the fitted skeleton as JSON and optionally the labelled cloud.

use crate::anatomy::Template;
use crate::cloud::ply::{WriteOptions, write_ply};
use crate::error::{Error, Result};
use crate::fakir::{Fit, Init, Registration, RegistrationOptions};
use crate::math::Vec3;
use serde::Serialize;
use std::collections::BTreeMap;
use std::io::{IsTerminal, Write};
use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Parses `x,y,z`.
pub fn parse_vec3(s: &str, what: &str) -> Result<Vec3> {
    let v: Vec<f32> = s
        .split(',')
        .map(|x| x.trim().parse::<f32>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| Error::input(format!("invalid {what} '{s}': expected x,y,z")))?;
    if v.len() != 3 || !v.iter().all(|x| x.is_finite()) {
        return Err(Error::input(format!(
            "invalid {what} '{s}': expected three finite numbers x,y,z"
        )));
    }
    Ok(Vec3::new(v[0], v[1], v[2]))
}

/// Parses an axis: `x`, `-y`, `+z` or `x,y,z`.
pub fn parse_axis(s: &str) -> Result<Vec3> {
    let v = match s.trim().to_ascii_lowercase().as_str() {
        "x" | "+x" => Vec3::X,
        "-x" => -Vec3::X,
        "y" | "+y" => Vec3::Y,
        "-y" => -Vec3::Y,
        "z" | "+z" => Vec3::Z,
        "-z" => -Vec3::Z,
        other => parse_vec3(other, "up axis")?,
    };
    if v.length() < 1e-9 {
        return Err(Error::input("the up axis must not be zero"));
    }
    Ok(v.normalize())
}

/// What `FIT.json` holds.
#[derive(Serialize)]
pub struct FitReport {
    pub template: String,
    pub source: String,
    pub joints: BTreeMap<String, [f32; 3]>,
    pub bones: Vec<crate::anatomy::skeleton::BoneJson>,
    pub root_rotation: [f32; 4],
    pub block_scale: f32,
    pub mean_distance: f64,
    pub points: usize,
    pub iterations: usize,
    pub work_units: u64,
    /// Points assigned to each bone.
    pub assignment: BTreeMap<String, usize>,
    /// The base (plinth) set aside, if one was found; its points are labelled
    /// `4294967295` (`u32::MAX`) in `--labels`.
    pub base: Option<BaseReport>,
    /// Bones of lost limbs: completed to their expected size and pose (the healthy mirror
    /// limb's, or the template's), no point assigned.
    pub missing: Vec<String>,
    /// Bones only partly there ([`crate::fakir::Fit::partial`]): partly covered by the scan,
    /// or the bone a lost limb broke on, its support not reaching through it.
    pub partial: Vec<String>,
    /// The support of every bone: covered share of its surface, axial reach. Its `missing`
    /// and `partial` flags are the verdicts of the two lists above, so the report never
    /// contradicts itself: coverage alone would flag a trunk bone under 0.4 (a head the fit
    /// laid badly) missing, but the trunk carries the figure and is never lost, so such a
    /// bone is listed partial; and a lost bone's coverage may lie anywhere (the lost-limb
    /// rules of `crate::fakir::registration` also take covered bones laid over another part).
    pub support: Vec<crate::fakir::support::BoneSupport>,
}

/// The base in `FIT.json`.
#[derive(Serialize)]
pub struct BaseReport {
    /// Normal of its top face (the statue's up).
    pub up: [f32; 3],
    /// Height of the top face along `up` (`p·up`).
    pub top: f32,
    /// The base is every point with `p·up` below this (the top plus a margin).
    pub cut: f32,
    /// Its points.
    pub points: usize,
}

impl FitReport {
    /// The report of a fit.
    pub fn new(fit: &Fit, source: &Path) -> Self {
        let j = fit.skeleton.to_json();
        let t = &fit.skeleton.template;
        // The support's flags as the registration decided (see `FitReport::support`).
        let partial = fit.partial();
        let support: Vec<crate::fakir::support::BoneSupport> = fit
            .support
            .iter()
            .enumerate()
            .map(|(k, s)| crate::fakir::support::BoneSupport {
                missing: fit.missing.get(k).copied().unwrap_or(false),
                partial: partial[k],
                ..s.clone()
            })
            .collect();
        FitReport {
            template: j.template,
            source: source.display().to_string(),
            joints: j.joints,
            bones: j.bones,
            root_rotation: fit.skeleton.root_rotation.to_array(),
            block_scale: fit.skeleton.block_scale,
            mean_distance: fit.mean_distance,
            points: fit.labels.len(),
            iterations: fit.iterations,
            work_units: fit.units,
            assignment: t
                .bones
                .iter()
                .zip(&fit.bone_counts)
                .map(|(b, c)| (b.name.clone(), *c))
                .collect(),
            base: fit.base.as_ref().map(|b| BaseReport {
                up: b.up.to_array(),
                top: b.top,
                cut: b.cut,
                points: b.points.len(),
            }),
            missing: fit.missing_names().into_iter().map(String::from).collect(),
            partial: support
                .iter()
                .filter(|s| s.partial)
                .map(|s| s.bone.clone())
                .collect(),
            support,
        }
    }
}

/// The command's arguments (as the CLI parsed them).
pub struct Args<'a> {
    pub input: &'a Path,
    pub template: &'a str,
    pub anchor: Option<&'a str>,
    pub up: Option<&'a str>,
    pub start: Option<&'a Path>,
    pub out: Option<&'a Path>,
    pub labels: Option<&'a Path>,
    pub drop_non_finite: bool,
    pub keep_base: bool,
    /// Bones known lost, comma-separated (`RegistrationOptions::lost`).
    pub missing: Option<&'a str>,
    /// The direction the figure faces (`RegistrationOptions::front`), as `parse_axis` reads.
    pub front: Option<&'a str>,
}

/// Runs the command.
pub fn run(a: &Args) -> Result<()> {
    let template = Arc::new(Template::resolve(a.template)?);
    let lost = parse_bone_list(a.missing);
    // A wrong bone name is reported before the cloud is read.
    crate::fakir::support::lost_from_names(&template, &lost)?;
    let cloud = super::read(a.input, a.drop_non_finite)?;
    let up = a.up.map(parse_axis).transpose()?;
    let init = match (
        a.anchor.map(|x| parse_vec3(x, "anchor")).transpose()?,
        up,
        a.start,
    ) {
        (_, _, Some(path)) => Init::Given(crate::anatomy::Skeleton::load_json(
            path,
            Some(template.clone()),
        )?),
        (Some(anchor), up, None) => Init::Anchor { anchor, up },
        (None, Some(up), None) => Init::Up(up),
        (None, None, None) => Init::Auto,
    };
    let opts = RegistrationOptions {
        init,
        base: if a.keep_base {
            None
        } else {
            RegistrationOptions::default().base
        },
        lost,
        front: a.front.map(parse_axis).transpose()?,
        ..Default::default()
    };
    fit(a.input, Arc::new(cloud), template, opts, a.out, a.labels)
}

/// The names of a comma-separated bone list (`None` or empty: none).
pub fn parse_bone_list(list: Option<&str>) -> Vec<String> {
    list.map(|l| {
        l.split(',')
            .map(str::trim)
            .filter(|n| !n.is_empty())
            .map(String::from)
            .collect()
    })
    .unwrap_or_default()
}

/// Runs `reg` in steps of 100 ms, drawing the progress line on the terminal between steps.
fn stepped(reg: &mut Registration, start: Instant) -> Result<crate::fakir::Fit> {
    while !reg.is_done() {
        let p = reg.step(Duration::from_millis(100));
        if !p.done {
            eprint!(
                "\r{:<5} {:<14} {:<10} iteration {} pass {} level {}  mean distance {:.5}  {:>8} units  {:5.1} s ",
                p.attempt.name(),
                p.activity.phase,
                p.activity.chain.as_deref().unwrap_or(""),
                p.activity.iteration,
                p.activity.pass,
                p.activity.level,
                p.mean_distance,
                p.units,
                start.elapsed().as_secs_f64()
            );
            let _ = std::io::stderr().flush();
        }
    }
    eprintln!();
    reg.take_result().expect("finished")
}

/// Fits `template` to a cloud already read from `input` (named in messages), with the
/// progress line, the summary and the optional outputs of `register`.
pub fn fit(
    input: &Path,
    cloud: Arc<crate::cloud::PointCloud>,
    template: Arc<Template>,
    opts: RegistrationOptions,
    out: Option<&Path>,
    labels: Option<&Path>,
) -> Result<()> {
    let mut reg = Registration::new(cloud.clone(), template.clone(), opts)
        .map_err(|e| Error::input(format!("{}: {e}", input.display())))?;
    let start = Instant::now();
    let tty = std::io::stderr().is_terminal();
    // Without a terminal there is no progress line to draw: the registration runs without
    // pauses, which lets it register its finalists at the same time (same result).
    let result = if tty {
        stepped(&mut reg, start)
    } else {
        reg.run_to_convergence()
    };
    let fit = result.map_err(|e| {
        Error::input(format!(
            "{}: cannot fit the '{}' template: {e}",
            input.display(),
            template.name
        ))
    })?;
    let secs = start.elapsed().as_secs_f64();
    if let Some(path) = out {
        let text = serde_json::to_string_pretty(&FitReport::new(&fit, input))
            .expect("fit report serialises");
        std::fs::write(path, text).map_err(|e| Error::Io {
            path: path.to_path_buf(),
            source: e,
        })?;
    }
    if let Some(path) = labels {
        write_ply(
            path,
            &cloud,
            &WriteOptions {
                labels: Some(("bone".into(), fit.labels.clone())),
                ..Default::default()
            },
        )?;
    }
    let base = match &fit.base {
        Some(b) => format!(" (a base of {} points set aside)", b.points.len()),
        None => String::new(),
    };
    let lost = fit.missing_names();
    let lost = if lost.is_empty() {
        String::new()
    } else {
        format!(", missing: {}", lost.join(", "))
    };
    println!(
        "{}: '{}' fitted to {} points{base} in {} iterations, mean distance {:.6} ({:.3}% of the statue's size){lost}, {:.2} s",
        input.display(),
        template.name,
        fit.labels.len() - fit.base.as_ref().map_or(0, |b| b.points.len()),
        fit.iterations,
        fit.mean_distance,
        100.0 * fit.mean_distance / cloud.scale_estimate().max(1e-30) as f64,
        secs
    );
    Ok(())
}
