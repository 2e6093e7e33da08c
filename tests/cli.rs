//! Tests of the command line (`pygmalion::cli::run`): the commands succeed on good input, write
//! what they promise, and answer bad input with an error naming the file.

use pygmalion::cli::run;

fn args(list: &[&str]) -> Vec<String> {
    std::iter::once("pygmalion")
        .chain(list.iter().copied())
        .map(String::from)
        .collect()
}

#[test]
fn info_synth_normals_and_register_write_what_they_promise() {
    let dir = crate::common::scratch("cli");
    let statue = crate::common::statues_dir().join("statue_dancing_faun_pompeii.ply");
    run(args(&["info", statue.to_str().unwrap()])).unwrap();

    let synth = dir.join("synth.ply");
    let truth = dir.join("truth.json");
    run(args(&[
        "synth",
        synth.to_str().unwrap(),
        "--seed",
        "3",
        "--points",
        "3000",
        "--truth",
        truth.to_str().unwrap(),
        "--labels",
    ]))
    .unwrap();
    let cloud = pygmalion::cloud::ply::read_ply(&synth).unwrap();
    assert_eq!(cloud.len(), 3000);
    assert!(cloud.normals.is_some());

    let renormed = dir.join("normals.ply");
    run(args(&[
        "normals",
        synth.to_str().unwrap(),
        renormed.to_str().unwrap(),
        "--k",
        "12",
    ]))
    .unwrap();
    let again = pygmalion::cloud::ply::read_ply(&renormed).unwrap();
    assert_eq!(
        again.positions, cloud.positions,
        "points kept in input order"
    );

    let fit = dir.join("fit.json");
    let labels = dir.join("labels.ply");
    run(args(&[
        "register",
        synth.to_str().unwrap(),
        "--out",
        fit.to_str().unwrap(),
        "--labels",
        labels.to_str().unwrap(),
    ]))
    .unwrap();
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&fit).unwrap()).unwrap();
    assert_eq!(v["template"], "human");
    assert!(
        v["joints"]["l_knee"]
            .as_array()
            .is_some_and(|a| a.len() == 3)
    );
    assert_eq!(v["bones"].as_array().unwrap().len(), 22);
    // A complete statue: every bone's support, no lost limb.
    assert_eq!(v["support"].as_array().unwrap().len(), 22);
    assert_eq!(v["missing"].as_array().map(|a| a.len()), Some(0));
    assert!(
        v["mean_distance"]
            .as_f64()
            .is_some_and(|d| d.is_finite() && d >= 0.0)
    );
    assert_eq!(
        v["assignment"]
            .as_object()
            .unwrap()
            .values()
            .map(|c| c.as_u64().unwrap())
            .sum::<u64>(),
        3000
    );
    let (labelled, bone) =
        pygmalion::cloud::ply::read_ply_with_property(&labels, &Default::default(), "bone")
            .unwrap();
    assert_eq!(labelled.len(), 3000);
    assert!(bone.iter().all(|b| *b >= 0.0 && *b < 22.0));

    // `--start`: registration from the ground truth stays on it.
    let refit = dir.join("refit.json");
    run(args(&[
        "register",
        synth.to_str().unwrap(),
        "--start",
        truth.to_str().unwrap(),
        "--out",
        refit.to_str().unwrap(),
    ]))
    .unwrap();
    let t = pygmalion::anatomy::Skeleton::load_json(&truth, None).unwrap();
    let f = pygmalion::anatomy::Skeleton::load_json(&refit, None).unwrap();
    let err = f.mean_joint_distance(&t);
    assert!(
        err < 0.005,
        "refit from the truth drifted by {err} (height 1)"
    );
    let missing = dir.join("missing.json");
    let e = run(args(&[
        "register",
        synth.to_str().unwrap(),
        "--start",
        missing.to_str().unwrap(),
    ]))
    .unwrap_err()
    .to_string();
    assert!(e.contains("missing.json"), "{e}");
}

