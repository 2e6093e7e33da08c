//! Tests of `cloud::base`: a plinth under a synthetic figure is found, with its up direction
//! and its points, in any orientation; figures without a plinth have none; an up hint
//! restricts the search; the bundled statues' plinths are found.

use crate::common;
use pygmalion::anatomy::Template;
use pygmalion::cloud::base::{BaseOptions, detect_base, find_along};
use pygmalion::math::Vec3;
use pygmalion::synth::{PLINTH_LABEL, SynthOptions, SynthStatue, generate};
use std::sync::Arc;

fn statue(seed: u64, plinth: f32, rigid: bool) -> SynthStatue {
    statue_of(30_000, seed, plinth, rigid)
}

fn statue_of(points: usize, seed: u64, plinth: f32, rigid: bool) -> SynthStatue {
    generate(
        Arc::new(Template::builtin("human").unwrap()),
        &SynthOptions {
            points,
            seed,
            height: 1.7,
            rigid,
            plinth_share: plinth,
            ..Default::default()
        },
    )
    .unwrap()
}

/// (plinth points found / plinth points, figure points taken / figure points).
fn recall_and_false_share(s: &SynthStatue, base: &[u32]) -> (f32, f32) {
    let plinth = s.labels.iter().filter(|&&l| l == PLINTH_LABEL).count();
    let found = base
        .iter()
        .filter(|&&i| s.labels[i as usize] == PLINTH_LABEL)
        .count();
    let wrong = base.len() - found;
    (
        found as f32 / plinth as f32,
        wrong as f32 / (s.labels.len() - plinth) as f32,
    )
}

#[test]
fn a_plinth_is_found_in_any_orientation_with_its_points() {
    // Tolerances: the up within 1° of the truth (the top face is exact; its normals are the
    // face's); every plinth point found; at most 0.5% of the figure's points taken (the
    // soles within the margin above the top face).
    for seed in 1..=6 {
        let s = statue(seed, 0.25, true);
        let truth_up = s.rigid.0 * Vec3::Y;
        let n = s.cloud.normals.as_ref().unwrap();
        let b = detect_base(&s.cloud.positions, n, None, &BaseOptions::default())
            .unwrap_or_else(|| panic!("seed {seed}: no base found"));
        let angle = b.up.dot(truth_up).clamp(-1.0, 1.0).acos().to_degrees();
        assert!(angle < 1.0, "seed {seed}: up off by {angle}°");
        let (recall, false_share) = recall_and_false_share(&s, &b.points);
        assert!(recall == 1.0, "seed {seed}: {recall} of the plinth found");
        assert!(
            false_share < 0.005,
            "seed {seed}: {false_share} of the figure taken for the base"
        );
        // The top face lies at the plinth's top (the lowest figure point), within 0.1% of the
        // height.
        let low = s
            .labels
            .iter()
            .zip(&s.cloud.positions)
            .filter(|(l, _)| **l != PLINTH_LABEL)
            .map(|(_, p)| p.dot(truth_up))
            .fold(f32::INFINITY, f32::min);
        assert!(
            (b.top - low).abs() < 1.7e-3,
            "seed {seed}: top {} vs {low}",
            b.top
        );
    }
}

#[test]
fn figures_without_a_plinth_have_no_base() {
    // Seed 23 at 6000 points is seated: the undersides of its thighs make a flat, wide,
    // upward-facing band near its bottom along one direction, which only the prism test
    // (step 6) refuses. Measured: no base on seeds 1–150 at 6000 points (and a base on every
    // one of seeds 1–60 with a plinth).
    for seed in 1..=40 {
        let s = statue_of(6_000, seed, 0.0, true);
        let n = s.cloud.normals.as_ref().unwrap();
        let b = detect_base(&s.cloud.positions, n, None, &BaseOptions::default());
        assert!(
            b.is_none(),
            "seed {seed} (6000 points): a base on a bare figure"
        );
    }
    for seed in 1..=12 {
        let s = statue(seed, 0.0, seed % 2 == 0);
        let n = s.cloud.normals.as_ref().unwrap();
        let b = detect_base(&s.cloud.positions, n, None, &BaseOptions::default());
        assert!(
            b.is_none(),
            "seed {seed}: a base of {} points found on a bare figure (band share {})",
            b.as_ref().map_or(0, |b| b.points.len()),
            b.as_ref().map_or(0.0, |b| b.band_share)
        );
    }
}

