//! The broken-limb hypothesis (`pygmalion::fakir::broken`): when a second registration with
//! one more bone of a limb lost is tried, and when its fit is kept.

use std::sync::Arc;

use pygmalion::anatomy::{Skeleton, Template};
use pygmalion::fakir::broken::{COST, END_COVERAGE, hypothesis};
use pygmalion::fakir::{Fit, Init, RegistrationOptions};

fn human() -> Arc<Template> {
    Arc::new(Template::builtin("human").unwrap())
}

/// The rest skeleton as a whole fit with the limbs of `lost` (each with what it carries)
/// missing and the bones of `shrunk` flagged shrunk; mean distance 1.
fn fit(t: &Arc<Template>, lost: &[&str], shrunk: &[&str]) -> Fit {
    let mut f = crate::fakir_pair::fit_missing(t, lost);
    f.mean_distance = 1.0;
    f.support = crate::common::full_support(t);
    for s in &mut f.support {
        s.shrunk = shrunk.contains(&s.bone.as_str());
    }
    f
}

/// The bone the hypothesis on `whole` loses, if one is tried.
fn loses(t: &Arc<Template>, whole: &Fit) -> Option<String> {
    hypothesis(t, &RegistrationOptions::default(), whole).map(|h| h.bone)
}

#[test]
fn a_limb_pulled_short_is_tried_with_its_deepest_present_bone_lost() {
    let t = human();
    // A shrunk clavicle, nothing lost: the hand, the arm's deepest present bone.
    let h = hypothesis(
        &t,
        &RegistrationOptions::default(),
        &fit(&t, &[], &["l_clavicle"]),
    )
    .unwrap();
    assert_eq!(h.bone, "l_hand");
    assert_eq!(h.opts.lost, vec!["l_hand"]);
    assert_eq!(h.opts.subsample, RegistrationOptions::default().subsample);
    // The hand already lost: one bone more, the forearm.
    assert_eq!(
        loses(&t, &fit(&t, &["r_hand"], &["r_upper_arm"])).as_deref(),
        Some("r_forearm")
    );
    // A leg: a shrunk shin, nothing lost, loses the foot.
    assert_eq!(
        loses(&t, &fit(&t, &[], &["l_shin"])).as_deref(),
        Some("l_foot")
    );
}

#[test]
fn no_broken_limb_is_tried_on_a_limb_that_is_not_pulled_short() {
    let t = human();
    // Nothing shrunk.
    assert_eq!(loses(&t, &fit(&t, &[], &[])), None);
    // Only the deepest present bone shrunk (a short hand): nothing above it pulled short.
    assert_eq!(loses(&t, &fit(&t, &[], &["l_hand"])), None);
    // A trunk bone shrunk: not a limb's.
    assert_eq!(loses(&t, &fit(&t, &[], &["spine_lower", "neck"])), None);
    // The whole arm lost: the pair hypotheses' case.
    assert_eq!(loses(&t, &fit(&t, &["l_upper_arm"], &["l_clavicle"])), None);
    // Everything below the first bone lost, neither it nor the clavicle shrunk.
    assert_eq!(loses(&t, &fit(&t, &["l_forearm"], &[])), None);
}

#[test]
fn a_limb_lost_below_its_shrunk_first_bone_is_tried_without_it() {
    let t = human();
    // The forearm and hand lost, the upper arm kept short over the shoulder: the whole arm
    // lost at the shoulder is tried.
    let h = hypothesis(
        &t,
        &RegistrationOptions::default(),
        &fit(&t, &["r_forearm"], &["r_upper_arm"]),
    )
    .unwrap();
    assert_eq!(h.bone, "r_upper_arm");
    assert_eq!(h.end, t.bone_index("r_hand").unwrap());
    // Its own shrinking is the pull the second fit must explain (it is lost there).
    assert_eq!(h.pulled, vec![t.bone_index("r_upper_arm").unwrap()]);
    // A leg: the shin and foot lost, the thigh shrunk.
    assert_eq!(
        loses(&t, &fit(&t, &["l_shin"], &["l_thigh"])).as_deref(),
        Some("l_thigh")
    );
    // A shrunk clavicle pulls the first bone too.
    assert_eq!(
        loses(&t, &fit(&t, &["l_forearm"], &["l_clavicle"])).as_deref(),
        Some("l_upper_arm")
    );
}

