//! Tests of `anatomy::pose`: the built-in poses parse, apply and look like what they claim;
//! bad poses and proportions are errors naming the file and the problem; identity round trips;
//! interpolation hits its endpoints; proportions change the lengths they name. Also the
//! `repose` command's checks that run before any skinning.

use pygmalion::anatomy::{BonePose, Pose, PoseBase, Proportions, Skeleton, Template, interpolate};
use pygmalion::math::{Quat, Vec3};
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

fn human() -> Arc<Template> {
    Arc::new(Template::builtin("human").expect("human template"))
}

/// A human skeleton placed in a scan's frame: turned, moved and scaled, with a few fitted
/// rotations away from the rest pose (so `Fitted` and `Rest` bases differ).
fn fitted() -> Skeleton {
    let t = human();
    let mut s = Skeleton::rest_placed(
        t.clone(),
        Vec3::new(1.0, -2.0, 0.5),
        Quat::from_rotation_x(-std::f32::consts::FRAC_PI_2) * Quat::from_rotation_y(0.4),
        1.7,
    );
    let i = t.bone_index("l_upper_arm").unwrap();
    s.bones[i].rotation = (s.bones[i].rotation * Quat::from_rotation_z(0.5)).normalize();
    let i = t.bone_index("r_shin").unwrap();
    s.bones[i].rotation = (s.bones[i].rotation * Quat::from_rotation_y(0.3)).normalize();
    s.enforce_constraints();
    s
}

/// Joint `name` of `s` in the template frame (undoing the root placement and scale), so
/// "up" is `+Y` and "front" is `+Z` whatever the skeleton's placement.
fn joint_local(s: &Skeleton, name: &str, scale: f32) -> Vec3 {
    let p = s.joint(name).unwrap_or_else(|| panic!("joint {name}"));
    let root = s.joint("pelvis").unwrap();
    s.root_rotation.inverse() * (p - root) / scale
}

fn src() -> &'static Path {
    Path::new("poses/test.ron")
}

#[test]
fn every_builtin_pose_parses_and_applies() {
    let names = Pose::builtin_names();
    for name in [
        "identity",
        "rest",
        "contrapposto",
        "arms_raised",
        "walking",
        "seated",
    ] {
        assert!(names.contains(&name), "{name}");
    }
    assert!(names.contains(&"thinker"));
    let fit = fitted();
    for name in names {
        let pose = Pose::builtin(name).unwrap_or_else(|| panic!("builtin {name}"));
        assert_eq!(&pose.name, name);
        let resolved = Pose::resolve(name).unwrap();
        assert_eq!(pose, resolved);
        let s = pose
            .apply(&fit, &Pose::source_path(name))
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(s.len(), fit.len());
        assert_eq!(s.root_position, fit.root_position);
        assert_eq!(s.root_rotation, fit.root_rotation);
        for (a, b) in s.bones.iter().zip(&fit.bones) {
            assert!((a.length - b.length).abs() < 1e-6, "{name}: lengths kept");
            assert_eq!((a.r1, a.r2), (b.r1, b.r2), "{name}: radii kept");
        }
        assert!(s.pose().joints.iter().all(|j| j.is_finite()), "{name}");
        // The files on disk are the compiled-in ones.
        if *name != "identity" {
            let path = crate::common::root().join(format!("config/poses/{name}.ron"));
            assert_eq!(Pose::load(&path).unwrap(), pose, "{name}");
            assert_eq!(Pose::resolve(path.to_str().unwrap()).unwrap(), pose);
        }
    }
    assert!(Pose::builtin("no_such_pose").is_none());
}

