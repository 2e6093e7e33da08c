//! Tests of `fakir`: the papers' chain experiment, LM derivatives, whole-skeleton registration.

use pygmalion::anatomy::Skeleton;
use pygmalion::fakir::assign::{AssignParams, Assignment};
use pygmalion::fakir::schedule::{ScheduleSettings, register_chain};
use pygmalion::fakir::solver::{NoPause, Solver, SolverSettings};
use pygmalion::fakir::world::WorldSkeleton;
use pygmalion::math::{Quat, Vec3};
use pygmalion::synth::{Cut, SynthStatue, chain4};

/// Fits a generic straight 4-bone chain (equal lengths 35, radii 7, pointing away from the
/// data) anchored at the true first extremity; returns (mean distance, joint errors, units).
fn fit_chain(s: &SynthStatue, settings: &ScheduleSettings) -> (f64, Vec<f32>, u64) {
    let t = s.truth.template.clone();
    let mut init = Skeleton::rest(t.clone());
    for b in &mut init.bones {
        b.length = 35.0;
        b.r1 = 7.0;
        b.r2 = 7.0;
    }
    init.root_rotation = Quat::from_rotation_z(0.9);
    let world = WorldSkeleton::from_skeleton(&init);
    let n = s.cloud.len();
    let asg = Assignment::new(
        s.cloud.positions.clone(),
        s.cloud.normals.clone().unwrap(),
        (0..n as u32).collect(),
        4,
        AssignParams {
            cone_slack: 0.2,
            cone_abs: 0.28,
        },
    );
    let mut pause = NoPause;
    let mut solver = Solver::new(world, asg, 1.0, SolverSettings::default(), &mut pause);
    solver.free_root = true;
    register_chain(&mut solver, &[0, 1, 2, 3], settings).unwrap();
    solver.assignment.params.cone_abs = 0.0;
    let n = solver.assignment.len();
    solver.assignment.relabel(0..n);
    solver.members = solver.assignment.members();
    pygmalion::fakir::schedule::chain_passes(&mut solver, &[0, 1, 2, 3], settings, true).unwrap();
    let fitted = solver.world.pose();
    let truth = s.truth.pose();
    let errors = fitted
        .joints
        .iter()
        .zip(&truth.joints)
        .map(|(a, b)| (*a - *b).length())
        .collect();
    (solver.mean_distance(), errors, solver.units)
}

#[test]
fn chain_experiment_noise_free() {
    let s = chain4(5_000, 1, 0.0, 0.0, vec![]).unwrap();
    let (d, errors, units) = fit_chain(&s, &ScheduleSettings::default());
    println!("noise-free: mean distance {d:.5}, joint errors {errors:?}, units {units}");
    assert!(d < 1e-4 * 140.0 * 100.0);
}

#[test]
fn chain_experiment_noisy_and_holed() {
    for sigma in [0.5f32, 1.0, 2.0] {
        let s = chain4(5_000, 2, sigma, 0.0, vec![]).unwrap();
        let (d, errors, units) = fit_chain(&s, &ScheduleSettings::default());
        println!("σ = {sigma}: mean distance {d:.4}, joint errors {errors:?}, units {units}");
    }
    // Missing middle portion: a slab across the third bone removed.
    let mut s = chain4(5_000, 3, 0.0, 0.0, vec![]).unwrap();
    let b = s.truth.pose().bones[2];
    let (mid, axis) = (0.5 * (b.c1 + b.c2), (b.c2 - b.c1).normalize());
    let keep: Vec<bool> = s
        .cloud
        .positions
        .iter()
        .map(|p| (*p - mid).dot(axis).abs() > 8.0)
        .collect();
    s.cloud.retain_indices(|i| keep[i]);
    let (d, errors, _) = fit_chain(&s, &ScheduleSettings::default());
    println!("holed: mean distance {d:.4}, joint errors {errors:?}");
}

