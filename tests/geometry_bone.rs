//! Tests of `geometry::bone`: projections of points on sphere-mesh bones, property-based over
//! random bones and points with fixed seeds.

use pygmalion::geometry::{Bone, Part};
use pygmalion::math::Vec3;
use pygmalion::rng::Rng;

/// A random bone of size about 1–10 near the origin; `kind` picks ordinary cones, cylinders,
/// steep cones and thin bones.
fn random_bone(rng: &mut Rng, kind: usize) -> Bone {
    let scale = rng.range(1.0, 10.0);
    let c1 = Vec3::new(
        rng.range(-1.0, 1.0),
        rng.range(-1.0, 1.0),
        rng.range(-1.0, 1.0),
    ) * scale;
    let dir = rng.unit_vector();
    let l = scale * rng.range(0.5, 2.0);
    let c2 = c1 + dir * l;
    let (r1, r2) = match kind % 4 {
        0 => (rng.range(0.05, 0.4) * l, rng.range(0.05, 0.4) * l),
        1 => {
            let r = rng.range(0.05, 0.4) * l;
            (r, r)
        }
        2 => {
            // Steep: |r2 − r1| close to l.
            let r1 = rng.range(0.05, 0.2) * l;
            (r1, r1 + rng.range(0.6, 0.9) * l)
        }
        _ => (rng.range(0.001, 0.02) * l, rng.range(0.001, 0.02) * l),
    };
    if rng.f32() < 0.5 {
        Bone::new(c1, r1, c2, r2)
    } else {
        Bone::new(c2, r2, c1, r1)
    }
}

fn random_point_near(rng: &mut Rng, b: &Bone) -> Vec3 {
    let mid = 0.5 * (b.c1 + b.c2);
    mid + rng.unit_vector() * b.size() * rng.range(0.0, 1.5)
}

#[test]
fn surface_points_project_onto_themselves() {
    let mut rng = Rng::new(1);
    let mut worst = 0.0f32;
    for i in 0..400 {
        let bone = random_bone(&mut rng, i);
        let pb = bone.prepare();
        let tol = 1e-6 * bone.size();
        for _ in 0..100 {
            let (p, n) = pb.sample_surface(&mut rng);
            let orth = pb.project(p);
            let cons = pb.project_constrained(p, n);
            worst = worst.max((orth.point - p).length() / bone.size());
            assert!(
                (orth.point - p).length() <= tol,
                "bone {bone:?}: {p} → {} (orthogonal)",
                orth.point
            );
            assert!(
                (cons.point - p).length() <= tol,
                "bone {bone:?}: {p} → {} (constrained)",
                cons.point
            );
            assert!(orth.normal.dot(n) > 0.999, "normal {n} vs {}", orth.normal);
            assert!(!cons.flipped);
        }
    }
    println!("worst self-projection error: {worst:e} × size");
}

/// Dense surface samples of a bone (for brute-force checks).
fn dense_samples(bone: &Bone, n: usize, seed: u64) -> Vec<Vec3> {
    let pb = bone.prepare();
    let mut rng = Rng::new(seed);
    (0..n).map(|_| pb.sample_surface(&mut rng).0).collect()
}

#[test]
fn orthogonal_projection_is_the_closest_surface_point() {
    let mut rng = Rng::new(2);
    for i in 0..24 {
        let bone = random_bone(&mut rng, i);
        let samples = dense_samples(&bone, 200_000, 100 + i as u64);
        // Sampling spacing: sqrt(area / n) bounds how far the nearest sample may be.
        let spacing = (bone.area() / samples.len() as f32).sqrt();
        for _ in 0..40 {
            let p = random_point_near(&mut rng, &bone);
            let proj = bone.project(p);
            let brute = samples
                .iter()
                .map(|s| (*s - p).length())
                .fold(f32::INFINITY, f32::min);
            // The projection is on the surface ...
            assert!(bone.signed_distance(proj.point).abs() <= 1e-5 * bone.size());
            // ... never farther than the best sample, and no sample is much closer.
            assert!(
                proj.distance <= brute + 1e-5 * bone.size(),
                "bone {bone:?} p {p}: {} > brute {brute}",
                proj.distance
            );
            assert!(
                brute <= proj.distance + 2.0 * spacing,
                "bone {bone:?} p {p}: brute {brute} ≪ {}",
                proj.distance
            );
            assert!(((proj.point - p).length() - proj.distance).abs() <= 1e-5 * bone.size());
        }
    }
}

