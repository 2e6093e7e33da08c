//! Point-set skinning (`src/skinning`): measured properties on synthetic statues whose
//! skeletons are known exactly (no registration error in the way).

use pygmalion::anatomy::{Skeleton, Template};
use pygmalion::cloud::PointCloud;
use pygmalion::math::{Quat, Vec3};
use pygmalion::skinning::{Binding, Method, Scratch};
use pygmalion::synth::{SynthOptions, chain_template, generate};
use std::sync::Arc;

/// A synthetic human in a random pose with some relief (heights ≠ 0), height 1.
fn human(seed: u64, points: usize) -> (PointCloud, Skeleton) {
    let t = Arc::new(Template::builtin("human").unwrap());
    let s = generate(
        t,
        &SynthOptions {
            points,
            seed,
            noise_sigma: 0.004,
            ..Default::default()
        },
    )
    .unwrap();
    (s.cloud, s.truth)
}

/// A straight two-bone limb along +X (lengths 1, 1; radii 0.25, 0.22, 0.18) with relief.
fn limb(points: usize) -> (PointCloud, Skeleton) {
    let t = Arc::new(chain_template("limb", &[1.0, 1.0], &[0.25, 0.22, 0.18]).unwrap());
    let s = generate(
        t.clone(),
        &SynthOptions {
            points,
            seed: 7,
            random_pose: false,
            proportion_jitter: 0.0,
            height: 1.0,
            noise_sigma: 0.002,
            ..Default::default()
        },
    )
    .unwrap();
    // `height` scales the template to unit height; undo it so lengths are 1 and 1.
    let k = 1.0 / s.truth.bones[0].length;
    let cloud = PointCloud::with_normals(
        s.cloud.positions.iter().map(|p| *p * k).collect(),
        s.cloud.normals.clone().unwrap(),
    );
    let mut skel = s.truth.clone();
    skel.scale_sizes(k);
    skel.root_position *= k;
    (cloud, skel)
}

fn max_dist(a: &[Vec3], b: &[Vec3]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (*x - *y).length())
        .fold(0.0, f32::max)
}

/// The child bone of the limb rotated by the world rotation `q` about the elbow.
fn rotate_child(skel: &Skeleton, q: Quat) -> Skeleton {
    let parent = skel.pose().frames[0];
    let local = (parent.inverse() * q * parent).normalize();
    let mut s = skel.clone();
    s.bones[1].rotation = (local * s.bones[1].rotation).normalize();
    s
}

#[test]
fn fitted_pose_gives_every_point_back() {
    let (cloud, skel) = human(3, 20_000);
    let bind = Binding::new(&cloud, &skel).unwrap();
    assert_eq!(bind.len(), cloud.len());
    for m in Method::ALL {
        let out = bind.deform_cloud(&skel, m).unwrap();
        let d = max_dist(&out.positions, &cloud.positions);
        assert!(d <= 1e-5, "{m}: a point moved by {d} (height 1)");
    }
}

#[test]
fn rigid_motion_of_the_skeleton_moves_the_cloud_rigidly() {
    let (cloud, skel) = human(5, 20_000);
    let bind = Binding::new(&cloud, &skel).unwrap();
    let q = Quat::from_axis_angle(Vec3::new(0.3, 1.0, -0.2).normalize(), 1.1);
    let t = Vec3::new(0.4, -2.0, 0.7);
    let mut moved = skel.clone();
    moved.transform_rigid(q, t);
    let expect: Vec<Vec3> = cloud.positions.iter().map(|p| q * *p + t).collect();
    for m in Method::ALL {
        let out = bind.deform_cloud(&moved, m).unwrap();
        let d = max_dist(&out.positions, &expect);
        assert!(d <= 1e-5 * 2.0, "{m}: off a rigid motion by {d}");
        let nd = out
            .normals
            .as_ref()
            .unwrap()
            .iter()
            .zip(cloud.normals.as_ref().unwrap())
            .map(|(a, b)| (*a - q * *b).length())
            .fold(0.0, f32::max);
        assert!(nd <= 1e-4, "{m}: normals off a rigid motion by {nd}");
    }
}

