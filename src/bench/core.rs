//! Benchmarks of the foundation: PLY input/output, normal estimation, bone projection.

use super::{BenchResult, Entry, time_it};
use crate::anatomy::Template;
use crate::cloud::PointCloud;
use crate::cloud::normals::{NormalOptions, estimate_normals};
use crate::cloud::ply::{WriteOptions, read_ply, write_ply};
use crate::error::{Error, Result};
use crate::geometry::PreparedBone;
use crate::synth::{SynthOptions, generate};
use rayon::prelude::*;
use std::hint::black_box;
use std::path::PathBuf;
use std::sync::{Arc, OnceLock};

const MILLION: usize = 1_000_000;

/// A 1M-point synthetic human statue (seed 1), generated once per process.
fn statue_1m() -> &'static crate::synth::SynthStatue {
    static S: OnceLock<crate::synth::SynthStatue> = OnceLock::new();
    S.get_or_init(|| {
        let t = Arc::new(Template::builtin("human").expect("built-in human template"));
        generate(
            t,
            &SynthOptions {
                points: MILLION,
                seed: 1,
                ..Default::default()
            },
        )
        .expect("synthetic statue")
    })
}

fn scratch_file(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("pygmalion-bench-{}", std::process::id()));
    let _ = std::fs::create_dir_all(&dir);
    dir.join(name)
}

pub(super) fn entries() -> Vec<Entry> {
    vec![
        Entry {
            name: "ply/load_1m",
            run: ply_load_1m,
        },
        Entry {
            name: "ply/write_1m",
            run: ply_write_1m,
        },
        Entry {
            name: "normals/1m",
            run: normals_1m,
        },
        Entry {
            name: "bone/project_22x1m",
            run: project_22x1m,
        },
        Entry {
            name: "bone/project_22x1m_1t",
            run: project_22x1m_1t,
        },
    ]
}

fn ply_load_1m(runs: usize) -> Result<BenchResult> {
    let s = statue_1m();
    let path = scratch_file("load_1m.ply");
    write_ply(&path, &s.cloud, &WriteOptions::default())?;
    let mut err = None;
    let r = time_it(
        "ply/load_1m",
        s.cloud.len() as u64,
        runs,
        || match read_ply(&path) {
            Ok(c) => {
                black_box(c);
            }
            Err(e) => err = Some(e),
        },
    );
    let _ = std::fs::remove_file(&path);
    match err {
        Some(e) => Err(e.into()),
        None => Ok(r),
    }
}

fn ply_write_1m(runs: usize) -> Result<BenchResult> {
    let s = statue_1m();
    let path = scratch_file("write_1m.ply");
    let mut err = None;
    let r = time_it("ply/write_1m", s.cloud.len() as u64, runs, || {
        if let Err(e) = write_ply(&path, &s.cloud, &WriteOptions::default()) {
            err = Some(e);
        }
    });
    let _ = std::fs::remove_file(&path);
    match err {
        Some(e) => Err(e.into()),
        None => Ok(r),
    }
}

fn normals_1m(runs: usize) -> Result<BenchResult> {
    let s = statue_1m();
    let opts = NormalOptions::default();
    let mut err: Option<Error> = None;
    let r = time_it(
        "normals/1m",
        s.cloud.len() as u64,
        runs,
        || match estimate_normals(&s.cloud.positions, &opts) {
            Ok(n) => {
                black_box(n);
            }
            Err(e) => err = Some(e),
        },
    );
    match err {
        Some(e) => Err(e),
        None => Ok(r),
    }
}

/// Normal-constrained projection of every point on every bone; returns the summed distance so
/// the work cannot be optimised away.
fn project_all(bones: &[PreparedBone], cloud: &PointCloud, parallel: bool) -> f64 {
    let normals = cloud
        .normals
        .as_ref()
        .expect("synthetic statues have normals");
    let per_chunk = |(ps, ns): (&[crate::math::Vec3], &[crate::math::Vec3])| -> f64 {
        let mut acc = 0.0f64;
        for (p, n) in ps.iter().zip(ns) {
            for b in bones {
                acc += b.project_constrained(*p, *n).distance as f64;
            }
        }
        acc
    };
    const CHUNK: usize = 4096;
    if parallel {
        cloud
            .positions
            .par_chunks(CHUNK)
            .zip(normals.par_chunks(CHUNK))
            .map(per_chunk)
            .sum()
    } else {
        cloud
            .positions
            .chunks(CHUNK)
            .zip(normals.chunks(CHUNK))
            .map(per_chunk)
            .sum()
    }
}

fn project_bench(name: &str, runs: usize, parallel: bool) -> Result<BenchResult> {
    let s = statue_1m();
    let bones: Vec<PreparedBone> = s.truth.pose().bones.iter().map(|b| b.prepare()).collect();
    let pairs = (bones.len() * s.cloud.len()) as u64;
    let body = || {
        black_box(project_all(&bones, &s.cloud, parallel));
    };
    let mut r = if parallel {
        time_it(name, pairs, runs, body)
    } else {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .map_err(|e| Error::input(format!("cannot build a one-thread pool: {e}")))?;
        pool.install(|| time_it(name, pairs, runs, body))
    };
    r.extra
        .insert("projections_per_s".into(), pairs as f64 / r.median_s);
    Ok(r)
}

fn project_22x1m(runs: usize) -> Result<BenchResult> {
    project_bench("bone/project_22x1m", runs, true)
}

fn project_22x1m_1t(runs: usize) -> Result<BenchResult> {
    project_bench("bone/project_22x1m_1t", runs, false)
}