#[test]
fn chain_debug_trace() {
    use pygmalion::fakir::schedule::{chain_initial_pass, chain_pass};
    let sigma: f32 = std::env::var("SIGMA")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0.0);
    let s = chain4(5_000, 2, sigma, 0.0, vec![]).unwrap();
    let t = s.truth.template.clone();
    let mut init = Skeleton::rest(t.clone());
    for b in &mut init.bones {
        b.length = 35.0;
        b.r1 = 7.0;
        b.r2 = 7.0;
    }
    init.root_rotation = Quat::from_rotation_z(0.9);
    let world = WorldSkeleton::from_skeleton(&init);
    let n = s.cloud.len();
    let asg = Assignment::new(
        s.cloud.positions.clone(),
        s.cloud.normals.clone().unwrap(),
        (0..n as u32).collect(),
        4,
        AssignParams {
            cone_slack: 0.2,
            cone_abs: 0.28,
        },
    );
    let mut pause = NoPause;
    let mut solver = Solver::new(world, asg, 1.0, SolverSettings::default(), &mut pause);
    solver.free_root = true;
    let truth = s.truth.pose();
    let report = |solver: &Solver, what: &str| {
        let f = solver.world.pose();
        let e: Vec<String> = f
            .joints
            .iter()
            .zip(&truth.joints)
            .map(|(a, b)| format!("{:.2}", (*a - *b).length()))
            .collect();
        let counts: Vec<usize> = solver.members.iter().map(|m| m.len()).collect();
        let radii: Vec<String> = f
            .bones
            .iter()
            .map(|b| format!("{:.1}/{:.1}", b.r1, b.r2))
            .collect();
        println!(
            "{what}: d {:.4} joints {:?} counts {:?} radii {:?}",
            solver.mean_distance(),
            e,
            counts,
            radii
        );
    };
    solver.refresh().unwrap();
    report(&solver, "start");
    solver
        .one_bone(0, pygmalion::fakir::world::End::Second, true)
        .unwrap();
    report(&solver, "bone0");
    for k in 0..3 {
        solver
            .one_bone(k + 1, pygmalion::fakir::world::End::Second, false)
            .unwrap();
        report(&solver, &format!("one {}", k + 1));
        solver.two_bone(k, k + 1).unwrap();
        report(&solver, &format!("two {k}-{}", k + 1));
    }
    let _ = chain_initial_pass;
    for p in 0..6 {
        chain_pass(&mut solver, &[0, 1, 2, 3], p % 2 == 0).unwrap();
        report(&solver, &format!("pass {p}"));
    }
}

#[test]
fn single_bone_debug() {
    use pygmalion::fakir::world::End;
    let s = chain4(5_000, 1, 0.0, 0.0, vec![]).unwrap();
    let t = s.truth.template.clone();
    // Only the points of the first bone; a 1-bone problem with the other bones disabled.
    let idx: Vec<usize> = (0..s.cloud.len()).filter(|&i| s.labels[i] == 0).collect();
    let pos: Vec<Vec3> = idx.iter().map(|&i| s.cloud.positions[i]).collect();
    let nrm: Vec<Vec3> = idx
        .iter()
        .map(|&i| s.cloud.normals.as_ref().unwrap()[i])
        .collect();
    let mut init = s.truth.clone();
    init.bones[0].rotation = init.bones[0].rotation * Quat::from_rotation_z(0.3);
    init.bones[0].length *= 1.3;
    init.bones[0].r2 *= 0.7;
    init.bones[1].r1 *= 0.7;
    let world = WorldSkeleton::from_skeleton(&init);
    let mut asg = Assignment::new(
        pos.clone(),
        nrm,
        (0..pos.len() as u32).collect(),
        4,
        AssignParams {
            cone_slack: 0.2,
            cone_abs: 0.28,
        },
    );
    asg.enabled = vec![true, false, false, false];
    let mut pause = NoPause;
    let mut solver = Solver::new(
        world,
        asg,
        1.0,
        SolverSettings {
            lm_iterations: 20,
            one_bone_rounds: 10,
            ..Default::default()
        },
        &mut pause,
    );
    solver.refresh().unwrap();
    println!("start d {:.5}", solver.mean_distance());
    for r in 0..5 {
        solver.one_bone(0, End::Second, true).unwrap();
        let b = solver.world.pose().bones[0];
        let tb = s.truth.pose().bones[0];
        println!(
            "round {r}: d {:.6} c2 err {:.4} len {:.3}/{:.3} r {:.3}/{:.3} vs {:.3}/{:.3}",
            solver.mean_distance(),
            (b.c2 - tb.c2).length(),
            b.length(),
            tb.length(),
            b.r1,
            b.r2,
            tb.r1,
            tb.r2
        );
    }
    let _ = t;
}

#[test]
fn two_bone_debug() {
    let s = chain4(5_000, 1, 0.0, 0.0, vec![]).unwrap();
    let mut w = WorldSkeleton::from_skeleton(&s.truth);
    let classes = pygmalion::fakir::world::RadiusClasses::new(&s.truth.template);
    // Move joint 1 by 8 units sideways with outer joints fixed.
    pygmalion::fakir::lm::apply(
        &mut w,
        &classes,
        &pygmalion::fakir::lm::Param::PairRotate { a: 0, b: 1 },
        0.4,
    );
    pygmalion::fakir::lm::apply(
        &mut w,
        &classes,
        &pygmalion::fakir::lm::Param::PairLength {
            a: 0,
            b: 1,
            first: true,
        },
        5.0,
    );
    let n = s.cloud.len();
    let asg = Assignment::new(
        s.cloud.positions.clone(),
        s.cloud.normals.clone().unwrap(),
        (0..n as u32).collect(),
        4,
        AssignParams {
            cone_slack: 0.2,
            cone_abs: 0.28,
        },
    );
    let mut pause = NoPause;
    let mut solver = Solver::new(
        w,
        asg,
        1.0,
        SolverSettings {
            lm_iterations: 10,
            two_bone_rounds: 10,
            ..Default::default()
        },
        &mut pause,
    );
    solver.refresh().unwrap();
    let truth = s.truth.pose();
    for r in 0..6 {
        let f = solver.world.pose();
        println!(
            "round {r}: d {:.6} j1 err {:.4} r {:.3} (truth {:.3}) E01 {:.3}",
            solver.mean_distance(),
            (f.joints[1] - truth.joints[1]).length(),
            f.bones[0].r2,
            truth.bones[0].r2,
            solver.energy_of(&[0, 1])
        );
        solver.two_bone(0, 1).unwrap();
    }
}