#[test]
fn signed_distance_is_negative_inside_and_positive_outside() {
    let mut rng = Rng::new(3);
    for i in 0..200 {
        let bone = random_bone(&mut rng, i);
        let pb = bone.prepare();
        for _ in 0..50 {
            let (s, n) = pb.sample_surface(&mut rng);
            let h = rng.range(0.01, 0.3) * bone.r1.min(bone.r2).max(1e-3);
            let out = bone.project(s + h * n);
            assert!(out.residual > 0.0);
            assert!(
                (out.distance - h).abs() <= 1e-3 * h + 1e-5 * bone.size(),
                "outside offset {h} vs {}",
                out.distance
            );
            // A point just inside, along the inward normal, by less than the local radius.
            let inside = bone.project(s - 0.5 * h * n);
            assert!(
                inside.residual < 0.0,
                "bone {bone:?}: point inside has residual {}",
                inside.residual
            );
            assert!(inside.distance <= 0.5 * h + 1e-5 * bone.size());
        }
    }
}

#[test]
fn projection_and_normal_are_continuous_across_the_cone_cap_seam() {
    let mut rng = Rng::new(4);
    for i in 0..300 {
        let bone = random_bone(&mut rng, i);
        let pb = bone.prepare();
        if pb.sphere_only.is_some() {
            continue;
        }
        // A point on the seam circle of cap 1 or 2, pushed outward along the seam normal, then
        // nudged along the axis both ways by ±δ.
        let which_end = rng.f32() < 0.5;
        let (c, r, sign) = if which_end {
            (bone.c1, bone.r1, -1.0)
        } else {
            (bone.c2, bone.r2, 1.0)
        };
        let _ = sign;
        let v = pb.perp;
        let seam_normal = pb.cos_a * v - pb.sin_a * pb.axis;
        let seam_point = c + r * seam_normal;
        let h = rng.range(0.0, 0.5) * bone.size();
        let p = seam_point + h * seam_normal;
        let delta = 1e-4 * bone.size();
        let a = bone.project(p + delta * pb.axis);
        let b = bone.project(p - delta * pb.axis);
        assert!(
            (a.point - b.point).length() <= 10.0 * delta,
            "seam jump {} for bone {bone:?}",
            (a.point - b.point).length()
        );
        assert!(
            (a.normal - b.normal).length() <= 10.0 * delta / r.max(1e-3) + 1e-3,
            "normal jump at the seam"
        );
        // And the seam point itself belongs to both parts: cone and cap agree there.
        let s = bone.project(seam_point);
        assert!((s.point - seam_point).length() <= 1e-5 * bone.size());
    }
}

#[test]
fn constrained_projection_follows_the_papers_rule_for_both_orientations() {
    let mut rng = Rng::new(5);
    let mut flipped_on_surface = 0;
    for i in 0..300 {
        let bone = random_bone(&mut rng, i);
        let pb = bone.prepare();
        for _ in 0..50 {
            let p = random_point_near(&mut rng, &bone);
            let orth = pb.project(p);
            if orth.residual <= 0.0 {
                continue; // The rule is stated for points outside the bone.
            }
            // Normal consistent with the closest point: the orthogonal projection.
            let same = pb.project_constrained(p, orth.normal);
            assert!((same.point - orth.point).length() <= 1e-5 * bone.size());
            assert!(!same.flipped);
            // Opposite normal: a projection on the far side, never the closest point.
            let n = -orth.normal;
            let opp = pb.project_constrained(p, n);
            assert!(
                opp.flipped,
                "bone {bone:?} p {p}: opposite normal must flip the projection"
            );
            assert!(opp.distance >= orth.distance - 1e-5 * bone.size());
            assert!(((opp.point - p).length() - opp.distance).abs() <= 1e-4 * bone.size());
            if opp.on_surface {
                flipped_on_surface += 1;
                // On the envelope: its normal agrees with n whenever the cone angle allows it
                // (the far cone normal makes an angle π − 2α with the near one).
                if pb.sin_a.abs() < 0.6 || opp.part != Part::Cone {
                    assert!(
                        opp.normal.dot(n) > 0.0,
                        "bone {bone:?}: far normal disagrees"
                    );
                }
                assert!(bone.signed_distance(opp.point).abs() <= 1e-4 * bone.size());
            }
        }
    }
    assert!(
        flipped_on_surface > 1000,
        "too few on-surface flipped cases exercised: {flipped_on_surface}"
    );
}

