//! Tests of `synth`: synthetic statues sample the outer envelope of a posed template, with the
//! requested proportions, noise, cuts and rigid motion, deterministically.

use pygmalion::anatomy::{BoneKind, Skeleton, Template};
use pygmalion::geometry::PreparedBone;
use pygmalion::math::Vec3;
use pygmalion::synth::{Cut, PLINTH_LABEL, SynthOptions, chain4, generate};
use std::sync::Arc;

fn human() -> Arc<Template> {
    Arc::new(Template::builtin("human").unwrap())
}

fn prepared(s: &Skeleton) -> Vec<PreparedBone> {
    s.pose().bones.iter().map(|b| b.prepare()).collect()
}

#[test]
fn points_lie_on_the_outer_envelope_with_outward_normals() {
    for name in pygmalion::anatomy::template::BUILTIN_TEMPLATES {
        let t = Arc::new(Template::builtin(name).unwrap());
        let s = generate(
            t,
            &SynthOptions {
                points: 20_000,
                seed: 11,
                height: 2.0,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(s.cloud.len(), 20_000);
        let bones = prepared(&s.truth);
        let normals = s.cloud.normals.as_ref().unwrap();
        let tol = 1e-5 * 2.0 * 10.0;
        for ((p, n), &l) in s.cloud.positions.iter().zip(normals).zip(&s.labels) {
            let own = bones[l as usize].project(*p);
            assert!(
                own.distance <= tol,
                "{name}: point off its bone by {}",
                own.distance
            );
            assert!(own.normal.dot(*n) > 0.999);
            // Not inside any other bone: the union's signed distance is ~0.
            let min_sdf = bones
                .iter()
                .map(|b| b.sdf_fast(*p))
                .fold(f32::INFINITY, f32::min);
            assert!(
                min_sdf > -tol,
                "{name}: point inside another bone ({min_sdf})"
            );
        }
    }
}

#[test]
fn same_seed_same_bytes_other_seed_other_statue() {
    let o = SynthOptions {
        points: 5_000,
        seed: 42,
        noise_sigma: 0.002,
        rigid: true,
        ..Default::default()
    };
    let a = generate(human(), &o).unwrap();
    let b = generate(human(), &o).unwrap();
    assert_eq!(a.cloud, b.cloud);
    assert_eq!(a.labels, b.labels);
    let c = generate(human(), &SynthOptions { seed: 43, ..o }).unwrap();
    assert_ne!(a.cloud.positions, c.cloud.positions);
}

#[test]
fn proportions_stay_within_the_jitter() {
    let t = human();
    let rest = Skeleton::rest(t.clone());
    for seed in 0..10 {
        let s = generate(
            t.clone(),
            &SynthOptions {
                points: 100,
                seed,
                proportion_jitter: 0.3,
                ..Default::default()
            },
        )
        .unwrap();
        let k = 1.0 / t.height; // height 1
        for (i, b) in t.bones.iter().enumerate() {
            if b.kind == BoneKind::Free {
                let ratio = s.truth.bones[i].length / (rest.bones[i].length * k);
                assert!(
                    (0.7 - 1e-4..=1.3 + 1e-4).contains(&ratio),
                    "{}: length ratio {ratio}",
                    b.name
                );
            }
        }
    }
}

#[test]
fn symmetric_proportions_give_left_and_right_the_same_bones_and_nothing_else_changes() {
    for name in pygmalion::anatomy::template::BUILTIN_TEMPLATES {
        let t = Arc::new(Template::builtin(name).unwrap());
        let mirror = t.mirror_bones();
        let statue = |symmetric: bool| {
            let o = SynthOptions {
                points: 100,
                seed: 7,
                proportion_jitter: 0.5,
                random_pose: false,
                symmetric,
                ..Default::default()
            };
            generate(t.clone(), &o).unwrap()
        };
        let (sym, lop) = (statue(true), statue(false));
        let (mut pairs, mut lopsided) = (0, 0);
        for (i, m) in mirror.iter().enumerate() {
            let Some(m) = *m else { continue };
            pairs += 1;
            let (a, b) = (&sym.truth.bones[i], &sym.truth.bones[m]);
            for (x, y) in [(a.length, b.length), (a.r1, b.r1), (a.r2, b.r2)] {
                assert!(
                    (x - y).abs() <= 1e-5 * x.abs().max(1.0),
                    "{name} {}: {x} / {y}",
                    t.bones[i].name
                );
            }
            let (a, b) = (&lop.truth.bones[i], &lop.truth.bones[m]);
            lopsided += usize::from((a.length - b.length).abs() > 1e-3 * a.length);
            // The first bone of each pair keeps its own factors: the same draws either way.
            if m > i {
                assert_eq!(sym.truth.bones[i].length, lop.truth.bones[i].length);
            }
        }
        assert!(pairs >= 4, "{name}: {pairs} mirrored bones");
        assert!(lopsided > 0, "{name}: the default figure is lopsided");
    }
}

#[test]
fn gaussian_noise_has_the_requested_level() {
    let sigma = 0.01;
    let s = generate(
        human(),
        &SynthOptions {
            points: 20_000,
            seed: 5,
            noise_sigma: sigma,
            ..Default::default()
        },
    )
    .unwrap();
    let bones = prepared(&s.truth);
    // Signed offset from the labelled bone along the normal: mean ≈ 0, std ≈ σ.
    let offsets: Vec<f32> = s
        .cloud
        .positions
        .iter()
        .zip(&s.labels)
        .map(|(p, &l)| bones[l as usize].project(*p).residual)
        .collect();
    let n = offsets.len() as f32;
    let mean = offsets.iter().sum::<f32>() / n;
    let std = (offsets.iter().map(|o| (o - mean).powi(2)).sum::<f32>() / n).sqrt();
    assert!(mean.abs() < 0.1 * sigma, "mean offset {mean}");
    assert!((std - sigma).abs() < 0.1 * sigma, "std {std} vs σ {sigma}");
}

#[test]
fn bone_cut_removes_the_limb_below_the_cut() {
    let t = human();
    let fore = t.bone_index("l_forearm").unwrap();
    let hand = t.bone_index("l_hand").unwrap();
    let o = SynthOptions {
        points: 20_000,
        seed: 8,
        cuts: vec![Cut::Bone {
            bone: "l_forearm".into(),
            at: 0.5,
        }],
        ..Default::default()
    };
    let full = generate(
        t.clone(),
        &SynthOptions {
            cuts: vec![],
            ..o.clone()
        },
    )
    .unwrap();
    let cut = generate(t.clone(), &o).unwrap();
    assert!(cut.cloud.len() < full.cloud.len());
    assert!(!cut.labels.contains(&(hand as u32)), "hand points remain");
    let geo = cut.truth.pose().bones[fore];
    let axis = (geo.c2 - geo.c1).normalize();
    let mid = 0.5 * (geo.c1 + geo.c2);
    for (p, &l) in cut.cloud.positions.iter().zip(&cut.labels) {
        if l as usize == fore {
            assert!((*p - mid).dot(axis) <= 1e-6, "forearm point beyond the cut");
        }
    }
    // Other bones are untouched: the same points as the full statue.
    let others_full = full
        .labels
        .iter()
        .filter(|&&l| l as usize != fore && l as usize != hand)
        .count();
    let others_cut = cut.labels.iter().filter(|&&l| l as usize != fore).count();
    assert_eq!(others_full, others_cut);
    // Parsing.
    assert_eq!(
        Cut::parse("bone:l_forearm@0.5").unwrap(),
        Cut::Bone {
            bone: "l_forearm".into(),
            at: 0.5
        }
    );
    assert!(matches!(
        Cut::parse("plane:0,0,0,0,1,0").unwrap(),
        Cut::Plane { .. }
    ));
    assert!(Cut::parse("plane:0,0,0,0,0,0").is_err());
    assert!(Cut::parse("bone:x@2").is_err());
    assert!(Cut::parse("knife").is_err());
    let bad = generate(
        t,
        &SynthOptions {
            cuts: vec![Cut::Bone {
                bone: "wing".into(),
                at: 0.0,
            }],
            ..o
        },
    );
    assert!(bad.unwrap_err().to_string().contains("wing"));
}

#[test]
fn plane_cut_and_rigid_transform() {
    let o = SynthOptions {
        points: 10_000,
        seed: 2,
        rigid: true,
        ..Default::default()
    };
    let s = generate(human(), &o).unwrap();
    // The truth skeleton moved with the points: they still lie on it.
    let bones = prepared(&s.truth);
    for (p, &l) in s.cloud.positions.iter().zip(&s.labels).take(2000) {
        assert!(bones[l as usize].project(*p).distance < 1e-4);
    }
    // The rigid motion preserves the skeleton's shape.
    let plain = generate(
        human(),
        &SynthOptions {
            rigid: false,
            ..o.clone()
        },
    )
    .unwrap();
    let (a, b) = (plain.truth.pose().joints, s.truth.pose().joints);
    for i in 0..a.len() {
        for j in 0..a.len() {
            assert!(((a[i] - a[j]).length() - (b[i] - b[j]).length()).abs() < 1e-4);
        }
    }
    // A plane cut removes exactly its half-space.
    let c = s.truth.pose().joints[0];
    let cut = generate(
        human(),
        &SynthOptions {
            cuts: vec![Cut::Plane {
                point: c,
                normal: Vec3::Y,
            }],
            ..o
        },
    )
    .unwrap();
    assert!(cut.cloud.positions.iter().all(|p| p.y <= c.y));
    assert!(cut.cloud.len() < s.cloud.len() && !cut.cloud.is_empty());
}

#[test]
fn chain_experiment_matches_the_papers_setup() {
    let s = chain4(5_000, 1, 0.0, 0.0, vec![]).unwrap();
    assert_eq!(s.cloud.len(), 5_000);
    assert_eq!(s.truth.bones.len(), 4);
    let total: f32 = s.truth.bones.iter().map(|b| b.length).sum();
    assert!((total - 140.0).abs() < 1e-3);
    let bones = prepared(&s.truth);
    assert!(s.cloud.positions.iter().all(|p| {
        bones
            .iter()
            .map(|b| b.sdf_fast(*p))
            .fold(f32::INFINITY, f32::min)
            .abs()
            < 1e-4 * 140.0
    }));
    // The anchor (root) is the first extremity, at the origin.
    assert_eq!(s.truth.pose().joints[0], Vec3::ZERO);
    // Noise and missing data variants.
    let noisy = chain4(5_000, 1, 1.0, 0.0, vec![]).unwrap();
    assert_ne!(noisy.cloud.positions, s.cloud.positions);
    let mid = s.truth.pose().joints[2];
    let holed = chain4(
        5_000,
        1,
        0.0,
        0.0,
        vec![Cut::Plane {
            point: mid + Vec3::X * 10.0,
            normal: Vec3::X,
        }],
    )
    .unwrap();
    assert!(holed.cloud.len() < 5_000);
}

#[test]
fn bad_options_are_errors() {
    assert!(
        generate(
            human(),
            &SynthOptions {
                points: 0,
                ..Default::default()
            }
        )
        .is_err()
    );
    assert!(
        generate(
            human(),
            &SynthOptions {
                height: f32::NAN,
                ..Default::default()
            }
        )
        .is_err()
    );
    assert!(
        generate(
            human(),
            &SynthOptions {
                proportion_jitter: 2.0,
                ..Default::default()
            }
        )
        .is_err()
    );
}

#[test]
fn a_plinth_adds_a_labelled_box_under_the_figure_and_leaves_the_figure_alone() {
    let o = SynthOptions {
        points: 8_000,
        seed: 5,
        height: 1.7,
        rigid: true,
        ..Default::default()
    };
    let bare = generate(human(), &o).unwrap();
    let with = generate(
        human(),
        &SynthOptions {
            plinth_share: 0.25,
            ..o.clone()
        },
    )
    .unwrap();
    // The figure is the same, point for point; the plinth follows it.
    assert_eq!(with.cloud.len(), 8_000 + 2_000);
    assert_eq!(&with.cloud.positions[..8_000], &bare.cloud.positions[..]);
    assert_eq!(&with.labels[..8_000], &bare.labels[..]);
    assert!(with.labels[8_000..].iter().all(|&l| l == PLINTH_LABEL));
    // The plinth lies under the figure along the template's up, its top touching the lowest
    // figure point (within 1e-4 of the height), 0.08 × height high.
    let up = with.rigid.0 * Vec3::Y;
    let low = bare
        .cloud
        .positions
        .iter()
        .map(|p| p.dot(up))
        .fold(f32::INFINITY, f32::min);
    let heights: Vec<f32> = with.cloud.positions[8_000..]
        .iter()
        .map(|p| p.dot(up))
        .collect();
    let top = heights.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
    let bottom = heights.iter().cloned().fold(f32::INFINITY, f32::min);
    assert!(
        (top - low).abs() < 1.7e-4,
        "top {top}, lowest figure point {low}"
    );
    assert!((top - bottom - 0.08 * 1.7).abs() < 1.7e-4);
    // Outward normals: each points away from the plinth's centre.
    let normals = with.cloud.normals.as_ref().unwrap();
    let centre = with.cloud.positions[8_000..]
        .iter()
        .fold(Vec3::ZERO, |a, p| a + *p)
        / 2_000.0;
    for (p, n) in with.cloud.positions[8_000..].iter().zip(&normals[8_000..]) {
        assert!((*p - centre).dot(*n) > 0.0);
    }
    // Out-of-range shares are refused.
    assert!(
        generate(
            human(),
            &SynthOptions {
                plinth_share: -1.0,
                ..o
            }
        )
        .is_err()
    );
}
