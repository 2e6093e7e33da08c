//! Tests of `cloud::normals`: PCA normals with consistent outward orientation, checked on
//! analytic shapes, on the bundled statues and (extended run) on every real data file.

use std::path::Path;
use std::time::Instant;

use pygmalion::cloud::PointCloud;
use pygmalion::cloud::normals::{
    NormalAgreement, NormalOptions, ensure_normals, estimate_normals, normal_agreement,
};
use pygmalion::cloud::ply::read_ply;
use pygmalion::math::Vec3;
use pygmalion::rng::Rng;

use crate::common;

/// Positions and file normals of a data file (read with `cloud::ply::read_ply`).
fn read_xyzn(path: &Path) -> (Vec<Vec3>, Vec<Vec3>) {
    let cloud = read_ply(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let normals = cloud
        .normals
        .unwrap_or_else(|| panic!("{}: no normals", path.display()));
    (cloud.positions, normals)
}

fn sphere(rng: &mut Rng, n: usize, center: Vec3, radius: f32) -> (Vec<Vec3>, Vec<Vec3>) {
    (0..n)
        .map(|_| {
            let u = rng.unit_vector();
            (center + u * radius, u)
        })
        .unzip()
}

fn ellipsoid(rng: &mut Rng, n: usize, axes: Vec3) -> (Vec<Vec3>, Vec<Vec3>) {
    // Area-uniformity does not matter here: parametrise by the unit sphere.
    (0..n)
        .map(|_| {
            let u = rng.unit_vector();
            let p = u * axes;
            let g = (p / (axes * axes)).normalize();
            (p, g)
        })
        .unzip()
}

fn torus(rng: &mut Rng, n: usize, big: f32, small: f32) -> (Vec<Vec3>, Vec<Vec3>) {
    let mut pos = Vec::with_capacity(n);
    let mut nor = Vec::with_capacity(n);
    while pos.len() < n {
        let u = rng.range(0.0, std::f32::consts::TAU);
        let v = rng.range(0.0, std::f32::consts::TAU);
        // Rejection for area-uniform sampling.
        if rng.f32() * (big + small) > big + small * v.cos() {
            continue;
        }
        let ring = Vec3::new(u.cos(), u.sin(), 0.0);
        let nrm = ring * v.cos() + Vec3::Z * v.sin();
        pos.push(ring * big + nrm * small);
        nor.push(nrm);
    }
    (pos, nor)
}

fn check(name: &str, est: &[Vec3], reference: &[Vec3], min_sign: f64, max_angle: f64) {
    let a = normal_agreement(est, reference);
    println!(
        "{name}: sign agreement {:.4}, median angle {:.2}°",
        a.sign_agreement, a.median_angle_deg
    );
    assert!(
        a.sign_agreement >= min_sign,
        "{name}: sign agreement {} < {min_sign}",
        a.sign_agreement
    );
    assert!(
        a.median_angle_deg < max_angle,
        "{name}: median angle {} >= {max_angle}",
        a.median_angle_deg
    );
    for v in est {
        assert!(
            v.is_finite() && (v.length() - 1.0).abs() < 1e-3,
            "{name}: not unit: {v:?}"
        );
    }
}

#[test]
fn sphere_ellipsoid_torus_outward() {
    let mut rng = Rng::new(7);
    let opts = NormalOptions::default();
    let (p, n) = sphere(&mut rng, 20_000, Vec3::new(3.0, -1.0, 2.0), 2.5);
    check(
        "sphere",
        &estimate_normals(&p, &opts).unwrap(),
        &n,
        0.995,
        3.0,
    );
    let (p, n) = ellipsoid(&mut rng, 30_000, Vec3::new(3.0, 1.0, 0.5));
    check(
        "ellipsoid",
        &estimate_normals(&p, &opts).unwrap(),
        &n,
        0.995,
        3.0,
    );
    let (p, n) = torus(&mut rng, 30_000, 2.0, 0.6);
    check(
        "torus",
        &estimate_normals(&p, &opts).unwrap(),
        &n,
        0.995,
        3.0,
    );
}

#[test]
fn two_disjoint_spheres_both_outward() {
    let mut rng = Rng::new(11);
    let (mut p, mut n) = sphere(&mut rng, 8_000, Vec3::ZERO, 1.0);
    let (p2, n2) = sphere(&mut rng, 5_000, Vec3::new(4.0, 0.5, -1.0), 0.7);
    p.extend(p2);
    n.extend(n2);
    let est = estimate_normals(&p, &NormalOptions::default()).unwrap();
    check("sphere A", &est[..8_000], &n[..8_000], 0.995, 3.0);
    check("sphere B", &est[8_000..], &n[8_000..], 0.995, 3.0);
}

#[test]
fn enclosed_sphere_is_a_cavity() {
    // A hollow ball: the inner surface bounds the cavity, its normals point into it (towards
    // the centre), the outer ones outward.
    let mut rng = Rng::new(13);
    let (mut p, mut n) = sphere(&mut rng, 20_000, Vec3::ZERO, 2.0);
    let (p2, n2) = sphere(&mut rng, 8_000, Vec3::new(0.2, -0.1, 0.1), 1.0);
    p.extend(p2);
    n.extend(n2.into_iter().map(|v| -v));
    let est = estimate_normals(&p, &NormalOptions::default()).unwrap();
    check("outer surface", &est[..20_000], &n[..20_000], 0.995, 3.0);
    check("cavity surface", &est[20_000..], &n[20_000..], 0.995, 3.0);
}

#[test]
fn degenerate_neighbourhoods_are_finite() {
    // A plane with a collinear line of points sticking out and duplicated points.
    let mut p = Vec::new();
    for i in 0..40 {
        for j in 0..40 {
            p.push(Vec3::new(i as f32, j as f32, 0.0));
        }
    }
    for i in 0..30 {
        p.push(Vec3::new(100.0 + i as f32, 0.0, 0.0));
    }
    for _ in 0..25 {
        p.push(Vec3::new(-50.0, -50.0, 3.0));
    }
    let est = estimate_normals(&p, &NormalOptions::default()).unwrap();
    assert_eq!(est.len(), p.len());
    for v in &est {
        assert!(v.is_finite() && (v.length() - 1.0).abs() < 1e-3, "{v:?}");
    }
    // The plane's normals are ±z and all agree.
    let z = est[0].z.signum();
    for v in &est[..1600] {
        assert!(v.z * z > 0.99, "{v:?}");
    }
    // Purely collinear input: still no NaN.
    let line: Vec<Vec3> = (0..50)
        .map(|i| Vec3::new(i as f32, 2.0 * i as f32, 0.5))
        .collect();
    for v in estimate_normals(&line, &NormalOptions::default()).unwrap() {
        assert!(v.is_finite() && (v.length() - 1.0).abs() < 1e-3, "{v:?}");
    }
}

#[test]
fn bad_input_is_an_error() {
    let opts = NormalOptions::default();
    let mut rng = Rng::new(3);
    let (p, _) = sphere(&mut rng, 200, Vec3::ZERO, 1.0);
    assert!(estimate_normals(&[], &opts).is_err());
    assert!(estimate_normals(&p[..opts.k], &opts).is_err());
    assert!(estimate_normals(&p[..opts.k + 1], &opts).is_ok());
    let mut bad = p.clone();
    bad[17].y = f32::NAN;
    assert!(estimate_normals(&bad, &opts).is_err());
    bad[17].y = f32::INFINITY;
    assert!(estimate_normals(&bad, &opts).is_err());
    for k in [0, 1, 2] {
        assert!(estimate_normals(&p, &NormalOptions { k, ..opts.clone() }).is_err());
    }
    assert!(
        estimate_normals(
            &p,
            &NormalOptions {
                k: 3,
                ..opts.clone()
            }
        )
        .is_ok()
    );
    assert!(
        estimate_normals(
            &p,
            &NormalOptions {
                k: 500,
                ..opts.clone()
            }
        )
        .is_err()
    );
    let same = vec![Vec3::splat(1.5); 100];
    assert!(estimate_normals(&same, &opts).is_err());
}

#[test]
fn deterministic() {
    let mut rng = Rng::new(5);
    let (p, _) = torus(&mut rng, 20_000, 1.0, 0.3);
    let a = estimate_normals(&p, &NormalOptions::default()).unwrap();
    let b = estimate_normals(&p, &NormalOptions::default()).unwrap();
    let bytes = |v: &[Vec3]| {
        v.iter()
            .flat_map(|x| x.to_array())
            .map(f32::to_bits)
            .collect::<Vec<_>>()
    };
    assert_eq!(bytes(&a), bytes(&b));
}

#[test]
fn ensure_normals_only_when_missing() {
    let mut rng = Rng::new(9);
    let (p, n) = sphere(&mut rng, 2_000, Vec3::ZERO, 1.0);
    let mut cloud = PointCloud::with_normals(p.clone(), n.clone());
    assert!(!ensure_normals(&mut cloud, &NormalOptions::default()).unwrap());
    assert_eq!(cloud.normals.as_ref().unwrap(), &n);
    let mut cloud = PointCloud::from_positions(p);
    assert!(ensure_normals(&mut cloud, &NormalOptions::default()).unwrap());
    check("ensure", cloud.normals.as_ref().unwrap(), &n, 0.995, 3.0);
}

#[test]
fn agreement_definition() {
    let a = [Vec3::X, Vec3::Y, -Vec3::Z];
    let b = [Vec3::X, Vec3::Y, Vec3::Z];
    let r: NormalAgreement = normal_agreement(&a, &b);
    assert!((r.sign_agreement - 2.0 / 3.0).abs() < 1e-12);
    assert!(r.median_angle_deg.abs() < 1e-9);
}

fn run_files(files: &[std::path::PathBuf], min_sign: f64, max_angle: f64) {
    let opts = NormalOptions::default();
    let mut failures = Vec::new();
    println!(
        "{:<45} {:>7} {:>9} {:>8} {:>8}",
        "file", "n", "sign", "median°", "ms"
    );
    for f in files {
        let (pos, reference) = read_xyzn(f);
        let t = Instant::now();
        let est = estimate_normals(&pos, &opts).unwrap();
        let ms = t.elapsed().as_secs_f64() * 1e3;
        let a = normal_agreement(&est, &reference);
        let name = f.file_name().unwrap().to_string_lossy().to_string();
        println!(
            "{:<45} {:>7} {:>9.4} {:>8.2} {:>8.1}",
            name,
            pos.len(),
            a.sign_agreement,
            a.median_angle_deg,
            ms
        );
        // Some references contradict their own neighbourhood (Theodoric: 2.8% of its normals);
        // that is reported, but every file is held to the bar all the same.
        let inconsistency = reference_inconsistency(&pos, &reference);
        if inconsistency > 0.01 {
            println!(
                "  ! {name}: {:.2}% of the file's own normals point against their neighbourhood",
                100.0 * inconsistency
            );
        }
        let bar = min_sign;
        if a.sign_agreement < bar || a.median_angle_deg >= max_angle {
            failures.push(format!("{name}: {a:?} (bar {bar:.4})"));
        }
    }
    assert!(failures.is_empty(), "below target: {failures:#?}");
}

#[test]
fn bundled_statues_match_file_normals() {
    let dir = common::statues_dir();
    let files: Vec<_> = [
        "statue_dancing_girl_thorvaldsen.ply",
        "statue_dancing_faun_pompeii.ply",
        "statue_venus_de_milo_cast_incomplete.ply",
    ]
    .iter()
    .map(|f| dir.join(f))
    .collect();
    run_files(&files, 0.97, 10.0);
}

#[test]
fn extended_every_data_file_matches_file_normals() {
    let files = common::shared_plys();
    if files.is_empty() {
        return;
    }
    run_files(&files, 0.97, 10.0);
}

/// Fraction of points whose reference normal points against the mean of its 16 nearest
/// neighbours' reference normals: a measure of how self-consistent a file's normals are.
pub fn reference_inconsistency(
    pos: &[pygmalion::math::Vec3],
    reference: &[pygmalion::math::Vec3],
) -> f64 {
    use kiddo::{ImmutableKdTree, SquaredEuclidean};
    let pts: Vec<[f32; 3]> = pos.iter().map(|p| p.to_array()).collect();
    let tree: ImmutableKdTree<f32, 3> = ImmutableKdTree::new_from_slice(&pts).unwrap();
    let k = std::num::NonZeroUsize::new(17).unwrap();
    let bad = pts
        .iter()
        .enumerate()
        .filter(|(i, p)| {
            let res = tree
                .query(p)
                .nearest_n::<SquaredEuclidean<f32>>(k)
                .execute();
            let mean = res
                .iter()
                .filter(|n| n.item as usize != *i)
                .fold(pygmalion::math::Vec3::ZERO, |a, n| {
                    a + reference[n.item as usize]
                });
            mean.dot(reference[*i]) < 0.0
        })
        .count();
    bad as f64 / pos.len() as f64
}