#[test]
fn an_up_hint_restricts_the_search() {
    let s = statue(3, 0.25, true);
    let up = s.rigid.0 * Vec3::Y;
    let n = s.cloud.normals.as_ref().unwrap();
    let o = BaseOptions::default();
    // A hint 20° off still finds the base, with the true up.
    let side = up.any_orthonormal_vector();
    let tilted = (up * 20f32.to_radians().cos() + side * 20f32.to_radians().sin()).normalize();
    let b = detect_base(&s.cloud.positions, n, Some(tilted), &o).expect("base");
    assert!(b.up.dot(up) > 1f32.to_radians().cos());
    // The opposite hint (the statue's head end) and a sideways one find nothing.
    assert!(detect_base(&s.cloud.positions, n, Some(-up), &o).is_none());
    assert!(detect_base(&s.cloud.positions, n, Some(side), &o).is_none());
    // Looking from the head end along -up finds no step facing down there.
    assert!(find_along(&s.cloud.positions, n, -up, &o).is_none());
}

#[test]
fn degenerate_input_gives_no_base_and_no_panic() {
    let o = BaseOptions::default();
    assert!(detect_base(&[], &[], None, &o).is_none());
    let p = vec![Vec3::ONE; 100];
    let n = vec![Vec3::Y; 100];
    assert!(detect_base(&p, &n, None, &o).is_none());
    assert!(detect_base(&p, &n, Some(Vec3::Y), &o).is_none());
    // Normals missing for some points.
    let s = statue(1, 0.25, false);
    let n = &s.cloud.normals.as_ref().unwrap()[..10];
    assert!(find_along(&s.cloud.positions, n, Vec3::Y, &o).is_none());
    // A flat square alone: every point would be base (more than `max_share`).
    let sq: Vec<Vec3> = (0..400)
        .map(|i| Vec3::new((i % 20) as f32, 0.0, (i / 20) as f32))
        .collect();
    let up = vec![Vec3::Y; 400];
    assert!(detect_base(&sq, &up, Some(Vec3::Y), &o).is_none());
}

#[test]
fn the_bundled_statues_stand_on_plinths_facing_up() {
    // The three demo scans stand on plinths, up +Y (assets/ATTRIBUTION.md, data README).
    // The base holds 10–45% of their points (measured 17–38%).
    for name in [
        "statue_dancing_girl_thorvaldsen.ply",
        "statue_dancing_faun_pompeii.ply",
        "statue_venus_de_milo_cast_incomplete.ply",
    ] {
        let c = pygmalion::cloud::ply::read_ply(common::statues_dir().join(name)).unwrap();
        let n = c.normals.as_ref().unwrap();
        let b = detect_base(&c.positions, n, None, &BaseOptions::default())
            .unwrap_or_else(|| panic!("{name}: no base"));
        assert!(
            b.up.dot(Vec3::Y) > 3f32.to_radians().cos(),
            "{name}: up {}",
            b.up
        );
        let share = b.points.len() as f32 / c.len() as f32;
        assert!((0.10..0.45).contains(&share), "{name}: base share {share}");
    }
}

#[test]
fn extended_bases_are_found_under_the_plinth_statues_only() {
    // `../shared/data` (when `PYGMALION_DATA` names it): the statues on flat plinths or socles
    // have a base facing within 20° of their file's up (+Y; the Greek sculpture is tilted
    // 16°); the rocky bases, the TOSCA shapes and the rigged meshes have none.
    let on_plinths = [
        "statue_bust_man_wreath_incomplete.ply",
        "statue_dancing_faun_pompeii.ply",
        "statue_dancing_girl_thorvaldsen.ply",
        "statue_greek_sculpture_aimatshape_tilted.ply",
        "statue_maria_barjatinskaja_thorvaldsen.ply",
        "statue_theodoric_the_great.ply",
        "statue_venus_de_milo_cast_incomplete.ply",
        "statue_zenobia_in_chains_hosmer.ply",
    ];
    let files = common::shared_plys();
    let mut plinths = 0;
    for path in &files {
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        let c = pygmalion::cloud::ply::read_ply(path).unwrap();
        let b = detect_base(
            &c.positions,
            c.normals.as_ref().unwrap(),
            None,
            &BaseOptions::default(),
        );
        if on_plinths.contains(&name.as_str()) {
            let b = b.unwrap_or_else(|| panic!("{name}: no base"));
            assert!(
                b.up.dot(Vec3::Y) > 20f32.to_radians().cos(),
                "{name}: up {}",
                b.up
            );
            plinths += 1;
        } else {
            assert!(b.is_none(), "{name}: a base where there is none");
        }
    }
    if !files.is_empty() {
        assert_eq!(
            plinths,
            on_plinths.len(),
            "plinth statues missing from the data"
        );
    }
}
