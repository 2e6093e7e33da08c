//! The command line: thin wrappers over the core.
//!
//! | command | what it does |
//! |---|---|
//! | `kiosk [--config FILE] [--screenshot OUT.png --frames N] [--pose NAME]` (default) | the museum kiosk in a window (see `src/cli/kiosk.rs`) |
//! | `demo` | loads the bundled demo statue, reports on it and fits the human anatomy |
//! | `info FILE` | points, bounding box, normals present, scale estimate |
//! | `normals IN OUT [--k 16]` | (re-)estimates oriented normals, points kept in input order |
//! | `synth OUT.ply [--template human] [--seed N] ...` | a synthetic statue with ground truth |
//! | `compare FIT.json TRUTH.json` | distances between a fitted skeleton and a ground truth of any topology (see [`crate::anatomy::compare`]) |
//! | `register IN.ply [--template human] [--anchor x,y,z] [--up y] [--out FIT.json] [--labels OUT.ply]` | FAKIR registration |
//! | `repose IN.ply FIT.json POSE [--method baseline] [--proportions FILE] --out OUT.ply` | re-poses a registered statue by point-set skinning (see [`crate::anatomy::pose`], [`crate::skinning`]) |
//! | `picture IN.ply --out OUT.png [--fit FIT.json] [--bones] [--pose POSE] [--method M\|all]` | a CPU-rendered picture; with a pose, one panel per method |
//! | `film IN.ply FIT.json POSE --out DIR [--frames N] [--method M] [--orbit DEG]` | PNG frames of the statue moving into a pose |
//! | `restore TARGET.ply --donor A.ply [--donor B.ply …] [--parts auto\|NAMES] [--pose donor\|keep] --out OUT.ply [--report R.json]` | virtual restoration by part combination |
//! | `bench [--json] [--only PREFIX]` | the benchmarks (see [`crate::bench`]) |

use crate::anatomy::Template;
use crate::cloud::normals::{NormalOptions, estimate_normals, normal_agreement};
use crate::cloud::ply::{ReadOptions, WriteOptions, read_ply_with, write_ply};
use crate::error::{Error, Result};
use crate::synth::{Cut, SynthOptions, generate};
use clap::{Parser, Subcommand};

mod kiosk;
mod picture;
pub(crate) mod register;
pub use register::FitReport;
mod repose;
mod restore;
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

/// The bundled demo statue (CC BY 4.0, see `assets/ATTRIBUTION.md`).
pub const DEMO_STATUE: &str = "assets/statues/statue_dancing_girl_thorvaldsen.ply";

