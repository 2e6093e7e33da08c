//! `pygmalion restore`: complete a broken statue with parts of donor statues (see
//! [`crate::restore`]). Statues are fitted on the fly (FAKIR) unless their fits are given.
//!
//! The output PLY keeps every point of the target first, then the donors' points; its
//! `provenance` property is `source × 256 + bone` (`source` 0 for the target, `i + 1` for the
//! `i`-th donor; `bone` the template bone index), and the JSON report (`--report`) lists the
//! support of every bone, what replaced what, and the parameters used.

use crate::anatomy::{Skeleton, Template};
use crate::cloud::PointCloud;
use crate::cloud::ply::{WriteOptions, write_ply};
use crate::error::{Error, Result};
use crate::fakir::{Init, RegistrationOptions, register};
use crate::restore::transfer::PoseSource;
use crate::restore::{Donor, RestoreOptions, restore};
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

/// The command's arguments.
pub struct Args<'a> {
    pub target: &'a Path,
    pub donors: &'a [std::path::PathBuf],
    pub fit: Option<&'a Path>,
    pub donor_fits: &'a [std::path::PathBuf],
    pub parts: &'a str,
    pub pose: &'a str,
    pub template: &'a str,
    pub up: Option<&'a str>,
    pub out: &'a Path,
    pub report: Option<&'a Path>,
}

fn read(path: &Path) -> Result<PointCloud> {
    Ok(super::read_with_normals(path, false)?.0)
}

/// A statue's fit and its missing bones (see [`crate::restore::missing_bones`]): read from
/// `fit` (a `FIT.json` of `register --out`, whose `missing` list is the registration's
/// verdict; a skeleton file without one leaves it unknown), or registered now.
fn fit_or_load(
    cloud: &PointCloud,
    path: &Path,
    fit: Option<&Path>,
    template: &Arc<Template>,
    up: Option<crate::math::Vec3>,
) -> Result<(Skeleton, Option<Vec<bool>>)> {
    if let Some(f) = fit {
        let skeleton = Skeleton::load_json(f, Some(template.clone()))?;
        let missing = missing_of_fit_file(f, &skeleton.template)?;
        return Ok((skeleton, missing));
    }
    let start = Instant::now();
    let opts = RegistrationOptions {
        init: up.map(Init::Up).unwrap_or_default(),
        ..Default::default()
    };
    let fit = register(
        cloud,
        template.clone(),
        &opts,
        &mut crate::fakir::solver::NoPause,
    )
    .map_err(|e| Error::input(format!("{}: {e}", path.display())))?;
    eprintln!(
        "{}: fitted in {:.1} s (mean distance {:.4})",
        path.display(),
        start.elapsed().as_secs_f64(),
        fit.mean_distance
    );
    Ok((fit.skeleton, Some(fit.missing)))
}

/// The `missing` list of a `FIT.json` as flags over `template`'s bones (`None` when the file
/// has none). Errors name the file: unreadable JSON, a bone the template lacks.
fn missing_of_fit_file(path: &Path, template: &Template) -> Result<Option<Vec<bool>>> {
    #[derive(serde::Deserialize)]
    struct Missing {
        missing: Option<Vec<String>>,
    }
    let text = std::fs::read_to_string(path).map_err(|e| Error::Io {
        path: path.to_path_buf(),
        source: e,
    })?;
    let m: Missing = serde_json::from_str(&text)
        .map_err(|e| Error::input(format!("{}: {e}", path.display())))?;
    let Some(names) = m.missing else {
        return Ok(None);
    };
    let mut flags = vec![false; template.bones.len()];
    for n in &names {
        let k = template.bone_index(n).ok_or_else(|| {
            Error::input(format!(
                "{}: missing bone '{n}' is not in template '{}'",
                path.display(),
                template.name
            ))
        })?;
        flags[k] = true;
    }
    Ok(Some(flags))
}

/// Runs the command.
pub fn run(a: &Args) -> Result<()> {
    if a.donors.is_empty() {
        return Err(Error::input("restore: give at least one --donor statue"));
    }
    if !a.donor_fits.is_empty() && a.donor_fits.len() != a.donors.len() {
        return Err(Error::input(format!(
            "restore: {} --donor-fit for {} --donor (give one per donor, or none)",
            a.donor_fits.len(),
            a.donors.len()
        )));
    }
    let pose = match a.pose {
        "keep" => PoseSource::Keep,
        "donor" => PoseSource::Donor,
        other => {
            return Err(Error::input(format!(
                "restore: --pose must be keep or donor, not '{other}'"
            )));
        }
    };
    let parts: Vec<String> = if a.parts == "auto" {
        Vec::new()
    } else {
        a.parts.split(',').map(|s| s.trim().to_string()).collect()
    };
    let template = Arc::new(Template::resolve(a.template)?);
    let up = a.up.map(super::register::parse_axis).transpose()?;
    let target = read(a.target)?;
    let (target_fit, target_missing) = fit_or_load(&target, a.target, a.fit, &template, up)?;
    let mut donor_clouds = Vec::new();
    let mut donor_fits = Vec::new();
    let mut donor_missing = Vec::new();
    for (i, d) in a.donors.iter().enumerate() {
        let c = read(d)?;
        let (f, m) = fit_or_load(
            &c,
            d,
            a.donor_fits.get(i).map(|p| p.as_path()),
            &template,
            up,
        )?;
        donor_clouds.push(c);
        donor_fits.push(f);
        donor_missing.push(m);
    }
    let donors: Vec<Donor> = a
        .donors
        .iter()
        .zip(&donor_clouds)
        .zip(&donor_fits)
        .zip(&donor_missing)
        .map(|(((p, c), f), m)| Donor {
            name: p.display().to_string(),
            cloud: c,
            fit: f,
            missing: m.as_deref(),
        })
        .collect();
    let start = Instant::now();
    let r = restore(
        &target,
        &target_fit,
        &donors,
        &RestoreOptions {
            parts,
            target_missing,
            pose,
            ..Default::default()
        },
    )
    .map_err(|e| Error::input(format!("{}: {e}", a.target.display())))?;
    let secs = start.elapsed().as_secs_f64();
    let provenance: Vec<u32> = r
        .source
        .iter()
        .zip(&r.bone)
        .map(|(s, b)| s * 256 + b)
        .collect();
    write_ply(
        a.out,
        &r.cloud,
        &WriteOptions {
            labels: Some(("provenance".into(), provenance)),
            ..Default::default()
        },
    )?;
    if let Some(rp) = a.report {
        let text = serde_json::to_string_pretty(&r.report).expect("report serialises");
        std::fs::write(rp, text).map_err(|e| Error::Io {
            path: rp.to_path_buf(),
            source: e,
        })?;
    }
    for p in &r.report.parts {
        // A part growing from a stump says where on its first bone it starts.
        let from = if p.from > 0.0 {
            format!(" (from {:.0}% of the {})", 100.0 * p.from, p.bones[0])
        } else {
            String::new()
        };
        println!(
            "{}: restored {}{from} from {} ({} points, overlap {} points, 3δ = {:.4})",
            a.target.display(),
            p.bones.join(", "),
            p.donor,
            p.points,
            p.merge.overlap_points,
            p.merge.three_delta
        );
    }
    println!(
        "{} points ({} from donors) in {secs:.2} s → {}",
        r.cloud.len(),
        r.source.iter().filter(|&&s| s != 0).count(),
        a.out.display()
    );
    Ok(())
}
