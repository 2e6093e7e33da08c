//! Tests of `anatomy`: templates (loading, validation, the human's joints), skeleton forward
//! kinematics, constraints and JSON.

use pygmalion::Error;
use pygmalion::anatomy::template::BUILTIN_TEMPLATES;
use pygmalion::anatomy::{BoneKind, Skeleton, Template};
use pygmalion::math::{Quat, Vec3};
use pygmalion::rng::Rng;
use std::path::Path;
use std::sync::Arc;

fn human() -> Arc<Template> {
    Arc::new(Template::builtin("human").expect("human template"))
}

#[test]
fn builtin_templates_load_and_match_the_config_files() {
    for name in BUILTIN_TEMPLATES {
        let t = Template::builtin(name).unwrap_or_else(|e| panic!("{name}: {e}"));
        let path = crate::common::root().join(format!("config/templates/{name}.toml"));
        let from_disk = Template::load(&path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(t.bones.len(), from_disk.bones.len());
        assert!(
            (t.height - 1.0).abs() < 0.06,
            "{name}: height {} is not about 1",
            t.height
        );
        // Every free bone is in exactly one chain; consecutive chain bones share their radius.
        for c in &t.chains {
            for w in c.bones.windows(2) {
                let (a, b) = (&t.bones[w[0]], &t.bones[w[1]]);
                if b.parent == Some(w[0]) {
                    assert_eq!(a.r2, b.r1, "{name}: {} / {}", a.name, b.name);
                }
            }
        }
        for b in &t.bones {
            assert!(b.r1 > 0.0 && b.r2 > 0.0);
            assert_eq!(
                b.kind == BoneKind::Free,
                b.chain.is_some(),
                "{name}: {}",
                b.name
            );
        }
    }
}

#[test]
fn human_template_has_22_bones_five_chains_and_anatomical_joints() {
    let t = human();
    assert_eq!(t.bones.len(), 22);
    assert_eq!(t.chains.len(), 5);
    assert_eq!(t.block_bones().count(), 3, "the pelvis triplet");
    let link = &t.bones[t.bone_index("neck_link").unwrap()];
    assert!(
        matches!(link.kind, BoneKind::Follower { leader, .. } if t.bones[leader].name == "spine_upper")
    );
    let j = |n: &str| t.joints[t.joint_index(n).unwrap_or_else(|| panic!("joint {n}"))].rest;
    for n in [
        "pelvis",
        "spine_mid",
        "neck",
        "head_top",
        "l_shoulder",
        "r_shoulder",
        "l_elbow",
        "r_elbow",
        "l_wrist",
        "r_wrist",
        "l_hand_tip",
        "r_hand_tip",
        "l_hip",
        "r_hip",
        "l_knee",
        "r_knee",
        "l_ankle",
        "r_ankle",
        "l_toe",
        "r_toe",
    ] {
        j(n);
    }
    // The pelvis is midway between the hips; l_ is the figure's own left (+X, facing +Z).
    assert!((j("pelvis") - 0.5 * (j("l_hip") + j("r_hip"))).length() < 1e-6);
    for side in [
        "hip", "knee", "ankle", "toe", "shoulder", "elbow", "wrist", "hand_tip",
    ] {
        let (l, r) = (j(&format!("l_{side}")), j(&format!("r_{side}")));
        assert!(l.x > 0.0 && r.x < 0.0, "{side}");
        assert!(
            (l - Vec3::new(-r.x, r.y, r.z)).length() < 1e-6,
            "{side} is not symmetric"
        );
    }
    // Vertical order of a standing figure.
    let order = [
        "l_toe",
        "l_ankle",
        "l_knee",
        "l_hip",
        "spine_mid",
        "neck",
        "head_top",
    ];
    for w in order.windows(2) {
        assert!(j(w[0]).y < j(w[1]).y, "{} below {}", w[0], w[1]);
    }
    assert!(j("l_elbow").y < j("l_shoulder").y && j("l_wrist").y < j("l_elbow").y);
    assert!(j("l_toe").z > j("l_ankle").z, "toes point forward (+Z)");
    // Chains in registration order: spine, legs, arms; mirrors pair left and right.
    let names: Vec<&str> = t.chains.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["spine", "l_leg", "r_leg", "l_arm", "r_arm"]);
    assert_eq!(t.chains[1].mirror, Some(2));
    assert_eq!(t.chains[3].mirror, Some(4));
}

#[test]
fn other_templates_have_their_distinctive_chains() {
    let q = Template::builtin("quadruped").unwrap();
    assert!(q.chain_index("tail").is_some());
    assert_eq!(
        q.chains.iter().filter(|c| c.name.contains("leg")).count(),
        4
    );
    let c = Template::builtin("centaur").unwrap();
    assert_eq!(
        c.chains.iter().filter(|c| c.name.contains("leg")).count(),
        4
    );
    assert!(c.chain_index("l_arm").is_some() && c.chain_index("r_arm").is_some());
    let m = Template::builtin("mermaid").unwrap();
    assert!(m.chain_index("tail").is_some());
    assert_eq!(
        m.chains.iter().filter(|c| c.name.contains("leg")).count(),
        0,
        "one tail chain instead of legs"
    );
}

