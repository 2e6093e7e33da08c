//! `pygmalion bench`: the project's benchmarks, with stable names so results can be compared
//! over time.
//!
//! ## Method
//! Each benchmark prepares its input once (not timed), runs its body once to warm caches and
//! the rayon pool (not counted), then times `runs` further executions with
//! [`std::time::Instant`] and reports the minimum, median and maximum wall-clock seconds.
//! Inputs are synthetic statues from [`crate::synth`] with fixed seeds, so every run measures
//! the same work. Build with `--release`; the figures are whole-machine wall time (all cores
//! used by rayon unless the name ends in `_1t`, which runs on a one-thread pool).
//!
//! The GPU benchmarks (`render/…`, see [`render`]) run only when `--only` names them: they need
//! a GPU and take minutes on a software renderer.
//!
//! With `--json`, one JSON object per line: `name`, `n` (problem size), `runs`, `median_s`,
//! `min_s`, `max_s`, plus benchmark-specific figures in `extra`.

mod core;
mod fakir;
mod kiosk;
pub mod render;
mod restore;
mod skin;

use crate::error::Result;
use serde::Serialize;
use std::collections::BTreeMap;
use std::time::Instant;

/// One benchmark's figures.
#[derive(Clone, Debug, Serialize)]
pub struct BenchResult {
    pub name: String,
    /// Problem size (points, or bone × point pairs; see each benchmark).
    pub n: u64,
    pub runs: usize,
    pub median_s: f64,
    pub min_s: f64,
    pub max_s: f64,
    /// Benchmark-specific figures (e.g. throughput).
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub extra: BTreeMap<String, f64>,
}

/// A registered benchmark: a stable name and a function that prepares its input and returns
/// the timed body.
pub struct Entry {
    pub name: &'static str,
    pub run: fn(usize) -> Result<BenchResult>,
}

/// Every benchmark, in a stable order.
pub fn entries() -> Vec<Entry> {
    let mut e = core::entries();
    e.extend(fakir::entries());
    e.extend(skin::entries());
    e.extend(restore::entries());
    e.extend(kiosk::entries());
    e
}

/// The benchmarks that need a GPU (run only when `--only` names them).
pub fn gpu_entries() -> Vec<Entry> {
    render::entries()
}

/// Times `body` once for warm-up and then `runs` times; `n` is the problem size.
pub fn time_it(name: &str, n: u64, runs: usize, mut body: impl FnMut()) -> BenchResult {
    body();
    let runs = runs.max(1);
    let mut times: Vec<f64> = (0..runs)
        .map(|_| {
            let t = Instant::now();
            body();
            t.elapsed().as_secs_f64()
        })
        .collect();
    summarise(name, n, &mut times)
}

/// Minimum, median and maximum of measured seconds (`times` is sorted in place; not empty).
pub fn summarise(name: &str, n: u64, times: &mut [f64]) -> BenchResult {
    times.sort_by(f64::total_cmp);
    let runs = times.len();
    let median = if runs % 2 == 1 {
        times[runs / 2]
    } else {
        0.5 * (times[runs / 2 - 1] + times[runs / 2])
    };
    BenchResult {
        name: name.to_string(),
        n,
        runs,
        median_s: median,
        min_s: times[0],
        max_s: times[runs - 1],
        extra: BTreeMap::new(),
    }
}

/// Runs the benchmarks whose name starts with `only` (all when `None`).
pub fn run(
    only: Option<&str>,
    runs: usize,
    mut report: impl FnMut(&BenchResult),
) -> Result<Vec<BenchResult>> {
    let mut out = Vec::new();
    // The GPU benchmarks only when `--only` selects (see the module docs).
    let gpu = if only.is_some() {
        gpu_entries()
    } else {
        Vec::new()
    };
    for e in entries().into_iter().chain(gpu) {
        if only.is_some_and(|p| !e.name.starts_with(p)) {
            continue;
        }
        let r = (e.run)(runs)?;
        report(&r);
        out.push(r);
    }
    Ok(out)
}

/// The CLI front end: prints a table, or JSON lines with `json`.
pub fn run_cli(json: bool, only: Option<&str>, runs: usize) -> Result<()> {
    if !json {
        println!(
            "{:<28} {:>10} {:>5} {:>11} {:>11} {:>11}  extra",
            "name", "n", "runs", "median_s", "min_s", "max_s"
        );
    }
    let results = run(only, runs, |r| {
        if json {
            println!(
                "{}",
                serde_json::to_string(r).expect("bench result serialises")
            );
        } else {
            let extra: Vec<String> = r
                .extra
                .iter()
                .map(|(k, v)| format!("{k}={v:.4e}"))
                .collect();
            println!(
                "{:<28} {:>10} {:>5} {:>11.6} {:>11.6} {:>11.6}  {}",
                r.name,
                r.n,
                r.runs,
                r.median_s,
                r.min_s,
                r.max_s,
                extra.join(" ")
            );
        }
    })?;
    if results.is_empty() {
        return Err(crate::Error::input(format!(
            "no benchmark matches '{}' (names: {})",
            only.unwrap_or(""),
            entries()
                .iter()
                .chain(&gpu_entries())
                .map(|e| e.name)
                .collect::<Vec<_>>()
                .join(", ")
        )));
    }
    Ok(())
}