#[derive(Parser, Debug)]
#[command(
    name = "pygmalion",
    version,
    about = "Bring scanned statues to life: anatomy registration (FAKIR), point-set skinning, virtual restoration."
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// The museum kiosk in a window: the statues of the configuration, their anatomy fitted
    /// live (cached in the configuration's cache folder), poses by touch (the default command).
    Kiosk {
        /// The kiosk configuration (a missing or wrong file falls back to the defaults).
        #[arg(long, default_value = "config/kiosk.toml")]
        config: PathBuf,
        /// Capture the window into this PNG once the statue is drawn, then exit.
        #[arg(long)]
        screenshot: Option<PathBuf>,
        /// Frames to run before the screenshot.
        #[arg(long, default_value_t = 30)]
        frames: u32,
        /// Request this pose once the statue is ready.
        #[arg(long)]
        pose: Option<String>,
    },
    /// Loads the bundled demo statue, reports on it and fits the human anatomy.
    Demo,
    /// Points, bounding box, normals present, scale estimate of a PLY file.
    Info {
        file: PathBuf,
        /// Drop points with NaN/inf coordinates instead of refusing the file.
        #[arg(long)]
        drop_non_finite: bool,
    },
    /// Estimates oriented normals (kNN PCA + propagation) and writes the cloud with them.
    Normals {
        input: PathBuf,
        output: PathBuf,
        /// Neighbours per point.
        #[arg(long, default_value_t = 16)]
        k: usize,
        /// Drop points with NaN/inf coordinates instead of refusing the file.
        #[arg(long)]
        drop_non_finite: bool,
    },
    /// Writes a synthetic statue sampled on a posed template, with its ground truth.
    Synth {
        output: PathBuf,
        /// Template name (human, centaur, quadruped, mermaid) or template file.
        #[arg(long, default_value = "human")]
        template: String,
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Number of points sampled on the envelope (before cuts).
        #[arg(long, default_value_t = 30_000)]
        points: usize,
        /// Keep the rest pose (no random pose).
        #[arg(long)]
        rest: bool,
        /// Proportion jitter per bone (0.3 = ±30%).
        #[arg(long, default_value_t = 0.3)]
        jitter: f32,
        /// Left and right limbs get the same proportions (a stylised figure, not a lopsided one).
        #[arg(long)]
        symmetric: bool,
        /// Height of the statue.
        #[arg(long, default_value_t = 1.0)]
        height: f32,
        /// Gaussian noise along the normal (standard deviation).
        #[arg(long, default_value_t = 0.0)]
        noise: f32,
        /// Poisson noise parameter λ.
        #[arg(long, default_value_t = 0.0)]
        poisson: f32,
        /// A cut: `bone:NAME[@FRACTION]` or `plane:px,py,pz,nx,ny,nz` (repeatable).
        #[arg(long)]
        cut: Vec<String>,
        /// Apply a random rigid transform.
        #[arg(long)]
        rigid: bool,
        /// Add a plinth under the figure with this many points per figure point (0: none).
        #[arg(long, default_value_t = 0.0)]
        plinth: f32,
        /// Write the ground-truth skeleton (JSON) here.
        #[arg(long)]
        truth: Option<PathBuf>,
        /// Also write each point's bone index as a `bone` property.
        #[arg(long)]
        labels: bool,
    },
    /// Compares a fitted skeleton (FIT.json) with a ground-truth skeleton of any topology (a
    /// rig's joint file, a synthetic statue's truth): mean distances between the two as
    /// curves, and from each truth joint to the nearest end of a fitted bone.
    Compare { fit: PathBuf, truth: PathBuf },
    /// Fits an anatomy template to a statue with FAKIR.
    Register {
        input: PathBuf,
        /// Template name (human, centaur, quadruped, mermaid) or template file.
        #[arg(long, default_value = "human")]
        template: String,
        /// Root (pelvis) position `x,y,z` instead of the automatic placement.
        #[arg(long)]
        anchor: Option<String>,
        /// The statue's up axis: `x`, `y`, `z`, `-x`, … or `x,y,z`.
        #[arg(long)]
        up: Option<String>,
        /// Start from this skeleton (JSON from `register --out`, e.g. an earlier fit or a
        /// restorer's correction) instead of the automatic placement.
        #[arg(long, conflicts_with_all = ["anchor", "up"])]
        start: Option<PathBuf>,
        /// Write the fitted skeleton here (JSON).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Write the cloud with each point's bone index (`bone` property) here.
        #[arg(long)]
        labels: Option<PathBuf>,
        /// Drop points with NaN/inf coordinates instead of refusing the file.
        #[arg(long)]
        drop_non_finite: bool,
        /// Register every point: do not look for a base (plinth) to set aside.
        #[arg(long)]
        keep_base: bool,
        /// Bones the statue is known to have lost, comma-separated (e.g.
        /// `l_upper_arm,r_forearm`): each is left out with the bones it carries, from the
        /// start, and completed at the end. Other lost limbs are still looked for.
        #[arg(long)]
        missing: Option<String>,
        /// The direction the figure faces: `x`, `y`, `z`, `-x`, … or `x,y,z`. Only headings
        /// near it are tried (an armless torso tells only its left-right axis, by its
        /// chest's breadth).
        #[arg(long, conflicts_with = "start")]
        front: Option<String>,
    },
    /// Re-poses a registered statue by point-set skinning and writes the re-posed cloud.
    Repose {
        /// The statue (PLY); normals are estimated when the file has none.
        input: PathBuf,
        /// The fitted skeleton (JSON written by `register --out`).
        fit: PathBuf,
        /// A built-in pose (identity, rest, contrapposto, arms_raised, walking, seated,
        /// thinker) or a pose file (RON, see config/poses/).
        pose: String,
        /// Skinning method: baseline, heightfield, lbs or dqs.
        #[arg(long, default_value = "baseline")]
        method: String,
        /// A proportions file (RON, see src/anatomy/pose.rs).
        #[arg(long)]
        proportions: Option<PathBuf>,
        /// Template name or file, when the fit's template is not built in.
        #[arg(long)]
        template: Option<String>,
        /// Write the re-posed cloud here (PLY).
        #[arg(long)]
        out: PathBuf,
        /// Drop points with NaN/inf coordinates instead of refusing the file.
        #[arg(long)]
        drop_non_finite: bool,
    },
    /// A picture of a statue (CPU renderer): with --fit and --bones its fitted bones, with
    /// --pose the statue re-posed by one method or by all of them side by side.
    Picture {
        input: PathBuf,
        /// The PNG to write.
        #[arg(long)]
        out: PathBuf,
        /// The fitted skeleton (JSON from `register --out`).
        #[arg(long)]
        fit: Option<PathBuf>,
        /// A built-in pose or a pose file (needs --fit).
        #[arg(long)]
        pose: Option<String>,
        /// Skinning method, or `all` for a panel per method.
        #[arg(long, default_value = "all")]
        method: String,
        /// Draw the bones over the statue (needs --fit).
        #[arg(long)]
        bones: bool,
        /// Template name or file, when the fit's template is not built in.
        #[arg(long)]
        template: Option<String>,
        /// Width of each panel in pixels.
        #[arg(long, default_value_t = 420)]
        width: u32,
        /// Height of each panel in pixels.
        #[arg(long, default_value_t = 720)]
        height: u32,
        /// Turn the camera about the statue's up axis by this many degrees.
        #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
        turn: f32,
    },
    /// A short film (PNG frames) of a statue moving from its fitted pose to a pose.
    Film {
        input: PathBuf,
        fit: PathBuf,
        /// A built-in pose or a pose file.
        pose: String,
        /// Skinning method.
        #[arg(long, default_value = "baseline")]
        method: String,
        /// Folder for frame_0000.png, frame_0001.png, …
        #[arg(long)]
        out: PathBuf,
        /// Number of frames.
        #[arg(long, default_value_t = 48)]
        frames: usize,
        /// Turn of the camera over the film, degrees.
        #[arg(long, default_value_t = 30.0, allow_hyphen_values = true)]
        orbit: f32,
        /// Template name or file, when the fit's template is not built in.
        #[arg(long)]
        template: Option<String>,
        /// Frame width in pixels.
        #[arg(long, default_value_t = 640)]
        width: u32,
        /// Frame height in pixels.
        #[arg(long, default_value_t = 720)]
        height: u32,
    },
    /// Completes a broken statue with parts of donor statues (virtual restoration).
    Restore {
        target: PathBuf,
        /// A donor statue (repeatable; the first that has a part gives it).
        #[arg(long = "donor", required = true)]
        donors: Vec<PathBuf>,
        /// The target's fitted skeleton (otherwise fitted now).
        #[arg(long)]
        fit: Option<PathBuf>,
        /// The donors' fitted skeletons, in the order of --donor (otherwise fitted now).
        #[arg(long = "donor-fit")]
        donor_fits: Vec<PathBuf>,
        /// `auto` (the missing bones) or bone names separated by commas.
        #[arg(long, default_value = "auto")]
        parts: String,
        /// Pose of the restored part: `donor` (its own pose) or `keep` (the target's guess).
        #[arg(long, default_value = "donor")]
        pose: String,
        /// Template name or file.
        #[arg(long, default_value = "human")]
        template: String,
        /// The statues' up axis, when known (x, y, z, -y, …).
        #[arg(long)]
        up: Option<String>,
        /// The restored statue (PLY with a `provenance` property).
        #[arg(long)]
        out: PathBuf,
        /// A JSON report of what replaced what.
        #[arg(long)]
        report: Option<PathBuf>,
    },
    /// Runs the benchmarks.
    Bench {
        /// One JSON object per line.
        #[arg(long)]
        json: bool,
        /// Only benchmarks whose name starts with this prefix.
        #[arg(long)]
        only: Option<String>,
        /// Timed runs per benchmark.
        #[arg(long, default_value_t = 5)]
        runs: usize,
    },
}

