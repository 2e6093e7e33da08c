//! Tests of `anatomy::compare`: a fitted skeleton against a ground truth of another topology.

use pygmalion::Error;
use pygmalion::anatomy::compare::{JointGraph, point_segment_distance, skeleton_distance};
use pygmalion::anatomy::{Skeleton, Template};
use pygmalion::math::Vec3;
use std::sync::Arc;

fn graph(segments: &[([f32; 3], [f32; 3])]) -> JointGraph {
    let mut g = JointGraph::default();
    for (k, (a, b)) in segments.iter().enumerate() {
        let (a, b) = (Vec3::from(*a), Vec3::from(*b));
        g.segments.push((a, b));
        g.names.push(format!("j{k}a"));
        g.joints.push(a);
        g.names.push(format!("j{k}b"));
        g.joints.push(b);
    }
    g
}

#[test]
fn point_segment_distance_covers_the_body_the_ends_and_a_point_segment() {
    let (a, b) = (Vec3::ZERO, Vec3::new(2.0, 0.0, 0.0));
    assert!((point_segment_distance(Vec3::new(1.0, 0.5, 0.0), a, b) - 0.5).abs() < 1e-6);
    assert!((point_segment_distance(Vec3::new(-3.0, 4.0, 0.0), a, b) - 5.0).abs() < 1e-6);
    assert!((point_segment_distance(Vec3::new(5.0, 0.0, 4.0), a, b) - 5.0).abs() < 1e-6);
    assert!((point_segment_distance(Vec3::new(0.0, 3.0, 4.0), a, a) - 5.0).abs() < 1e-6);
}

#[test]
fn a_skeleton_is_at_distance_zero_from_itself_and_from_a_subdivided_copy() {
    let truth = graph(&[
        ([0.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
        ([0.0, 1.0, 0.0], [0.5, 1.5, 0.0]),
        ([0.0, 1.0, 0.0], [-0.5, 1.5, 0.2]),
    ]);
    let d = skeleton_distance(&truth, &truth).unwrap();
    // Zero up to rounding (a sample's lerp and its projection).
    assert!(
        d.truth_to_fit < 1e-6 && d.fit_to_truth < 1e-6 && d.joints == 0.0,
        "{d:?}"
    );
    assert!((d.extent - 1.5).abs() < 1e-6);
    // Another topology along the same curve: every segment split at a third.
    let mut split = JointGraph::default();
    for &(a, b) in &truth.segments {
        let m = a.lerp(b, 1.0 / 3.0);
        split.segments.extend([(a, m), (m, b)]);
        split.joints.extend([a, m, b]);
    }
    for (fit, truth) in [(&split, &truth), (&truth, &split)] {
        let d = skeleton_distance(fit, truth).unwrap();
        assert!(d.truth_to_fit < 1e-6 && d.fit_to_truth < 1e-6, "{d:?}");
    }
    // The truth's joints are all ends of the split bones; not the other way round.
    assert!(skeleton_distance(&split, &truth).unwrap().joints < 1e-6);
    // The first bone's split point is a third of a unit from both its ends.
    let d = skeleton_distance(&truth, &split).unwrap();
    assert!(
        d.joints > 0.05 && (d.worst_joint.1 - 1.0 / 3.0).abs() < 1e-6,
        "{d:?}"
    );
}

#[test]
fn an_offset_and_a_missing_bone_give_their_exact_distances() {
    let truth = graph(&[([0.0, 0.0, 0.0], [1.0, 0.0, 0.0])]);
    let fit = graph(&[([0.0, 0.1, 0.0], [1.0, 0.1, 0.0])]);
    let d = skeleton_distance(&fit, &truth).unwrap();
    for v in [d.truth_to_fit, d.fit_to_truth, d.joints, d.worst_joint.1] {
        assert!((v - 0.1).abs() < 1e-6, "{d:?}");
    }
    assert!((d.percent(d.truth_to_fit) - 10.0).abs() < 1e-4);
    // A truth bone the fit lacks: its samples are 0 to 1 away (mean 1/2), as many as the
    // first bone's (mean 0), so the mean is 1/4 one way and 0 the other.
    let truth = graph(&[
        ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0]),
        ([1.0, 0.0, 0.0], [1.0, 1.0, 0.0]),
    ]);
    let fit = graph(&[([0.0, 0.0, 0.0], [1.0, 0.0, 0.0])]);
    let d = skeleton_distance(&fit, &truth).unwrap();
    assert!((d.truth_to_fit - 0.25).abs() < 1e-6, "{d:?}");
    assert!(d.fit_to_truth < 1e-6, "{d:?}");
    assert!((d.worst_joint.1 - 1.0).abs() < 1e-6);
    assert_eq!(d.worst_joint.0, "j1b");
    // Nothing to compare.
    assert!(skeleton_distance(&JointGraph::default(), &truth).is_none());
    let point = graph(&[([1.0, 1.0, 1.0], [1.0, 1.0, 1.0])]);
    assert!(skeleton_distance(&fit, &point).is_none());
}

