//! Virtual restoration (`src/restore`): support and missing bones, part transfer, merge — on
//! synthetic statues whose skeletons are known, so what is measured is the restoration itself.

use pygmalion::anatomy::Template;
use pygmalion::fakir::support::support;
use pygmalion::geometry::Bone;
use pygmalion::math::Vec3;
use pygmalion::restore::transfer::PoseSource;
use pygmalion::restore::{Donor, FROM_TARGET, RestoreOptions, Restored, restore};
use pygmalion::rng::Rng;
use pygmalion::synth::{Cut, SynthOptions, SynthStatue, generate};
use std::sync::Arc;

/// A synthetic human of 20,000 points (height 1) with `cuts` (the generator's syntax).
pub(crate) fn statue(seed: u64, cuts: &[&str]) -> SynthStatue {
    let t = Arc::new(Template::builtin("human").unwrap());
    generate(
        t,
        &SynthOptions {
            points: 20_000,
            seed,
            cuts: cuts.iter().map(|c| Cut::parse(c).unwrap()).collect(),
            ..Default::default()
        },
    )
    .unwrap()
}

/// A synthetic statue as a donor, its truth as its fit, its missing bones judged by support.
pub(crate) fn donor_of(d: &SynthStatue) -> Donor<'_> {
    Donor {
        name: "donor".into(),
        cloud: &d.cloud,
        fit: &d.truth,
        missing: None,
    }
}

/// `target` (its truth as its fit) restored from `donor` in the target's pose
/// ([`PoseSource::Keep`]), every target point kept.
pub(crate) fn restore_keeping_pose(target: &SynthStatue, donor: &SynthStatue) -> Restored {
    let r = restore(
        &target.cloud,
        &target.truth,
        &[donor_of(donor)],
        &RestoreOptions {
            pose: PoseSource::Keep,
            ..Default::default()
        },
    )
    .unwrap();
    let n_target = r.source.iter().filter(|&&s| s == FROM_TARGET).count();
    assert_eq!(n_target, target.cloud.len(), "every target point is kept");
    r
}

/// A random point of bone `k`'s surface outside every other bone (`None` when hidden), and
/// whether a point of `cloud` lies within `tol` of it.
pub(crate) fn visible_sample(
    bones: &[pygmalion::geometry::bone::PreparedBone],
    k: usize,
    cloud: &[Vec3],
    tol: f32,
    rng: &mut Rng,
) -> Option<(Vec3, bool)> {
    let (p, _) = bones[k].sample_surface(rng);
    if bones
        .iter()
        .enumerate()
        .any(|(j, b)| j != k && b.sdf_fast(p) < 0.0)
    {
        return None;
    }
    Some((p, cloud.iter().any(|q| (*q - p).length() < tol)))
}

fn missing(st: &SynthStatue) -> Vec<String> {
    support(&st.cloud, &st.truth)
        .unwrap()
        .into_iter()
        .filter(|b| b.missing)
        .map(|b| b.bone)
        .collect()
}

#[test]
fn the_missing_bones_are_the_cut_ones() {
    let full = statue(5, &[]);
    assert!(missing(&full).is_empty(), "{:?}", missing(&full));
    let st = statue(5, &["bone:l_forearm", "bone:l_hand"]);
    assert_eq!(missing(&st), ["l_forearm", "l_hand"]);
    let st = statue(8, &["bone:r_shin", "bone:r_foot"]);
    assert_eq!(missing(&st), ["r_shin", "r_foot"]);
}

/// Signed distance to the union of a skeleton's bones.
pub(crate) fn sdf(p: Vec3, bones: &[pygmalion::geometry::bone::PreparedBone]) -> f32 {
    bones
        .iter()
        .map(|b| b.sdf_fast(p))
        .fold(f32::INFINITY, f32::min)
}