const MINI: &str = r#"
name = "mini"
root = "a"
[[joints]]
name = "a"
at = [0, 0, 0]
[[joints]]
name = "b"
at = [0, 1, 0]
[[joints]]
name = "c"
at = [0, 2, 0]
[[bones]]
name = "ab"
from = "a"
to = "b"
r1 = 0.2
r2 = 0.1
[[bones]]
name = "bc"
from = "b"
to = "c"
r1 = 0.1
r2 = 0.1
[[chains]]
name = "main"
bones = ["ab", "bc"]
"#;

fn expect_config_error(text: &str, needle: &str) {
    let path = Path::new("broken_template.toml");
    match Template::from_toml(text, path) {
        Err(Error::Config { path: p, problem }) => {
            assert_eq!(p, path);
            assert!(
                problem.contains(needle),
                "expected '{needle}' in '{problem}'"
            );
            let shown = Error::Config { path: p, problem }.to_string();
            assert!(shown.contains("broken_template.toml"));
        }
        Err(e) => panic!("expected a config error containing '{needle}', got {e}"),
        Ok(_) => panic!("expected a config error containing '{needle}', got a template"),
    }
}

#[test]
fn template_validation_errors_are_clear() {
    assert!(Template::from_toml(MINI, Path::new("mini.toml")).is_ok());
    expect_config_error(
        &MINI.replace("r2 = 0.1\n[[bones]]", "r2 = -0.1\n[[bones]]"),
        "positive",
    );
    expect_config_error(&MINI.replace("to = \"c\"", "to = \"b\""), "ends two bones");
    expect_config_error(
        &MINI.replace("from = \"b\"", "from = \"x\""),
        "unknown joint 'x'",
    );
    expect_config_error(
        &MINI.replace("root = \"a\"", "root = \"z\""),
        "root joint 'z'",
    );
    expect_config_error(
        &MINI.replace("bones = [\"ab\", \"bc\"]", "bones = [\"ab\"]"),
        "in no chain",
    );
    expect_config_error(
        &MINI.replace("bones = [\"ab\", \"bc\"]", "bones = [\"bc\", \"ab\"]"),
        "does not start where",
    );
    expect_config_error(
        &MINI.replace("r1 = 0.1\nr2 = 0.1", "r1 = 0.15\nr2 = 0.1"),
        "share their joint radius",
    );
    expect_config_error(
        &MINI.replace("name = \"bc\"", "name = \"ab\""),
        "defined twice",
    );
    expect_config_error(
        &MINI.replace("at = [0, 2, 0]", "at = [0, 1, 0]"),
        "zero length",
    );
    expect_config_error(
        &MINI.replace(
            "r2 = 0.1\n[[bones]]",
            "r2 = 0.1\nblock = true\nfrobnicate = 1\n[[bones]]",
        ),
        "invalid template",
    );
    expect_config_error(
        &MINI.replace(
            "name = \"bc\"\nfrom = \"b\"",
            "name = \"bc\"\nblock = true\nfrom = \"b\"",
        ),
        "must start at the root",
    );
    expect_config_error("this is not toml = = =", "invalid template");
    // The bust's lost limbs must be bones of the template.
    let with_bust =
        |names: &str| MINI.replace("root = \"a\"", &format!("root = \"a\"\nbust = [{names}]"));
    expect_config_error(&with_bust("\"bc\", \"hand\""), "bust: unknown bone 'hand'");
    let t = Template::from_toml(&with_bust("\"bc\""), Path::new("mini.toml")).unwrap();
    assert_eq!(t.bust, ["bc"]);
    assert!(
        Template::from_toml(MINI, Path::new("mini.toml"))
            .unwrap()
            .bust
            .is_empty()
    );
    assert_eq!(
        Template::builtin("human").unwrap().bust,
        ["l_upper_arm", "r_upper_arm", "l_thigh", "r_thigh"]
    );
    // Two joints ending each other's bones: a cycle the root never reaches.
    let cycle = format!(
        "{MINI}\n[[joints]]\nname = \"x\"\nat = [1, 0, 0]\n[[joints]]\nname = \"y\"\nat = [2, 0, 0]\n\
         [[bones]]\nname = \"xy\"\nfrom = \"x\"\nto = \"y\"\nr1 = 0.1\nr2 = 0.1\n\
         [[bones]]\nname = \"yx\"\nfrom = \"y\"\nto = \"x\"\nr1 = 0.1\nr2 = 0.1\n"
    );
    expect_config_error(&cycle, "not connected to the root: xy, yx");
    expect_config_error(&MINI.replace("r1 = 0.2", "r1 = 1.5"), "contains the other");
    // A missing file names the file.
    match Template::load("/nonexistent/dir/t.toml") {
        Err(e) => assert!(e.to_string().contains("/nonexistent/dir/t.toml")),
        Ok(_) => panic!("loaded a missing file"),
    }
    assert!(
        Template::builtin("dragon")
            .unwrap_err()
            .to_string()
            .contains("dragon")
    );
}