#[test]
fn rig_joint_files_and_fit_files_parse_and_a_fit_leaves_its_lost_bones_out() {
    let rig = r#"{"joints": {"j01": [0, 0, 0], "j02": [0, 2, 0], "j03": [1, 2, 0]},
                  "bones": [["j01", "j02"], ["j02", "j03"]]}"#;
    let g = JointGraph::parse(rig).unwrap();
    assert_eq!(g.segments.len(), 2);
    assert_eq!(
        g.segments[1],
        (Vec3::new(0.0, 2.0, 0.0), Vec3::new(1.0, 2.0, 0.0))
    );
    assert_eq!(g.extent(), 2.0);
    // A synthetic statue's truth (the skeleton JSON) and the same as a fit with a lost hand.
    let t = Arc::new(Template::builtin("human").unwrap());
    let s = Skeleton::rest(t.clone());
    let json = serde_json::to_value(s.to_json()).unwrap();
    let truth = JointGraph::parse(&json.to_string()).unwrap();
    assert_eq!(truth.segments.len(), t.bones.len());
    let mut fit = json.clone();
    fit["missing"] = serde_json::json!(["l_hand"]);
    let fit = JointGraph::parse(&fit.to_string()).unwrap();
    assert_eq!(fit.segments.len(), t.bones.len() - 1);
    let d = skeleton_distance(&fit, &truth).unwrap();
    assert!(d.fit_to_truth < 1e-6, "{d:?}");
    assert!(d.truth_to_fit > 1e-4, "{d:?}");
    // The hand's tip is the truth joint left without a fitted joint.
    let hand = s.pose().bones[t.bone_index("l_hand").unwrap()];
    assert!(
        (d.worst_joint.1 - (hand.c2 - hand.c1).length()).abs() < 1e-5,
        "{d:?}"
    );
}

#[test]
fn a_bad_skeleton_file_is_refused_with_its_name_and_problem() {
    for (text, needle) in [
        ("not json", "not a skeleton JSON file"),
        (r#"{"bones": []}"#, "no `joints`"),
        (r#"{"joints": {"a": [0, 0]}, "bones": []}"#, "joint `a`"),
        (r#"{"joints": {"a": [0, 0, 0]}}"#, "no `bones`"),
        (r#"{"joints": {"a": [0, 0, 0]}, "bones": []}"#, "no bones"),
        (
            r#"{"joints": {"a": [0, 0, 0]}, "bones": [["a", "b"]]}"#,
            "unknown joint `b`",
        ),
        (
            r#"{"joints": {"a": [0, 0, 0]}, "bones": [["a"]]}"#,
            "not a [parent, child] pair",
        ),
        (
            r#"{"joints": {"a": [0, 0, 0]}, "bones": [{"name": "x", "c1": [0, 0, 0]}]}"#,
            "bone 0 (x) has no finite `c2`",
        ),
    ] {
        let dir = crate::common::scratch("anatomy_compare_bad");
        let path = dir.join("skeleton.json");
        std::fs::write(&path, text).unwrap();
        match JointGraph::load(&path) {
            Err(e @ Error::Config { .. }) => {
                let msg = e.to_string();
                assert!(
                    msg.contains("skeleton.json") && msg.contains(needle),
                    "{msg}"
                );
            }
            other => panic!("{text}: {other:?}"),
        }
    }
    let missing = std::path::Path::new("/nonexistent/skeleton.json");
    assert!(matches!(JointGraph::load(missing), Err(Error::Io { .. })));
}

#[test]
fn the_compare_command_reads_both_files_and_names_a_bad_one() {
    let dir = crate::common::scratch("anatomy_compare_cli");
    let truth = dir.join("truth.json");
    let t = Arc::new(Template::builtin("human").unwrap());
    Skeleton::rest(t).save_json(&truth).unwrap();
    let rig = dir.join("rig.json");
    std::fs::write(
        &rig,
        r#"{"joints": {"a": [0, 0, 0], "b": [0, 1, 0]}, "bones": [["a", "b"]]}"#,
    )
    .unwrap();
    let run = |fit: &std::path::Path, truth: &std::path::Path| {
        pygmalion::cli::run([
            "pygmalion",
            "compare",
            fit.to_str().unwrap(),
            truth.to_str().unwrap(),
        ])
    };
    run(&truth, &truth).unwrap();
    run(&truth, &rig).unwrap();
    let bad = dir.join("bad.json");
    std::fs::write(&bad, r#"{"joints": {}, "bones": []}"#).unwrap();
    for (f, t) in [(&bad, &truth), (&truth, &bad)] {
        let e = run(f, t).unwrap_err().to_string();
        assert!(e.contains("bad.json") && e.contains("no bones"), "{e}");
    }
    let point = dir.join("point.json");
    std::fs::write(
        &point,
        r#"{"joints": {"a": [1, 1, 1]}, "bones": [["a", "a"]]}"#,
    )
    .unwrap();
    let e = run(&truth, &point).unwrap_err().to_string();
    assert!(e.contains("point.json") && e.contains("no extent"), "{e}");
}

/// The rigged wolf of the shared data (`skel_wolf_cragl`, 40k points, ground-truth skeleton of
/// 21 bones, other joints than the quadruped template's): registered with automatic placement,
/// its fit lies within 2.5% of the wolf's skeleton extent of the truth, both ways (measured
/// 2026-11-28: 1.39% and 1.52%; the rigged cow and Cheburashka, stylised, are much further,
/// see the README).
#[test]
fn the_rigged_wolf_is_fitted_close_to_its_ground_truth_skeleton() {
    let Some(data) = crate::common::shared_data() else {
        return;
    };
    let dir = crate::common::scratch("anatomy_compare_wolf");
    let fit = dir.join("wolf.json");
    let cloud = data.join("skel_wolf_cragl.ply");
    let args = [
        "pygmalion",
        "register",
        cloud.to_str().unwrap(),
        "--template",
        "quadruped",
        "--out",
        fit.to_str().unwrap(),
    ];
    pygmalion::cli::run(args).unwrap();
    let truth = JointGraph::load(&data.join("skel_wolf_cragl_joints.json")).unwrap();
    let d = skeleton_distance(&JointGraph::load(&fit).unwrap(), &truth).unwrap();
    let (a, b) = (d.percent(d.truth_to_fit), d.percent(d.fit_to_truth));
    assert!(
        a < 2.5 && b < 2.5,
        "truth → fit {a:.2}%, fit → truth {b:.2}%"
    );
}