#[test]
fn a_cut_forearm_is_restored_from_a_different_donor_in_a_single_layer() {
    let target = statue(5, &["bone:l_forearm", "bone:l_hand"]);
    let donor = statue(9, &[]);
    let r = restore_keeping_pose(&target, &donor);
    assert_eq!(r.report.parts.len(), 1);
    assert_eq!(r.report.parts[0].bones, ["l_forearm", "l_hand"]);
    let posed = r.skeleton.pose();
    let bones: Vec<_> = posed.bones.iter().map(Bone::prepare).collect();
    // The new points lie on the completed statue's surface (height 1).
    let mut d: Vec<f32> = r
        .cloud
        .positions
        .iter()
        .zip(&r.source)
        .filter(|(_, s)| **s != FROM_TARGET)
        .map(|(p, _)| sdf(*p, &bones).abs())
        .collect();
    d.sort_by(f32::total_cmp);
    let p95 = d[d.len() * 95 / 100];
    println!(
        "donor points: {}, |distance| median {:.5} p95 {:.5}",
        d.len(),
        d[d.len() / 2],
        p95
    );
    assert!(p95 < 0.004, "p95 distance to the surface {p95}");
    // Single layer at the seam: every point of the overlap is on the surface.
    let stats = r.report.parts[0].merge;
    println!("{stats:?}");
    assert!(stats.overlap_points > 50);
    // Coverage: the restored forearm and hand's visible surface is covered.
    let tol = 3.0 * stats.rho;
    let mut rng = Rng::new(3);
    let (mut seen, mut hit) = (0, 0);
    for name in ["l_forearm", "l_hand"] {
        let k = r
            .skeleton
            .template
            .bones
            .iter()
            .position(|b| b.name == name)
            .unwrap();
        for _ in 0..400 {
            if let Some((_, covered)) = visible_sample(&bones, k, &r.cloud.positions, tol, &mut rng)
            {
                seen += 1;
                hit += usize::from(covered);
            }
        }
    }
    let coverage = hit as f32 / seen as f32;
    println!("coverage of the restored part: {coverage:.3}");
    assert!(coverage > 0.9, "coverage {coverage}");
}

/// The `restore` command: provenance in the PLY, the JSON report, and clear refusals.
#[test]
fn restore_command_writes_provenance_and_refuses_impossible_requests() {
    use pygmalion::cli::run;
    use pygmalion::cloud::ply::{WriteOptions, read_ply_with_property, write_ply};
    let dir = crate::common::scratch("restore_cli");
    let target = statue(5, &["bone:l_forearm", "bone:l_hand"]);
    let donor = statue(9, &[]);
    let broken_donor = statue(9, &["bone:l_forearm", "bone:l_hand"]);
    let p = |n: &str| dir.join(n).to_str().unwrap().to_string();
    write_ply(p("t.ply"), &target.cloud, &WriteOptions::default()).unwrap();
    write_ply(p("d.ply"), &donor.cloud, &WriteOptions::default()).unwrap();
    write_ply(p("b.ply"), &broken_donor.cloud, &WriteOptions::default()).unwrap();
    target.truth.save_json(p("t.json")).unwrap();
    donor.truth.save_json(p("d.json")).unwrap();
    broken_donor.truth.save_json(p("b.json")).unwrap();
    let args = |extra: &[&str]| -> Vec<String> {
        ["pygmalion", "restore"]
            .iter()
            .map(|s| s.to_string())
            .chain(extra.iter().map(|s| s.to_string()))
            .collect()
    };
    run(args(&[
        &p("t.ply"),
        "--fit",
        &p("t.json"),
        "--donor",
        &p("d.ply"),
        "--donor-fit",
        &p("d.json"),
        "--out",
        &p("out.ply"),
        "--report",
        &p("r.json"),
    ]))
    .unwrap();
    let (cloud, prov) = read_ply_with_property(
        p("out.ply"),
        &pygmalion::cloud::ply::ReadOptions::default(),
        "provenance",
    )
    .unwrap();
    let prov: Vec<u32> = prov.iter().map(|&v| v as u32).collect();
    assert_eq!(cloud.len(), prov.len());
    let from_donor = prov.iter().filter(|&&v| v >= 256).count();
    assert_eq!(cloud.len() - from_donor, target.cloud.len());
    let forearm = target
        .truth
        .template
        .bones
        .iter()
        .position(|b| b.name == "l_forearm")
        .unwrap();
    assert!(
        prov.iter().any(|&v| v == 256 + forearm as u32),
        "donor forearm points are labelled"
    );
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(p("r.json")).unwrap()).unwrap();
    assert_eq!(report["parts"][0]["bones"][0], "l_forearm");
    assert_eq!(report["three_delta_over_rho"], 10.0);
    // A donor without that part.
    let err = run(args(&[
        &p("t.ply"),
        "--fit",
        &p("t.json"),
        "--donor",
        &p("b.ply"),
        "--donor-fit",
        &p("b.json"),
        "--out",
        &p("x.ply"),
    ]))
    .unwrap_err()
    .to_string();
    assert!(err.contains("l_forearm") && err.contains("donor"), "{err}");
    // Nothing missing on a complete statue.
    let err = run(args(&[
        &p("d.ply"),
        "--fit",
        &p("d.json"),
        "--donor",
        &p("t.ply"),
        "--donor-fit",
        &p("t.json"),
        "--out",
        &p("x.ply"),
    ]))
    .unwrap_err()
    .to_string();
    assert!(err.contains("no missing part"), "{err}");
    // Unknown bone, bad pose source, different templates.
    let err = run(args(&[
        &p("t.ply"),
        "--fit",
        &p("t.json"),
        "--donor",
        &p("d.ply"),
        "--donor-fit",
        &p("d.json"),
        "--parts",
        "l_wing",
        "--out",
        &p("x.ply"),
    ]))
    .unwrap_err()
    .to_string();
    assert!(err.contains("l_wing"), "{err}");
    let err = run(args(&[
        &p("t.ply"),
        "--fit",
        &p("t.json"),
        "--donor",
        &p("d.ply"),
        "--pose",
        "sideways",
        "--out",
        &p("x.ply"),
    ]))
    .unwrap_err()
    .to_string();
    assert!(err.contains("sideways"), "{err}");
    assert!(!dir.join("x.ply").exists());
}

