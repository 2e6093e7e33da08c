//! `config/kiosk.toml` (`src/kiosk/config.rs`): the shipped file is clean, and every kind of
//! mistake falls back to a default with a message naming the file — the kiosk always starts.

use pygmalion::kiosk::config::{KioskConfig, stays_inside};
use pygmalion::skinning::Method;
use std::path::Path;

#[test]
fn the_shipped_configuration_is_clean_and_matches_the_defaults() {
    let path = crate::common::root().join("config/kiosk.toml");
    let c = KioskConfig::load(&path);
    assert!(c.problems.is_empty(), "{:?}", c.problems);
    let d = KioskConfig::default();
    assert_eq!(c.statues, d.statues);
    assert_eq!(c.idle, d.idle);
    assert_eq!(c.skinning, d.skinning);
    for s in &c.statues {
        assert!(
            crate::common::root()
                .join(&c.assets_root)
                .join(&s.file)
                .is_file(),
            "{}",
            s.file.display()
        );
    }
    // Every pose on the strip resolves.
    for p in &c.skinning.poses {
        pygmalion::anatomy::Pose::resolve(p).unwrap();
    }
}

#[test]
fn mistakes_fall_back_to_defaults_and_are_reported() {
    let file = Path::new("museum/kiosk.toml");
    let text = r#"
assets_root = "assets"
colour = "red"

[[statues]]
file = "../../etc/passwd"

[[statues]]
file = "/abs/statue.ply"

[[statues]]
file = "statues/a.ply"
title = 12

[idle]
attract_after_s = -5
still_there_after_s = 10
countdown_s = "soon"

[budget]
fakir_ms_per_frame = 1e9
point_budget = 12.5

[skinning]
method = "wobbly"
poses = [1, 2]

[render]
background = [300, 0, 0]
edl = "yes"

[window]
width = 10
"#;
    let c = KioskConfig::from_toml(text, file);
    let d = KioskConfig::default();
    let all = c.problems.join("\n");
    for p in &c.problems {
        assert!(p.starts_with("museum/kiosk.toml: "), "{p}");
    }
    for key in [
        "colour",
        "statues[0]",
        "statues[1]",
        "statues[2].title",
        "idle.attract_after_s",
        "idle.countdown_s",
        "budget.fakir_ms_per_frame",
        "budget.point_budget",
        "skinning.method",
        "skinning.poses",
        "render.background",
        "render.edl",
        "window.width",
    ] {
        assert!(all.contains(key), "no message about {key}:\n{all}");
    }
    // Only the statue inside the root is kept; bad values took their defaults.
    assert_eq!(c.statues.len(), 1);
    assert_eq!(c.statues[0].file, Path::new("statues/a.ply"));
    assert_eq!(c.statues[0].title, "a");
    assert_eq!(c.idle.attract_after_s, d.idle.attract_after_s);
    // still_there (10) < attract (60): raised to attract, and said so.
    assert_eq!(c.idle.still_there_after_s, c.idle.attract_after_s);
    assert!(all.contains("still_there_after_s"));
    assert_eq!(c.budget, d.budget);
    assert_eq!(c.skinning.method, Method::Baseline);
    assert_eq!(c.render.background, d.render.background);
    assert_eq!(c.window.width, d.window.width);
}

#[test]
fn broken_or_missing_files_give_the_defaults() {
    let c = KioskConfig::from_toml("this is = = not toml", Path::new("k.toml"));
    assert_eq!(c.statues, KioskConfig::default().statues);
    assert!(c.problems[0].contains("k.toml") && c.problems[0].contains("TOML"));
    let c = KioskConfig::load(Path::new("/nonexistent/kiosk.toml"));
    assert!(c.problems[0].contains("/nonexistent/kiosk.toml"));
    assert!(!c.statues.is_empty());
}

#[test]
fn statue_paths_must_stay_inside_the_root() {
    assert!(stays_inside(Path::new("statues/a.ply")));
    assert!(stays_inside(Path::new("./a.ply")));
    assert!(!stays_inside(Path::new("../a.ply")));
    assert!(!stays_inside(Path::new("statues/../../a.ply")));
    assert!(!stays_inside(Path::new("/a.ply")));
    assert!(!stays_inside(Path::new("")));
}

#[test]
fn a_statues_facing_and_lost_limbs_are_read_and_checked() {
    let file = Path::new("museum/kiosk.toml");
    let text = r#"
[[statues]]
file = "statues/venus.ply"
front = "-z"
missing = ["l_upper_arm", "r_forearm"]

[[statues]]
file = "statues/bust.ply"
front = "sideways"
missing = ["l_uper_arm", "spine_upper", 3, "r_thigh"]

[[statues]]
file = "statues/other.ply"
missing = "l_upper_arm"
"#;
    let c = KioskConfig::from_toml(text, file);
    let all = c.problems.join("\n");
    assert_eq!(c.statues.len(), 3);
    assert_eq!(c.statues[0].front.as_deref(), Some("-z"));
    assert_eq!(c.statues[0].missing, ["l_upper_arm", "r_forearm"]);
    // A bad axis, a misspelt bone (with the closest name), a trunk bone and a number are
    // reported and left out; the good name stays.
    assert_eq!(c.statues[1].front, None);
    assert_eq!(c.statues[1].missing, ["r_thigh"]);
    assert!(all.contains("statues[1].front"), "{all}");
    assert!(
        all.contains("unknown bone 'l_uper_arm'") && all.contains("l_upper_arm"),
        "{all}"
    );
    assert!(all.contains("'spine_upper' is part of the trunk"), "{all}");
    assert!(all.contains("expected a bone name, not 3"), "{all}");
    // Not a list: ignored.
    assert!(c.statues[2].missing.is_empty());
    assert!(all.contains("statues[2].missing"), "{all}");
    assert_eq!(c.problems.len(), 5, "{all}");
}