/// Runs the command line with these arguments (the first is the program name).
pub fn run<I, T>(args: I) -> Result<()>
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    let cli = match Cli::try_parse_from(args) {
        Ok(c) => c,
        Err(e) => {
            // --help and --version are not errors.
            let code = e.exit_code();
            let _ = e.print();
            if code == 0 {
                return Ok(());
            }
            return Err(Error::input("invalid command line (see above)"));
        }
    };
    let command = cli.command.unwrap_or_else(|| Command::Kiosk {
        config: PathBuf::from("config/kiosk.toml"),
        screenshot: None,
        frames: 30,
        pose: None,
    });
    match command {
        Command::Kiosk {
            config,
            screenshot,
            frames,
            pose,
        } => kiosk::run(&kiosk::KioskArgs {
            config: &config,
            screenshot: screenshot.as_deref(),
            frames,
            pose: pose.as_deref(),
        }),
        Command::Demo => demo(),
        Command::Info {
            file,
            drop_non_finite,
        } => info(&file, drop_non_finite),
        Command::Normals {
            input,
            output,
            k,
            drop_non_finite,
        } => normals(&input, &output, k, drop_non_finite),
        Command::Synth {
            output,
            template,
            seed,
            points,
            rest,
            jitter,
            symmetric,
            height,
            noise,
            poisson,
            cut,
            rigid,
            plinth,
            truth,
            labels,
        } => {
            let cuts = cut
                .iter()
                .map(|c| Cut::parse(c))
                .collect::<Result<Vec<_>>>()?;
            let opts = SynthOptions {
                points,
                seed,
                random_pose: !rest,
                proportion_jitter: jitter,
                symmetric,
                height,
                noise_sigma: noise,
                poisson_lambda: poisson,
                cuts,
                rigid,
                plinth_share: plinth,
            };
            synth(&output, &template, &opts, truth.as_deref(), labels)
        }
        Command::Register {
            input,
            template,
            anchor,
            up,
            start,
            out,
            labels,
            drop_non_finite,
            keep_base,
            missing,
            front,
        } => crate::cli::register::run(&crate::cli::register::Args {
            input: &input,
            template: &template,
            anchor: anchor.as_deref(),
            up: up.as_deref(),
            start: start.as_deref(),
            out: out.as_deref(),
            labels: labels.as_deref(),
            drop_non_finite,
            keep_base,
            missing: missing.as_deref(),
            front: front.as_deref(),
        }),
        Command::Compare { fit, truth } => compare(&fit, &truth),
        Command::Repose {
            input,
            fit,
            pose,
            method,
            proportions,
            template,
            out,
            drop_non_finite,
        } => repose::run(&repose::Args {
            input: &input,
            fit: &fit,
            pose: &pose,
            method: &method,
            proportions: proportions.as_deref(),
            template: template.as_deref(),
            out: &out,
            drop_non_finite,
        }),
        Command::Picture {
            input,
            out,
            fit,
            pose,
            method,
            bones,
            template,
            width,
            height,
            turn,
        } => picture::run_picture(&picture::PictureArgs {
            input: &input,
            out: &out,
            fit: fit.as_deref(),
            pose: pose.as_deref(),
            method: &method,
            bones,
            template: template.as_deref(),
            width,
            height,
            turn_deg: turn,
        }),
        Command::Film {
            input,
            fit,
            pose,
            method,
            out,
            frames,
            orbit,
            template,
            width,
            height,
        } => picture::run_film(&picture::FilmArgs {
            input: &input,
            fit: &fit,
            pose: &pose,
            method: &method,
            out_dir: &out,
            frames,
            orbit_deg: orbit,
            template: template.as_deref(),
            width,
            height,
        }),
        Command::Restore {
            target,
            donors,
            fit,
            donor_fits,
            parts,
            pose,
            template,
            up,
            out,
            report,
        } => restore::run(&restore::Args {
            target: &target,
            donors: &donors,
            fit: fit.as_deref(),
            donor_fits: &donor_fits,
            parts: &parts,
            pose: &pose,
            template: &template,
            up: up.as_deref(),
            out: &out,
            report: report.as_deref(),
        }),
        Command::Bench { json, only, runs } => crate::bench::run_cli(json, only.as_deref(), runs),
    }
}