#[test]
fn rest_pose_forward_kinematics_reproduces_the_template() {
    for name in BUILTIN_TEMPLATES {
        let t = Arc::new(Template::builtin(name).unwrap());
        let posed = Skeleton::rest(t.clone()).pose();
        for (j, p) in t.joints.iter().zip(&posed.joints) {
            assert!(
                (j.rest - *p).length() < 1e-5,
                "{name}: joint {} at {p} instead of {}",
                j.name,
                j.rest
            );
        }
        for (b, geo) in t.bones.iter().zip(&posed.bones) {
            assert_eq!((geo.r1, geo.r2), (b.r1, b.r2));
        }
    }
}

fn random_skeleton(seed: u64) -> Skeleton {
    let mut rng = Rng::new(seed);
    let mut s = Skeleton::rest(human());
    pygmalion::synth::random_pose(&mut s, &mut rng);
    s.scale_sizes(1.7);
    s.transform_rigid(
        pygmalion::synth::random_rotation(&mut rng),
        Vec3::new(3.0, -2.0, 0.5),
    );
    s
}

#[test]
fn skeleton_json_round_trip() {
    let dir = crate::common::scratch("anatomy_json");
    for seed in 0..5 {
        let s = random_skeleton(seed);
        let path = dir.join(format!("s{seed}.json"));
        s.save_json(&path).unwrap();
        let back = Skeleton::load_json(&path, None).unwrap();
        let (a, b) = (s.pose(), back.pose());
        for (x, y) in a.joints.iter().zip(&b.joints) {
            assert!((*x - *y).length() < 1e-5, "joint moved in the round trip");
        }
        for (x, y) in a.frames.iter().zip(&b.frames) {
            assert!(
                x.dot(*y).abs() > 1.0 - 1e-5,
                "frame changed in the round trip"
            );
        }
        // The JSON names joints and bones.
        let text = std::fs::read_to_string(&path).unwrap();
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert!(
            v["joints"]["l_knee"]
                .as_array()
                .is_some_and(|a| a.len() == 3)
        );
        assert_eq!(v["bones"].as_array().unwrap().len(), 22);
        assert!(v["bones"][0]["c1"].is_array() && v["bones"][0]["r1"].is_number());
    }
    // Without frames or root rotation, joints still come back exactly.
    let s = random_skeleton(9);
    let mut json = s.to_json();
    for b in &mut json.bones {
        b.frame = None;
    }
    json.root_rotation = None;
    json.block_scale = None;
    let back = Skeleton::from_json(human(), &json, Path::new("mem.json")).unwrap();
    for (x, y) in s.pose().joints.iter().zip(&back.pose().joints) {
        assert!((*x - *y).length() < 1e-4);
    }
    // Errors name the file.
    let bad = dir.join("bad.json");
    std::fs::write(&bad, "{ not json").unwrap();
    assert!(
        Skeleton::load_json(&bad, None)
            .unwrap_err()
            .to_string()
            .contains("bad.json")
    );
    let mut wrong = s.to_json();
    wrong.bones.pop();
    let e = Skeleton::from_json(human(), &wrong, Path::new("wrong.json"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("missing") && e.contains("wrong.json"), "{e}");
    let mut nan = s.to_json();
    nan.bones[3].c1[0] = f32::NAN;
    assert!(Skeleton::from_json(human(), &nan, Path::new("nan.json")).is_err());
}

#[test]
fn constraints_and_rigid_motion() {
    let t = human();
    let mut s = Skeleton::rest(t.clone());
    let rest = s.clone();
    s.block_scale = 1.5;
    let up = t.bone_index("spine_upper").unwrap();
    s.bones[up].length *= 2.0;
    s.enforce_constraints();
    for b in t.block_bones() {
        assert!((s.bones[b].length - 1.5 * rest.bones[b].length).abs() < 1e-6);
    }
    let link = t.bone_index("neck_link").unwrap();
    let ratio = s.bones[link].length / s.bones[up].length;
    assert!((ratio - rest.bones[link].length / rest.bones[up].length).abs() < 1e-6);

    // A rigid motion moves every joint rigidly.
    let s = random_skeleton(3);
    let mut m = s.clone();
    let q = Quat::from_axis_angle(Vec3::new(1.0, 2.0, 3.0).normalize(), 1.1);
    let tr = Vec3::new(10.0, 0.0, -4.0);
    m.transform_rigid(q, tr);
    for (a, b) in s.pose().joints.iter().zip(&m.pose().joints) {
        assert!(((q * *a + tr) - *b).length() < 1e-4);
    }
}

#[test]
fn a_skeletons_up_is_the_templates_up_carried_by_its_root() {
    let mut s = Skeleton::rest(human());
    assert!((s.up() - Vec3::Y).length() < 1e-6);
    let q = Quat::from_axis_angle(Vec3::new(1.0, 0.2, -0.5).normalize(), 0.8);
    s.transform_rigid(q, Vec3::new(3.0, -1.0, 2.0));
    assert!((s.up() - q * Vec3::Y).length() < 1e-5);
}