#[test]
fn the_registrations_verdict_decides_what_is_missing() {
    use pygmalion::restore::missing_bones;
    let target = statue(5, &["bone:l_forearm", "bone:l_hand"]);
    let donor = statue(9, &[]);
    let t = target.truth.template.clone();
    let n = t.bones.len();
    let names = |m: &[bool]| -> Vec<String> {
        (0..n)
            .filter(|&b| m[b])
            .map(|b| t.bones[b].name.clone())
            .collect()
    };
    // Without a verdict the support judges; with one, the verdict stands (one rule for
    // `restore`, the kiosk's ghost limbs and FIT.json).
    let judged = missing_bones(&target.cloud, &target.truth, None).unwrap();
    assert_eq!(names(&judged), ["l_forearm", "l_hand"]);
    let mut told = vec![false; n];
    told[t.bone_index("r_foot").unwrap()] = true;
    let kept = missing_bones(&target.cloud, &target.truth, Some(&told)).unwrap();
    assert_eq!(names(&kept), ["r_foot"]);
    assert!(missing_bones(&target.cloud, &target.truth, Some(&told[..3])).is_err());
    let donors = [donor_of(&donor)];
    // A registration that found nothing lost: nothing to restore, and it says how to ask.
    let e = restore(
        &target.cloud,
        &target.truth,
        &donors,
        &RestoreOptions {
            target_missing: Some(vec![false; n]),
            ..Default::default()
        },
    )
    .err()
    .expect("nothing is missing")
    .to_string();
    assert!(e.contains("--parts"), "{e}");
    // A donor whose registration lost that part cannot lend it.
    let mut donor_lost = vec![false; n];
    donor_lost[t.bone_index("l_hand").unwrap()] = true;
    let e = restore(
        &target.cloud,
        &target.truth,
        &[Donor {
            missing: Some(&donor_lost),
            ..donors[0].clone()
        }],
        &RestoreOptions::default(),
    )
    .err()
    .expect("the donor lacks the hand")
    .to_string();
    assert!(e.contains("lacks l_hand"), "{e}");
}
