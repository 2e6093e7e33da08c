//! Parts growing from a bone cut part-way (`src/restore/stump.rs`): the stump's end measured on
//! synthetic statues cut at known fractions, and a restoration through a cut upper arm that
//! leaves no hole between the stump and the donor's part.

use crate::restore::{donor_of, restore_keeping_pose, sdf, statue, visible_sample};
use pygmalion::geometry::Bone;
use pygmalion::geometry::bone::PreparedBone;
use pygmalion::math::Vec3;
use pygmalion::restore::stump::{MIN_POINTS, WHOLE, start_at_stumps, stump_end};
use pygmalion::restore::transfer::{PoseSource, TransferOptions, parts_of, transfer};
use pygmalion::restore::{RestoreOptions, restore};
use pygmalion::rng::Rng;
use pygmalion::skinning::Binding;

#[test]
fn a_stumps_end_is_where_its_cut_was() {
    // Synthetic statues (height 1) cut through a bone at known fractions of its length, their
    // true skeletons as fits: the end measured within 0.05 of the cut.
    for (bone, at) in [
        ("l_upper_arm", 0.2),
        ("l_upper_arm", 0.5),
        ("l_upper_arm", 0.7),
        ("r_shin", 0.35),
        ("r_forearm", 0.6),
    ] {
        let s = statue(5, &[&format!("bone:{bone}@{at}")]);
        let t = &s.truth.template;
        let b = t.bone_index(bone).unwrap();
        // The bones below the cut have no points: left out.
        let below: Vec<usize> = t.subtree(b).into_iter().filter(|&k| k != b).collect();
        let end = stump_end(&s.cloud.positions, &s.truth, b, &below).unwrap();
        println!("{bone}@{at}: end {end:.3}");
        assert!((end - at).abs() < 0.05, "{bone} cut at {at}: end {end}");
    }
    // On a whole statue every limb bone reaches WHOLE: no part would start inside one.
    let s = statue(5, &[]);
    let t = &s.truth.template;
    for name in [
        "l_upper_arm",
        "l_forearm",
        "r_upper_arm",
        "r_forearm",
        "l_thigh",
        "l_shin",
        "r_thigh",
        "r_shin",
    ] {
        let b = t.bone_index(name).unwrap();
        let end = stump_end(&s.cloud.positions, &s.truth, b, &[]);
        assert!(end.unwrap() >= WHOLE, "{name}: {end:?}");
        // So is it when what it carries is left out (a limb lost at the joint): the points
        // round the joint's sphere are then its own.
        let below: Vec<usize> = t.subtree(b).into_iter().filter(|&k| k != b).collect();
        let end = stump_end(&s.cloud.positions, &s.truth, b, &below);
        assert!(
            end.unwrap() >= 1.0,
            "{name}, its children left out: {end:?}"
        );
    }
    // Too few points tell nothing.
    let ua = t.bone_index("l_upper_arm").unwrap();
    let few: Vec<Vec3> = (0..s.cloud.len())
        .filter(|&i| s.labels[i] as usize == ua)
        .take(MIN_POINTS - 1)
        .map(|i| s.cloud.positions[i])
        .collect();
    assert_eq!(few.len(), MIN_POINTS - 1);
    assert_eq!(stump_end(&few, &s.truth, ua, &[]), None);
}