#[test]
fn far_side_cone_projection_matches_equation_2_1() {
    // A cylinder along X: p above it with a downward normal projects to the bottom line,
    // at distance y + r (eq. 2.1, second case with α = 0).
    let bone = Bone::new(Vec3::ZERO, 1.0, Vec3::new(10.0, 0.0, 0.0), 1.0);
    let p = Vec3::new(5.0, 3.0, 0.0);
    let q = bone.project_constrained(p, Vec3::new(0.0, -1.0, 0.0));
    assert!(q.flipped && q.on_surface && q.part == Part::Cone);
    assert!((q.point - Vec3::new(5.0, -1.0, 0.0)).length() < 1e-5);
    assert!((q.distance - 4.0).abs() < 1e-5);
    // Upward normal: the near side at distance y − r.
    let q = bone.project_constrained(p, Vec3::Y);
    assert!(!q.flipped && (q.point - Vec3::new(5.0, 1.0, 0.0)).length() < 1e-5);
    assert!((q.distance - 2.0).abs() < 1e-5);
}

#[test]
fn cap_case_with_inconsistent_normal_takes_the_antipode_or_the_far_cone() {
    let bone = Bone::new(Vec3::ZERO, 1.0, Vec3::new(10.0, 0.0, 0.0), 1.0);
    // Beyond c2 on the axis, normal pointing back towards the bone: the antipodal point of
    // sphere 2 falls inside the bone, so the far cone / fallback is used.
    let p = Vec3::new(13.0, 0.0, 0.0);
    let q = bone.project_constrained(p, -Vec3::X);
    assert!(q.flipped);
    assert!(
        q.normal.dot(-Vec3::X) > 0.0,
        "the normal of p̃ must agree with n_p: {:?}",
        q
    );
    assert!(
        (q.point - Vec3::new(-1.0, 0.0, 0.0)).length() < 1e-4,
        "fallback to the cap of sphere 1: {:?}",
        q.point
    );
    // Beside cap 2 with a normal pointing away from c2: plain cap projection.
    let p = Vec3::new(12.0, 1.0, 0.0);
    let q = bone.project_constrained(p, Vec3::new(1.0, 0.5, 0.0).normalize());
    assert!(!q.flipped && q.part == Part::Cap2);
    assert!((q.distance - ((p - bone.c2).length() - 1.0)).abs() < 1e-5);
}

#[test]
fn zero_normal_means_orthogonal_projection() {
    let mut rng = Rng::new(6);
    for i in 0..100 {
        let bone = random_bone(&mut rng, i);
        let p = random_point_near(&mut rng, &bone);
        assert_eq!(bone.project_constrained(p, Vec3::ZERO), bone.project(p));
    }
}

#[test]
fn degenerate_bones() {
    // One sphere inside the other: the bone is the larger sphere.
    let b = Bone::new(Vec3::ZERO, 3.0, Vec3::new(1.0, 0.0, 0.0), 1.0);
    let pb = b.prepare();
    assert_eq!(pb.sphere_only, Some(1));
    let q = b.project(Vec3::new(0.0, 5.0, 0.0));
    assert!(
        (q.point - Vec3::new(0.0, 3.0, 0.0)).length() < 1e-6 && (q.distance - 2.0).abs() < 1e-6
    );
    let q = b.project_constrained(Vec3::new(0.0, 5.0, 0.0), -Vec3::Y);
    assert!(
        q.flipped
            && (q.point - Vec3::new(0.0, -3.0, 0.0)).length() < 1e-6
            && (q.distance - 8.0).abs() < 1e-5
    );
    assert!((b.area() - 4.0 * std::f32::consts::PI * 9.0).abs() < 1e-3);
    // Zero length.
    let b = Bone::new(Vec3::ONE, 2.0, Vec3::ONE, 2.0);
    let q = b.project(Vec3::ONE + Vec3::new(0.0, 0.0, 4.0));
    assert!((q.point - (Vec3::ONE + Vec3::new(0.0, 0.0, 2.0))).length() < 1e-6);
    // A point at a sphere centre or on the axis: finite, deterministic, on the surface.
    let b = Bone::new(Vec3::ZERO, 1.0, Vec3::new(4.0, 0.0, 0.0), 0.5);
    for p in [
        Vec3::ZERO,
        Vec3::new(2.0, 0.0, 0.0),
        Vec3::new(4.0, 0.0, 0.0),
    ] {
        let q = b.project(p);
        assert!(q.point.is_finite() && q.normal.is_finite());
        assert!(b.signed_distance(q.point).abs() < 1e-5);
        assert_eq!(q, b.project(p));
    }
    // Cylinder area: 2πrl + 4πr².
    let c = Bone::new(Vec3::ZERO, 1.0, Vec3::new(5.0, 0.0, 0.0), 1.0);
    let expect = 2.0 * std::f32::consts::PI * 5.0 + 4.0 * std::f32::consts::PI;
    assert!((c.area() - expect).abs() < 1e-3 * expect);
}