fn seg_dist(p: Vec3, a: Vec3, b: Vec3) -> f32 {
    let ab = b - a;
    let t = ((p - a).dot(ab) / ab.length_squared()).clamp(0.0, 1.0);
    (p - (a + t * ab)).length()
}

/// The bend test of the issue: a 90° elbow bend about Z (the child turns towards +Y, so the
/// convex side is −Y). "Keeping the convex side" is measured as each convex-side point's
/// distance to the skeleton (the two bones' axes), rest against bent: a collapsing joint thins
/// there, while points that merely slide along the limb (baseline skinning stretches its
/// baselines over the opened joint) keep it.
#[test]
fn elbow_bend_keeps_the_convex_side_and_lbs_collapses() {
    let (cloud, skel) = limb(20_000);
    let bind = Binding::new(&cloud, &skel).unwrap();
    let target = rotate_child(&skel, Quat::from_rotation_z(std::f32::consts::FRAC_PI_2));
    let j = Vec3::X; // the elbow
    let tip_rest = 2.0 * Vec3::X;
    let tip_bent = j + Vec3::Y;
    let mut ratios = Vec::new();
    for m in Method::ALL {
        let out = bind.deform_cloud(&target, m).unwrap();
        assert!(out.positions.iter().all(|p| p.is_finite()), "{m}: NaN");
        // Convex side near the joint: rest points with y < −0.1 within 0.3 of the elbow.
        let mut worst = f32::INFINITY;
        for (p, q) in cloud.positions.iter().zip(&out.positions) {
            let r = *p - j;
            if r.y < -0.1 && r.length() < 0.3 {
                let d0 = seg_dist(*p, Vec3::ZERO, j).min(seg_dist(*p, j, tip_rest));
                let d1 = seg_dist(*q, Vec3::ZERO, j).min(seg_dist(*q, j, tip_bent));
                worst = worst.min(d1 / d0);
            }
        }
        ratios.push((m, worst));
        // Neighbourhoods stay neighbourhoods: the longest 8-NN edge grows by a bounded factor.
        let grow = knn_growth(&cloud.positions, &out.positions, 8);
        assert!(grow < 4.0, "{m}: the longest 8-NN edge grew {grow}×");
    }
    let get = |m: Method| ratios.iter().find(|r| r.0 == m).unwrap().1;
    assert!(get(Method::Heightfield) >= 0.9, "{ratios:?}");
    assert!(get(Method::Baseline) >= 0.9, "{ratios:?}");
    assert!(get(Method::Lbs) < 0.85, "LBS should collapse: {ratios:?}");
}

/// Longest k-NN edge of the deformed cloud over the longest of the rest cloud, the neighbours
/// being taken in the rest cloud (brute force on a subsample).
fn knn_growth(rest: &[Vec3], moved: &[Vec3], k: usize) -> f32 {
    let idx: Vec<usize> = (0..rest.len()).step_by(7).collect();
    let (mut l0, mut l1) = (0.0f32, 0.0f32);
    for &i in &idx {
        let mut d: Vec<(f32, usize)> = idx
            .iter()
            .filter(|&&j| j != i)
            .map(|&j| ((rest[i] - rest[j]).length_squared(), j))
            .collect();
        d.select_nth_unstable_by(k, |a, b| a.0.total_cmp(&b.0));
        for &(_, j) in &d[..k] {
            l0 = l0.max((rest[i] - rest[j]).length());
            l1 = l1.max((moved[i] - moved[j]).length());
        }
    }
    l1 / l0
}