#[test]
fn only_a_part_hanging_on_a_cut_limb_bone_grows_from_it() {
    let cut = statue(5, &["bone:l_upper_arm@0.4"]);
    let t = cut.truth.template.clone();
    let idx = |n: &str| t.bone_index(n).unwrap();
    let mut missing = vec![false; t.bones.len()];
    for n in ["l_forearm", "l_hand", "r_foot"] {
        missing[idx(n)] = true;
    }
    let mut parts = parts_of(&t, &missing);
    assert!(parts.iter().all(|p| p.from == 0.0));
    start_at_stumps(&mut parts, &cut.cloud.positions, &cut.truth);
    // The forearm's part takes the cut upper arm from its stump's end, and hangs on the
    // clavicle; the foot's part hangs on a whole shin and is left as it was.
    let arm = parts
        .iter()
        .find(|p| p.bones.contains(&idx("l_hand")))
        .unwrap();
    assert_eq!(
        arm.bones,
        [idx("l_upper_arm"), idx("l_forearm"), idx("l_hand")]
    );
    assert_eq!(arm.attach, Some(idx("l_clavicle")));
    assert!((arm.from - 0.4).abs() < 0.05, "from {}", arm.from);
    let foot = parts
        .iter()
        .find(|p| p.bones.contains(&idx("r_foot")))
        .unwrap();
    assert_eq!(
        (foot.bones.as_slice(), foot.from),
        (&[idx("r_foot")][..], 0.0)
    );
    // Applied twice, nothing more changes.
    let again = {
        let mut p = parts.clone();
        start_at_stumps(&mut p, &cut.cloud.positions, &cut.truth);
        p
    };
    assert_eq!(again, parts);
    // In the donor's pose the part's bones turn as the donor's, but the cut bone keeps the
    // stump's direction (the statue tells it); only the donor's points past the stump's end
    // less the margin come along, the margin ones before the end.
    let donor = statue(9, &[]);
    let binding = Binding::new_on_base(&donor.cloud, &donor.truth).unwrap();
    let opts = TransferOptions::default();
    let tr = transfer(&cut.truth, &donor.cloud, &binding, arm, &opts).unwrap();
    assert_eq!(opts.pose, PoseSource::Donor);
    let ua = idx("l_upper_arm");
    assert_eq!(tr.skeleton.bones[ua].rotation, cut.truth.bones[ua].rotation);
    let fa = idx("l_forearm");
    assert_eq!(
        tr.skeleton.bones[fa].rotation,
        donor.truth.bones[fa].rotation
    );
    let dp = donor.truth.pose();
    let (c1, c2) = (dp.bones[ua].c1, dp.bones[ua].c2);
    let mut margin_points = 0;
    for (k, &i) in tr.indices.iter().enumerate() {
        if tr.bones[k] as usize != ua {
            assert!(!tr.margin[k]);
            continue;
        }
        let f = (donor.cloud.positions[i as usize] - c1).dot(c2 - c1) / (c2 - c1).length_squared();
        assert!(f >= arm.from - opts.margin - 1e-4, "a donor point at {f}");
        assert_eq!(tr.margin[k], f < arm.from, "a donor point at {f}");
        margin_points += usize::from(tr.margin[k]);
    }
    assert!(margin_points > 50, "{margin_points} margin points");
    // An arm lost whole hangs on the clavicle, a bone that carries nothing outside the part
    // but is whole: its part starts at the shoulder.
    let armless = statue(5, &["bone:l_upper_arm"]);
    let mut m = vec![false; t.bones.len()];
    for n in ["l_upper_arm", "l_forearm", "l_hand"] {
        m[idx(n)] = true;
    }
    let mut parts = parts_of(&t, &m);
    start_at_stumps(&mut parts, &armless.cloud.positions, &armless.truth);
    assert_eq!(parts[0].bones[0], idx("l_upper_arm"));
    assert_eq!(parts[0].from, 0.0);
}

#[test]
fn an_arm_cut_through_the_upper_arm_is_restored_without_a_hole() {
    // The forearm and hand of a statue cut at 0.3 of its left upper arm, restored from a
    // differently proportioned, differently posed donor. Before parts grew from stumps the
    // part hung from the elbow with a margin of 0.3 of the upper arm: the upper arm's surface
    // from 0.3 to 0.6 of its length was 8–13% covered (see `src/restore/stump.rs`).
    let target = statue(5, &["bone:l_upper_arm@0.3"]);
    let donor = statue(9, &[]);
    let r = restore_keeping_pose(&target, &donor);
    assert_eq!(r.report.parts.len(), 1);
    let part = &r.report.parts[0];
    assert_eq!(part.bones, ["l_upper_arm", "l_forearm", "l_hand"]);
    assert!((part.from - 0.3).abs() < 0.05, "from {}", part.from);
    let ua = r.skeleton.template.bone_index("l_upper_arm").unwrap();
    let posed = r.skeleton.pose();
    let bones: Vec<PreparedBone> = posed.bones.iter().map(Bone::prepare).collect();
    // Coverage: the upper arm's visible surface, stump and restored part together.
    let tol = 3.0 * part.merge.rho;
    let mut rng = Rng::new(3);
    let (mut seen, mut hit) = ([0usize; 10], [0usize; 10]);
    let b = &posed.bones[ua];
    let axis = b.c2 - b.c1;
    for _ in 0..3000 {
        let Some((p, covered)) = visible_sample(&bones, ua, &r.cloud.positions, tol, &mut rng)
        else {
            continue;
        };
        let f = ((p - b.c1).dot(axis) / axis.length_squared()).clamp(0.0, 0.999);
        let bin = (f * 10.0) as usize;
        seen[bin] += 1;
        hit[bin] += usize::from(covered);
    }
    let cov: Vec<f32> = (0..10)
        .map(|k| hit[k] as f32 / seen[k].max(1) as f32)
        .collect();
    println!("upper arm coverage by tenth: {cov:.2?}");
    for (k, c) in cov.iter().enumerate().take(9) {
        assert!(*c > 0.9, "tenth {k} of the upper arm covered {c}");
    }
    // A single layer at the seam: the points near the cut (within 0.3 of the upper arm's
    // length either way) lie on the completed surface.
    let mut d: Vec<f32> = r
        .cloud
        .positions
        .iter()
        .filter(|q| {
            let f = (**q - b.c1).dot(axis) / axis.length_squared();
            let off = (**q - b.c1 - f * axis).length();
            (f - part.from).abs() < 0.3 && off < 2.0 * b.r1.max(b.r2)
        })
        .map(|q| sdf(*q, &bones).abs())
        .collect();
    d.sort_by(f32::total_cmp);
    let (p95, max) = (d[d.len() * 95 / 100], d[d.len() - 1]);
    println!(
        "seam: {} points, |distance| p95 {p95:.5} max {max:.5}",
        d.len()
    );
    assert!(d.len() > 300);
    assert!(p95 < 0.002 && max < 0.005, "seam p95 {p95} max {max}");
}