/// The LM gradient `2 Jᵀr` matches central finite differences of the energy for every kind of
/// parameter (the derivative check the papers' eq. 2.9–2.15 are replaced by).
#[test]
fn lm_gradient_matches_finite_differences_of_the_energy() {
    use pygmalion::fakir::lm::{EnergyTerms, MAX_PARAMS, Param, apply, normal_equations};
    use pygmalion::fakir::world::{End, RadiusClasses};
    let s = chain4(5_000, 4, 0.0, 0.0, vec![]).unwrap();
    let mut w = WorldSkeleton::from_skeleton(&s.truth);
    let classes = RadiusClasses::new(&s.truth.template);
    // Off the optimum so the gradient is not zero.
    apply(&mut w, &classes, &Param::PairRotate { a: 1, b: 2 }, 0.2);
    apply(&mut w, &classes, &Param::Length { bone: 0 }, 3.0);
    apply(
        &mut w,
        &classes,
        &Param::Radius {
            bone: 1,
            end: End::Second,
        },
        1.0,
    );
    let n = s.cloud.len();
    let mut asg = Assignment::new(
        s.cloud.positions.clone(),
        s.cloud.normals.clone().unwrap(),
        (0..n as u32).collect(),
        4,
        AssignParams {
            cone_slack: 0.2,
            cone_abs: 0.28,
        },
    );
    let prepared: Vec<_> = w.bones().iter().map(|b| b.prepare()).collect();
    asg.refresh(&prepared, &[0, 1, 2, 3]);
    let members = asg.members();
    let size = 140.0;
    let cases = [
        (
            vec![
                Param::Swing {
                    bone: 1,
                    axis: w.frames[1] * Vec3::Y,
                },
                Param::Swing {
                    bone: 1,
                    axis: w.frames[1] * Vec3::Z,
                },
            ],
            vec![1usize, 2, 3],
        ),
        (vec![Param::Length { bone: 1 }], vec![1, 2, 3]),
        (
            vec![Param::Radius {
                bone: 1,
                end: End::Second,
            }],
            vec![1, 2],
        ),
        (
            vec![
                Param::PairRotate { a: 1, b: 2 },
                Param::PairLength {
                    a: 1,
                    b: 2,
                    first: true,
                },
                Param::PairLength {
                    a: 1,
                    b: 2,
                    first: false,
                },
            ],
            vec![1, 2],
        ),
        (
            vec![Param::AnchorMove {
                bone: 0,
                axis: Vec3::Y,
            }],
            vec![0],
        ),
    ];
    for (params, bones) in cases {
        let terms = EnergyTerms {
            assignment: &asg,
            members: &members,
            bones: &bones,
            cap: None,
        };
        let (_, jtr, energy) = normal_equations(&w, &classes, &params, &terms, size);
        for (j, p) in params.iter().enumerate() {
            let h = match p {
                Param::Swing { .. } | Param::PairRotate { .. } => 1e-3,
                _ => 1e-2,
            };
            let mut plus = w.clone();
            apply(&mut plus, &classes, p, h);
            let mut minus = w.clone();
            apply(&mut minus, &classes, p, -h);
            let (ep, em) = (terms.energy(&plus.bones()), terms.energy(&minus.bones()));
            let fd = (ep - em) / (2.0 * h as f64);
            println!(
                "  e+ {ep} e- {em} j2+ {:?} j2- {:?}",
                plus.pose().joints[2],
                minus.pose().joints[2]
            );
            let analytic = 2.0 * jtr[j];
            println!("{p:?}: energy {energy:.3} fd {fd:.4} analytic {analytic:.4}");
            assert!(
                (fd - analytic).abs() <= 0.02 * fd.abs().max(analytic.abs()) + 1e-3 * energy,
                "{p:?}: fd {fd} vs {analytic}"
            );
        }
        let _ = MAX_PARAMS;
    }
}

#[test]
fn pair_rotate_debug() {
    use pygmalion::fakir::lm::{Param, apply};
    use pygmalion::fakir::world::RadiusClasses;
    let s = chain4(100, 4, 0.0, 0.0, vec![]).unwrap();
    let mut w = WorldSkeleton::from_skeleton(&s.truth);
    let classes = RadiusClasses::new(&s.truth.template);
    apply(&mut w, &classes, &Param::PairRotate { a: 1, b: 2 }, 0.2);
    println!("after 0.2: {:?}", w.pose().joints);
    for v in [0.0f32, 0.001, -0.001] {
        let mut x = w.clone();
        apply(&mut x, &classes, &Param::PairRotate { a: 1, b: 2 }, v);
        println!("{v}: {:?}", x.pose().joints);
    }
}