/// The candy-wrapper test: a 90° twist of the child about its own axis.
#[test]
fn twist_keeps_the_cross_section_and_lbs_pinches() {
    let (cloud, skel) = limb(20_000);
    let bind = Binding::new(&cloud, &skel).unwrap();
    let target = rotate_child(&skel, Quat::from_rotation_x(std::f32::consts::FRAC_PI_2));
    let mut res = Vec::new();
    for m in Method::ALL {
        let out = bind.deform_cloud(&target, m).unwrap();
        // Radius about the limb's axis (X) of the points of the cone parts, relative to rest.
        let mut worst = f32::INFINITY;
        for (p, q) in cloud.positions.iter().zip(&out.positions) {
            if (p.x - 0.5).abs() < 1.0 {
                let r0 = Vec3::new(0.0, p.y, p.z).length();
                let r1 = Vec3::new(0.0, q.y, q.z).length();
                worst = worst.min(r1 / r0);
            }
        }
        res.push((m, worst));
    }
    let get = |m: Method| res.iter().find(|r| r.0 == m).unwrap().1;
    assert!(get(Method::Heightfield) >= 0.9, "{res:?}");
    assert!(get(Method::Baseline) >= 0.9, "{res:?}");
    assert!(get(Method::Lbs) < 0.85, "LBS should pinch: {res:?}");
}

#[test]
fn lengthening_a_bone_moves_the_distal_points_by_as_much() {
    let (cloud, skel) = limb(10_000);
    let bind = Binding::new(&cloud, &skel).unwrap();
    let mut target = skel.clone();
    target.bones[0].length *= 1.3;
    for m in [Method::Baseline, Method::Heightfield] {
        let out = bind.deform_cloud(&target, m).unwrap();
        // Points well inside the distal bone move by +0.3 along the limb.
        let mut worst = 0.0f32;
        for (p, q) in cloud.positions.iter().zip(&out.positions) {
            if p.x > 1.5 {
                worst = worst.max((*q - (*p + Vec3::new(0.3, 0.0, 0.0))).length());
            }
        }
        assert!(worst < 1e-3, "{m}: distal points off by {worst}");
    }
}

#[test]
fn scaling_the_radii_scales_the_heights() {
    let (cloud, skel) = limb(10_000);
    let bind = Binding::new(&cloud, &skel).unwrap();
    let mut target = skel.clone();
    for b in &mut target.bones {
        b.r1 *= 1.5;
        b.r2 *= 1.5;
    }
    for m in [Method::Baseline, Method::Heightfield] {
        let out = bind.deform_cloud(&target, m).unwrap();
        let mut worst = 0.0f32;
        for (p, q) in cloud.positions.iter().zip(&out.positions) {
            if (p.x - 0.5).abs() < 0.3 || (p.x - 1.5).abs() < 0.3 {
                let r0 = Vec3::new(0.0, p.y, p.z).length();
                let r1 = Vec3::new(0.0, q.y, q.z).length();
                worst = worst.max((r1 / r0 - 1.5).abs());
            }
        }
        assert!(worst < 0.02, "{m}: radius ratio off 1.5 by {worst}");
    }
}

#[test]
fn deform_is_deterministic_and_checks_its_inputs() {
    let (cloud, skel) = human(11, 8_000);
    let bind = Binding::new(&cloud, &skel).unwrap();
    let mut target = skel.clone();
    for b in target.bones.iter_mut().skip(3) {
        b.rotation = (Quat::from_rotation_z(0.3) * b.rotation).normalize();
    }
    for m in Method::ALL {
        let a = bind.deform_cloud(&target, m).unwrap();
        let b = bind.deform_cloud(&target, m).unwrap();
        let bits = |c: &PointCloud| -> Vec<u32> {
            c.positions
                .iter()
                .flat_map(|p| p.to_array())
                .map(f32::to_bits)
                .collect()
        };
        assert_eq!(bits(&a), bits(&b), "{m}");
    }
    // Bad inputs.
    let mut nan = skel.clone();
    nan.bones[4].length = f32::NAN;
    let err = bind
        .deform_cloud(&nan, Method::Baseline)
        .unwrap_err()
        .to_string();
    assert!(err.contains("length"), "{err}");
    let mut pos = vec![Vec3::ZERO; 3];
    let mut nrm = vec![Vec3::ZERO; 3];
    let err = bind
        .deform(
            &skel,
            Method::Lbs,
            &mut Scratch::default(),
            &mut pos,
            &mut nrm,
        )
        .unwrap_err()
        .to_string();
    assert!(err.contains("buffers"), "{err}");
    let empty = PointCloud::from_positions(Vec::new());
    assert!(Binding::new(&empty, &skel).is_err());
    let bad = PointCloud::from_positions(vec![Vec3::new(f32::NAN, 0.0, 0.0)]);
    let err = Binding::new(&bad, &skel).unwrap_err().to_string();
    assert!(err.contains("non-finite"), "{err}");
    assert!("dqs".parse::<Method>().is_ok());
    assert!("bogus".parse::<Method>().is_err());
}

