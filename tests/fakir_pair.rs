//! The pair hypothesis (`pygmalion::fakir::pair`): when a second registration with both
//! limbs of a pair lost is tried, and with what.

use std::sync::Arc;

use pygmalion::anatomy::{Skeleton, Template};
use pygmalion::fakir::pair::hypothesis;
use pygmalion::fakir::support::lost_from_names;
use pygmalion::fakir::{Fit, RegistrationOptions};

/// The rest skeleton of the human template as a whole fit with the limbs of `lost` (each
/// with what it carries) missing.
fn fit_missing(t: &Arc<Template>, lost: &[&str]) -> Fit {
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
    let (pair, mirror) = hypothesis(&t, &opts, &fit_missing(&t, &["l_upper_arm"])).unwrap();
    assert_eq!(pair.lost, vec!["l_upper_arm", "r_upper_arm"]);
    assert_eq!(mirror, "r_upper_arm");
    assert_eq!(pair.subsample, opts.subsample);
    // A right thigh lost: both thighs, the left one to explain.
    let (pair, mirror) = hypothesis(&t, &opts, &fit_missing(&t, &["r_thigh"])).unwrap();
    assert_eq!(pair.lost, vec!["r_thigh", "l_thigh"]);
    assert_eq!(mirror, "l_thigh");
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
    // A lost arm, but the curator named the lost limbs, or the detection is off.
    let whole = fit_missing(&t, &["l_upper_arm"]);
    let named = RegistrationOptions {
        lost: vec!["l_upper_arm".into()],
        ..Default::default()
    };
    assert!(hypothesis(&t, &named, &whole).is_none());
    let off = RegistrationOptions {
        missing: false,
        ..Default::default()
    };
    assert!(hypothesis(&t, &off, &whole).is_none());
}
