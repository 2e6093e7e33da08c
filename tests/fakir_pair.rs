//! The pair hypothesis (`pygmalion::fakir::pair`): when a second registration with both
//! limbs of a pair lost is tried, and with what.

use std::sync::Arc;

use pygmalion::anatomy::{Skeleton, Template};
use pygmalion::fakir::bust::removal_cost;
use pygmalion::fakir::pair::{
    COST, COST_BELOW, Level, RECOVERY, hypotheses, hypothesis, hypothesis_below,
};
use pygmalion::fakir::support::{BoneSupport, lost_from_names};
use pygmalion::fakir::{Fit, Init, RegistrationOptions};
use pygmalion::math::Vec3;
use pygmalion::synth::{Cut, SynthOptions, generate};

/// The rest skeleton of the human template as a whole fit with the limbs of `lost` (each
/// with what it carries) missing.
pub(crate) fn fit_missing(t: &Arc<Template>, lost: &[&str]) -> Fit {
    let names: Vec<String> = lost.iter().map(|s| s.to_string()).collect();
    let skeleton = Skeleton::rest(t.clone());
    Fit {
        skeleton,
        labels: Vec::new(),
        mean_distance: 0.0,
        base: None,
        bone_counts: vec![0; t.bones.len()],
        iterations: 0,
        units: 0,
        candidate: 0,
        candidate_distances: Vec::new(),
        support: Vec::new(),
        missing: lost_from_names(t, &names).unwrap(),
    }
}

fn human() -> Arc<Template> {
    Arc::new(Template::builtin("human").unwrap())
}

#[test]
fn a_lost_arm_beside_a_present_one_is_tried_with_both_lost() {
    // The left arm lost with all it carries, the right one whole: both upper arms lost from
    // the start, the right one the limb whose points the second fit must explain; the other
    // options unchanged.
    let t = human();
    let opts = RegistrationOptions::default();
    let h = hypothesis(&t, &opts, &fit_missing(&t, &["l_upper_arm"])).unwrap();
    assert_eq!(h.level, Level::Limb);
    assert_eq!(h.opts.lost, vec!["l_upper_arm", "r_upper_arm"]);
    assert_eq!(h.mirror, "r_upper_arm");
    assert_eq!(h.stump, None);
    assert_eq!(h.opts.subsample, opts.subsample);
    // A right thigh lost: both thighs, the left one to explain.
    let h = hypothesis(&t, &opts, &fit_missing(&t, &["r_thigh"])).unwrap();
    assert_eq!(h.opts.lost, vec!["r_thigh", "l_thigh"]);
    assert_eq!(h.mirror, "l_thigh");
}

#[test]
fn no_pair_is_tried_without_a_whole_limb_lost_beside_a_whole_mirror() {
    let t = human();
    let opts = RegistrationOptions::default();
    // Complete; only a forearm lost (the upper arm kept); both arms lost already; the mirror
    // arm missing its hand.
    for lost in [
        &[][..],
        &["l_forearm"][..],
        &["l_upper_arm", "r_upper_arm"][..],
        &["l_upper_arm", "r_hand"][..],
    ] {
        assert!(
            hypothesis(&t, &opts, &fit_missing(&t, lost)).is_none(),
            "tried with {lost:?} lost"
        );
    }
    // One bone down: complete; both forearms lost already; the mirror forearm missing its
    // hand; only a hand lost.
    for lost in [
        &[][..],
        &["l_forearm", "r_forearm"][..],
        &["l_forearm", "r_hand"][..],
        &["l_hand"][..],
    ] {
        assert!(
            hypothesis_below(&t, &opts, &fit_missing(&t, lost)).is_none(),
            "tried with {lost:?} lost"
        );
    }
    // A lost arm, but the curator named the lost limbs, or the detection is off.
    let whole = fit_missing(&t, &["l_upper_arm"]);
    let named = RegistrationOptions {
        lost: vec!["l_upper_arm".into()],
        ..Default::default()
    };
    assert!(hypothesis(&t, &named, &whole).is_none());
    assert!(hypotheses(&t, &named, &whole).is_empty());
    let off = RegistrationOptions {
        missing: false,
        ..Default::default()
    };
    assert!(hypothesis(&t, &off, &whole).is_none());
    assert!(hypotheses(&t, &off, &whole).is_empty());
}