pub(crate) fn read(path: &Path, drop_non_finite: bool) -> Result<crate::cloud::PointCloud> {
    Ok(read_ply_with(
        path,
        &ReadOptions {
            drop_non_finite,
            ..Default::default()
        },
    )?)
}

/// Reads a PLY and estimates normals when it has none (the commands that bind or render need
/// them); returns whether they were estimated.
pub(crate) fn read_with_normals(
    path: &Path,
    drop_non_finite: bool,
) -> Result<(crate::cloud::PointCloud, bool)> {
    let mut cloud = read(path, drop_non_finite)?;
    let estimated = crate::cloud::normals::ensure_normals(&mut cloud, &NormalOptions::default())
        .map_err(|e| Error::input(format!("{}: {e}", path.display())))?;
    Ok((cloud, estimated))
}

/// `pygmalion compare FIT.json TRUTH.json` (see [`crate::anatomy::compare`]).
fn compare(fit: &Path, truth: &Path) -> Result<()> {
    use crate::anatomy::compare::{JointGraph, skeleton_distance};
    let (f, t) = (JointGraph::load(fit)?, JointGraph::load(truth)?);
    let d = skeleton_distance(&f, &t).ok_or_else(|| {
        Error::config(
            truth,
            "the ground truth has no extent (all its joints coincide)",
        )
    })?;
    println!(
        "{} against {}: truth → fit {:.2}%, fit → truth {:.2}%, truth joints → nearest fitted \
         bone end {:.2}% (worst {} {:.2}%) of the truth's extent {:.4}",
        fit.display(),
        truth.display(),
        d.percent(d.truth_to_fit),
        d.percent(d.fit_to_truth),
        d.percent(d.joints),
        d.worst_joint.0,
        d.percent(d.worst_joint.1),
        d.extent
    );
    Ok(())
}