#[test]
fn builtin_poses_look_like_their_names() {
    let fit = fitted();
    let k = 1.7; // the fitted skeleton's scale
    let apply = |name: &str| Pose::builtin(name).unwrap().apply(&fit, src()).unwrap();
    let j = |s: &Skeleton, n: &str| joint_local(s, n, k);

    // The rest pose is the template's rest pose, placed as the fit.
    let rest = apply("rest");
    let t = human();
    for joint in &t.joints {
        let expect = joint.rest - t.joints[t.root].rest;
        assert!(
            (j(&rest, &joint.name) - expect).length() < 1e-4,
            "rest: {}",
            joint.name
        );
    }

    // Arms raised: both hands above the head.
    let s = apply("arms_raised");
    let head = j(&s, "head_top").y;
    for hand in ["l_wrist", "l_hand_tip", "r_wrist", "r_hand_tip"] {
        assert!(j(&s, hand).y > head + 0.05, "arms_raised: {hand}");
    }
    assert!(j(&s, "l_hand_tip").x > 0.0 && j(&s, "r_hand_tip").x < 0.0);

    // Seated: knees about at hip height and in front of the hips; feet below the knees.
    let s = apply("seated");
    for side in ["l", "r"] {
        let hip = j(&s, &format!("{side}_hip"));
        let knee = j(&s, &format!("{side}_knee"));
        let ankle = j(&s, &format!("{side}_ankle"));
        assert!((knee.y - hip.y).abs() < 0.05, "seated: {side} knee height");
        assert!(knee.z - hip.z > 0.15, "seated: {side} knee in front");
        assert!(knee.y - ankle.y > 0.15, "seated: {side} shin down");
    }

    // Walking: left foot ahead, right foot behind.
    let s = apply("walking");
    assert!(j(&s, "l_ankle").z > 0.08 && j(&s, "r_ankle").z < -0.08);
    assert!(
        j(&s, "r_wrist").z > j(&s, "l_wrist").z,
        "arms swing opposite"
    );

    // Contrapposto: the left knee forward and bent, the right leg straight.
    let s = apply("contrapposto");
    assert!(j(&s, "l_knee").z > j(&s, "r_knee").z + 0.02);
    let r_leg = j(&s, "r_ankle") - j(&s, "r_hip");
    assert!(r_leg.length() > 0.44, "right leg straight: {r_leg}");

    // The Thinker: seated, the right hand at the head, the right elbow at the left knee.
    let s = apply("thinker");
    let hand = (j(&s, "r_wrist") + j(&s, "r_hand_tip")) * 0.5;
    let head = j(&s, "head_base");
    assert!(
        (hand - head).length() < 0.1,
        "thinker: right hand {hand} far from the head {head}"
    );
    let elbow = j(&s, "r_elbow");
    let knee = j(&s, "l_knee");
    assert!(
        (elbow - knee).length() < 0.15,
        "thinker: right elbow {elbow} far from the left knee {knee}"
    );
    assert!((knee.y - j(&s, "l_hip").y).abs() < 0.06, "thinker: seated");
    assert!(head.z > 0.15, "thinker: bent forward");
}

#[test]
fn directions_are_in_the_template_frame_and_twist_spins_the_bone() {
    let fit = fitted();
    let mut bones = BTreeMap::new();
    bones.insert(
        "l_forearm".to_string(),
        BonePose {
            direction: Some([0.0, 0.0, 2.0]),
            twist: Some(30.0),
            ..Default::default()
        },
    );
    bones.insert(
        "r_thigh".to_string(),
        BonePose {
            rotate: Some([1.0, 0.0, 0.0, -90.0]),
            ..Default::default()
        },
    );
    let pose = Pose {
        name: "t".into(),
        description: String::new(),
        base: PoseBase::Fitted,
        bones,
    };
    let s = pose.apply(&fit, src()).unwrap();
    let t = &fit.template;
    let fa = t.bone_index("l_forearm").unwrap();
    let (p0, p1) = (s.pose(), fit.pose());
    let dir = fit.root_rotation.inverse() * (p0.bones[fa].c2 - p0.bones[fa].c1).normalize();
    assert!(
        (dir - Vec3::Z).length() < 1e-5,
        "forearm points forward: {dir}"
    );
    // Twist: the frame's Y axis turned by 30° about the bone compared with no twist.
    let mut no_twist = pose.clone();
    no_twist.bones.get_mut("l_forearm").unwrap().twist = None;
    let s2 = no_twist.apply(&fit, src()).unwrap();
    let y_a = p0.frames[fa] * Vec3::Y;
    let y_b = s2.pose().frames[fa] * Vec3::Y;
    assert!((y_a.angle_between(y_b).to_degrees() - 30.0).abs() < 1e-2);
    // Rotate: the right thigh (pointing down at rest, fitted unchanged) turned -90° about +X
    // (the figure's left) swings forward.
    let th = t.bone_index("r_thigh").unwrap();
    let before = fit.root_rotation.inverse() * (p1.bones[th].c2 - p1.bones[th].c1).normalize();
    let after = fit.root_rotation.inverse() * (p0.bones[th].c2 - p0.bones[th].c1).normalize();
    assert!(before.y < -0.99);
    assert!(after.z > 0.99, "thigh forward: {after}");
    // Unnamed bones keep the fitted relative rotations with a Fitted base.
    let other = t.bone_index("l_upper_arm").unwrap();
    assert_eq!(s.bones[other].rotation, fit.bones[other].rotation);
}

