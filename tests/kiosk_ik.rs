//! Inverse kinematics of limb drags (`kiosk::ik`): FABRIK and the way back into the
//! skeleton's relative rotations.

use pygmalion::anatomy::{Skeleton, Template};
use pygmalion::kiosk::ik::{
    IkOptions, apply_chain_points, chain_points, drag_chain, end_bone, fabrik, limb_bones,
};
use pygmalion::math::{Quat, Vec3};
use std::sync::Arc;

fn human() -> Skeleton {
    Skeleton::rest(Arc::new(
        Template::builtin("human").expect("human template"),
    ))
}

fn lengths(points: &[Vec3]) -> Vec<f32> {
    points.windows(2).map(|w| (w[1] - w[0]).length()).collect()
}

fn assert_lengths_kept(before: &[Vec3], after: &[Vec3]) {
    for (a, b) in lengths(before).iter().zip(lengths(after)) {
        assert!(((a - b) / a).abs() < 1e-4, "segment length {a} became {b}");
    }
}

fn arm(s: &Skeleton) -> Vec<usize> {
    let chain = s.template.chain_index("l_arm").expect("l_arm");
    limb_bones(&s.template, chain)
}

#[test]
fn limb_bones_are_the_chain_without_its_end_bone() {
    let s = human();
    let t = &s.template;
    let names = |bones: Vec<usize>| -> Vec<String> {
        bones.iter().map(|&b| t.bones[b].name.clone()).collect()
    };
    let l_arm = t.chain_index("l_arm").unwrap();
    assert_eq!(
        names(limb_bones(t, l_arm)),
        ["l_clavicle", "l_upper_arm", "l_forearm"]
    );
    assert_eq!(t.bones[end_bone(t, l_arm).unwrap()].name, "l_hand");
    let r_leg = t.chain_index("r_leg").unwrap();
    assert_eq!(names(limb_bones(t, r_leg)), ["r_thigh", "r_shin"]);
    let spine = t.chain_index("spine").unwrap();
    assert_eq!(t.bones[end_bone(t, spine).unwrap()].name, "head");
    // The effector of an arm is the wrist.
    let pts = chain_points(&s.pose(), &limb_bones(t, l_arm));
    let wrist = s.joint("l_wrist").unwrap();
    assert!((pts[3] - wrist).length() < 1e-6);
}

#[test]
fn reachable_target_is_reached_with_lengths_kept() {
    let s = human();
    let pts = chain_points(&s.pose(), &arm(&s));
    let total: f32 = lengths(&pts).iter().sum();
    for target in [
        pts[3] + Vec3::new(0.0, 0.2, 0.1),
        pts[0] + Vec3::new(0.1, -0.2, 0.25).normalize() * 0.7 * total,
        pts[0] + Vec3::new(0.0, 0.0, 0.3) * total,
    ] {
        assert!((target - pts[0]).length() < total);
        let out = fabrik(&pts, target, &IkOptions::default());
        assert_eq!(out.len(), pts.len());
        assert_eq!(out[0], pts[0], "the root stays");
        assert!(
            (out[3] - target).length() < 1e-3 * total,
            "end {:?} vs target {target:?}",
            out[3]
        );
        assert_lengths_kept(&pts, &out);
    }
}

#[test]
fn unreachable_target_straightens_the_chain_toward_it() {
    let s = human();
    let pts = chain_points(&s.pose(), &arm(&s));
    let total: f32 = lengths(&pts).iter().sum();
    let target = pts[0] + Vec3::new(1.0, 0.5, 2.0).normalize() * 3.0 * total;
    let out = fabrik(&pts, target, &IkOptions::default());
    assert_lengths_kept(&pts, &out);
    let dir = (target - pts[0]).normalize();
    for (i, p) in out.iter().enumerate().skip(1) {
        let along = (*p - pts[0]).normalize();
        assert!(along.dot(dir) > 1.0 - 1e-5, "point {i} is off the line");
    }
    assert!((out[3] - (pts[0] + dir * total)).length() < 1e-4);
}