fn info(path: &Path, drop_non_finite: bool) -> Result<()> {
    let t = Instant::now();
    let cloud = read(path, drop_non_finite)?;
    report(path, &cloud, t.elapsed().as_secs_f64())
}

/// Prints what `info` prints for a cloud already read.
fn report(path: &Path, cloud: &crate::cloud::PointCloud, read_secs: f64) -> Result<()> {
    let bb = cloud
        .bounding_box()
        .ok_or_else(|| Error::input(format!("{}: no points", path.display())))?;
    println!("file:        {}", path.display());
    println!("points:      {}", cloud.len());
    println!(
        "normals:     {}",
        if cloud.normals.is_some() {
            "present"
        } else {
            "absent"
        }
    );
    println!(
        "colours:     {}",
        if cloud.colors.is_some() {
            "present"
        } else {
            "absent"
        }
    );
    println!(
        "bbox min:    [{:.6}, {:.6}, {:.6}]",
        bb.min.x, bb.min.y, bb.min.z
    );
    println!(
        "bbox max:    [{:.6}, {:.6}, {:.6}]",
        bb.max.x, bb.max.y, bb.max.z
    );
    println!(
        "bbox size:   [{:.6}, {:.6}, {:.6}]",
        bb.size().x,
        bb.size().y,
        bb.size().z
    );
    println!(
        "scale:       {:.6} (largest bounding-box edge)",
        cloud.scale_estimate()
    );
    // The base (plinth) that `register` would set aside (needs the file's normals).
    match cloud.normals.as_deref().map(|n| {
        crate::cloud::base::detect_base(
            &cloud.positions,
            n,
            None,
            &crate::cloud::base::BaseOptions::default(),
        )
    }) {
        Some(Some(b)) => println!(
            "base:        {} points ({:.1}%) below the top face at {:.6} along up [{:.3}, {:.3}, {:.3}]",
            b.points.len(),
            100.0 * b.points.len() as f64 / cloud.len() as f64,
            b.top,
            b.up.x,
            b.up.y,
            b.up.z
        ),
        Some(None) => println!("base:        none found"),
        None => println!("base:        not looked for (no normals in the file)"),
    }
    println!("read in:     {read_secs:.3} s");
    Ok(())
}