#[test]
fn identity_pose_gives_back_the_fitted_skeleton_exactly() {
    // Through JSON, as the CLI does: the loaded skeleton need not satisfy the constraints to
    // the last bit, and identity must not touch it.
    let dir = crate::common::scratch("anatomy_pose_identity");
    let path = dir.join("fit.json");
    fitted().save_json(&path).unwrap();
    let fit = Skeleton::load_json(&path, None).unwrap();
    let s = Pose::resolve("identity")
        .unwrap()
        .apply(&fit, src())
        .unwrap();
    assert_eq!(s.bones, fit.bones);
    assert_eq!(s.root_position, fit.root_position);
    assert_eq!(s.root_rotation, fit.root_rotation);
    assert_eq!(s.pose(), fit.pose());
}

#[test]
fn unknown_and_constrained_bones_are_errors_naming_the_bone_and_the_file() {
    let dir = crate::common::scratch("anatomy_pose_errors");
    let file = dir.join("bad_pose.ron");
    std::fs::write(
        &file,
        r#"(name: "bad", bones: { "l_thig": (direction: (0.0, -1.0, 0.3)) })"#,
    )
    .unwrap();
    let pose = Pose::resolve(file.to_str().unwrap()).unwrap();
    let e = pose.apply(&fitted(), &file).unwrap_err().to_string();
    assert!(e.contains("bad_pose.ron"), "{e}");
    assert!(e.contains("l_thig"), "{e}");
    assert!(e.contains("l_thigh"), "suggests the closest names: {e}");

    for bone in ["pelvis_left", "neck_link"] {
        let text = format!(r#"(name: "c", bones: {{ "{bone}": (twist: 10.0) }})"#);
        let e = Pose::from_ron_str(&text, src())
            .unwrap()
            .apply(&fitted(), src())
            .unwrap_err()
            .to_string();
        assert!(e.contains(bone) && e.contains("test.ron"), "{e}");
    }

    // A typo in a field, or a missing file, is an error naming the file.
    let e = Pose::from_ron_str(
        r#"(name: "x", bones: { "head": (directon: (0, 1, 0)) })"#,
        src(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("test.ron") && e.contains("directon"), "{e}");
    let e = Pose::resolve("no/such/pose.ron").unwrap_err().to_string();
    assert!(
        e.contains("no/such/pose.ron") && e.contains("thinker"),
        "{e}"
    );
}

#[test]
fn non_finite_or_zero_numbers_are_errors() {
    for (body, what) in [
        ("direction: (NaN, 1.0, 0.0)", "not finite"),
        ("direction: (0.0, inf, 0.0)", "not finite"),
        ("direction: (0.0, 0.0, 0.0)", "zero length"),
        ("twist: NaN", "not finite"),
        ("rotate: (1.0, 0.0, 0.0, NaN)", "finite"),
        ("rotate: (0.0, 0.0, 0.0, 10.0)", "zero length"),
        (
            "direction: (0.0, 1.0, 0.0), rotate: (1.0, 0.0, 0.0, 10.0)",
            "not both",
        ),
    ] {
        let text = format!(r#"(name: "n", bones: {{ "head": ({body}) }})"#);
        let e = Pose::from_ron_str(&text, src()).unwrap_err().to_string();
        assert!(
            e.contains("test.ron") && e.contains("head") && e.contains(what),
            "{body}: {e}"
        );
    }
    // The same checks when the pose is built in code.
    let mut bones = BTreeMap::new();
    bones.insert(
        "head".to_string(),
        BonePose {
            direction: Some([f32::NAN, 0.0, 1.0]),
            ..Default::default()
        },
    );
    let pose = Pose {
        name: "code".into(),
        description: String::new(),
        base: PoseBase::Rest,
        bones,
    };
    let e = pose.apply(&fitted(), src()).unwrap_err().to_string();
    assert!(e.contains("not finite"), "{e}");
}

#[test]
fn interpolate_hits_the_endpoints_and_passes_between() {
    let a = fitted();
    let b = Pose::builtin("arms_raised")
        .unwrap()
        .apply(&a, src())
        .unwrap();
    let close = |x: &Skeleton, y: &Skeleton| {
        x.pose()
            .joints
            .iter()
            .zip(&y.pose().joints)
            .all(|(p, q)| (*p - *q).length() < 1e-6)
    };
    assert!(close(&interpolate(&a, &b, 0.0), &a));
    assert!(close(&interpolate(&a, &b, 1.0), &b));
    assert!(close(&interpolate(&a, &b, -1.0), &a), "clamped");
    let mid = interpolate(&a, &b, 0.5);
    let k = 1.7;
    let y = |s: &Skeleton| joint_local(s, "l_wrist", k).y;
    assert!(
        y(&a) < y(&mid) && y(&mid) < y(&b),
        "{} {} {}",
        y(&a),
        y(&mid),
        y(&b)
    );
    // Half-way rotations: the upper arm's angle to both endpoints is the same.
    let i = a.template.bone_index("l_upper_arm").unwrap();
    let (qa, qm, qb) = (
        a.bones[i].rotation,
        mid.bones[i].rotation,
        b.bones[i].rotation,
    );
    assert!((qa.angle_between(qm) - qm.angle_between(qb)).abs() < 1e-4);
    // Lengths are lerped.
    let mut longer = a.clone();
    longer.bones[i].length *= 2.0;
    let m = interpolate(&a, &longer, 0.25);
    assert!((m.bones[i].length - 1.25 * a.bones[i].length).abs() < 1e-6);
}

#[test]
fn proportions_change_the_named_lengths_and_radii() {
    let fit = fitted();
    let text = r#"(
        lengths: { "l_thigh": 1.5, "spine_upper": 2.0 },
        radii: { "l_upper_arm": 1.2 },
    )"#;
    let p = Proportions::from_ron_str(text, src()).unwrap();
    assert_eq!(p.scale, 1.0);
    let s = p.apply(&fit, src()).unwrap();
    let d = |s: &Skeleton, a: &str, b: &str| (s.joint(a).unwrap() - s.joint(b).unwrap()).length();
    let ratio = d(&s, "l_hip", "l_knee") / d(&fit, "l_hip", "l_knee");
    assert!((ratio - 1.5).abs() < 1e-4, "{ratio}");
    assert!((d(&s, "r_hip", "r_knee") - d(&fit, "r_hip", "r_knee")).abs() < 1e-5);
    // The neck link follows the spine.
    let ratio = d(&s, "spine_top", "neck") / d(&fit, "spine_top", "neck");
    assert!((ratio - 2.0).abs() < 1e-4, "{ratio}");
    let i = fit.template.bone_index("l_upper_arm").unwrap();
    assert!((s.bones[i].r1 / fit.bones[i].r1 - 1.2).abs() < 1e-5);
    assert!((s.bones[i].r2 / fit.bones[i].r2 - 1.2).abs() < 1e-5);

    // Uniform scale: every joint distance from the root doubles.
    let p = Proportions {
        scale: 2.0,
        ..Default::default()
    };
    let s = p.apply(&fit, src()).unwrap();
    let ratio = d(&s, "pelvis", "head_top") / d(&fit, "pelvis", "head_top");
    assert!((ratio - 2.0).abs() < 1e-4, "{ratio}");

    // Errors: unknown bone, bad factors, constrained lengths.
    let e = Proportions::from_ron_str(r#"(lengths: { "l_thumb": 1.1 })"#, src())
        .unwrap()
        .apply(&fit, src())
        .unwrap_err()
        .to_string();
    assert!(e.contains("l_thumb") && e.contains("test.ron"), "{e}");
    for text in [
        r#"(lengths: { "l_thigh": 0.05 })"#,
        r#"(radii: { "l_thigh": NaN })"#,
        r#"(scale: 11.0)"#,
    ] {
        assert!(Proportions::from_ron_str(text, src()).is_err(), "{text}");
    }
    let e = Proportions::from_ron_str(r#"(lengths: { "neck_link": 1.1 })"#, src())
        .unwrap()
        .apply(&fit, src())
        .unwrap_err()
        .to_string();
    assert!(e.contains("neck_link"), "{e}");
    // A file on disk.
    let dir = crate::common::scratch("anatomy_pose_proportions");
    let file = dir.join("long_legs.ron");
    std::fs::write(&file, r#"(scale: 1.0, lengths: { "l_shin": 1.3 })"#).unwrap();
    assert_eq!(Proportions::load(&file).unwrap().lengths["l_shin"], 1.3);
}

#[test]
fn proportion_files_load_and_apply() {
    let fit = fitted();
    let dir = crate::common::root().join("config/proportions");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "ron") {
            let p = Proportions::load(&path).unwrap_or_else(|e| panic!("{e}"));
            let s = p.apply(&fit, &path).unwrap_or_else(|e| panic!("{e}"));
            assert!(s.pose().joints.iter().all(|j| j.is_finite()));
            n += 1;
        }
    }
    assert!(n > 0, "no proportions file in {}", dir.display());
}

#[test]
fn repose_command_checks_the_pose_before_binding() {
    use pygmalion::cli::run;
    let dir = crate::common::scratch("anatomy_pose_cli");
    let fit = dir.join("fit.json");
    fitted().save_json(&fit).unwrap();
    let statue = crate::common::statues_dir().join("statue_dancing_faun_pompeii.ply");
    let out = dir.join("out.ply");
    let args = |pose: &str, extra: &[&str]| -> Vec<String> {
        let mut v: Vec<String> = [
            "pygmalion",
            "repose",
            statue.to_str().unwrap(),
            fit.to_str().unwrap(),
            pose,
            "--out",
            out.to_str().unwrap(),
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        v.extend(extra.iter().map(|s| s.to_string()));
        v
    };
    let e = run(args("dancing_wildly", &[])).unwrap_err().to_string();
    assert!(
        e.contains("dancing_wildly") && e.contains("no such pose"),
        "{e}"
    );

    let bad = dir.join("bad.ron");
    std::fs::write(&bad, r#"(name: "bad", bones: { "tail": (twist: 5.0) })"#).unwrap();
    let e = run(args(bad.to_str().unwrap(), &[]))
        .unwrap_err()
        .to_string();
    assert!(e.contains("bad.ron") && e.contains("tail"), "{e}");

    let e = run(args("walking", &["--method", "magic"]))
        .unwrap_err()
        .to_string();
    assert!(e.contains("magic"), "{e}");

    let props = dir.join("props.ron");
    std::fs::write(&props, r#"(lengths: { "wing": 1.2 })"#).unwrap();
    let e = run(args("walking", &["--proportions", props.to_str().unwrap()]))
        .unwrap_err()
        .to_string();
    assert!(e.contains("props.ron") && e.contains("wing"), "{e}");

    let e = run(args("walking", &["--template", "dragon"]))
        .unwrap_err()
        .to_string();
    assert!(e.contains("dragon"), "{e}");
    assert!(!out.exists(), "nothing written");
    // `--out` is required.
    assert!(
        run([
            "pygmalion",
            "repose",
            statue.to_str().unwrap(),
            fit.to_str().unwrap(),
            "walking"
        ])
        .is_err()
    );
}