#[test]
fn rotations_round_trip_through_the_skeleton() {
    let mut s = human();
    let before = s.clone();
    let bones = arm(&s);
    let pts = chain_points(&s.pose(), &bones);
    let target = pts[3] + Vec3::new(0.05, 0.25, 0.15);
    let solved = fabrik(&pts, target, &IkOptions::default());
    apply_chain_points(&mut s, &bones, &solved);
    let posed = s.pose();
    let again = chain_points(&posed, &bones);
    for (a, b) in again.iter().zip(&solved) {
        assert!((*a - *b).length() < 1e-4, "{a:?} vs {b:?}");
    }
    // Lengths and radii untouched; bones outside the chain keep their relative rotations
    // (the hand follows the forearm).
    for (i, (a, b)) in s.bones.iter().zip(&before.bones).enumerate() {
        assert_eq!(a.length, b.length);
        assert_eq!((a.r1, a.r2), (b.r1, b.r2));
        if !bones.contains(&i) {
            assert!(a.rotation.dot(b.rotation).abs() > 1.0 - 1e-6);
        }
    }
    let hand = s.template.bone_index("l_hand").unwrap();
    let old_posed = before.pose();
    let hand_len = (posed.bones[hand].c2 - posed.bones[hand].c1).length();
    let old_len = (old_posed.bones[hand].c2 - old_posed.bones[hand].c1).length();
    assert!((hand_len - old_len).abs() < 1e-5);
    assert!((posed.bones[hand].c1 - target).length() < 1e-3);
    // The rest of the body did not move.
    let r_wrist = s.template.joint_index("r_wrist").unwrap();
    assert!((posed.joints[r_wrist] - old_posed.joints[r_wrist]).length() < 1e-6);
}

#[test]
fn each_bone_gets_the_minimal_swing_and_keeps_its_twist() {
    let mut s = human();
    let bones = arm(&s);
    let old = s.pose();
    let pts = chain_points(&old, &bones);
    let target = pts[3] + Vec3::new(-0.1, 0.2, 0.2);
    drag_chain(&mut s, &bones, target, &IkOptions::default());
    let new = s.pose();
    // The first bone's parent did not move, so its world change is a pure swing: the
    // rotation from the old to the new frame turns about an axis orthogonal to both bone
    // directions (no twist about the bone).
    let b = bones[0];
    let delta: Quat = new.frames[b] * old.frames[b].inverse();
    let (axis, angle) = delta.to_axis_angle();
    let d_old = old.frames[b] * Vec3::X;
    let d_new = new.frames[b] * Vec3::X;
    if angle > 1e-4 {
        assert!(axis.dot(d_old).abs() < 1e-3, "twist about the old axis");
        assert!(axis.dot(d_new).abs() < 1e-3, "twist about the new axis");
    }
}

#[test]
fn spine_chain_through_the_follower_bone_round_trips() {
    let mut s = human();
    let t = s.template.clone();
    let spine = t.chain_index("spine").unwrap();
    let bones = limb_bones(&t, spine);
    assert_eq!(bones.len(), 3, "spine_lower, spine_upper, neck");
    let link = t.bone_index("neck_link").unwrap();
    let link_rot = s.bones[link].rotation;
    let pts = chain_points(&s.pose(), &bones);
    let target = pts[3] + Vec3::new(0.06, -0.03, 0.08);
    let solved = drag_chain(&mut s, &bones, target, &IkOptions::default());
    assert_lengths_kept(&pts, &solved);
    let again = chain_points(&s.pose(), &bones);
    for (a, b) in again.iter().zip(&solved) {
        assert!((*a - *b).length() < 1e-4, "{a:?} vs {b:?}");
    }
    assert!((again[3] - target).length() < 1e-3);
    assert_eq!(
        s.bones[link].rotation, link_rot,
        "the follower keeps its rotation"
    );
}

#[test]
fn applying_the_current_points_changes_nothing() {
    let mut s = human();
    let before = s.clone();
    for chain in 0..s.template.chains.len() {
        let bones = limb_bones(&s.template, chain);
        let pts = chain_points(&s.pose(), &bones);
        apply_chain_points(&mut s, &bones, &pts);
    }
    for (a, b) in s.bones.iter().zip(&before.bones) {
        assert!(a.rotation.dot(b.rotation).abs() > 1.0 - 1e-6);
    }
}