#[test]
fn a_bone_shrunk_onto_its_stump_gets_its_length_back_for_a_restoration() {
    use pygmalion::fakir::support::{complete_cut, complete_with};
    // The upper arm cut at 0.4, and fitted as FAKIR often leaves such a bone: shrunk onto its
    // stump (0.45 of its length; held-out cuts were fitted at 0.49–0.88).
    let target = statue(5, &["bone:l_upper_arm@0.4"]);
    let t = target.truth.template.clone();
    let idx = |n: &str| t.bone_index(n).unwrap();
    let (ua, mirror) = (idx("l_upper_arm"), idx("r_upper_arm"));
    let mut fit = target.truth.clone();
    fit.bones[ua].length *= 0.45;
    let mut missing = vec![false; t.bones.len()];
    for n in ["l_forearm", "l_hand"] {
        missing[idx(n)] = true;
    }
    let healthy: Vec<bool> = missing.iter().map(|m| !m).collect();
    let plain = complete_with(&fit, &missing, Some(&healthy));
    let cut = complete_cut(&fit, &missing, Some(&healthy));
    // The registration's completion keeps it as fitted; the restoration's gives it its
    // mirror's length, along its fitted direction, radii kept.
    assert_eq!(plain.bones[ua], fit.bones[ua]);
    assert_eq!(cut.bones[ua].length, fit.bones[mirror].length);
    assert_eq!(cut.bones[ua].rotation, fit.bones[ua].rotation);
    assert_eq!(
        (cut.bones[ua].r1, cut.bones[ua].r2),
        (fit.bones[ua].r1, fit.bones[ua].r2)
    );
    // Nothing else changes but the lost bones' places, carried by it.
    for (k, lost) in missing.iter().enumerate() {
        if k != ua && !lost {
            assert_eq!(cut.bones[k], plain.bones[k], "{}", t.bones[k].name);
        }
    }
    // The elbow comes back near its truth (the left and right upper arms of a synthetic
    // statue differ by up to ±30% each).
    let truth_elbow = target.truth.pose().bones[ua].c2;
    let err = |s: &pygmalion::anatomy::Skeleton| s.pose().bones[ua].c2.distance(truth_elbow);
    println!(
        "elbow off its truth: {:.4} as fitted, {:.4} given back",
        err(&plain),
        err(&cut)
    );
    assert!(err(&cut) < 0.5 * err(&plain));
    // Without a mirror that tells (its mirror shrunk too), it keeps its fitted length: the
    // template's proportions alone do not tell a cut bone (the armless Venus de Milo's whole
    // clavicles are fitted at half the template's length).
    let mut both = fit.clone();
    both.bones[mirror].length *= 0.45;
    let kept = complete_cut(&both, &missing, Some(&healthy));
    assert_eq!(kept.bones[ua].length, both.bones[ua].length);
    // A bone not shrunk (the truth), or a whole limb lost with it, keeps its length.
    let whole = complete_cut(&target.truth, &missing, Some(&healthy));
    assert_eq!(whole.bones[ua].length, target.truth.bones[ua].length);
    let mut arm_lost = missing.clone();
    arm_lost[ua] = true;
    let healthy2: Vec<bool> = arm_lost.iter().map(|m| !m).collect();
    assert_eq!(
        complete_cut(&fit, &arm_lost, Some(&healthy2)).bones,
        complete_with(&fit, &arm_lost, Some(&healthy2)).bones
    );
    // Restored with that fit, the part grows from the stump's end on the lengthened bone.
    let donor = statue(9, &[]);
    let r = restore(
        &target.cloud,
        &fit,
        &[donor_of(&donor)],
        &RestoreOptions {
            target_missing: Some(missing.clone()),
            ..Default::default()
        },
    )
    .unwrap();
    let part = &r.report.parts[0];
    let want = 0.4 * target.truth.bones[ua].length / fit.bones[mirror].length;
    println!(
        "the part starts at {:.3} of the upper arm (the stump's end at {want:.3})",
        part.from
    );
    assert_eq!(part.bones[0], "l_upper_arm");
    assert!(
        (part.from - want).abs() < 0.05,
        "from {} for {want}",
        part.from
    );
}