#[test]
fn no_broken_limb_is_tried_where_the_curator_or_the_options_decide() {
    let t = human();
    let whole = fit(&t, &[], &["l_clavicle"]);
    let named = RegistrationOptions {
        lost: vec!["r_hand".into()],
        ..Default::default()
    };
    assert!(hypothesis(&t, &named, &whole).is_none());
    let off = RegistrationOptions {
        missing: false,
        ..Default::default()
    };
    assert!(hypothesis(&t, &off, &whole).is_none());
    let given = RegistrationOptions {
        init: Init::Given(Skeleton::rest(t.clone())),
        ..Default::default()
    };
    assert!(hypothesis(&t, &given, &whole).is_none());
}

#[test]
fn a_broken_limb_fit_is_kept_only_when_its_mean_distance_falls_clearly() {
    let t = human();
    let whole = fit(&t, &[], &["l_clavicle"]);
    let h = hypothesis(&t, &RegistrationOptions::default(), &whole).unwrap();
    // The second fit: the hand lost and completed where the scan has nothing.
    let bare_hand = |mut f: Fit| {
        let hand = t.bone_index("l_hand").unwrap();
        f.support[hand].coverage = 0.0;
        f
    };
    let mut second = bare_hand(fit(&t, &["l_hand"], &[]));
    second.mean_distance = COST - 0.01;
    assert!(h.keeps(&whole, &second));
    // The completed hand lying on scan points: a hand the statue has.
    let mut covered = fit(&t, &["l_hand"], &[]);
    covered.mean_distance = COST - 0.01;
    let hand = t.bone_index("l_hand").unwrap();
    covered.support[hand].coverage = END_COVERAGE + 0.05;
    assert!(!h.keeps(&whole, &covered));
    second.mean_distance = COST + 0.01;
    assert!(!h.keeps(&whole, &second));
    second.mean_distance = 1.2;
    assert!(!h.keeps(&whole, &second));
    // Cheaper, but the clavicle that triggered it is still shrunk: the lost hand did not
    // explain the pull.
    let mut still = bare_hand(fit(&t, &["l_hand"], &["l_clavicle"]));
    still.mean_distance = COST - 0.01;
    assert!(!h.keeps(&whole, &still));
    assert_eq!(h.pulled, vec![t.bone_index("l_clavicle").unwrap()]);
}

#[test]
fn a_second_fit_that_moved_the_trunk_is_not_trusted_with_its_lost_bone() {
    use pygmalion::fakir::broken::{TRUNK_MOVED, trunk_shift};
    use pygmalion::math::Vec3;
    let t = human();
    let whole = {
        let mut f = fit(&t, &[], &["l_clavicle"]);
        // Two figure points 5 apart: the figure's diagonal is 5.
        f.labels = vec![0, 0];
        f
    };
    let positions = [Vec3::ZERO, Vec3::new(3.0, 4.0, 0.0)];
    let mut second = fit(&t, &["l_hand"], &[]);
    // The same trunk: no shift, whatever the arm does.
    assert_eq!(trunk_shift(&whole, &second, &positions), 0.0);
    // The whole figure moved by 0.05: every trunk bone's ends by 0.05, 1% of the diagonal.
    second.skeleton.root_position += Vec3::new(0.0, 0.05, 0.0);
    let shift = trunk_shift(&whole, &second, &positions);
    assert!((shift - 0.01).abs() < 1e-5, "shift {shift}");
    assert!(shift < TRUNK_MOVED);
    second.skeleton.root_position += Vec3::new(0.0, 0.1, 0.0);
    assert!(trunk_shift(&whole, &second, &positions) > TRUNK_MOVED);
    // The third registration starts from the second fit, nothing lost from the start.
    let h = hypothesis(&t, &RegistrationOptions::default(), &whole).unwrap();
    let again = h.again(&second);
    assert!(again.lost.is_empty());
    assert!(again.missing);
    match again.init {
        Init::Given(s) => assert_eq!(s.root_position, second.skeleton.root_position),
        other => panic!("started from {other:?}"),
    }
}
