//! Benchmarks of FAKIR registration on synthetic statues (automatic initialisation for the
//! human; the papers' setting — a straight generic chain anchored at the true extremity — for
//! the chain). Each result also reports the fit's accuracy in `extra`.

use super::{BenchResult, Entry, time_it};
use crate::anatomy::{Skeleton, Template};
use crate::error::Result;
use crate::fakir::solver::{Cancelled, Pause, Solver};
use crate::fakir::{Fit, Init, Registration, RegistrationOptions, register};
use crate::math::Quat;
use crate::synth::{SynthOptions, SynthStatue, chain4, generate};
use std::sync::Arc;

pub(super) fn entries() -> Vec<Entry> {
    vec![
        Entry {
            name: "fakir/chain4_5k",
            run: chain4_5k,
        },
        Entry {
            name: "fakir/human_10k",
            run: human_10k,
        },
        Entry {
            name: "fakir/human_140k",
            run: human_140k,
        },
        Entry {
            name: "fakir/unit_100k",
            run: unit_100k,
        },
    ]
}

fn run_case(
    name: &str,
    statue: &SynthStatue,
    opts: RegistrationOptions,
    height: f32,
    runs: usize,
) -> Result<BenchResult> {
    let cloud = Arc::new(statue.cloud.clone());
    let t = statue.truth.template.clone();
    let mut last: Option<Result<Fit>> = None;
    let mut r = time_it(name, cloud.len() as u64, runs, || {
        last = Some(
            Registration::new(cloud.clone(), t.clone(), opts.clone())
                .and_then(|reg| reg.run_to_convergence()),
        );
    });
    let fit = last.expect("ran at least once")?;
    r.extra.insert("mean_distance".into(), fit.mean_distance);
    r.extra.insert(
        "joint_error_pct".into(),
        100.0 * (fit.skeleton.mean_joint_distance(&statue.truth) / height) as f64,
    );
    r.extra.insert("iterations".into(), fit.iterations as f64);
    r.extra.insert("work_units".into(), fit.units as f64);
    Ok(r)
}

fn chain4_5k(runs: usize) -> Result<BenchResult> {
    let s = chain4(5_000, 1, 0.0, 0.0, vec![])?;
    let mut init = Skeleton::rest(s.truth.template.clone());
    for b in &mut init.bones {
        b.length = 35.0;
        b.r1 = 7.0;
        b.r2 = 7.0;
    }
    init.root_rotation = Quat::from_rotation_z(0.9);
    let opts = RegistrationOptions {
        init: Init::Given(init),
        ..Default::default()
    };
    run_case("fakir/chain4_5k", &s, opts, 140.0, runs)
}

fn human(points: usize) -> Result<SynthStatue> {
    let t = Arc::new(Template::builtin("human")?);
    generate(
        t,
        &SynthOptions {
            points,
            seed: 1,
            rigid: true,
            height: 1.7,
            ..Default::default()
        },
    )
}

fn human_10k(runs: usize) -> Result<BenchResult> {
    run_case(
        "fakir/human_10k",
        &human(10_000)?,
        RegistrationOptions::default(),
        1.7,
        runs,
    )
}

fn human_140k(runs: usize) -> Result<BenchResult> {
    run_case(
        "fakir/human_140k",
        &human(140_000)?,
        RegistrationOptions::default(),
        1.7,
        runs.min(3),
    )
}

/// Records the wall time between consecutive work units.
struct UnitTimer {
    last: std::time::Instant,
    durations: Vec<f64>,
}

impl Pause for UnitTimer {
    fn unit(&mut self, _: &Solver) -> Result<(), Cancelled> {
        let now = std::time::Instant::now();
        self.durations.push((now - self.last).as_secs_f64());
        self.last = now;
        Ok(())
    }
}

/// The longest work unit of a registration of a 100k-point synthetic human (the kiosk
/// registers between frames, so no unit may take more than about 2 ms). `median_s` is the
/// whole registration; `extra` gives the longest unit and the 99th and 50th percentiles.
fn unit_100k(runs: usize) -> Result<BenchResult> {
    let statue = human(100_000)?;
    let t = statue.truth.template.clone();
    let mut durations = Vec::new();
    let mut r = time_it(
        "fakir/unit_100k",
        statue.cloud.len() as u64,
        runs.min(3),
        || {
            let mut timer = UnitTimer {
                last: std::time::Instant::now(),
                durations: Vec::new(),
            };
            let _ = register(
                &statue.cloud,
                t.clone(),
                &RegistrationOptions::default(),
                &mut timer,
            );
            durations = timer.durations;
        },
    );
    durations.sort_by(f64::total_cmp);
    let pick = |q: f64| {
        durations
            .get(((durations.len() as f64 - 1.0) * q).round() as usize)
            .copied()
            .unwrap_or(0.0)
    };
    r.extra.insert("units".into(), durations.len() as f64);
    r.extra.insert("max_unit_ms".into(), 1e3 * pick(1.0));
    r.extra.insert("p99_unit_ms".into(), 1e3 * pick(0.99));
    r.extra.insert("p50_unit_ms".into(), 1e3 * pick(0.5));
    Ok(r)
}