#[test]
fn fit_json_support_flags_agree_with_its_lists() {
    use pygmalion::anatomy::{Skeleton, Template};
    use pygmalion::cli::FitReport;
    use pygmalion::fakir::Fit;
    use std::sync::Arc;
    let t = Arc::new(Template::builtin("human").unwrap());
    let nb = t.bones.len();
    let bone = |name: &str| t.bone_index(name).unwrap();
    // Coverage bands as the support measured them: the head uncovered (a trunk bone, never
    // lost), the left forearm and hand covered but lost (laid over another part), the right
    // shin partly covered.
    let mut support = crate::common::full_support(&t);
    support[bone("head")].coverage = 0.3;
    support[bone("head")].missing = true;
    support[bone("r_shin")].coverage = 0.6;
    support[bone("r_shin")].partial = true;
    support[bone("l_forearm")].coverage = 0.6;
    support[bone("l_forearm")].partial = true;
    // The left arm broke part-way along the upper arm (its support reaches 0.4 of it); the
    // right hand was cut at the wrist (the forearm's support reaches through it).
    support[bone("l_upper_arm")].reach = 0.4;
    let mut missing = vec![false; nb];
    missing[bone("l_forearm")] = true;
    missing[bone("l_hand")] = true;
    missing[bone("r_hand")] = true;
    let fit = Fit {
        skeleton: Skeleton::rest(t.clone()),
        labels: Vec::new(),
        mean_distance: 0.0,
        base: None,
        bone_counts: vec![0; nb],
        iterations: 0,
        units: 0,
        candidate: 0,
        candidate_distances: Vec::new(),
        support,
        missing,
    };
    let v = serde_json::to_value(FitReport::new(&fit, std::path::Path::new("x.ply"))).unwrap();
    let names = |key: &str| -> Vec<String> {
        v[key]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_str().unwrap().to_string())
            .collect()
    };
    assert_eq!(names("missing"), ["l_forearm", "l_hand", "r_hand"]);
    // The uncovered head is not lost (a trunk bone): listed partial. So is the bone the left
    // arm broke on, covered but not through; not the right forearm.
    let mut partial = names("partial");
    partial.sort();
    assert_eq!(partial, ["head", "l_upper_arm", "r_shin"]);
    for s in v["support"].as_array().unwrap() {
        let b = s["bone"].as_str().unwrap().to_string();
        assert_eq!(
            s["missing"].as_bool(),
            Some(names("missing").contains(&b)),
            "{b}"
        );
        assert_eq!(
            s["partial"].as_bool(),
            Some(names("partial").contains(&b)),
            "{b}"
        );
    }
    // The coverage stays as measured.
    assert_eq!(
        v["support"][bone("head")]["coverage"].as_f64(),
        Some(0.3f32 as f64)
    );
}