fn normals(input: &Path, output: &Path, k: usize, drop_non_finite: bool) -> Result<()> {
    let mut cloud = read(input, drop_non_finite)?;
    let t = Instant::now();
    let est = estimate_normals(
        &cloud.positions,
        &NormalOptions {
            k,
            ..Default::default()
        },
    )
    .map_err(|e| Error::input(format!("{}: {e}", input.display())))?;
    let secs = t.elapsed().as_secs_f64();
    if let Some(old) = &cloud.normals {
        let a = normal_agreement(&est, old);
        println!(
            "compared with the file's normals: {:.2}% agree in sign, median angle {:.2}°",
            100.0 * a.sign_agreement,
            a.median_angle_deg
        );
    }
    cloud.normals = Some(est);
    write_ply(output, &cloud, &WriteOptions::default())?;
    println!(
        "{} points, normals estimated in {secs:.3} s (k = {k}) → {}",
        cloud.len(),
        output.display()
    );
    Ok(())
}

fn synth(
    output: &Path,
    template: &str,
    opts: &SynthOptions,
    truth: Option<&Path>,
    labels: bool,
) -> Result<()> {
    let t = Arc::new(Template::resolve(template)?);
    let s = generate(t, opts)?;
    let mut w = WriteOptions::default();
    if labels {
        w.labels = Some(("bone".to_string(), s.labels.clone()));
    }
    write_ply(output, &s.cloud, &w)?;
    if let Some(path) = truth {
        s.truth.save_json(path)?;
    }
    println!(
        "{} points of a synthetic '{}' (seed {}) → {}{}",
        s.cloud.len(),
        template,
        opts.seed,
        output.display(),
        truth
            .map(|p| format!(", ground truth → {}", p.display()))
            .unwrap_or_default()
    );
    Ok(())
}

fn demo() -> Result<()> {
    let path = Path::new(DEMO_STATUE);
    if !path.exists() {
        return Err(Error::input(format!(
            "{}: the demo statue is missing (run from the repository root)",
            path.display()
        )));
    }
    println!("Pygmalion demo: Thorvaldsen's Dancing Girl (scan by Geoffrey Marchal, CC BY 4.0)\n");
    let t = Instant::now();
    let cloud = read(path, false)?;
    report(path, &cloud, t.elapsed().as_secs_f64())?;
    let t = Instant::now();
    let est = estimate_normals(&cloud.positions, &NormalOptions::default())?;
    let secs = t.elapsed().as_secs_f64();
    if let Some(old) = &cloud.normals {
        let a = normal_agreement(&est, old);
        println!(
            "\nnormals re-estimated in {secs:.3} s: {:.2}% agree in sign with the scan's, median angle {:.2}°",
            100.0 * a.sign_agreement,
            a.median_angle_deg
        );
    }
    let template = Template::builtin("human")?;
    println!(
        "template '{}': {} bones in {} chains; fitting it with FAKIR …",
        template.name,
        template.bones.len(),
        template.chains.len()
    );
    register::fit(
        path,
        Arc::new(cloud),
        Arc::new(template),
        crate::fakir::RegistrationOptions::default(),
        None,
        None,
    )?;
    println!(
        "(try: pygmalion register {} --out FIT.json --labels LABELS.ply)",
        path.display()
    );
    Ok(())
}
