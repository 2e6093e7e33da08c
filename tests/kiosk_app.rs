//! The kiosk app without a window (`MinimalPlugins` + `KioskPlugin { headless: true }`):
//! a statue loads off the main thread, registers incrementally within its per-frame budget,
//! binds, animates to a preset pose; the next start comes from the cache; a corrupt file ends
//! in an error card while the app keeps running.

use bevy::prelude::*;
use pygmalion::anatomy::Template;
use pygmalion::cloud::ply::{WriteOptions, write_ply};
use pygmalion::fakir::Attempt;
use pygmalion::kiosk::config::{KioskConfig, StatueEntry};
use pygmalion::kiosk::fitting::FitWork;
use pygmalion::kiosk::ui::{fitting_percent, progress_fraction};
use pygmalion::kiosk::{
    CurrentPose, KioskPlugin, PoseRequested, SkinnedPoints, StatueCloud, StatueState,
};
use pygmalion::synth::{SynthOptions, generate};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

fn config(root: &Path, file: &str) -> KioskConfig {
    let mut c = KioskConfig {
        assets_root: root.to_path_buf(),
        cache_dir: root.join("cache"),
        statues: vec![StatueEntry {
            file: PathBuf::from(file),
            template: "human".into(),
            title: "test".into(),
            credit: String::new(),
            up: Some("y".into()),
            ..Default::default()
        }],
        ..Default::default()
    };
    c.budget.point_budget = 20_000;
    c.budget.fakir_ms_per_frame = 4.0;
    c.skinning.pose_seconds = 0.2;
    // No attract mode: under load the registration can outlast its default 60 s of idle
    // time, and its pose changes would then move the statue these tests watch.
    c.idle.attract_after_s = 86_400.0;
    c.idle.still_there_after_s = 86_400.0;
    c
}

fn app(c: KioskConfig) -> App {
    let mut app = App::new();
    app.add_plugins((
        MinimalPlugins,
        bevy::input::InputPlugin,
        KioskPlugin {
            config: c,
            headless: true,
        },
    ));
    app
}

/// Updates until `done` or the wall-clock limit; returns the frames run.
fn run_until(app: &mut App, limit: Duration, mut done: impl FnMut(&mut World) -> bool) -> usize {
    let start = Instant::now();
    let mut frames = 0;
    while start.elapsed() < limit {
        app.update();
        frames += 1;
        if done(app.world_mut()) {
            return frames;
        }
    }
    panic!("not done after {frames} frames");
}

fn state(world: &mut World) -> Option<String> {
    let mut q = world.query::<&StatueState>();
    q.iter(world).next().map(|s| format!("{s:?}"))
}

fn synth_statue(dir: &Path) {
    let t = Arc::new(Template::builtin("human").unwrap());
    let s = generate(
        t,
        &SynthOptions {
            points: 12_000,
            seed: 21,
            ..Default::default()
        },
    )
    .unwrap();
    write_ply(dir.join("statue.ply"), &s.cloud, &WriteOptions::default()).unwrap();
}