#[test]
fn a_lost_forearm_beside_a_present_one_is_tried_one_bone_down() {
    // The left forearm lost with its hand, the right arm whole: both forearms (and hands)
    // lost from the start, the upper arms free; the right forearm to explain, the right upper
    // arm the bone that must be a stump.
    let t = human();
    let opts = RegistrationOptions::default();
    let whole = fit_missing(&t, &["l_forearm"]);
    assert!(hypothesis(&t, &opts, &whole).is_none());
    let h = hypothesis_below(&t, &opts, &whole).unwrap();
    assert_eq!(h.level, Level::Below);
    assert_eq!(h.opts.lost, vec!["l_forearm", "r_forearm"]);
    assert_eq!(h.mirror, "r_forearm");
    assert_eq!(h.stump.as_deref(), Some("r_upper_arm"));
    // Started from the whole fit's skeleton (its placement and trunk kept).
    let Init::Given(start) = &h.opts.init else {
        panic!(
            "one bone down starts from the whole fit, not {:?}",
            h.opts.init
        );
    };
    assert_eq!(start.pose().joints, whole.skeleton.pose().joints);
    // A right shin lost with its foot: both shins, the left thigh to be a stump.
    let h = hypothesis_below(&t, &opts, &fit_missing(&t, &["r_shin"])).unwrap();
    assert_eq!(h.opts.lost, vec!["r_shin", "l_shin"]);
    assert_eq!(h.mirror, "l_shin");
    assert_eq!(h.stump.as_deref(), Some("l_thigh"));
    // A whole arm lost: the limbs' level first, afresh then from the whole fit, then one
    // bone down.
    let whole = fit_missing(&t, &["l_upper_arm"]);
    let all = hypotheses(&t, &opts, &whole);
    let levels: Vec<Level> = all.iter().map(|h| h.level).collect();
    assert_eq!(levels, [Level::Limb, Level::Limb, Level::Below]);
    // The limbs' level searches a placement as the whole fit did, then starts from the whole
    // fit's skeleton with the same bones lost and the same limb to explain.
    assert!(matches!(all[0].opts.init, Init::Auto));
    let Init::Given(start) = &all[1].opts.init else {
        panic!(
            "the second try starts from the whole fit, not {:?}",
            all[1].opts.init
        );
    };
    assert_eq!(start.pose().joints, whole.skeleton.pose().joints);
    assert_eq!(all[1].opts.lost, all[0].opts.lost);
    assert_eq!(
        (&all[1].mirror, &all[1].stump),
        (&all[0].mirror, &all[0].stump)
    );
    assert_eq!(all[2].opts.lost, vec!["l_forearm", "r_forearm"]);
}