#[test]
fn surface_sampling_is_area_uniform() {
    // Fraction of samples on each part equals its share of the area (within 4 σ).
    let b = Bone::new(Vec3::ZERO, 1.0, Vec3::new(6.0, 0.0, 0.0), 2.0);
    let pb = b.prepare();
    let areas = pb.part_areas();
    let total: f32 = areas.iter().sum();
    let mut rng = Rng::new(7);
    let n = 200_000;
    let mut counts = [0usize; 3];
    for _ in 0..n {
        let (p, _) = pb.sample_surface(&mut rng);
        let part = b.project(p).part;
        counts[match part {
            Part::Cap1 => 0,
            Part::Cone => 1,
            Part::Cap2 => 2,
        }] += 1;
    }
    for k in 0..3 {
        let expect = areas[k] / total;
        let got = counts[k] as f32 / n as f32;
        let sigma = (expect * (1.0 - expect) / n as f32).sqrt();
        assert!(
            (got - expect).abs() < 4.0 * sigma + 1e-4,
            "part {k}: {got} vs {expect}"
        );
    }
    // Along the cone, the density per unit axial length grows with the radius: compare the
    // two halves of the cone with their exact area ratio.
    let mut halves = [0usize; 2];
    for _ in 0..n {
        let (p, _) = pb.sample_surface(&mut rng);
        let q = b.project(p);
        if q.part == Part::Cone {
            halves[(q.tau >= 0.5) as usize] += 1;
        }
    }
    // Radii 1 → 1.5 and 1.5 → 2 along the generatrix: areas ∝ (1 + 1.5) and (1.5 + 2).
    let ratio = halves[1] as f32 / halves[0] as f32;
    assert!(
        (ratio - 3.5 / 2.5).abs() < 0.03,
        "cone halves ratio {ratio}"
    );
}

/// Finite-difference check of `Projection::gradient` (the basis of every LM derivative).
#[test]
fn residual_gradient_matches_finite_differences() {
    let mut rng = Rng::new(8);
    let mut checked = 0;
    for i in 0..300 {
        let bone = random_bone(&mut rng, i % 3); // no very thin bones: curvature ~ 1/r
        for _ in 0..20 {
            let p = random_point_near(&mut rng, &bone);
            let n = if rng.f32() < 0.5 {
                rng.unit_vector()
            } else {
                Vec3::ZERO
            };
            let base = bone.project_constrained(p, n);
            let g = base.gradient();
            let h = 1e-3 * bone.size();
            // Near the axis (or a sphere centre) the radial direction is not smooth.
            let (_, y, _) = bone.prepare().local(p);
            if y < 20.0 * h
                || (p - bone.c1).length() < 20.0 * h
                || (p - bone.c2).length() < 20.0 * h
            {
                continue;
            }
            let eval = |b: Bone| {
                let q = b.project_constrained(p, n);
                // Finite differences only where the projection case does not change.
                (q.flipped == base.flipped
                    && q.part == base.part
                    && q.on_surface == base.on_surface)
                    .then_some(q.residual)
            };
            let mut check = |plus: Bone, minus: Bone, analytic: f32| {
                if let (Some(a), Some(b)) = (eval(plus), eval(minus)) {
                    let fd = (a - b) / (2.0 * h);
                    assert!(
                        (fd - analytic).abs() <= 2e-2 * (1.0 + analytic.abs()),
                        "bone {bone:?} p {p} n {n}: fd {fd} vs {analytic} ({base:?})"
                    );
                    checked += 1;
                }
            };
            for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
                check(
                    Bone {
                        c1: bone.c1 + h * axis,
                        ..bone
                    },
                    Bone {
                        c1: bone.c1 - h * axis,
                        ..bone
                    },
                    g.dc1.dot(axis),
                );
                check(
                    Bone {
                        c2: bone.c2 + h * axis,
                        ..bone
                    },
                    Bone {
                        c2: bone.c2 - h * axis,
                        ..bone
                    },
                    g.dc2.dot(axis),
                );
            }
            check(
                Bone {
                    r1: bone.r1 + h,
                    ..bone
                },
                Bone {
                    r1: bone.r1 - h,
                    ..bone
                },
                g.dr1,
            );
            check(
                Bone {
                    r2: bone.r2 + h,
                    ..bone
                },
                Bone {
                    r2: bone.r2 - h,
                    ..bone
                },
                g.dr2,
            );
        }
    }
    assert!(checked > 20_000, "only {checked} derivatives checked");
}