#[test]
fn bad_input_is_an_error_naming_the_file() {
    let dir = crate::common::scratch("cli_bad");
    let bad = dir.join("broken.ply");
    std::fs::write(
        &bad,
        b"ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nend_header\n1\n",
    )
    .unwrap();
    for cmd in ["info", "register"] {
        let e = run(args(&[cmd, bad.to_str().unwrap()]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("broken.ply"), "{cmd}: {e}");
    }
    let good = crate::common::statues_dir().join("statue_dancing_faun_pompeii.ply");
    let e = run(args(&[
        "register",
        good.to_str().unwrap(),
        "--anchor",
        "1,2",
    ]))
    .unwrap_err()
    .to_string();
    assert!(e.contains("anchor"), "{e}");
    let e = run(args(&[
        "synth",
        dir.join("x.ply").to_str().unwrap(),
        "--template",
        "dragon",
    ]))
    .unwrap_err()
    .to_string();
    assert!(e.contains("dragon"), "{e}");
    let e = run(args(&["bench", "--only", "nothing/here"]))
        .unwrap_err()
        .to_string();
    assert!(e.contains("no benchmark"), "{e}");
    assert!(run(args(&["no-such-command"])).is_err());
}

/// `repose`, `picture` and `film` on a synthetic statue with its true skeleton: the outputs
/// exist with the promised sizes, the identity pose gives the points back, and bad requests
/// are refused before anything is written.
#[test]
fn repose_picture_and_film_write_what_they_promise() {
    let dir = crate::common::scratch("cli_repose");
    let synth = dir.join("synth.ply");
    let truth = dir.join("truth.json");
    run(args(&[
        "synth",
        synth.to_str().unwrap(),
        "--seed",
        "4",
        "--points",
        "4000",
        "--rest",
        "--truth",
        truth.to_str().unwrap(),
    ]))
    .unwrap();
    let (s, t) = (synth.to_str().unwrap(), truth.to_str().unwrap());
    let same = dir.join("same.ply");
    run(args(&[
        "repose",
        s,
        t,
        "identity",
        "--out",
        same.to_str().unwrap(),
    ]))
    .unwrap();
    let a = pygmalion::cloud::ply::read_ply(&synth).unwrap();
    let b = pygmalion::cloud::ply::read_ply(&same).unwrap();
    let moved = a
        .positions
        .iter()
        .zip(&b.positions)
        .map(|(p, q)| (*p - *q).length())
        .fold(0.0f32, f32::max);
    assert!(moved < 1e-5, "identity pose moved a point by {moved}");

    let pic = dir.join("cmp.png");
    run(args(&[
        "picture",
        s,
        "--fit",
        t,
        "--pose",
        "greeting",
        "--out",
        pic.to_str().unwrap(),
        "--width",
        "120",
        "--height",
        "200",
    ]))
    .unwrap();
    let img = pygmalion::render::Image::load_png(&pic).unwrap();
    // Five panels (statue + four methods) of 120 px with 8 px gaps.
    assert_eq!((img.width, img.height), (5 * 120 + 4 * 8, 200));
    let lit = img.rgb.chunks(3).filter(|c| c[0] > 120).count();
    assert!(
        lit > 5 * 300,
        "the panels show the statue ({lit} lit pixels)"
    );

    let film = dir.join("film");
    run(args(&[
        "film",
        s,
        t,
        "greeting",
        "--out",
        film.to_str().unwrap(),
        "--frames",
        "3",
        "--width",
        "64",
        "--height",
        "96",
    ]))
    .unwrap();
    for f in 0..3 {
        assert!(film.join(format!("frame_{f:04}.png")).is_file());
    }

    // Bad requests: a pose without a fit, an unknown method, zero frames.
    let bad = dir.join("bad.png");
    assert!(
        run(args(&[
            "picture",
            s,
            "--pose",
            "greeting",
            "--out",
            bad.to_str().unwrap()
        ]))
        .is_err()
    );
    let err = run(args(&[
        "picture",
        s,
        "--fit",
        t,
        "--pose",
        "greeting",
        "--method",
        "wobble",
        "--out",
        bad.to_str().unwrap(),
    ]))
    .unwrap_err()
    .to_string();
    assert!(err.contains("wobble"), "{err}");
    assert!(
        run(args(&[
            "film",
            s,
            t,
            "greeting",
            "--out",
            film.to_str().unwrap(),
            "--frames",
            "0"
        ]))
        .is_err()
    );
    assert!(!bad.exists());
}

#[cfg(unix)]
#[test]
fn printing_into_a_closed_pipe_ends_quietly() {
    use std::process::{Command, Stdio};
    // `pygmalion info X | head -0`: the reader is gone before the first line is printed.
    let statue = crate::common::statues_dir().join("statue_dancing_faun_pompeii.ply");
    let mut child = Command::new(env!("CARGO_BIN_EXE_pygmalion"))
        .args(["info", statue.to_str().unwrap()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
}