#[test]
fn a_saved_binding_loads_back_and_deforms_identically() {
    let (cloud, skel) = human(13, 6_000);
    let bind = Binding::new(&cloud, &skel).unwrap();
    let dir = crate::common::scratch("skinning_store");
    let path = dir.join("statue.binding");
    bind.save(&path).unwrap();
    let back = Binding::load(&path, skel.template.clone()).unwrap();
    assert_eq!(back.len(), bind.len());
    let mut target = skel.clone();
    for b in target.bones.iter_mut().skip(3) {
        b.rotation = (Quat::from_rotation_y(0.4) * b.rotation).normalize();
    }
    for m in Method::ALL {
        let a = bind.deform_cloud(&target, m).unwrap();
        let b = back.deform_cloud(&target, m).unwrap();
        assert_eq!(a.positions, b.positions, "{m}");
        assert_eq!(a.normals, b.normals, "{m}");
    }
    // Damaged files: each error names the file.
    let bytes = std::fs::read(&path).unwrap();
    let cases: Vec<(&str, Vec<u8>)> = vec![
        ("truncated", bytes[..bytes.len() / 2].to_vec()),
        ("magic", [b"NOTABIND".as_slice(), &bytes[8..]].concat()),
        ("trailing", [bytes.as_slice(), &[0u8; 5]].concat()),
        ("empty", Vec::new()),
    ];
    for (name, data) in cases {
        let p = dir.join(format!("{name}.binding"));
        std::fs::write(&p, data).unwrap();
        let err = Binding::load(&p, skel.template.clone())
            .unwrap_err()
            .to_string();
        assert!(err.contains(&format!("{name}.binding")), "{name}: {err}");
    }
    // Another template is refused.
    let other = Arc::new(Template::builtin("quadruped").unwrap());
    let err = Binding::load(&path, other).unwrap_err().to_string();
    assert!(err.contains("human"), "{err}");
}

/// The bench's worst case on a human: every free joint bent by 0.4 rad about an oblique axis,
/// twisted by 0.3 rad, every bone 10% longer.
fn worst_case(fitted: &Skeleton) -> Skeleton {
    let mut s = fitted.clone();
    for (b, def) in s.bones.iter_mut().zip(&fitted.template.bones) {
        if def.kind == pygmalion::anatomy::BoneKind::Free && def.parent.is_some() {
            b.rotation = (b.rotation
                * Quat::from_axis_angle(Vec3::new(0.0, 0.6, 0.8), 0.4)
                * Quat::from_rotation_x(0.3))
            .normalize();
        }
        b.length *= 1.1;
    }
    s.enforce_constraints();
    s
}