#[test]
fn a_statue_loads_fits_within_budget_binds_animates_and_is_cached() {
    let dir = crate::common::scratch("kiosk_app");
    synth_statue(&dir);
    let c = config(&dir, "statue.ply");
    let mut a = app(c.clone());
    // Loading happens off the main thread: the first frames return at once.
    let t0 = Instant::now();
    a.update();
    assert!(t0.elapsed() < Duration::from_millis(500));
    let mut poses = Vec::new();
    // The percentage a visitor reads on the status line, frame after frame.
    let mut shown: Vec<u32> = Vec::new();
    // The attempts seen, and where each one's percentages start in `shown`.
    let (mut attempts, mut starts) = (Vec::new(), Vec::new());
    // A guard against a kiosk that never gets there, not a speed target (those are the
    // bench's): the registration gets 4 ms a frame. Measured on this 2-core machine
    // (2026-12-07): 213 s alone; past 240 s, the old limit, beside a build.
    run_until(&mut a, Duration::from_secs(600), |w| {
        let mut q = w.query::<&CurrentPose>();
        if let Some(p) = q.iter(w).next() {
            let j = p.0.pose().joints[0];
            if poses.last() != Some(&j) {
                poses.push(j);
            }
        }
        let mut q = w.query::<&StatueState>();
        if let Some(state) = q.iter(w).next()
            && let Some(f) = progress_fraction(state)
        {
            // Each attempt (the whole figure, then any second registration the lost-limb
            // hypotheses ask for) has its own bar, which starts again from 0.
            if let StatueState::Fitting { attempt, .. } = state
                && attempts.last() != Some(attempt)
            {
                attempts.push(*attempt);
                starts.push(shown.len());
            }
            shown.push(fitting_percent(f));
        }
        state(w).is_some_and(|s| s == "Ready")
    });
    // The fitting percentage starts near 0, never goes back, moves in many steps, and reads
    // 100 once the fit is done (while the binding is built).
    let distinct = {
        let mut d = shown.clone();
        d.dedup();
        d.len()
    };
    println!(
        "fitting percentage over {} frames: first {:?}, last {:?}, {distinct} distinct values",
        shown.len(),
        shown.first(),
        shown.last()
    );
    assert!(shown.first().is_some_and(|&p| p <= 5), "{shown:?}");
    assert_eq!(attempts.first(), Some(&Attempt::Whole), "{attempts:?}");
    // Within each attempt the percentage never goes back (each attempt has its own kind:
    // whole, bust, pair, pair below, broken limb, broken limb again).
    starts.push(shown.len());
    for (k, w) in starts.windows(2).enumerate() {
        assert!(
            shown[w[0]..w[1]].windows(2).all(|p| p[0] <= p[1]),
            "went back within attempt {k} ({:?}): {:?}",
            attempts[k],
            &shown[w[0]..w[1]]
        );
    }
    println!("attempts: {attempts:?}");
    assert_eq!(shown.last(), Some(&100));
    assert!(distinct >= 20, "{distinct} distinct percentages: {shown:?}");
    let work = *a.world().resource::<FitWork>();
    println!(
        "registration: {} frames, {} units (at most {} in a frame), budget {} ms, largest frame {:.2} ms, {} skeleton states seen",
        work.frames,
        work.units,
        work.max_units,
        work.budget_ms,
        work.max_ms,
        poses.len()
    );
    // The frame times themselves are measured by `pygmalion bench` (fakir/unit_100k): under
    // the test runner other tests share the two cores, so a wall-clock bound here would only
    // measure the neighbours. What is asserted is that the fit was cut into frames.
    assert!(work.frames > 10, "the fit ran over many frames");
    assert!(
        work.max_units * 10 < work.units,
        "one frame ran {} of the {} work units",
        work.max_units,
        work.units
    );
    assert!(poses.len() > 5, "the skeleton was seen settling in");

    // Animate to a preset pose.
    let before = {
        let w = a.world_mut();
        let mut q = w.query::<&SkinnedPoints>();
        let p = q.iter(w).next().unwrap();
        (p.version, p.positions.clone())
    };
    a.world_mut()
        .write_message(PoseRequested("greeting".into()));
    let start = Instant::now();
    while start.elapsed() < Duration::from_millis(500) {
        a.update();
        std::thread::sleep(Duration::from_millis(10));
    }
    let w = a.world_mut();
    let mut q = w.query::<&SkinnedPoints>();
    let p = q.iter(w).next().unwrap();
    assert!(
        p.version > before.0 + 2,
        "the points were re-skinned over several frames"
    );
    let moved = p
        .positions
        .iter()
        .zip(&before.1)
        .filter(|(a, b)| (**a - **b).length() > 1e-3)
        .count();
    assert!(moved > 100, "the arm moved ({moved} points)");
    assert!(
        moved < p.positions.len() / 2,
        "the rest stayed ({moved} points)"
    );

    // The next start is immediate: from the cache, no registration.
    let mut b = app(c);
    let frames = run_until(&mut b, Duration::from_secs(60), |w| {
        state(w).is_some_and(|s| s == "Ready")
    });
    assert_eq!(b.world().resource::<FitWork>().frames, 0, "fitted again");
    println!("ready from the cache after {frames} frames");
}

#[test]
fn a_corrupt_statue_shows_an_error_and_the_app_keeps_running() {
    let dir = crate::common::scratch("kiosk_app_corrupt");
    std::fs::write(
        dir.join("broken.ply"),
        b"ply\nformat ascii 1.0\nelement vertex 5\nend_header\n1 2\n",
    )
    .unwrap();
    let mut a = app(config(&dir, "broken.ply"));
    run_until(&mut a, Duration::from_secs(30), |w| {
        state(w).is_some_and(|s| s.starts_with("Failed"))
    });
    let s = state(a.world_mut()).unwrap();
    assert!(s.contains("broken.ply"), "{s}");
    for _ in 0..20 {
        a.update();
    }
    let w = a.world_mut();
    assert_eq!(w.query::<&StatueCloud>().iter(w).count(), 0);
    // A statue outside the assets root (through a link) is refused too.
    let outside = crate::common::scratch("kiosk_app_outside");
    synth_statue(&outside);
    let link = dir.join("link.ply");
    let _ = std::fs::remove_file(&link);
    std::os::unix::fs::symlink(outside.join("statue.ply"), &link).unwrap();
    let mut a = app(config(&dir, "link.ply"));
    run_until(&mut a, Duration::from_secs(30), |w| {
        state(w).is_some_and(|s| s.starts_with("Failed"))
    });
    let s = state(a.world_mut()).unwrap();
    assert!(s.contains("outside the assets root"), "{s}");
}