#[test]
fn rotation_arc_keeps_small_angles() {
    use pygmalion::geometry::frames::rotation_arc;
    let a = Vec3::new(1.0, 0.2, -0.3).normalize();
    for angle in [1e-6f32, 1e-5, 1e-4, 1e-3, 0.5, 3.0] {
        let axis = a.any_orthonormal_vector();
        let b = pygmalion::math::Quat::from_axis_angle(axis, angle) * a;
        let q = rotation_arc(a, b);
        assert!((q * a - b).length() < 1e-6, "angle {angle}");
        assert!(
            (q.to_axis_angle().1 - angle).abs() < 1e-5 * angle.max(1.0),
            "angle {angle}: {}",
            q.to_axis_angle().1
        );
    }
    assert!((rotation_arc(a, -a) * a + a).length() < 1e-5);
    assert_eq!(rotation_arc(a, a), pygmalion::math::Quat::IDENTITY);
}

#[test]
fn the_bounding_sphere_holds_every_surface_sample() {
    let mut rng = Rng::new(17);
    for (c1, r1, c2, r2) in [
        (Vec3::ZERO, 0.1, Vec3::new(0.0, 1.0, 0.0), 0.3),
        (
            Vec3::new(1.0, 2.0, 3.0),
            0.5,
            Vec3::new(1.2, 2.1, 2.9),
            0.05,
        ),
        (Vec3::ZERO, 0.4, Vec3::new(0.05, 0.0, 0.0), 0.1),
    ] {
        let bone = Bone::new(c1, r1, c2, r2);
        let (centre, radius) = bone.bounding_sphere();
        let pb = bone.prepare();
        let mut farthest = 0.0f32;
        for _ in 0..2000 {
            farthest = farthest.max((pb.sample_surface(&mut rng).0 - centre).length());
        }
        // Within it, and tight: the far cap reaches it along the axis.
        assert!(farthest <= radius * (1.0 + 1e-5), "{farthest} > {radius}");
        assert!(farthest >= 0.9 * radius, "{farthest} much inside {radius}");
    }
}

/// `PreparedBone::local` decides between the radial direction `w / y` and the fixed `perp`
/// with a shortcut that skips `|d|` in the common case; it must decide exactly as the plain
/// rule `y > 1e-12 (1 + |d|)` does, near the axis, far from the bone and at the shortcut's
/// edges (`y` = 1e-4, `|d|` = 1e7).
#[test]
fn local_radial_direction_follows_the_plain_rule() {
    let bone = Bone::new(Vec3::ZERO, 0.5, Vec3::new(0.0, 0.0, 2.0), 0.3);
    let pb = bone.prepare();
    let mut checked = 0;
    for y in [
        0.0f32, 1e-13, 1e-11, 1e-6, 9.99e-5, 1e-4, 1.01e-4, 0.5, 100.0,
    ] {
        for x in [0.0f32, 1.0, -3.0, 1e6, 9.9e6, 1e7, 1.2e7, 1e9, -1e10] {
            let p = Vec3::new(y * 0.6, y * 0.8, x);
            let (xl, yl, v) = pb.local(p);
            let d = p - bone.c1;
            let plain = if yl > 1e-12 * (1.0 + d.length()) {
                (d - xl * pb.axis) / yl
            } else {
                pb.perp
            };
            assert_eq!(
                v, plain,
                "y {y}, x {x}: {v:?} against the plain rule's {plain:?}"
            );
            checked += 1;
        }
    }
    assert_eq!(checked, 81);
}