/// Heightfield skinning tabulates the bend per frame (see `skinning::heightfield`): points
/// outside the joints' zones are exactly where the per-point iteration of Algorithm 2 puts
/// them, and inside the zones the table stays close to it (it smooths where the iteration
/// itself jumps, at the sides of a bend: the maxima, printed, sit there).
#[test]
fn tabulated_heightfield_bend_matches_the_per_point_iteration() {
    let cases = {
        let (cloud, skel) = human(17, 40_000);
        let target = worst_case(&skel);
        let (lc, ls) = limb(20_000);
        let lt = rotate_child(&ls, Quat::from_rotation_z(std::f32::consts::FRAC_PI_2));
        // (name, cloud, skeleton, target, size, p99 and rms bounds relative to the size)
        vec![
            ("human", cloud, skel, target, 1.0, 2e-3, 1e-3),
            ("elbow", lc, ls, lt, 2.0, 3e-3, 1e-3),
        ]
    };
    for (name, cloud, skel, target, size, p99_max, rms_max) in cases {
        let bind = Binding::new(&cloud, &skel).unwrap();
        let fast = bind.deform_cloud(&target, Method::Heightfield).unwrap();
        let slow = bind.deform_heightfield_reference(&target).unwrap();
        let partner = &bind.points().partner;
        let mut zone = Vec::new();
        let mut outside = 0.0f32;
        for ((a, b), &m) in fast.positions.iter().zip(&slow.positions).zip(partner) {
            let d = (*a - *b).length() / size;
            if m == u16::MAX {
                outside = outside.max(d);
            } else {
                zone.push(d);
            }
        }
        zone.sort_by(f32::total_cmp);
        let p99 = zone[zone.len() * 99 / 100];
        let rms = (zone.iter().map(|x| x * x).sum::<f32>() / zone.len() as f32).sqrt();
        let max = zone.last().copied().unwrap_or(0.0);
        eprintln!(
            "{name}: outside the zones {outside:.1e}; in them p99 {p99:.1e} rms {rms:.1e} max {max:.1e}"
        );
        assert!(outside <= 1e-6, "{name}: rigid points moved by {outside}");
        assert!(
            p99 <= p99_max && rms <= rms_max,
            "{name}: p99 {p99}, rms {rms}"
        );
        assert!(fast.positions.iter().all(|p| p.is_finite()), "{name}: NaN");
    }
}

#[test]
fn a_base_stays_where_it_stands_and_follows_only_the_root_placement() {
    use pygmalion::cloud::base::{BaseOptions, detect_base};
    use pygmalion::synth::PLINTH_LABEL;
    let t = Arc::new(Template::builtin("human").unwrap());
    let s = generate(
        t,
        &SynthOptions {
            points: 8_000,
            seed: 4,
            plinth_share: 0.25,
            ..Default::default()
        },
    )
    .unwrap();
    let (cloud, skel) = (s.cloud, s.truth);
    let base = detect_base(
        &cloud.positions,
        cloud.normals.as_ref().unwrap(),
        None,
        &BaseOptions::default(),
    )
    .expect("base");
    let bind = Binding::new(&cloud, &skel)
        .unwrap()
        .with_base(&base.points)
        .unwrap();
    assert_eq!(bind.base(), base.points.as_slice());
    let on_base = |i: usize| base.points.binary_search(&(i as u32)).is_ok();
    // Every joint bent, twisted, lengthened: the base does not move (exactly), the figure does.
    let target = worst_case(&skel);
    let normals = cloud.normals.as_ref().unwrap();
    for m in Method::ALL {
        let out = bind.deform_cloud(&target, m).unwrap();
        let on = out.normals.as_ref().unwrap();
        let mut moved_figure = 0;
        for i in 0..cloud.len() {
            if on_base(i) {
                assert!(
                    (out.positions[i] - cloud.positions[i]).length() <= 1e-5,
                    "{m}"
                );
                assert!((on[i] - normals[i]).length() <= 1e-4, "{m}");
            } else if (out.positions[i] - cloud.positions[i]).length() > 1e-3 {
                moved_figure += 1;
            }
        }
        assert!(
            moved_figure > cloud.len() / 2,
            "{m}: the figure did not move"
        );
    }
    // Without the base, the plinth's points near the feet would follow them.
    let plain = Binding::new(&cloud, &skel).unwrap();
    let out = plain.deform_cloud(&target, Method::Baseline).unwrap();
    let plinth_moved = (0..cloud.len())
        .filter(|&i| s.labels[i] == PLINTH_LABEL)
        .filter(|&i| (out.positions[i] - cloud.positions[i]).length() > 1e-3)
        .count();
    assert!(plinth_moved > 0);
    // A rigid motion of the root moves the base rigidly.
    let q = Quat::from_axis_angle(Vec3::new(0.3, 1.0, -0.2).normalize(), 1.1);
    let tr = Vec3::new(0.4, -2.0, 0.7);
    let mut moved = skel.clone();
    moved.transform_rigid(q, tr);
    let out = bind.deform_cloud(&moved, Method::Baseline).unwrap();
    for &i in bind.base() {
        let i = i as usize;
        assert!((out.positions[i] - (q * cloud.positions[i] + tr)).length() <= 2e-5);
    }
    // Saved and loaded, the base is kept.
    let dir = crate::common::scratch("skinning_store_base");
    let path = dir.join("statue.binding");
    bind.save(&path).unwrap();
    let back = Binding::load(&path, skel.template.clone()).unwrap();
    assert_eq!(back.base(), bind.base());
    assert_eq!(
        back.deform_cloud(&target, Method::Baseline)
            .unwrap()
            .positions,
        bind.deform_cloud(&target, Method::Baseline)
            .unwrap()
            .positions
    );
    // An index out of range is refused.
    let n = cloud.len() as u32;
    assert!(
        Binding::new(&cloud, &skel)
            .unwrap()
            .with_base(&[0, n])
            .is_err()
    );
}