#[test]
fn a_pair_fit_is_kept_on_its_level_s_cost_and_one_bone_down_on_a_stump() {
    // Points on the trunk only: no point lies nearest to the mirror limb, whose excess is
    // then 0 (`bust::limb_excess`), so the cost and the stump decide.
    let t = human();
    let opts = RegistrationOptions::default();
    let trunk: Vec<_> = {
        let posed = Skeleton::rest(t.clone()).pose();
        let spine = posed.bones[t.bone_index("spine_upper").unwrap()];
        (0..50)
            .map(|k| spine.c1 + (spine.c2 - spine.c1) * (k as f32 / 49.0))
            .collect()
    };
    let mut whole = fit_missing(&t, &["l_upper_arm"]);
    whole.mean_distance = 1.0;
    let [limb, limb_again, below] = &hypotheses(&t, &opts, &whole)[..] else {
        panic!("three hypotheses expected");
    };
    let support = |shrunk: bool| -> Vec<BoneSupport> {
        let mut all = crate::common::full_support(&t);
        all.iter_mut().for_each(|b| b.shrunk = shrunk);
        all
    };
    let pair_fit = |lost: &[&str], cost: f64, shrunk: bool| {
        let mut f = fit_missing(&t, lost);
        f.mean_distance = cost;
        f.support = support(shrunk);
        f
    };
    let keeps =
        |h: &pygmalion::fakir::pair::Hypothesis, f: &Fit| h.keeps(&whole, f, &trunk).unwrap();
    // The limbs' level: under 1.5 times the whole fit's mean distance.
    let both_arms = ["l_upper_arm", "r_upper_arm"];
    for h in [limb, limb_again] {
        assert!(keeps(h, &pair_fit(&both_arms, 1.4, false)));
        assert!(!keeps(h, &pair_fit(&both_arms, 1.6, false)));
    }
    // One bone down: under 2.5 times, and the mirror's upper arm a stump (lost or shrunk).
    let forearms = ["l_forearm", "r_forearm"];
    assert!(!keeps(below, &pair_fit(&forearms, 2.0, false)));
    assert!(keeps(below, &pair_fit(&forearms, 2.0, true)));
    let upper_lost = ["l_upper_arm", "r_upper_arm"];
    assert!(keeps(below, &pair_fit(&upper_lost, 2.0, false)));
    assert!(!keeps(below, &pair_fit(&forearms, 2.6, true)));
}

#[test]
fn a_pair_is_not_registered_when_its_mirror_limb_explains_points_no_other_bone_can() {
    // A whole fit (the rest skeleton) that lost its left arm. Over points on the trunk's
    // axis no point lies nearest to the right arm: leaving it out costs nothing
    // (`bust::removal_cost` 1), both levels are worth a second registration.
    let t = human();
    let opts = RegistrationOptions::default();
    let mut whole = fit_missing(&t, &["l_upper_arm"]);
    // Fifty figure points (labels of bone 0, none of the base).
    whole.labels = vec![0; 50];
    let [limb, limb_again, below] = &hypotheses(&t, &opts, &whole)[..] else {
        panic!("three hypotheses expected");
    };
    let posed = Skeleton::rest(t.clone()).pose();
    let spine = posed.bones[t.bone_index("spine_upper").unwrap()];
    let trunk: Vec<Vec3> = (0..50)
        .map(|k| spine.c1 + (spine.c2 - spine.c1) * (k as f32 / 49.0))
        .collect();
    for h in [limb, limb_again, below] {
        let mirror = std::slice::from_ref(&h.mirror);
        assert_eq!(removal_cost(&whole, &trunk, mirror).unwrap(), 1.0);
        assert!(h.worth_trying(&whole, &trunk).unwrap(), "{:?}", h.level);
    }
    assert_eq!((limb.cost_bound(), below.cost_bound()), (COST, COST_BELOW));
    // A statue that lost its left arm at the shoulder, its truth as the whole fit: its points
    // lie on its bones' surfaces, and the healthy right arm's (or forearm's and hand's) lie
    // far from every other bone. Far over `RECOVERY` times either level's cost bound:
    // nothing is registered.
    let s = generate(
        t.clone(),
        &SynthOptions {
            points: 20_000,
            seed: 12,
            random_pose: true,
            height: 1.7,
            plinth_share: 0.0,
            cuts: vec![Cut::Bone {
                bone: "l_upper_arm".into(),
                at: 0.0,
            }],
            ..Default::default()
        },
    )
    .unwrap();
    let mut cut = fit_missing(&t, &["l_upper_arm"]);
    cut.skeleton = s.truth.clone();
    cut.labels = vec![0; s.cloud.len()];
    for h in [limb, limb_again, below] {
        let mirror = std::slice::from_ref(&h.mirror);
        let cost = removal_cost(&cut, &s.cloud.positions, mirror).unwrap();
        assert!(
            cost > RECOVERY * h.cost_bound(),
            "{:?}: removal cost {cost}",
            h.level
        );
        assert!(
            !h.worth_trying(&cut, &s.cloud.positions).unwrap(),
            "{:?}",
            h.level
        );
    }
}
