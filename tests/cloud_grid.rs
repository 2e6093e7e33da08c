//! Tests of `cloud::grid`: the near-point grid answers as a brute-force search does, its "yes"
//! at [`BELOW`] times a slack implies that the k-d tree's nearest point is within the slack,
//! and clouds it cannot hold give `None`.

use pygmalion::cloud::grid::{BELOW, NearGrid};
use pygmalion::math::Vec3;
use pygmalion::rng::Rng;

/// Points on a sphere of radius 1 and a few inside it (a surface and some clutter).
fn points(n: usize, seed: u64) -> Vec<Vec3> {
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|i| {
            let u = rng.unit_vector();
            if i % 10 == 0 { u * rng.f32() } else { u }
        })
        .collect()
}

fn brute(points: &[Vec3], q: Vec3, r: f32) -> bool {
    points.iter().any(|p| (*p - q).length_squared() <= r * r)
}

#[test]
fn the_grid_answers_as_a_brute_force_search() {
    let pts = points(3_000, 5);
    let cell = 0.05;
    let grid = NearGrid::new(&pts, cell).unwrap();
    let mut rng = Rng::new(9);
    let (mut yes, mut misses, mut total) = (0usize, 0usize, 0usize);
    for _ in 0..20_000 {
        // Queries around the sphere, inside and outside the points' box.
        let q = rng.unit_vector() * rng.range(0.0, 1.3);
        let r = rng.range(0.0, cell);
        let (g, b) = (grid.any_within(q, r), brute(&pts, q, r));
        assert!(!g || b, "a yes with no point within {r} of {q}");
        yes += g as usize;
        misses += (b && !g) as usize;
        total += 1;
    }
    // Misses can come only from rounding at cell borders (see the module docs): none expected
    // in 20,000 random queries; a handful would still be correct, only slower.
    assert!(yes > 1_000, "too few near queries to mean anything: {yes}");
    assert!(misses <= 2, "{misses} misses in {total} queries");
    // A radius over one cell is refused (the tree decides).
    assert!(!grid.any_within(pts[0], 2.0 * cell));
    assert!(!grid.any_within(Vec3::splat(f32::NAN), 0.01));
}

#[test]
fn a_yes_below_the_slack_means_the_nearest_point_is_within_it() {
    let pts = points(2_000, 3);
    let slack = 0.04;
    let grid = NearGrid::new(&pts, slack).unwrap();
    let arr: Vec<[f32; 3]> = pts.iter().map(|p| p.to_array()).collect();
    let tree = kiddo::ImmutableKdTree::<f32, 3>::new_from_slice(&arr).unwrap();
    let mut rng = Rng::new(11);
    let mut checked = 0;
    for _ in 0..20_000 {
        let q = rng.unit_vector() * rng.range(0.9, 1.1);
        if grid.within_below(q, slack) {
            let nn = tree
                .query(&q.to_array())
                .nearest_one::<kiddo::SquaredEuclidean<f32>>()
                .execute();
            let l = (q - pts[nn.item as usize]).length();
            assert!(l <= slack, "nearest at {l} > {slack}");
            checked += 1;
        }
    }
    assert!(checked > 1_000, "{checked}");
    const { assert!(BELOW < 1.0 && BELOW > 0.9999) };
}

#[test]
fn clouds_the_grid_cannot_hold_give_none() {
    assert!(NearGrid::new(&[], 1.0).is_none());
    let pts = points(100, 1);
    assert!(NearGrid::new(&pts, 0.0).is_none());
    assert!(NearGrid::new(&pts, f32::NAN).is_none());
    let mut bad = pts.clone();
    bad.push(Vec3::new(f32::INFINITY, 0.0, 0.0));
    assert!(NearGrid::new(&bad, 0.1).is_none());
    // A far outlier would need far more cells than points.
    let mut far = pts.clone();
    far.push(Vec3::splat(1.0e4));
    assert!(NearGrid::new(&far, 0.01).is_none());
    // One point: one cell, found from anywhere within the cell size.
    let one = NearGrid::new(&[Vec3::ONE], 0.5).unwrap();
    assert!(one.any_within(Vec3::new(1.4, 1.0, 1.0), 0.45));
    assert!(!one.any_within(Vec3::new(1.6, 1.0, 1.0), 0.5));
}