#[test]
fn lost_bones_bind_no_point() {
    // A broken statue's lost limbs (registration level 6) are completed to a plausible pose
    // that may pass through parts that are there: no point may follow them.
    let (cloud, skel) = human(7, 20_000);
    let t = skel.template.clone();
    let all = Binding::new(&cloud, &skel).unwrap();
    let lost: Vec<bool> = t
        .bones
        .iter()
        .map(|b| b.name == "l_forearm" || b.name == "l_hand")
        .collect();
    let ids: Vec<u16> = (0..t.bones.len())
        .filter(|&b| lost[b])
        .map(|b| b as u16)
        .collect();
    let on_lost = all.points().bone.iter().filter(|b| ids.contains(b)).count();
    assert!(on_lost > 500, "the forearm and hand hold {on_lost} points");
    let without = Binding::new_without(&cloud, &skel, &lost).unwrap();
    let p = without.points();
    assert!(
        p.bone.iter().all(|b| !ids.contains(b)),
        "a point bound to a lost bone"
    );
    assert!(
        p.partner
            .iter()
            .zip(&p.weight)
            .all(|(m, w)| !ids.contains(m) || *w == 0.0),
        "a point blended with a lost bone"
    );
    // The other points keep their bones, and the fitted pose gives every point back.
    let same = all
        .points()
        .bone
        .iter()
        .zip(&p.bone)
        .filter(|(a, b)| !ids.contains(a) && a == b)
        .count();
    assert_eq!(same, cloud.len() - on_lost);
    for m in Method::ALL {
        let out = without.deform_cloud(&skel, m).unwrap();
        let d = max_dist(&out.positions, &cloud.positions);
        assert!(d <= 1e-5, "{m}: a point moved by {d} (height 1)");
    }
    // The binding remembers what it left out (the kiosk's ghost limbs), through a save and
    // load too; a binding of every bone has none.
    assert_eq!(without.lost(), lost.as_slice());
    assert!(all.lost().is_empty());
    let dir = crate::common::scratch("binding_lost");
    let path = dir.join("statue.binding");
    without.save(&path).unwrap();
    let back = Binding::load(&path, t.clone()).unwrap();
    assert_eq!(back.lost(), lost.as_slice());
    assert_eq!(back.points().bone, without.points().bone);
    all.save(&path).unwrap();
    assert!(Binding::load(&path, t.clone()).unwrap().lost().is_empty());
    // Flags that do not match the template, or that leave nothing, are refused.
    assert!(Binding::new_without(&cloud, &skel, &[true, false]).is_err());
    assert!(Binding::new_without(&cloud, &skel, &vec![true; t.bones.len()]).is_err());
}
