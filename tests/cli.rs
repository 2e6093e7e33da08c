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
