//! Tests of `fakir`: the papers' chain experiment, LM derivatives, whole-skeleton registration.
//!
//! **Long tier.** The regression statues of the level-5 checks and the level-6 lost-limb rules
//! (one whole registration of one generator statue each, most at 30k points with the CLI's
//! defaults, 50–255 s each on our 2-core machine) are `#[ignore]`d with the reason "long
//! tier": `bash tests/run.sh` (and CI) leaves them out, `bash tests/run.sh --include-ignored`
//! runs them with the rest, `bash tests/run.sh --ignored` runs them alone. Any change to what
//! a registration computes runs them before it is committed. One case per family of checks
//! stays in the default run (the crossed legs, the arm slid one joint in, both hands cut at
//! the wrists) beside the accuracy, template, stepping and lost-limb tests.

use crate::common::on_one_thread;
use pygmalion::anatomy::Skeleton;
use pygmalion::fakir::assign::{AssignParams, Assignment};
use pygmalion::fakir::schedule::{ScheduleSettings, register_chain};
use pygmalion::fakir::solver::{NoPause, Solver, SolverSettings};
use pygmalion::fakir::world::WorldSkeleton;
use pygmalion::math::{Quat, Vec3};
use pygmalion::synth::{SynthStatue, chain4};

/// An assignment of all the points of a chain statue to its 4 bones.
fn assignment_of(s: &SynthStatue, cone_abs: f32) -> Assignment {
    let n = s.cloud.len();
    Assignment::new(
        s.cloud.positions.clone(),
        s.cloud.normals.clone().unwrap(),
        (0..n as u32).collect(),
        4,
        AssignParams {
            cone_slack: 0.2,
            cone_abs,
        },
    )
}

/// The papers' chain start on `s`'s chain template: a straight generic chain (lengths 35,
/// radii 7) turned 0.9 rad away from the points.
fn papers_chain_start(s: &SynthStatue) -> Skeleton {
    let mut init = Skeleton::rest(s.truth.template.clone());
    for b in &mut init.bones {
        b.length = 35.0;
        b.r1 = 7.0;
        b.r2 = 7.0;
    }
    init.root_rotation = Quat::from_rotation_z(0.9);
    init
}

/// Fits a generic straight 4-bone chain (equal lengths 35, radii 7, pointing away from the
/// data) anchored at the true first extremity; returns (mean distance, joint errors, units).
fn fit_chain(s: &SynthStatue, settings: &ScheduleSettings) -> (f64, Vec<f32>, u64) {
    let world = WorldSkeleton::from_skeleton(&papers_chain_start(s));
    let asg = assignment_of(s, 0.28);
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
    // Papers: 4-bone chain, total length 140, 5k points, anchor at one extremity, the chain
    // starting away from the points; the noise-free fit converges to distance 0.
    let s = chain4(5_000, 1, 0.0, 0.0, vec![]).unwrap();
    let (d, errors, _) = fit_chain(&s, &ScheduleSettings::default());
    println!("noise-free: mean distance {d:.5}, joint errors {errors:?}");
    assert!(d < 0.05, "mean distance {d} (length 140)");
    assert!(errors.iter().all(|e| *e < 1.0), "joint errors {errors:?}");
}

#[test]
fn chain_experiment_gaussian_noise() {
    // Converges to a mean distance close to the noise level (E|N(0, σ)| = 0.80 σ) with
    // joints within a few σ of the truth (thesis fig. 2.8–2.9).
    for (seed, sigma) in [(2u64, 0.5f32), (2, 1.0), (2, 2.0)] {
        let s = chain4(5_000, seed, sigma, 0.0, vec![]).unwrap();
        let (d, errors, _) = fit_chain(&s, &ScheduleSettings::default());
        println!("σ = {sigma}: mean distance {d:.4}, joint errors {errors:?}");
        assert!(
            d > 0.6 * sigma as f64 && d < 1.0 * sigma as f64,
            "σ = {sigma}: mean distance {d}"
        );
        assert!(
            errors.iter().all(|e| *e < 3.0 * sigma),
            "σ = {sigma}: joint errors {errors:?}"
        );
    }
}

#[test]
fn chain_experiment_missing_middle() {
    // A slab 16 units thick removed across the third bone (thesis fig. 2.12).
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
    assert!(s.cloud.len() < 4_600);
    let (d, errors, _) = fit_chain(&s, &ScheduleSettings::default());
    println!("missing middle: mean distance {d:.4}, joint errors {errors:?}");
    assert!(d < 0.05, "mean distance {d}");
    assert!(errors.iter().all(|e| *e < 1.0), "joint errors {errors:?}");
}

#[test]
fn two_bone_fit_recovers_a_displaced_joint() {
    use pygmalion::fakir::lm::{Param, apply};
    use pygmalion::fakir::world::RadiusClasses;
    let s = chain4(5_000, 1, 0.0, 0.0, vec![]).unwrap();
    let mut w = WorldSkeleton::from_skeleton(&s.truth);
    let classes = RadiusClasses::new(&s.truth.template);
    // Joint 1 moved by about 7 units, outer joints fixed.
    apply(&mut w, &classes, &Param::PairRotate { a: 0, b: 1 }, 0.4);
    apply(
        &mut w,
        &classes,
        &Param::PairLength {
            a: 0,
            b: 1,
            first: true,
        },
        5.0,
    );
    let truth = s.truth.pose();
    assert!((w.pose().joints[1] - truth.joints[1]).length() > 5.0);
    let asg = assignment_of(&s, 0.0);
    let mut pause = NoPause;
    let mut solver = Solver::new(
        w,
        asg,
        1.0,
        SolverSettings {
            occupancy: false,
            ..Default::default()
        },
        &mut pause,
    );
    solver.refresh().unwrap();
    solver.two_bone(0, 1).unwrap();
    solver.two_bone(0, 1).unwrap();
    let f = solver.world.pose();
    let err = (f.joints[1] - truth.joints[1]).length();
    assert!(err < 0.05, "joint 1 error {err}");
    assert!((f.bones[0].r2 - truth.bones[0].r2).abs() < 0.05);
    // The outer joints did not move.
    assert!(
        (f.joints[0] - truth.joints[0]).length() < 1e-4
            && (f.joints[2] - truth.joints[2]).length() < 1e-3
    );
}

/// The LM gradient `2 Jᵀr` matches central finite differences of the energy for every kind of
/// parameter (the derivative check the papers' eq. 2.9–2.15 are replaced by).
#[test]
fn lm_gradient_matches_finite_differences_of_the_energy() {
    use pygmalion::fakir::lm::{EnergyTerms, Param, apply, normal_equations};
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
            occupancy: None,
            prior: None,
        };
        let ne = normal_equations(&w, &classes, &params, &terms, size);
        let (jtr, energy) = (ne.jtr, ne.energy);
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
            let analytic = 2.0 * jtr[j];
            assert!(
                (fd - analytic).abs() <= 0.02 * fd.abs().max(analytic.abs()) + 1e-3 * energy,
                "{p:?}: fd {fd} vs {analytic}"
            );
        }
    }
}

/// The support's mean spacing summed in work-unit slices (`add_spacings`, as the
/// registration does) is `mean_spacing` bit for bit, whatever the slices (multiples of
/// `SPACING_CHUNK`); on a small cloud it is the brute-force mean nearest-neighbour distance
/// (relative tolerance 1e-5), and a cloud over 20k points is sampled every
/// `n / 20 000`-th point, each sample counted once (against a direct loop, relative 1e-9).
#[test]
fn the_mean_spacing_summed_in_slices_is_the_mean_spacing_bit_for_bit() {
    use pygmalion::fakir::support::{SPACING_CHUNK, add_spacings, mean_spacing, spacing_samples};
    let tree_of = |p: &[Vec3]| {
        let arr: Vec<[f32; 3]> = p.iter().map(|v| v.to_array()).collect();
        kiddo::ImmutableKdTree::<f32, 3>::new_from_slice(&arr).unwrap()
    };
    // Brute force on 2000 points.
    let small = chain4(2_000, 3, 0.5, 0.0, vec![]).unwrap().cloud.positions;
    let brute: f64 = small
        .iter()
        .enumerate()
        .map(|(i, p)| {
            small
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .map(|(_, q)| p.distance(*q) as f64)
                .fold(f64::INFINITY, f64::min)
        })
        .sum::<f64>()
        / small.len() as f64;
    let m = mean_spacing(&small, &tree_of(&small)) as f64;
    assert!(
        (m - brute).abs() <= 1e-5 * brute,
        "mean spacing {m} against brute force {brute}"
    );
    // Slices of a 45k-point cloud (every second point sampled).
    let big = chain4(45_000, 5, 0.5, 0.0, vec![]).unwrap().cloud.positions;
    let tree = tree_of(&big);
    let n = spacing_samples(big.len());
    assert_eq!(n, 22_500);
    let mut whole = 0.0f64;
    add_spacings(&big, &tree, 0..n, &mut whole);
    // Every second point, each counted once.
    let direct: f64 = (0..n)
        .map(|k| {
            let two = std::num::NonZero::new(2).unwrap();
            let nn = tree
                .query(&big[2 * k].to_array())
                .nearest_n::<kiddo::SquaredEuclidean<f32>>(two)
                .execute();
            nn[1].distance.sqrt() as f64
        })
        .sum();
    assert!(
        (whole - direct).abs() <= 1e-9 * direct,
        "{whole} against {direct}"
    );
    assert_eq!(
        mean_spacing(&big, &tree).to_bits(),
        ((whole / n as f64) as f32).to_bits()
    );
    for slice in [
        SPACING_CHUNK,
        3 * SPACING_CHUNK,
        8 * SPACING_CHUNK,
        100 * SPACING_CHUNK,
    ] {
        let mut sum = 0.0f64;
        for start in (0..n).step_by(slice) {
            add_spacings(&big, &tree, start..start + slice, &mut sum);
        }
        assert_eq!(sum.to_bits(), whole.to_bits(), "slices of {slice}");
    }
}

/// A Jacobian row whose entries outside its bone's active parameters are zeros adds the same
/// `JᵀJ`, `Jᵀr` and energy, bit for bit, through `NormalEquations::add_sparse_row` (the active
/// entries only) as through `add_row` (every entry): the normal equations skip the zeros of
/// the whole-chain fit's rows without changing a registration. Zeros of both signs, rows of
/// several active sets mixed in one sum, partial sums added together as the chunks are.
#[test]
fn a_sparse_normal_row_adds_what_the_dense_row_adds_bit_for_bit() {
    use pygmalion::fakir::lm::NormalEquations;
    use pygmalion::rng::Rng;
    let k = 17;
    let mut rng = Rng::new(7);
    // Active sets of a chain's bones: the first bones' rows are mostly zeros.
    let sets: Vec<Vec<usize>> = vec![
        vec![0, 1, 8, 12, 13],
        vec![0, 1, 2, 3, 8, 9, 12, 13, 14],
        (0..k).filter(|j| j % 3 != 1).collect(),
        vec![16],
        vec![],
    ];
    let (mut dense, mut sparse) = (NormalEquations::zeros(k), NormalEquations::zeros(k));
    for chunk in 0..6 {
        let (mut d, mut s) = (NormalEquations::zeros(k), NormalEquations::zeros(k));
        for i in 0..500 {
            let act = &sets[(chunk + i) % sets.len()];
            let mut row = vec![0.0f64; k];
            for (j, x) in row.iter_mut().enumerate() {
                *x = if act.contains(&j) {
                    (rng.range(-3.0, 3.0) as f64) * 1e-3
                } else if rng.f32() < 0.5 {
                    -0.0
                } else {
                    0.0
                };
            }
            let r = rng.range(-1.0, 1.0) as f64;
            d.add_row(&row, r);
            let packed: Vec<f64> = act.iter().map(|&j| row[j]).collect();
            s.add_sparse_row(act, &packed, r);
        }
        assert_eq!(bits(&d.jtj), bits(&s.jtj), "chunk {chunk}: JᵀJ");
        dense.add(&d);
        sparse.add(&s);
    }
    assert_eq!(bits(&dense.jtj), bits(&sparse.jtj), "JᵀJ");
    assert_eq!(bits(&dense.jtr), bits(&sparse.jtr), "Jᵀr");
    assert_eq!(dense.energy.to_bits(), sparse.energy.to_bits(), "energy");
    // The sums are not trivially zero.
    assert!(dense.jtj.iter().filter(|x| **x != 0.0).count() > 50);
}

/// The LM sums cut into work-unit slices (`NormalAccumulator`, `EnergyAccumulator`) are the
/// unsliced sums bit for bit, whatever the slice size, so pausing between slices cannot
/// change a registration.
#[test]
fn sliced_lm_sums_equal_the_unsliced_sums_bit_for_bit() {
    use pygmalion::fakir::assign::CHUNK;
    use pygmalion::fakir::lm::{
        EnergyAccumulator, EnergyTerms, NO_ROW, NormalAccumulator, Param, RangePrior, Rows, apply,
        normal_equations,
    };
    use pygmalion::fakir::world::RadiusClasses;
    // About 7500 points per bone: several chunks each.
    let s = chain4(30_000, 4, 0.5, 0.0, vec![]).unwrap();
    let mut w = WorldSkeleton::from_skeleton(&s.truth);
    let classes = RadiusClasses::new(&s.truth.template);
    apply(&mut w, &classes, &Param::PairRotate { a: 1, b: 2 }, 0.2);
    let mut asg = assignment_of(&s, 0.28);
    let prepared: Vec<_> = w.bones().iter().map(|b| b.prepare()).collect();
    asg.refresh(&prepared, &[0, 1, 2, 3]);
    let members = asg.members();
    assert!(
        members.iter().all(|m| m.len() > 2 * CHUNK),
        "{:?}",
        members.iter().map(Vec::len).collect::<Vec<_>>()
    );
    let bones = [1usize, 2, 3];
    let terms = EnergyTerms {
        assignment: &asg,
        members: &members,
        bones: &bones,
        occupancy: None,
        prior: None,
    };
    let params = [
        Param::PairRotate { a: 1, b: 2 },
        Param::PairLength {
            a: 1,
            b: 2,
            first: true,
        },
    ];
    let whole = normal_equations(&w, &classes, &params, &terms, 140.0);
    let energy = terms.energy(&w.bones());
    for budget in [1, CHUNK, 3 * CHUNK, 5_000] {
        let mut acc = NormalAccumulator::new(&w, &classes, &params, &terms, 140.0);
        let mut slices = 1;
        while !acc.feed(&terms, budget) {
            slices += 1;
        }
        let sliced = acc.finish(&w, &terms);
        assert!(slices >= 3, "budget {budget}: {slices} slices");
        assert_eq!(bits(&sliced.jtj), bits(&whole.jtj), "JᵀJ, budget {budget}");
        assert_eq!(bits(&sliced.jtr), bits(&whole.jtr), "Jᵀr, budget {budget}");
        assert_eq!(
            sliced.energy.to_bits(),
            whole.energy.to_bits(),
            "energy, budget {budget}"
        );
        let mut e = EnergyAccumulator::new(w.bones());
        while !e.feed(&terms, budget) {}
        assert_eq!(
            e.data.to_bits(),
            energy.to_bits(),
            "data energy, budget {budget}"
        );
        assert_eq!(
            e.finish(&terms, &w).to_bits(),
            terms.total_energy(&w).to_bits()
        );
    }
    // The unsliced energy is the plain sum of squared residuals (to rounding).
    let direct: f64 = bones
        .iter()
        .flat_map(|&b| {
            let pb = w.bones()[b].prepare();
            let asg = &asg;
            members[b].iter().map(move |&i| {
                let r = pb
                    .project_constrained(asg.positions[i as usize], asg.normals[i as usize])
                    .residual as f64;
                r * r
            })
        })
        .sum();
    assert!(
        (direct - energy).abs() <= 1e-9 * direct,
        "{direct} vs {energy}"
    );
    // A pass that keeps its rows (residual and gradient of every point), and a pass at the
    // same state that reads them instead of projecting, give the same sums bit for bit, prior
    // included.
    let prior = RangePrior {
        bones: vec![(2, 3.0)],
        margin: 0.1,
        ratios: vec![(2, 1, 0.2, 2.0)],
    };
    assert!(prior.energy(&w) > 0.0, "the prior must take part");
    let terms = EnergyTerms {
        prior: Some(&prior),
        ..terms
    };
    let whole = normal_equations(&w, &classes, &params, &terms, 140.0);
    let energy = {
        let mut e = EnergyAccumulator::new(w.bones());
        while !e.feed(&terms, usize::MAX) {}
        e.finish(&terms, &w)
    };
    for budget in [CHUNK, 5_000, usize::MAX] {
        let mut kept = vec![NO_ROW; terms.count()];
        let mut e = EnergyAccumulator::new(w.bones());
        let mut rows = Rows {
            read: None,
            write: Some(&mut kept),
        };
        while !e.feed_rows(&terms, budget, &mut rows) {}
        assert_eq!(e.finish(&terms, &w).to_bits(), energy.to_bits());
        let mut rows = Rows {
            read: Some(&kept),
            write: None,
        };
        let mut acc = NormalAccumulator::new(&w, &classes, &params, &terms, 140.0);
        while !acc.feed_rows(&terms, budget, &mut rows) {}
        let ne = acc.finish(&w, &terms);
        assert_eq!(bits(&ne.jtj), bits(&whole.jtj));
        assert_eq!(bits(&ne.jtr), bits(&whole.jtr));
        assert_eq!(
            ne.energy.to_bits(),
            whole.energy.to_bits(),
            "budget {budget}"
        );
        let mut e = EnergyAccumulator::new(w.bones());
        while !e.feed_rows(&terms, budget, &mut rows) {}
        assert_eq!(e.finish(&terms, &w).to_bits(), energy.to_bits());
    }
    // Rows read at another state are another state's: the sums differ.
    let mut moved = w.clone();
    apply(&mut moved, &classes, &params[0], 0.05);
    let mut kept = vec![NO_ROW; terms.count()];
    let mut e = EnergyAccumulator::new(moved.bones());
    let mut rows = Rows {
        read: None,
        write: Some(&mut kept),
    };
    while !e.feed_rows(&terms, usize::MAX, &mut rows) {}
    let mut acc = NormalAccumulator::new(&w, &classes, &params, &terms, 140.0);
    let mut rows = Rows {
        read: Some(&kept),
        write: None,
    };
    while !acc.feed_rows(&terms, usize::MAX, &mut rows) {}
    assert_ne!(
        acc.finish(&w, &terms).energy.to_bits(),
        whole.energy.to_bits()
    );
}

/// An assignment built in slices (`with_capacity` + `push`, as level 1 builds its 100k-point
/// one across work units) is the one built at once.
#[test]
fn an_assignment_built_in_slices_equals_one_built_at_once() {
    let s = chain4(5_000, 4, 0.5, 0.0, vec![]).unwrap();
    let n = s.cloud.len();
    let whole = assignment_of(&s, 0.28);
    let normals = s.cloud.normals.clone().unwrap();
    let mut sliced = Assignment::with_capacity(n, 4, whole.params);
    for start in (0..n).step_by(1_234) {
        let end = (start + 1_234).min(n);
        let source: Vec<u32> = (start as u32..end as u32).collect();
        sliced.push(
            &s.cloud.positions[start..end],
            &normals[start..end],
            &source,
        );
    }
    assert_eq!(sliced.len(), n);
    assert_eq!(
        (&sliced.positions, &sliced.normals, &sliced.source),
        (&whole.positions, &whole.normals, &whole.source)
    );
    let prepared: Vec<_> = s.truth.pose().bones.iter().map(|b| b.prepare()).collect();
    let (mut a, mut b) = (whole, sliced);
    a.refresh(&prepared, &[0, 1, 2, 3]);
    b.refresh(&prepared, &[0, 1, 2, 3]);
    assert_eq!(a.label, b.label);
    assert!(a.label.contains(&3) && a.label.contains(&0));
    for i in 0..n {
        for bone in 0..4 {
            assert_eq!(a.distance(bone, i).to_bits(), b.distance(bone, i).to_bits());
        }
    }
}

/// The mean distance (eq. 2.16) is the sum, in order, of the sums of runs of `CHUNK` points
/// (each run summed in order), over the point count: bit for bit, whatever the threads, for
/// a count that is not a multiple of `CHUNK` (5,000 = 2 × 2,048 + 904) and for one run.
#[test]
fn the_mean_distance_sums_runs_of_chunk_points_in_order() {
    use pygmalion::fakir::assign::CHUNK;
    for points in [5_000usize, 700] {
        let s = chain4(points, 4, 0.5, 0.0, vec![]).unwrap();
        let mut a = assignment_of(&s, 0.28);
        let prepared: Vec<_> = s.truth.pose().bones.iter().map(|b| b.prepare()).collect();
        a.refresh(&prepared, &[0, 1, 2, 3]);
        let n = a.len();
        assert_eq!(n, points);
        let runs: Vec<f64> = (0..n)
            .step_by(CHUNK)
            .map(|start| {
                (start..(start + CHUNK).min(n))
                    .map(|i| a.own_distance(i) as f64)
                    .sum::<f64>()
            })
            .collect();
        let expected = runs.iter().sum::<f64>() / n as f64;
        assert!(expected > 0.0);
        for threads in [1, 2, 3] {
            let got = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| a.mean_distance());
            assert_eq!(
                got.to_bits(),
                expected.to_bits(),
                "{points} points, {threads} threads"
            );
        }
    }
}

/// Mean joint error of a fitted skeleton against the truth, as a fraction of `height`.
pub fn joint_error(fit: &Skeleton, truth: &Skeleton, height: f32) -> f32 {
    fit.mean_joint_distance(truth) / height
}

fn small_human(seed: u64, points: usize, random_pose: bool) -> SynthStatue {
    use pygmalion::anatomy::Template;
    use pygmalion::synth::{SynthOptions, generate};
    let t = std::sync::Arc::new(Template::builtin("human").unwrap());
    generate(
        t,
        &SynthOptions {
            points,
            seed,
            rigid: true,
            random_pose,
            proportion_jitter: 0.1,
            height: 1.7,
            ..Default::default()
        },
    )
    .unwrap()
}

/// Options of the small registrations whose bytes the stepping and row-reuse tests compare.
fn small_options() -> pygmalion::fakir::RegistrationOptions {
    pygmalion::fakir::RegistrationOptions {
        subsample: 1_500,
        init_subsample: 600,
        ..Default::default()
    }
}

/// A complete statue and a broken one (its lost forearm and hand settled by level 6), each
/// with its registration under [`small_options`] run to convergence. Computed once for the
/// tests that compare other ways of running the same registration against it (a second
/// caller waits for the first; the two registrations run in parallel).
fn small_references() -> &'static [(SynthStatue, pygmalion::fakir::Fit)] {
    static REFERENCES: std::sync::OnceLock<Vec<(SynthStatue, pygmalion::fakir::Fit)>> =
        std::sync::OnceLock::new();
    REFERENCES.get_or_init(|| {
        use rayon::prelude::*;
        // Both at once: the test waiting for them lends its core.
        vec![
            small_human(11, 3_000, true),
            cut_human(12, 3_000, &[("l_forearm", 0.0)]),
        ]
        .into_par_iter()
        .map(|s| {
            let fit = register_with(&s, small_options());
            (s, fit)
        })
        .collect()
    })
}

#[test]
fn registration_steps_of_any_budget_give_the_same_bytes() {
    for (s, reference) in small_references() {
        budgets_give_the_same_bytes(s, reference);
    }
}

/// Runs `s`'s registration under [`small_options`] in steps of a zero budget (one work unit a
/// step: every unit boundary is a pause) and of 5 ms (several units a step) and compares each
/// result with `reference`, the same registration run to convergence.
fn budgets_give_the_same_bytes(s: &SynthStatue, reference: &pygmalion::fakir::Fit) {
    use pygmalion::fakir::Registration;
    use std::sync::Arc;
    use std::time::Duration;
    let t = s.truth.template.clone();
    let opts = small_options();
    let cloud = Arc::new(s.cloud.clone());
    for budget_us in [0u64, 5_000] {
        let mut reg = Registration::new(cloud.clone(), t.clone(), opts.clone()).unwrap();
        let mut steps = 0;
        let mut last_units = 0;
        let mut last_fraction = 0.0f32;
        while !reg.is_done() {
            let p = reg.step(Duration::from_micros(budget_us));
            assert!(p.units >= last_units, "progress goes forward");
            assert!(
                p.activity.fraction >= last_fraction && p.activity.fraction <= 1.0,
                "the progress fraction goes forward: {last_fraction} then {}",
                p.activity.fraction
            );
            last_fraction = p.activity.fraction;
            if budget_us == 0 && !p.done {
                // A step stops at the first unit boundary after its budget: with no budget,
                // exactly one unit (the kiosk's frames overshoot by at most one unit).
                assert_eq!(
                    p.units,
                    last_units + 1,
                    "a zero budget ran more than one unit"
                );
            }
            last_units = p.units;
            steps += 1;
        }
        assert_eq!(
            reg.progress().activity.fraction,
            1.0,
            "done is the whole way"
        );
        assert!(last_fraction > 0.0);
        let fit = reg.take_result().unwrap().unwrap();
        assert!(steps > 1, "a {budget_us} µs budget must take several steps");
        assert_eq!(fit.labels, reference.labels);
        assert_eq!(
            fit.mean_distance.to_bits(),
            reference.mean_distance.to_bits()
        );
        let (a, b) = (fit.skeleton.pose(), reference.skeleton.pose());
        assert_eq!(
            a.bones, b.bones,
            "budget {budget_us} µs changed the skeleton"
        );
        assert_eq!(fit.units, reference.units);
        assert_eq!(fit.missing, reference.missing);
    }
    println!(
        "lost bones: {:?}",
        (0..t.bones.len())
            .filter(|&b| reference.missing[b])
            .map(|b| &t.bones[b].name)
            .collect::<Vec<_>>()
    );
    // Dropping a registration half way stops its worker cleanly.
    let mut reg = Registration::new(cloud, t, opts).unwrap();
    reg.step(Duration::from_micros(200));
    drop(reg);
}

/// Reading the last pass's residuals and gradients at an unchanged state (`reuse_rows`)
/// instead of projecting again changes no sum: the same labels, mean distance and skeleton
/// bit for bit, on a complete statue and a broken one (the work units are the same: a pass
/// reading rows is sliced like one projecting).
#[test]
fn reusing_the_last_pass_rows_gives_the_same_bytes() {
    // The references read the rows (`reuse_rows` is on by default).
    assert!(small_options().solver.reuse_rows);
    for (s, with) in small_references() {
        let mut opts = small_options();
        opts.solver.reuse_rows = false;
        let without = register_with(s, opts);
        assert_eq!(with.labels, without.labels);
        assert_eq!(
            with.mean_distance.to_bits(),
            without.mean_distance.to_bits()
        );
        assert_eq!(with.skeleton.pose().bones, without.skeleton.pose().bones);
        assert_eq!(with.missing, without.missing);
        assert_eq!(with.units, without.units);
    }
}

#[test]
fn registration_fits_a_rest_pose_statue_under_a_random_rigid_motion() {
    use pygmalion::fakir::{Registration, RegistrationOptions};
    use std::sync::Arc;
    let s = small_human(5, 6_000, false);
    let fit = Registration::new(
        Arc::new(s.cloud.clone()),
        s.truth.template.clone(),
        RegistrationOptions::default(),
    )
    .unwrap()
    .run_to_convergence()
    .unwrap();
    let err = joint_error(&fit.skeleton, &s.truth, 1.7);
    println!(
        "rest pose under a rigid motion: joint error {:.2}% of height, mean distance {:.5}",
        100.0 * err,
        fit.mean_distance
    );
    assert!(err < 0.03, "joint error {err}");
    assert_eq!(fit.labels.len(), s.cloud.len());
    assert_eq!(fit.bone_counts.iter().sum::<usize>(), s.cloud.len());
}

#[test]
fn registration_rejects_clouds_it_cannot_fit() {
    use pygmalion::anatomy::Template;
    use pygmalion::cloud::PointCloud;
    use pygmalion::fakir::{Registration, RegistrationOptions};
    use std::sync::Arc;
    let t = Arc::new(Template::builtin("human").unwrap());
    let few = Arc::new(PointCloud::from_positions(vec![Vec3::ONE; 10]));
    let e = Registration::new(few, t.clone(), RegistrationOptions::default())
        .err()
        .expect("too few points")
        .to_string();
    assert!(e.contains("too few points"), "{e}");
    let line: Vec<Vec3> = (0..2000).map(|i| Vec3::new(i as f32, 0.0, 0.0)).collect();
    let r = Registration::new(
        Arc::new(PointCloud::from_positions(line)),
        t.clone(),
        RegistrationOptions::default(),
    )
    .unwrap()
    .run_to_convergence();
    assert!(r.is_err_and(|e| e.to_string().contains("degenerate")));
    let mut nan: Vec<Vec3> = (0..2000)
        .map(|i| Vec3::new(i as f32, (i % 7) as f32, (i % 13) as f32))
        .collect();
    nan[5].y = f32::NAN;
    let r = Registration::new(
        Arc::new(PointCloud::from_positions(nan)),
        t,
        RegistrationOptions::default(),
    )
    .unwrap()
    .run_to_convergence();
    assert!(r.is_err_and(|e| e.to_string().contains("non-finite")));
}

/// Points in a tilted square, `thickness` thick (relative to its side 2), 3000 of them.
fn tilted_slab(thickness: f32) -> Vec<Vec3> {
    use pygmalion::rng::Rng;
    let mut rng = Rng::new(7);
    let q = Quat::from_euler(pygmalion::math::EulerRot::XYZ, 0.4, 0.7, 0.2);
    (0..3000)
        .map(|_| {
            let p = Vec3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                thickness * rng.range(-1.0, 1.0),
            );
            q * p + Vec3::new(3.0, -2.0, 1.0)
        })
        .collect()
}

#[test]
fn clouds_on_a_plane_or_a_line_in_any_direction_are_refused_and_figures_are_not() {
    use pygmalion::anatomy::Template;
    use pygmalion::cloud::PointCloud;
    use pygmalion::fakir::registration::{FLAT_SPREAD, check_spread};
    use pygmalion::fakir::{Registration, RegistrationOptions};
    use std::sync::Arc;
    // A flat square tilted in space (its bounding box is no thinner than a statue's), and one
    // with a thickness of a tenth of the limit, are planes; at 3 times the limit, not.
    for t in [0.0, 0.1 * FLAT_SPREAD] {
        let e = check_spread(&tilted_slab(t)).unwrap_err().to_string();
        assert!(e.contains("lie on a plane"), "{t}: {e}");
    }
    assert!(check_spread(&tilted_slab(3.0 * FLAT_SPREAD)).is_ok());
    // A line along a diagonal.
    let line: Vec<Vec3> = (0..2000)
        .map(|i| Vec3::new(1.0, 2.0, -0.5) * i as f32 + Vec3::splat(0.25))
        .collect();
    let e = check_spread(&line).unwrap_err().to_string();
    assert!(e.contains("lie on a line"), "{e}");
    // Spreads that are not finite are refused; an empty cloud is left to the point count.
    assert!(check_spread(&[Vec3::NAN; 30]).is_err());
    assert!(check_spread(&[Vec3::splat(1e30), Vec3::splat(-1e30), Vec3::X]).is_err());
    assert!(check_spread(&[]).is_ok());
    let e = check_spread(&[Vec3::ONE; 30]).unwrap_err().to_string();
    assert!(e.contains("all points coincide"), "{e}");
    // Statues of every built-in template, at rest and posed, are figures.
    for name in ["human", "centaur", "quadruped", "mermaid"] {
        let t = Arc::new(Template::builtin(name).unwrap());
        for rest in [true, false] {
            let s = pygmalion::synth::generate(
                t.clone(),
                &pygmalion::synth::SynthOptions {
                    points: 3000,
                    seed: 3,
                    random_pose: !rest,
                    rigid: true,
                    ..Default::default()
                },
            )
            .unwrap();
            assert!(check_spread(&s.cloud.positions).is_ok(), "{name} {rest}");
        }
    }
    // Registration ends with the message.
    let t = Arc::new(Template::builtin("human").unwrap());
    let r = Registration::new(
        Arc::new(PointCloud::from_positions(tilted_slab(0.0))),
        t,
        RegistrationOptions::default(),
    )
    .unwrap()
    .run_to_convergence();
    assert!(r.is_err_and(|e| e.to_string().contains("lie on a plane")));
    // A flat panel standing on a block plinth: the whole cloud has depth, the figure off the
    // base has none.
    let mut rng = pygmalion::rng::Rng::new(2);
    let mut panel: Vec<Vec3> = (0..6000)
        .map(|_| {
            let mut p = [
                rng.range(-0.5, 0.5),
                rng.range(0.0, 0.3),
                rng.range(-0.5, 0.5),
            ];
            let face = rng.below(6);
            let (lo, hi) = ([-0.5, 0.0, -0.5], [0.5, 0.3, 0.5]);
            p[face / 2] = if face.is_multiple_of(2) {
                lo[face / 2]
            } else {
                hi[face / 2]
            };
            Vec3::from_array(p)
        })
        .collect();
    panel.extend((0..12000).map(|_| Vec3::new(rng.range(-0.3, 0.3), rng.range(0.3, 2.0), 0.0)));
    assert!(check_spread(&panel).is_ok());
    let t = Arc::new(Template::builtin("human").unwrap());
    let r = Registration::new(
        Arc::new(PointCloud::from_positions(panel)),
        t,
        RegistrationOptions::default(),
    )
    .unwrap()
    .run_to_convergence();
    let e = r.expect_err("refused").to_string();
    assert!(
        e.contains("off the base") && e.contains("lie on a plane"),
        "{e}"
    );
}

#[test]
fn incremental_culled_assignment_equals_a_full_recomputation() {
    use pygmalion::fakir::lm::{Param, apply};
    use pygmalion::fakir::world::RadiusClasses;
    use pygmalion::rng::Rng;
    let s = small_human(21, 4_000, true);
    let t = s.truth.template.clone();
    let classes = RadiusClasses::new(&t);
    let mut w = WorldSkeleton::from_skeleton(&s.truth);
    let n = s.cloud.len();
    let params = AssignParams {
        cone_slack: 0.2,
        cone_abs: 0.003,
    };
    let mk = || {
        Assignment::new(
            s.cloud.positions.clone(),
            s.cloud.normals.clone().unwrap(),
            (0..n as u32).collect(),
            t.bones.len(),
            params,
        )
    };
    let mut incremental = mk();
    let all: Vec<usize> = (0..t.bones.len()).collect();
    let prepared = |w: &WorldSkeleton| w.bones().iter().map(|b| b.prepare()).collect::<Vec<_>>();
    incremental.refresh(&prepared(&w), &all);
    let mut rng = Rng::new(3);
    for step in 0..40 {
        // Move one bone (its subtree follows) and refresh only the bones that moved.
        let b = rng.below(t.bones.len());
        let before = w.bones();
        let axis = w.frames[b] * Vec3::Y;
        apply(
            &mut w,
            &classes,
            &Param::Swing { bone: b, axis },
            rng.range(-0.6, 0.6),
        );
        apply(
            &mut w,
            &classes,
            &Param::Length { bone: b },
            rng.range(-0.05, 0.05),
        );
        let after = w.bones();
        let moved: Vec<usize> = (0..after.len())
            .filter(|&x| after[x] != before[x])
            .collect();
        // A bone lost (its points relabelled, as `Solver::set_absent` does), then found again
        // with other preference parameters: the update's shortcut must see both.
        match step {
            10 => {
                incremental.enabled[5] = false;
                incremental.relabel(0..n);
            }
            25 => {
                incremental.enabled[5] = true;
                incremental.params.cone_abs = 0.01;
            }
            _ => {}
        }
        incremental.refresh(&prepared(&w), &moved);
        let mut full = mk();
        full.enabled.clone_from(&incremental.enabled);
        full.params = incremental.params;
        full.refresh(&prepared(&w), &all);
        assert_eq!(
            incremental.label, full.label,
            "labels differ after step {step}"
        );
        for i in 0..n {
            assert_eq!(
                incremental.own_distance(i),
                full.own_distance(i),
                "own distance of point {i}, step {step}"
            );
        }
    }
}

#[test]
fn registration_fits_rest_pose_quadruped_centaur_and_mermaid() {
    use pygmalion::anatomy::Template;
    use pygmalion::fakir::{Registration, RegistrationOptions};
    use pygmalion::synth::{SynthOptions, generate};
    use std::sync::Arc;
    for name in ["quadruped", "centaur", "mermaid"] {
        let t = Arc::new(Template::builtin(name).unwrap());
        let s = generate(
            t.clone(),
            &SynthOptions {
                points: 6_000,
                seed: 9,
                rigid: true,
                random_pose: false,
                proportion_jitter: 0.1,
                height: 1.0,
                ..Default::default()
            },
        )
        .unwrap();
        let fit = Registration::new(Arc::new(s.cloud.clone()), t, RegistrationOptions::default())
            .unwrap()
            .run_to_convergence()
            .unwrap();
        let err = joint_error(&fit.skeleton, &s.truth, 1.0);
        println!(
            "{name}: joint error {:.2}% of height, mean distance {:.5}",
            100.0 * err,
            fit.mean_distance
        );
        assert!(err < 0.03, "{name}: joint error {err}");
    }
}

/// A synthetic human in a random pose with ±30% proportions (the issue's test population).
pub(crate) fn posed_human(seed: u64, points: usize) -> SynthStatue {
    cut_human(seed, points, &[])
}

/// Mean angle (degrees) between corresponding bone directions of the limb chains.
fn limb_angle_error(a: &Skeleton, b: &Skeleton) -> f32 {
    let (pa, pb) = (a.pose(), b.pose());
    let t = &a.template;
    let limbs: Vec<usize> = t.chains[1..]
        .iter()
        .flat_map(|c| c.bones.iter().copied())
        .collect();
    limbs
        .iter()
        .map(|&i| {
            let da = (pa.bones[i].c2 - pa.bones[i].c1).normalize();
            let db = (pb.bones[i].c2 - pb.bones[i].c1).normalize();
            da.dot(db).clamp(-1.0, 1.0).acos().to_degrees()
        })
        .sum::<f32>()
        / limbs.len() as f32
}

#[test]
fn seeding_aims_limbs_far_from_the_rest_pose() {
    // The rest pose placed on the true pelvis, then only the seeding (no least squares).
    let mut before_total = 0.0;
    let mut after_total = 0.0;
    for seed in [3u64, 8, 16] {
        let s = posed_human(seed, 6_000);
        let t = s.truth.template.clone();
        let start = Skeleton::rest_placed(
            t.clone(),
            s.truth.root_position,
            s.truth.root_rotation,
            s.truth.block_scale,
        );
        let before = limb_angle_error(&start, &s.truth);
        let n = s.cloud.len();
        let asg = Assignment::new(
            s.cloud.positions.clone(),
            s.cloud.normals.clone().unwrap(),
            (0..n as u32).collect(),
            t.bones.len(),
            AssignParams {
                cone_slack: 0.2,
                cone_abs: 0.003,
            },
        );
        let mut pause = NoPause;
        let mut solver = Solver::new(
            WorldSkeleton::from_skeleton(&start),
            asg,
            s.truth.block_scale,
            SolverSettings::default(),
            &mut pause,
        );
        let settings = ScheduleSettings {
            max_iterations: 0,
            ..Default::default()
        };
        pygmalion::fakir::schedule::register_skeleton(&mut solver, &settings, true).unwrap();
        let after = limb_angle_error(&solver.world.to_skeleton(), &s.truth);
        println!("seed {seed}: limb bones {before:.1}° off at rest, {after:.1}° after seeding");
        before_total += before;
        after_total += after;
    }
    let (before, after) = (before_total / 3.0, after_total / 3.0);
    // Measured: 38.6° → 21.7° (hands, feet and clavicles, which the surface barely orients,
    // included).
    assert!(
        after < 0.65 * before && after < 25.0,
        "seeding: {before:.1}° → {after:.1}°"
    );
}

#[test]
fn range_and_proportion_priors_cost_nothing_within_their_margins() {
    use pygmalion::anatomy::Template;
    use pygmalion::fakir::lm::{PRIOR_MARGIN, RATIO_MARGIN, RangePrior};
    use std::sync::Arc;
    let t = Arc::new(Template::builtin("human").unwrap());
    let rest = Skeleton::rest(t.clone());
    let forearm = t.bone_index("l_forearm").unwrap();
    let upper = t.bone_index("l_upper_arm").unwrap();
    let prior = RangePrior {
        bones: vec![(forearm, 1.0)],
        margin: PRIOR_MARGIN,
        ratios: vec![(
            forearm,
            upper,
            rest.bones[forearm].length / rest.bones[upper].length,
            1.0,
        )],
    };
    let w = WorldSkeleton::from_skeleton(&rest);
    assert!(prior.residuals(&w).iter().all(|r| *r == 0.0));
    // Folding the forearm back onto the upper arm leaves its range (bend 0–120°, swing 5°)
    // by 55°, 10° beyond the 45° margin.
    let mut folded = w.clone();
    let axis = folded.frames[upper] * Vec3::Y;
    folded.rotate_subtree(forearm, Quat::from_axis_angle(axis, std::f32::consts::PI));
    let r = prior.residuals(&folded);
    assert!(
        (r[0] - 10f64.to_radians()).abs() < 0.05,
        "folded forearm: residual {}",
        r[0]
    );
    // A forearm 1.5× longer is within the proportion margin; 3× is beyond it.
    let mut longer = w.clone();
    longer.lengths[forearm] *= 1.5;
    assert_eq!(prior.residuals(&longer)[1], 0.0);
    longer.lengths[forearm] *= 2.0;
    let expected = (3.0f64).ln() - (RATIO_MARGIN as f64).ln();
    assert!((prior.residuals(&longer)[1] - expected).abs() < 1e-4);
}

#[test]
fn sphere_directions_cover_the_sphere_evenly() {
    use pygmalion::fakir::solver::sphere_directions;
    let d = sphere_directions(64);
    assert!(d.iter().all(|v| (v.length() - 1.0).abs() < 1e-5));
    // Every direction of a fine probe lies within 20° of one of the 64.
    for probe in sphere_directions(2000) {
        let best = d.iter().map(|v| v.dot(probe)).fold(-1.0f32, f32::max);
        assert!(best > 20f32.to_radians().cos(), "{probe:?}: {best}");
    }
}

#[test]
fn registration_of_posed_statues_with_stylised_proportions() {
    on_one_thread(posed_statues_registration);
}

fn posed_statues_registration() {
    // Six random statue-like poses, ±30% proportions, a random rigid motion, automatic
    // initialisation, and no left/right swap allowed.
    let mut errors = Vec::new();
    for seed in 21u64..=26 {
        let s = posed_human(seed, 6_000);
        let fit = register_posed(&s);
        errors.push(unswapped_joint_error(
            &fit.skeleton,
            &s.truth,
            &format!("seed {seed}"),
        ));
        // Complete statues have lost nothing (registration level 6).
        assert!(
            fit.missing.iter().all(|m| !m),
            "seed {seed}: bones found lost on a complete statue: {:?}",
            fit.support
        );
    }
    // A regression guard, not the issue's target (90% of statues under 2%, measured over 32
    // statues in the issue notes): every one of the six under 2%, their mean under 1%.
    // Measured with the refits and their limb resets: 0.35, 0.60, 0.42, 1.81, 0.41, 0.13%
    // (mean 0.62%); with plain refits: 0.28, 0.74, 0.69, 1.68, 0.41, 0.43% (mean 0.71%); before
    // them, with the scale restarts and two level-1 iterations: 0.65, 0.84, 1.71, 1.68, 0.79,
    // 0.69%; before those: 0.65, 0.80, 1.89, 1.43, 6.19, 6.39%.
    assert!(errors.iter().all(|e| *e < 0.02), "joint errors {errors:?}");
    let mean = errors.iter().sum::<f32>() / errors.len() as f32;
    assert!(mean < 0.01, "mean joint error {mean}: {errors:?}");
}

#[test]
fn refits_lower_the_mean_distance_of_posed_statues() {
    on_one_thread(refits_comparison);
}

fn refits_comparison() {
    use pygmalion::fakir::RegistrationOptions;
    // Refits (registration level 5, two rounds here, each with its limb resets) are kept
    // only when they lower the two-sided score. On these two statues (6000 points),
    // measured: seed 4 keeps its fit (mean distance 0.00870, joint error 4.68% either way);
    // on seed 20 the mean distance falls from 0.00674 to 0.00286 and the joint error from
    // 1.93% to 1.40% (with plain refits before the limb resets: 0.00364 and 1.89%).
    let (mut with, mut without) = (0.0f64, 0.0f64);
    for seed in [4u64, 20] {
        let s = posed_human(seed, 6_000);
        let fit = |refits: usize| {
            register_with(
                &s,
                RegistrationOptions {
                    subsample: 4_000,
                    refits,
                    ..Default::default()
                },
            )
        };
        let (a, b) = (fit(2), fit(0));
        let (ea, eb) = (
            joint_error(&a.skeleton, &s.truth, 1.7),
            joint_error(&b.skeleton, &s.truth, 1.7),
        );
        println!(
            "seed {seed}: joint error {:.2}% with refits, {:.2}% without; mean distance {:.5} / {:.5}",
            100.0 * ea,
            100.0 * eb,
            a.mean_distance,
            b.mean_distance
        );
        assert!(
            a.mean_distance <= 1.02 * b.mean_distance,
            "seed {seed}: refits raised the mean distance from {} to {}",
            b.mean_distance,
            a.mean_distance
        );
        assert!(
            ea <= eb + 0.003,
            "seed {seed}: refits raised the joint error from {eb} to {ea}"
        );
        with += a.mean_distance;
        without += b.mean_distance;
    }
    assert!(
        with < 0.9 * without,
        "refits: mean distances {with} against {without} without"
    );
}

/// The automatic registration of the posed-statue tests (level 0 on 4000 points).
fn register_posed(s: &SynthStatue) -> pygmalion::fakir::Fit {
    register_with(
        s,
        pygmalion::fakir::RegistrationOptions {
            subsample: 4_000,
            ..Default::default()
        },
    )
}

/// The automatic registration with default options, as `register` runs it.
pub(crate) fn register_as_the_cli(s: &SynthStatue) -> pygmalion::fakir::Fit {
    register_with(s, Default::default())
}

/// A synthetic statue registered with `opts`, run to convergence.
fn register_with(
    s: &SynthStatue,
    opts: pygmalion::fakir::RegistrationOptions,
) -> pygmalion::fakir::Fit {
    pygmalion::fakir::Registration::new(
        std::sync::Arc::new(s.cloud.clone()),
        s.truth.template.clone(),
        opts,
    )
    .unwrap()
    .run_to_convergence()
    .unwrap()
}

/// `synth --seed SEED --rigid --height 1.7` with `points` points ([`posed_human`]) registered
/// as the CLI does: asserts its joint error under `limit` of the height, left and right not
/// exchanged ([`unswapped_joint_error`]); returns the fit.
fn posed_fit_within(seed: u64, points: usize, limit: f32) -> pygmalion::fakir::Fit {
    let s = posed_human(seed, points);
    let fit = register_as_the_cli(&s);
    let err = unswapped_joint_error(&fit.skeleton, &s.truth, &format!("seed {seed}"));
    assert!(err < limit, "seed {seed}: joint error {err}");
    fit
}

/// Joint error of a fit of a 1.7-high statue (printed with its mirrored error), asserting
/// that left and right are not exchanged.
fn unswapped_joint_error(fit: &Skeleton, truth: &Skeleton, what: &str) -> f32 {
    let err = joint_error(fit, truth, 1.7);
    let mirrored = mirrored_joint_error(fit, truth, 1.7);
    println!(
        "{what}: joint error {:.2}% of height (mirrored {:.2}%)",
        100.0 * err,
        100.0 * mirrored
    );
    assert!(err < mirrored, "{what}: left and right swapped");
    err
}

/// Joint error with the fit's left and right exchanged.
fn mirrored_joint_error(fit: &Skeleton, truth: &Skeleton, height: f32) -> f32 {
    let t = &fit.template;
    let (a, b) = (fit.pose().joints, truth.pose().joints);
    let swap = |name: &str| -> String {
        if let Some(r) = name.strip_prefix("l_") {
            format!("r_{r}")
        } else if let Some(r) = name.strip_prefix("r_") {
            format!("l_{r}")
        } else {
            name.to_string()
        }
    };
    let total: f32 = t
        .joints
        .iter()
        .enumerate()
        .map(|(j, def)| {
            let k = t.joint_index(&swap(&def.name)).unwrap();
            (a[k] - b[j]).length()
        })
        .sum();
    total / t.joints.len() as f32 / height
}

#[test]
fn trunk_bones_are_the_block_and_the_chains_limbs_hang_from() {
    use pygmalion::anatomy::Template;
    use pygmalion::fakir::solver::trunk_bones;
    let t = Template::builtin("human").unwrap();
    let trunk = trunk_bones(&t);
    let names: Vec<&str> = (0..t.bones.len())
        .filter(|&b| trunk[b])
        .map(|b| t.bones[b].name.as_str())
        .collect();
    assert_eq!(
        names,
        [
            "pelvis_up",
            "pelvis_left",
            "pelvis_right",
            "spine_lower",
            "spine_upper",
            "neck_link",
            "neck",
            "head"
        ]
    );
    // A lone chain carries nothing: only its tip gets the occupancy term.
    let chain = pygmalion::synth::chain_template("c", &[40.0, 35.0], &[9.0, 8.0, 7.0]).unwrap();
    assert!(trunk_bones(&chain).iter().all(|b| !b));
}

#[test]
fn a_rescaled_candidate_keeps_its_orientation_and_scales_about_the_pivot() {
    use pygmalion::anatomy::Template;
    use pygmalion::fakir::init::{Candidate, rescaled};
    use std::sync::Arc;
    let t = Arc::new(Template::builtin("human").unwrap());
    let q = Quat::from_axis_angle(Vec3::new(1.0, 2.0, -0.5).normalize(), 0.7);
    let root = Vec3::new(0.3, 1.1, -0.4);
    let c = Candidate {
        skeleton: Skeleton::rest_placed(t.clone(), root, q, 1.6),
        scale: 1.6,
    };
    let pivot = Vec3::new(0.1, 1.4, 0.2);
    let r = rescaled(&c, pivot, 0.88);
    assert!((r.scale - 1.6 * 0.88).abs() < 1e-6);
    assert!(r.skeleton.root_rotation.dot(q).abs() > 1.0 - 1e-6);
    // The root moves along the line from the pivot, to 0.88 of its distance.
    let expected = pivot + (root - pivot) * 0.88;
    assert!((r.skeleton.root_position - expected).length() < 1e-6);
    // Every bone is 0.88 times as long and as thick, and points the same way.
    let (a, b) = (c.skeleton.pose(), r.skeleton.pose());
    for (x, y) in a.bones.iter().zip(&b.bones) {
        assert!((y.length() - 0.88 * x.length()).abs() < 1e-5);
        assert!((y.r1 - 0.88 * x.r1).abs() < 1e-5 && (y.r2 - 0.88 * x.r2).abs() < 1e-5);
        if x.length() > 1e-6 {
            let (dx, dy) = ((x.c2 - x.c1).normalize(), (y.c2 - y.c1).normalize());
            assert!(dx.dot(dy) > 1.0 - 1e-5);
        }
    }
    // With the anchor as the pivot, the root stays on the anchor.
    let anchored = rescaled(&c, root, 1.12);
    assert!((anchored.skeleton.root_position - root).length() < 1e-6);
}

#[test]
fn registration_sets_a_plinth_aside_and_fits_the_figure_on_it() {
    on_one_thread(plinth_registration);
}

fn plinth_registration() {
    use pygmalion::anatomy::Template;
    use pygmalion::fakir::BASE_LABEL;
    use pygmalion::synth::{PLINTH_LABEL, SynthOptions, generate};
    use std::sync::Arc;
    // Two statues of `registration_of_posed_statues_with_stylised_proportions` (joint errors
    // 0.65% and 0.84% there) on plinths of a quarter of their points, automatic initialisation
    // without an up hint: the plinth is set aside, the up found, the figure fitted as well.
    for seed in [21u64, 22] {
        let s = generate(
            Arc::new(Template::builtin("human").unwrap()),
            &SynthOptions {
                points: 6_000,
                seed,
                rigid: true,
                height: 1.7,
                plinth_share: 0.25,
                ..Default::default()
            },
        )
        .unwrap();
        let fit = register_posed(&s);
        let base = fit.base.as_ref().expect("a base");
        let up = s.rigid.0 * Vec3::Y;
        assert!(
            base.up.dot(up) > 1f32.to_radians().cos(),
            "seed {seed}: up {}",
            base.up
        );
        // Every plinth point is labelled as base; the figure's other points have bones.
        let plinth = s.labels.iter().filter(|&&l| l == PLINTH_LABEL).count();
        assert_eq!(plinth, 1_500);
        let mut as_base = 0;
        for (l, f) in s.labels.iter().zip(&fit.labels) {
            if *l == PLINTH_LABEL {
                assert_eq!(*f, BASE_LABEL);
            } else if *f == BASE_LABEL {
                as_base += 1;
            }
        }
        assert!(
            as_base <= 30,
            "seed {seed}: {as_base} figure points taken as base"
        );
        assert_eq!(
            fit.bone_counts.iter().sum::<usize>() + base.points.len(),
            s.cloud.len()
        );
        let err =
            unswapped_joint_error(&fit.skeleton, &s.truth, &format!("seed {seed} on a plinth"));
        assert!(err < 0.02, "seed {seed}: joint error {err}");
    }
}

#[test]
fn registration_finds_lost_limbs_and_completes_them() {
    on_one_thread(lost_limbs_registration);
}

/// A posed statue of the posed-statue tests, cut as `cuts` says.
fn cut_human(seed: u64, points: usize, cuts: &[(&str, f32)]) -> SynthStatue {
    use pygmalion::anatomy::Template;
    use pygmalion::synth::{Cut, SynthOptions, generate};
    generate(
        std::sync::Arc::new(Template::builtin("human").unwrap()),
        &SynthOptions {
            points,
            seed,
            rigid: true,
            random_pose: true,
            proportion_jitter: 0.3,
            height: 1.7,
            cuts: cuts
                .iter()
                .map(|(bone, at)| Cut::Bone {
                    bone: bone.to_string(),
                    at: *at,
                })
                .collect(),
            ..Default::default()
        },
    )
    .unwrap()
}

fn lost_limbs_registration() {
    // Registration level 6. A right arm cut through the upper arm (at 0.3 of its length) and,
    // on another statue, a left leg cut through the shin: the bones below the cut must be
    // reported lost (the cut bone itself may be, when its stump is short), nothing else;
    // no point goes to a lost bone; a lost bone gets its healthy mirror's length; the joints
    // the scan still has stay within 3% of the height (the issue's 2% is for complete
    // statues). Measured when written (6000 points): seed 21 arm: lost r_upper_arm,
    // r_forearm, r_hand, joint error 0.91%; seed 21 leg: lost l_foot, 2.13%; seed 27 arm:
    // lost r_upper_arm, r_forearm, r_hand, 2.53%. Broken statues are harder to register: of
    // seeds 21 and 23–27 with these two cuts (12 statues), 4 fits were wrong as a whole
    // (joint error 15–28%: left and right exchanged, a lost leg taken for the other one)
    // and 3 more came out 5–7% off with a wrong lost set; the lost set is right whenever the
    // fit is (these three, and seed 26's arm).
    const ARM: &[&str] = &["r_forearm", "r_hand"];
    let cases: [LostCase; 3] = [
        (21, "r_upper_arm", 0.3, ARM, &["r_upper_arm"]),
        (21, "l_shin", 0.3, &["l_foot"], &["l_shin"]),
        (27, "r_upper_arm", 0.3, ARM, &["r_upper_arm"]),
    ];
    for (seed, bone, at, must, may) in cases {
        check_lost_case(seed, &[(bone, at)], must, may, 6_000, register_posed);
    }
}

#[test]
#[ignore = "long tier (bash tests/run.sh --include-ignored)"]
fn limb_bones_folded_onto_a_stump_or_into_the_trunk_are_found_lost() {
    on_one_thread(starved_limbs_registration);
}

fn starved_limbs_registration() {
    // Registration level 6, starved subtrees: the bones below a cut that FAKIR folds back onto
    // the stump (seed 48, a left leg cut through the shin: the foot) or lays into the trunk
    // (seed 47, a right arm cut through the upper arm: the forearm and hand) take a few
    // points that the stump or the trunk explains nearly as well, but not within a quarter
    // of the bone's radius. With a quarter of the points of their mirror's subtree, they are
    // lost within half the radius (`STARVED`, `STARVED_REDUNDANT`). Default options, 30k
    // points, as the CLI runs them. Measured when written: before the starved bound, neither
    // was found (removal excess 0.34 and 0.29 of the radius).
    let cases: [LostCase; 2] = [
        (48, "l_shin", 0.4, &["l_foot"], &["l_shin"]),
        (
            47,
            "r_upper_arm",
            0.3,
            &["r_forearm", "r_hand"],
            &["r_upper_arm"],
        ),
    ];
    for (seed, bone, at, must, may) in cases {
        check_lost_case(seed, &[(bone, at)], must, may, 30_000, register_as_the_cli);
    }
}

#[test]
#[ignore = "long tier (bash tests/run.sh --include-ignored)"]
fn a_leg_cut_through_the_thigh_does_not_take_the_other_leg() {
    on_one_thread(|| {
        // The crossed-over-limb check: seed 62 cut through the left thigh at 0.3 (30k points,
        // as the CLI runs it). Without the check the left leg ran from its hip over to the
        // right knee and down the right leg, the right shin and foot kept 88 points and none,
        // nothing was found lost, and the joints but the left ankle and toe were 4.36% of the
        // height off (the left knee, gone with the cut, counted); with the legs exchanged
        // below the thighs: 1.71%, the left shin and foot lost.
        check_lost_case(
            62,
            &[("l_thigh", 0.3)],
            &["l_shin", "l_foot"],
            &[],
            30_000,
            register_as_the_cli,
        )
    });
}

#[test]
#[ignore = "long tier (bash tests/run.sh --include-ignored)"]
fn a_hand_cut_at_the_wrist_is_found_lost_though_the_forearm_made_room_for_it() {
    on_one_thread(|| {
        // Seed 98 without its right hand (cut at the wrist; 30k points, as the CLI runs it).
        // FAKIR shortened the right forearm to 0.185 (truth 0.307) and laid the hand over its
        // far half: removing the hand cost its points more than the redundancy bound, and
        // nothing was found lost. Its support says missing (the left hand's does not), the
        // two bones are shorter together than the left ones (0.27 against 0.46), and the
        // forearm reaching to the hand's end explains its points: the hand is lost.
        check_lost_case(
            98,
            &[("r_hand", 0.0)],
            &["r_hand"],
            &[],
            30_000,
            register_as_the_cli,
        )
    });
}

#[test]
fn both_hands_cut_at_the_wrists_are_found_lost() {
    on_one_thread(|| {
        // Seed 120 without either hand (cut at the wrists; 30k points, as the CLI runs it).
        // The left hand took no point and was found lost; the right one, shortened with its
        // forearm (0.215 + 0.08 against a forearm of 0.33) and laid over the forearm's end,
        // was covered by the forearm's surface, and the laid-over-parent rule wanted a healthy
        // mirror: it was reported partial, the right wrist 6.8% of the height off. Examined
        // again once its mirror is lost, both ends shrunk, the forearm reaching to its end
        // explains its points (0.0016 against a bound of 0.0136): lost, and the forearm refitted
        // without it. Measured when written: both lost, 0.33% over the joints left.
        check_lost_case(
            120,
            &[("l_hand", 0.0), ("r_hand", 0.0)],
            &["l_hand", "r_hand"],
            &[],
            30_000,
            register_as_the_cli,
        )
    });
}

#[test]
#[ignore = "long tier (bash tests/run.sh --include-ignored)"]
fn a_hand_cut_whole_beside_a_lost_mirror_is_not_kept_as_a_stump() {
    on_one_thread(|| {
        // Seed 121 without either hand (cut at the wrists; 30k points, as the CLI runs it).
        // The left hand was found lost; the right one, holding 66 points (0.19 of what the
        // template's proportions give a hand at the statue's point count) with its support
        // reaching 0.4 of its length, was kept as a stump: no healthy mirror to count its
        // points against. With its mirror lost a stump must hold a quarter of its expected
        // points (`STUMP_FED_ALONE`): both hands lost. Measured when written: 0.52% of the
        // height in joint error over all joints (1.55% with the right hand kept partial).
        check_lost_case(
            121,
            &[("l_hand", 0.0), ("r_hand", 0.0)],
            &["l_hand", "r_hand"],
            &[],
            30_000,
            register_as_the_cli,
        )
    });
}

/// A lost-limb case: seed, bone cut, where along it, bones that must be lost, bones that may be.
type LostCase<'a> = (u64, &'a str, f32, &'a [&'a str], &'a [&'a str]);

/// Registers a statue cut at `cuts` (bone, fraction each) with `register` and checks level 6: the
/// bones of `must` are reported lost, nothing outside `must` and `may` is; no point goes to a
/// lost bone; a lost bone gets its healthy mirror's length; the joints the scan still has
/// stay within 3% of the height; the lost bones of `must` are bare on the completed
/// skeleton.
fn check_lost_case(
    seed: u64,
    cuts: &[(&str, f32)],
    must: &[&str],
    may: &[&str],
    points: usize,
    register: fn(&SynthStatue) -> pygmalion::fakir::Fit,
) {
    let s = cut_human(seed, points, cuts);
    let fit = register(&s);
    let t = &fit.skeleton.template;
    let lost: Vec<&str> = (0..t.bones.len())
        .filter(|&b| fit.missing[b])
        .map(|b| t.bones[b].name.as_str())
        .collect();
    // The joints the scan still has: those not at the far end of a cut bone.
    let (fj, tj) = (fit.skeleton.pose().joints, s.truth.pose().joints);
    let gone: Vec<usize> = must
        .iter()
        .chain(may)
        .map(|n| t.bone_index(n).unwrap())
        .collect();
    let present: Vec<usize> = (0..t.joints.len())
        .filter(|&j| {
            !gone
                .iter()
                .any(|&b| (s.truth.pose().bones[b].c2 - tj[j]).length() < 1e-6)
        })
        .collect();
    let err = present
        .iter()
        .map(|&j| (fj[j] - tj[j]).length())
        .sum::<f32>()
        / present.len() as f32
        / 1.7;
    println!(
        "seed {seed}, cut {cuts:?}: lost {lost:?}, joint error of the {} joints left {:.2}%",
        present.len(),
        100.0 * err
    );
    for m in must {
        assert!(
            lost.contains(m),
            "seed {seed}: {m} not found lost: {lost:?}"
        );
    }
    for l in &lost {
        assert!(
            must.contains(l) || may.contains(l),
            "seed {seed}: {l} wrongly lost: {lost:?}"
        );
    }
    for (b, m) in fit.missing.iter().enumerate() {
        if *m {
            assert_eq!(fit.bone_counts[b], 0, "a lost bone took points");
            let mirror = t.mirror_bones()[b].unwrap();
            let (a, c) = (&fit.skeleton.bones[b], &fit.skeleton.bones[mirror]);
            assert!(
                (a.length - c.length).abs() < 1e-4 * c.length.max(1e-6),
                "{}: length {} against its mirror's {}",
                t.bones[b].name,
                a.length,
                c.length
            );
        }
    }
    assert!(err < 0.03, "seed {seed}: joint error {err}");
    // The support of the completed skeleton: the lost bones below the cut are bare.
    for m in must {
        let sup = &fit.support[t.bone_index(m).unwrap()];
        assert!(sup.coverage < 0.4, "{m}: coverage {}", sup.coverage);
    }
}

/// The joints of both arms from the elbows down: what a statue cut through both upper arms
/// (a Venus) lacks.
const BELOW_THE_ELBOWS: [&str; 6] = [
    "l_elbow",
    "l_wrist",
    "l_hand_tip",
    "r_elbow",
    "r_wrist",
    "r_hand_tip",
];

/// Asserts that `fit` found both forearms and both hands lost.
fn assert_forearms_and_hands_lost(fit: &pygmalion::fakir::Fit) {
    let t = &fit.skeleton.template;
    for name in ["l_forearm", "r_forearm", "l_hand", "r_hand"] {
        assert!(fit.missing[t.bone_index(name).unwrap()], "{name} not lost");
    }
}

/// Mean distance of the joints of `fit` to the truth's (fraction of `height`), joints named
/// in `leave_out` excepted; with `mirrored`, each truth joint is compared with the fit's
/// joint of the other side (left and right exchanged).
fn joint_error_without(
    fit: &Skeleton,
    truth: &Skeleton,
    leave_out: &[&str],
    height: f32,
    mirrored: bool,
) -> f32 {
    let t = &truth.template;
    let (fj, tj) = (fit.pose().joints, truth.pose().joints);
    let other = |name: &str| -> usize {
        let swapped = match (name.strip_prefix("l_"), name.strip_prefix("r_")) {
            (Some(r), _) if mirrored => format!("r_{r}"),
            (_, Some(r)) if mirrored => format!("l_{r}"),
            _ => name.to_string(),
        };
        t.joint_index(&swapped).unwrap()
    };
    let kept: Vec<usize> = (0..t.joints.len())
        .filter(|&j| !leave_out.contains(&t.joints[j].name.as_str()))
        .collect();
    kept.iter()
        .map(|&j| (fj[other(&t.joints[j].name)] - tj[j]).length())
        .sum::<f32>()
        / kept.len() as f32
        / height
}

#[test]
fn limbs_known_lost_are_left_out_from_the_start() {
    on_one_thread(known_lost_registration);
}

fn known_lost_registration() {
    use pygmalion::fakir::{Registration, RegistrationOptions};
    // A Venus: both arms broken off near the shoulder (a stump of 0.2 of the upper arm).
    // Told so (`RegistrationOptions::lost`) and where she faces (`front`), the registration
    // leaves the arms out from the start: no point goes to them, they come out completed,
    // and the figure that is there is fitted. Measured when written (6000 points, a
    // 4000-point level 0) over the joints the scan has (without the elbows, wrists and hand
    // tips): seed 22 2.32%, seed 23 3.27% (a guard at 4%: the issue's 2% is for complete
    // statues, and the shoulders lose their stumps' points to the clavicles). Told only the lost arms, seed 22 came out with left
    // and right exchanged (22.7%): an armless trunk does not tell its heading.
    let arms = BELOW_THE_ELBOWS;
    for seed in [22, 23] {
        let s = cut_human(seed, 6_000, &[("l_upper_arm", 0.2), ("r_upper_arm", 0.2)]);
        let t = s.truth.template.clone();
        let fit = Registration::new(
            std::sync::Arc::new(s.cloud.clone()),
            t.clone(),
            RegistrationOptions {
                subsample: 4_000,
                lost: vec!["l_upper_arm".into(), "r_upper_arm".into()],
                // Where she faces (an armless trunk does not tell).
                front: Some(s.truth.root_rotation * Vec3::Z),
                ..Default::default()
            },
        )
        .unwrap()
        .run_to_convergence()
        .unwrap();
        let err = joint_error_without(&fit.skeleton, &s.truth, &arms, 1.7, false);
        let mirrored = joint_error_without(&fit.skeleton, &s.truth, &arms, 1.7, true);
        let lost: Vec<&str> = (0..t.bones.len())
            .filter(|&b| fit.missing[b])
            .map(|b| t.bones[b].name.as_str())
            .collect();
        println!(
            "seed {seed}: lost {lost:?}, joint error of the joints left {:.2}%",
            100.0 * err
        );
        for name in [
            "l_upper_arm",
            "l_forearm",
            "l_hand",
            "r_upper_arm",
            "r_forearm",
            "r_hand",
        ] {
            let b = t.bone_index(name).unwrap();
            assert!(fit.missing[b], "seed {seed}: {name} not reported lost");
            assert_eq!(fit.bone_counts[b], 0, "seed {seed}: {name} took points");
            // Completed to the template's proportions (no healthy mirror): not collapsed.
            let rest = Skeleton::rest(t.clone()).bones[b].length * fit.skeleton.block_scale;
            let l = fit.skeleton.bones[b].length;
            assert!(
                l > 0.5 * rest && l < 2.0 * rest,
                "seed {seed}: {name} has length {l}, expected about {rest}"
            );
        }
        assert!(err < mirrored, "seed {seed}: left and right exchanged");
        assert!(err < 0.04, "seed {seed}: joint error {err}");
    }
}

#[test]
fn a_clavicle_whose_arm_is_lost_from_the_start_is_still_fitted() {
    on_one_thread(|| {
        use pygmalion::fakir::{Init, RegistrationOptions};
        // `synth --seed 393 --rigid --height 1.7 --points 6000 --cut bone:l_upper_arm@0 --cut
        // bone:r_upper_arm@0`, registered from its own truth with both upper arms lost from
        // the start (`register --start TRUTH --missing l_upper_arm,r_upper_arm`): each arm
        // chain is fitted up to where it broke, its clavicle alone (`schedule::chain_pass`).
        // Measured when written: the clavicles 0.237 and 0.234 long against the truth's
        // 0.252 and 0.254; before, they kept the initial pass's length, 0.199 both (0.75
        // times the template's proportion), the mean distance twice as high.
        let s = cut_human(393, 6_000, &[("l_upper_arm", 0.0), ("r_upper_arm", 0.0)]);
        let t = s.truth.template.clone();
        let fit = register_with(
            &s,
            RegistrationOptions {
                lost: vec!["l_upper_arm".into(), "r_upper_arm".into()],
                init: Init::Given(s.truth.clone()),
                ..Default::default()
            },
        );
        for name in ["l_clavicle", "r_clavicle"] {
            let b = t.bone_index(name).unwrap();
            let (l, truth) = (fit.skeleton.bones[b].length, s.truth.bones[b].length);
            println!("{name}: length {l:.4}, truth {truth:.4}");
            assert!(
                (l / truth - 1.0).abs() < 0.12,
                "{name}: length {l} against the truth's {truth}"
            );
        }
    });
}

#[test]
fn an_armless_figure_is_faced_across_its_breadth() {
    use pygmalion::fakir::init::{
        ACROSS_COS, FRONT_SPREAD, Init, armless_shoulders, breadth_axis, candidates,
        template_samples,
    };
    use pygmalion::fakir::support::lost_from_names;
    // Synthetic Venuses (both upper arms cut at 0.2 of their length, 6000 points, random rigid
    // motion). Measured when written: the chest band's spread across the breadth 1.32 times
    // the spread through it on both, the breadth within 12° of the true shoulders' line.
    for seed in [22, 23] {
        let s = cut_human(seed, 6_000, &[("l_upper_arm", 0.2), ("r_upper_arm", 0.2)]);
        let t = s.truth.template.clone();
        let pts = &s.cloud.positions;
        let q = s.truth.root_rotation;
        let (up, left, front) = (q * Vec3::Y, q * Vec3::X, q * Vec3::Z);
        let samples = template_samples(&t, 4000);
        let arms = lost_from_names(&t, &["l_upper_arm".into(), "r_upper_arm".into()]).unwrap();
        let f = armless_shoulders(&t, &samples, &arms).expect("armless");
        assert!(
            (0.7..0.9).contains(&f),
            "the shoulders at {f} of the height"
        );
        let m = breadth_axis(pts, up, f).expect("a chest wider than deep");
        assert!(
            m.dot(left).abs() > 20f32.to_radians().cos(),
            "seed {seed}: the breadth {m} is {:.1}° from the shoulders' line",
            m.dot(left).abs().acos().to_degrees()
        );
        // With the up axis: three headings about each way across the breadth, the middle
        // ones within the breadth's error of the front and the back.
        let c = candidates(&t, pts, &Init::Up(up), None, &arms);
        assert_eq!(c.len(), 6);
        for (k, cand) in c.iter().enumerate() {
            let facing = cand.skeleton.root_rotation * Vec3::Z;
            let off = facing.dot(front).abs().acos();
            let step = if k % 3 == 1 { 0.0 } else { FRONT_SPREAD };
            assert!(
                (off - step).abs() < 20f32.to_radians(),
                "seed {seed}: heading {k} {:.1}° off the front or the back",
                off.to_degrees()
            );
        }
        // Without it: the principal-axis placements whose left-right axis lies along the
        // breadth their own up finds.
        let all = candidates(&t, pts, &Init::Auto, None, &[]);
        let across = candidates(&t, pts, &Init::Auto, None, &arms);
        assert!(!across.is_empty() && across.len() < all.len());
        for cand in &across {
            let r = cand.skeleton.root_rotation;
            let m = breadth_axis(pts, r * Vec3::Y, f).unwrap();
            assert!((r * Vec3::X).dot(m).abs() >= ACROSS_COS);
        }
        // Not armless: nothing lost, or a bust (the thighs lost too), or a facing hint given.
        assert_eq!(candidates(&t, pts, &Init::Up(up), None, &[]).len(), 8);
        let bust = lost_from_names(&t, &t.bust).unwrap();
        assert_eq!(armless_shoulders(&t, &samples, &bust), None);
        assert_eq!(
            candidates(&t, pts, &Init::Up(up), Some(front), &arms).len(),
            3
        );
    }
}

#[test]
fn the_breadth_is_the_major_level_axis_of_the_chest_band() {
    use pygmalion::fakir::init::breadth_axis;
    // An upright elliptic cylinder (semi-axes 2 along x and 1 along z, height 10): the
    // breadth is along x at every height; a round one (and a flat-topped heap of too few
    // points) tells none.
    let ring = |a: f32, b: f32, n: usize| -> Vec<Vec3> {
        (0..n)
            .map(|i| {
                let t = i as f32 * 0.618_034 * std::f32::consts::TAU;
                let y = 10.0 * (i as f32 + 0.5) / n as f32;
                Vec3::new(a * t.cos(), y, b * t.sin())
            })
            .collect()
    };
    let m = breadth_axis(&ring(2.0, 1.0, 4000), Vec3::Y, 0.8).unwrap();
    assert!(m.dot(Vec3::X).abs() > 0.999, "{m}");
    assert!(m.dot(Vec3::Y).abs() < 1e-6);
    assert_eq!(breadth_axis(&ring(1.0, 1.0, 4000), Vec3::Y, 0.8), None);
    assert_eq!(breadth_axis(&ring(2.0, 1.0, 40), Vec3::Y, 0.8), None);
    assert_eq!(breadth_axis(&ring(2.0, 1.0, 4000), Vec3::ZERO, 0.8), None);
}

#[test]
fn a_facing_hint_keeps_the_headings_near_it() {
    use pygmalion::fakir::init::{FRONT_SPREAD, Init, candidates};
    let s = small_human(3, 3_000, false);
    let t = s.truth.template.clone();
    let pts = &s.cloud.positions;
    let front = Vec3::new(1.0, 0.3, 1.0).normalize();
    let level = Vec3::new(1.0, 0.0, 1.0).normalize();
    // With the up axis: three headings, FRONT_SPREAD apart, centred on the hint made level.
    let c = candidates(&t, pts, &Init::Up(Vec3::Y), Some(front), &[]);
    assert_eq!(c.len(), 3);
    for (k, cand) in c.iter().enumerate() {
        let q = cand.skeleton.root_rotation;
        assert!((q * Vec3::Y - Vec3::Y).length() < 1e-4, "up kept");
        let angle = (q * Vec3::Z).angle_between(level);
        let want = if k == 1 { 0.0 } else { FRONT_SPREAD };
        assert!((angle - want).abs() < 1e-3, "heading {k}: {angle} rad");
    }
    // Without it: only the principal-axis placements facing within 60° of the hint.
    let all = candidates(&t, pts, &Init::Auto, None, &[]);
    let near = candidates(&t, pts, &Init::Auto, Some(front), &[]);
    assert!(
        !near.is_empty() && near.len() < all.len(),
        "{} of {}",
        near.len(),
        all.len()
    );
    for cand in &near {
        assert!((cand.skeleton.root_rotation * Vec3::Z).dot(front) >= 0.5);
    }
}

#[test]
fn lost_limbs_are_named_with_what_they_carry_and_collapse_into_their_joint() {
    use pygmalion::anatomy::Template;
    use pygmalion::fakir::support::{COLLAPSED, collapse, lost_from_names};
    let t = std::sync::Arc::new(Template::builtin("human").unwrap());
    let lost = lost_from_names(&t, &["r_forearm".to_string(), "l_shin".into()]).unwrap();
    let named: Vec<&str> = (0..t.bones.len())
        .filter(|&b| lost[b])
        .map(|b| t.bones[b].name.as_str())
        .collect();
    assert_eq!(named.len(), 4, "{named:?}");
    for n in ["r_forearm", "r_hand", "l_shin", "l_foot"] {
        assert!(named.contains(&n), "{named:?}");
    }
    // Errors name the bone: a misspelling gets the closest names, the trunk is refused.
    let e = lost_from_names(&t, &["r_forarm".to_string()])
        .unwrap_err()
        .to_string();
    assert!(e.contains("'r_forarm'") && e.contains("r_forearm"), "{e}");
    let e = lost_from_names(&t, &["spine_upper".to_string()])
        .unwrap_err()
        .to_string();
    assert!(e.contains("trunk"), "{e}");
    // Collapsed: a sliver at the joint it hangs from, inside that joint's sphere.
    let rest = Skeleton::rest(t.clone());
    let mut s = rest.clone();
    collapse(&mut s, &lost);
    let (posed, before) = (s.pose(), rest.pose());
    for b in 0..t.bones.len() {
        if !lost[b] {
            assert_eq!(s.bones[b], rest.bones[b]);
            continue;
        }
        assert!((s.bones[b].length - COLLAPSED * rest.bones[b].length).abs() < 1e-6);
        let p = t.bones[b].parent.unwrap();
        if !lost[p] {
            // The first lost bone keeps its joint's radius; its far end lies in that sphere.
            assert_eq!(s.bones[b].r1, rest.bones[b].r1);
            let joint = before.bones[p].c2;
            assert!((posed.bones[b].c2 - joint).length() < before.bones[p].r2);
        } else {
            assert_eq!(
                s.bones[b].r1, s.bones[p].r2,
                "radius shared along the chain"
            );
        }
    }
}

#[test]
fn a_skeleton_turned_around_exchanges_its_sides_and_pays_for_its_joints() {
    use pygmalion::fakir::init::implausibility;
    for seed in [3u64, 8, 16, 21, 22, 23, 24, 25] {
        let s = posed_human(seed, 2_000);
        let truth = &s.truth;
        let mirror = truth.template.mirror_bones();
        // The pelvis block's two sides are each other's mirror, the bone up the middle none.
        let side = |n: &str| mirror[truth.template.bone_index(n).unwrap()];
        assert_eq!(
            side("pelvis_left"),
            truth.template.bone_index("pelvis_right")
        );
        assert_eq!(
            side("pelvis_right"),
            truth.template.bone_index("pelvis_left")
        );
        assert_eq!(side("pelvis_up"), None);
        let w = WorldSkeleton::from_skeleton(truth);
        let turned = w.turned_around(&mirror);
        let (a, b) = (w.pose(), turned.pose());
        // The same figure: each paired bone lies where its mirror lay (its first joint moves
        // only with the hip or shoulder it hangs from), each unpaired bone where it lay.
        let t = &truth.template;
        for (i, bone) in t.bones.iter().enumerate() {
            let name = &bone.name;
            let (src, dst) = (a.bones[mirror[i].unwrap_or(i)], b.bones[i]);
            let dir = (src.c2 - src.c1).normalize();
            let turned_dir = (dst.c2 - dst.c1).normalize();
            assert!(
                dir.dot(turned_dir) > 0.9999,
                "seed {seed}, {name}: direction {turned_dir} instead of {dir}"
            );
            assert!(((dst.c2 - dst.c1).length() - (src.c2 - src.c1).length()).abs() < 1e-4);
            assert!((dst.r1 - src.r1).abs() < 1e-6 && (dst.r2 - src.r2).abs() < 1e-6);
            assert!(
                (dst.c1 - src.c1).length() < 0.05 * 1.7,
                "seed {seed}, {name}: starts {} away from its mirror",
                (dst.c1 - src.c1).length()
            );
        }
        // Turned twice: the figure as it was.
        let back = turned.turned_around(&mirror).pose();
        for (j, (x, y)) in a.joints.iter().zip(&back.joints).enumerate() {
            assert!(
                (*x - *y).length() < 1e-3,
                "seed {seed}: joint {j} moved by {}",
                (*x - *y).length()
            );
        }
        // The generator draws poses within the joint ranges; facing the other way, knees,
        // elbows and feet leave them (what the registration's facing check relies on).
        let own = implausibility(truth);
        let cost = implausibility(&turned.to_skeleton());
        println!("seed {seed}: implausibility {own:.3} rad, turned around {cost:.3} rad");
        // Measured (untwisted, see `implausibility`): 0.000–0.065 rad as drawn (the
        // generator's twists move a hinge's axis a little), 6.1–10.6 rad turned around.
        assert!(own < 0.2, "seed {seed}: the truth is implausible ({own})");
        assert!(cost > 3.0, "seed {seed}: plausible turned around ({cost})");
    }
}

#[test]
fn a_statue_fitted_facing_backwards_before_is_fitted_facing_front() {
    on_one_thread(facing_registration);
}

fn facing_registration() {
    // Two statues (6000 points, default options, as `register` runs them) fitted facing
    // backwards before the facing check and the untwisted joint ranges. Seed 30: joint error
    // 27.0% (10.0% with left and right exchanged) before; 2.76% after, the finalists' rule
    // now choosing a fit facing front. Seed 49: 26.4% (3.4% exchanged) before; 0.63% after,
    // the fit turned around by the facing check scoring lower and bending its joints within
    // their ranges.
    for (seed, limit) in [(30u64, 0.04f32), (49, 0.02)] {
        posed_fit_within(seed, 6_000, limit);
    }
}

#[test]
#[ignore = "long tier (bash tests/run.sh --include-ignored)"]
fn a_fit_still_facing_backwards_after_the_refits_is_turned_around() {
    on_one_thread(second_facing_registration);
}

fn second_facing_registration() {
    // `synth --seed 14 --rigid --height 1.7` (30k points), registered as `register` does.
    // Without the second facing check the fit ends facing backwards: joint error 21.8% of the
    // height (6.0% with left and right exchanged), implausibility 7.8 rad, two-sided score
    // 0.0184; the first facing check had its turned fit score 0.0411 against 0.0268, just
    // outside the near-ties. Turned around after the refits it scores 0.0103 and ends at
    // 0.73%.
    posed_fit_within(14, 30_000, 0.02);
}

#[test]
fn a_limb_reset_puts_one_limb_back_at_rest_and_keeps_the_rest_of_the_fit() {
    use pygmalion::fakir::registration::{limb_reset, resettable_chains};
    use pygmalion::fakir::support::lost_from_names;
    let s = posed_human(5, 2_000);
    let t = s.truth.template.clone();
    let names = |chains: Vec<usize>| -> Vec<String> {
        chains.iter().map(|&c| t.chains[c].name.clone()).collect()
    };
    // The limbs, not the spine that carries them; a lost limb is not reset.
    let none = vec![false; t.bones.len()];
    assert_eq!(
        names(resettable_chains(&t, &none)),
        ["l_leg", "r_leg", "l_arm", "r_arm"]
    );
    let lost = lost_from_names(&t, &["l_upper_arm".to_string()]).unwrap();
    assert_eq!(
        names(resettable_chains(&t, &lost)),
        ["l_leg", "r_leg", "r_arm"]
    );
    let world = WorldSkeleton::from_skeleton(&s.truth);
    let k = world.block_scale;
    let rest = Skeleton::rest(t.clone());
    let before = s.truth.pose();
    for c in resettable_chains(&t, &none) {
        let r = limb_reset(&world, c);
        assert_eq!(r.scale, k);
        let first = t.chains[c].bones[0];
        let moved = t.subtree(first);
        let after = r.skeleton.pose();
        for b in 0..t.bones.len() {
            let (x, y) = (before.bones[b], after.bones[b]);
            if !moved.contains(&b) {
                // Every other bone stays where it was fitted, with its size.
                assert!((x.c1 - y.c1).length() < 1e-5 && (x.c2 - y.c2).length() < 1e-5);
                assert!((x.r1 - y.r1).abs() < 1e-6 && (x.r2 - y.r2).abs() < 1e-6);
                continue;
            }
            // The limb: the template's rest rotation relative to its parent, rest sizes
            // scaled like the fit's block; the joint it hangs from keeps its radius.
            let (got, want) = (r.skeleton.bones[b], rest.bones[b]);
            assert!(
                got.rotation.dot(want.rotation).abs() > 1.0 - 1e-5,
                "{}",
                t.bones[b].name
            );
            assert!((got.length - k * want.length).abs() < 1e-5 * k);
            assert!((got.r2 - k * want.r2).abs() < 1e-5 * k);
            if b == first {
                assert!((y.r1 - x.r1).abs() < 1e-6 && (y.c1 - x.c1).length() < 1e-5);
            } else {
                assert!((got.r1 - k * want.r1).abs() < 1e-5 * k);
            }
        }
    }
}

#[test]
fn crossed_limbs_are_found_and_exchanging_below_them_uncrosses_them() {
    for seed in [3u64, 8, 16, 21] {
        let s = posed_human(seed, 2_000);
        let t = s.truth.template.clone();
        let mirror = t.mirror_bones();
        let none = vec![false; t.bones.len()];
        let w = WorldSkeleton::from_skeleton(&s.truth);
        // The generator draws no crossed limbs (measured: on 72 statues the lowest ratio of
        // exchanged to straight lengths of a pair was 1.1).
        assert_eq!(w.most_crossed(&mirror, &none), None, "seed {seed}");
        let before = w.pose();
        for name in ["l_thigh", "l_shin", "l_upper_arm", "l_forearm"] {
            let a = t.bone_index(name).unwrap();
            let b = mirror[a].unwrap();
            let x = w.exchanged_below(a, &mirror).unwrap();
            let after = x.pose();
            // Each of the two keeps its first joint and reaches the other's end...
            for (p, q) in [(a, b), (b, a)] {
                assert!((after.bones[p].c1 - before.bones[p].c1).length() < 1e-5);
                assert!(
                    (after.bones[p].c2 - before.bones[q].c2).length() < 1e-4,
                    "seed {seed}, {name}: end off by {}",
                    (after.bones[p].c2 - before.bones[q].c2).length()
                );
                assert_eq!(after.bones[p].r2, before.bones[q].r2);
                // ...and what hangs below lies where its mirror lay, with its mirror's sizes.
                for i in t.subtree(p).into_iter().skip(1) {
                    let m = mirror[i].unwrap();
                    let (got, want) = (after.bones[i], before.bones[m]);
                    assert!((got.c1 - want.c1).length() < 1e-4, "seed {seed}, {i}");
                    assert!((got.c2 - want.c2).length() < 1e-4, "seed {seed}, {i}");
                    assert_eq!((got.r1, got.r2), (want.r1, want.r2));
                }
            }
            // Everything else stays (to rounding: the block's frames are made again).
            let moved: Vec<usize> = t.subtree(a).into_iter().chain(t.subtree(b)).collect();
            for i in (0..t.bones.len()).filter(|i| !moved.contains(i)) {
                assert!((after.bones[i].c1 - before.bones[i].c1).length() < 1e-6);
                assert!((after.bones[i].c2 - before.bones[i].c2).length() < 1e-6);
            }
            // The exchanged pair is now the crossed one: its exchanged ends are the truth's.
            assert_eq!(
                x.most_crossed(&mirror, &none),
                Some(a),
                "seed {seed}, {name}"
            );
            // A pair whose limb holds a known-lost bone is not examined.
            let mut lost = none.clone();
            lost[*t.subtree(b).last().unwrap()] = true;
            assert_ne!(
                x.most_crossed(&mirror, &lost),
                Some(a),
                "seed {seed}, {name}"
            );
            // Exchanged again: the skeleton as it was.
            let back = x.exchanged_below(a, &mirror).unwrap().pose();
            for (j, (p, q)) in before.joints.iter().zip(&back.joints).enumerate() {
                assert!((*p - *q).length() < 1e-4, "seed {seed}, {name}: joint {j}");
            }
        }
    }
}

#[test]
fn a_starved_limb_whose_mirror_reached_over_to_its_place_is_found() {
    use pygmalion::fakir::lost::STARVED;
    use pygmalion::fakir::registration::CROSSED_OVER_NEAR;
    for seed in [3u64, 8, 16, 21] {
        let s = posed_human(seed, 2_000);
        let t = s.truth.template.clone();
        let mirror = t.mirror_bones();
        let none = vec![false; t.bones.len()];
        let bone = |n: &str| t.bone_index(n).unwrap();
        let (lt, ls) = (bone("l_thigh"), bone("l_shin"));
        let (rt, rs, rf) = (bone("r_thigh"), bone("r_shin"), bone("r_foot"));
        let truth = WorldSkeleton::from_skeleton(&s.truth);
        let posed = truth.pose();
        // The left thigh laid from its hip over to the right knee, as on a statue cut
        // through the left thigh: the left leg takes the right leg's points and the right
        // shin and foot keep almost none.
        let mut w = truth.clone();
        w.aim(lt, posed.bones[lt].c1, posed.bones[rt].c2);
        let mut points = vec![500usize; t.bones.len()];
        (points[rs], points[rf]) = (20, 0);
        let found = |w: &WorldSkeleton, points: &[usize], skip: &[bool]| {
            w.most_crossed_over(&mirror, skip, points, STARVED, CROSSED_OVER_NEAR)
        };
        // The limbs below the right thigh (its parent) are the ones to exchange.
        assert_eq!(found(&w, &points, &none), Some(rt), "seed {seed}");
        // Not starved: the shin's and the foot's subtrees at 30% of their mirrors' points
        // (the bound is a quarter).
        let mut fed = points.clone();
        (fed[rs], fed[rf]) = (150, 150);
        assert_eq!(found(&w, &fed, &none), None, "seed {seed}");
        // Starved, but the left thigh where it belongs (the true knees are further apart
        // than half the longer thigh on these statues): a limb cut short, not a crossed-over
        // one.
        let apart = (posed.bones[lt].c2 - posed.bones[rt].c2).length();
        let longer = truth.lengths[lt].max(truth.lengths[rt]);
        assert!(
            apart >= CROSSED_OVER_NEAR * longer,
            "seed {seed}: knees close"
        );
        assert_eq!(found(&truth, &points, &none), None, "seed {seed}");
        // One thigh collapsed (to a tenth of its length), the other reaching to a fifth of the
        // way from there to its own hip: the ends are near for the longer of the two, not
        // for the collapsed one (a fit cut through the thigh, seed 72).
        let mut short = truth.clone();
        let (rc1, rc2) = (posed.bones[rt].c1, posed.bones[rt].c2);
        short.aim(rt, rc1, rc1.lerp(rc2, 0.1));
        let end = short.pose().bones[rt].c2;
        let hip = posed.bones[lt].c1;
        short.aim(lt, hip, end.lerp(hip, 0.2));
        assert_eq!(found(&short, &points, &none), Some(rt), "seed {seed}");
        // A bone of the four in `skip` (known lost) leaves the pair out (the shins' pair,
        // starved at the foot, may then be found when the two ankles are near).
        for k in [rs, rt, ls, lt] {
            let mut skip = none.clone();
            skip[k] = true;
            assert_ne!(found(&w, &points, &skip), Some(rt), "seed {seed}, {k}");
        }
        // Of two pairs, the one nearest the root: the legs' shins end together too and the
        // foot is the more starved, but the exchange below the thighs moves both.
        let mut w2 = w.clone();
        w2.aim(ls, w.pose().bones[ls].c1, posed.bones[rs].c2);
        assert_eq!(found(&w2, &points, &none), Some(rt), "seed {seed}");
        // An arm crossed over: the right hand starved (a fifth of the left one's points), the
        // left forearm reaching the right wrist; the legs fed. With the legs starved as above
        // too, the thighs win: they hang nearer the root than the forearms.
        let (lfa, rfa, rh) = (bone("l_forearm"), bone("r_forearm"), bone("r_hand"));
        w.aim(lfa, posed.bones[lfa].c1, posed.bones[rfa].c2);
        let mut arm = vec![500usize; t.bones.len()];
        arm[rh] = 100;
        assert_eq!(found(&w, &arm, &none), Some(rfa), "seed {seed}");
        (arm[rs], arm[rf]) = (20, 0);
        assert_eq!(found(&w, &arm, &none), Some(rt), "seed {seed}");
    }
}

#[test]
#[ignore = "long tier (bash tests/run.sh --include-ignored)"]
fn a_statue_fitted_upside_down_is_turned_upright() {
    // `synth --seed 81 --rigid --height 1.7 --cut bone:l_thigh@0.6` (30k points), registered
    // as `register` does. With its left leg lost through the thigh, the finalists' rule kept
    // an upside-down fit (the arms in the legs, the right leg in the head and neck): 42.0%
    // of the height in joint error over the joints the scan has. The up-down check
    // registers the best upright finalist again, which scores lower: 4.8%; the search of
    // the upright placements that follows scores lower still, at 6.4% (its healthy right
    // hand taken lost). The guard at 8%: a broken statue, the stump's lost joints left out.
    on_one_thread(|| upside_down_registration(81, ("l_thigh", 0.6), 0.08))
}

#[test]
#[ignore = "long tier (bash tests/run.sh --include-ignored)"]
fn a_statue_whose_flipped_finalist_fits_badly_is_searched_upright() {
    // `synth --seed 47 --rigid --height 1.7 --cut bone:r_thigh@0.5` (30k points), registered
    // as `register` does. It was fitted upside down (46.7% over the joints the scan has, a
    // score of 0.0393), and its best upright finalist, registered again, scored worse
    // (0.052). The up-down check's search of the upright placements finds the upright fit:
    // 4.1%, the right shin and foot found lost.
    on_one_thread(|| upside_down_registration(47, ("r_thigh", 0.5), 0.07))
}

#[test]
#[ignore = "long tier (bash tests/run.sh --include-ignored)"]
fn a_cut_limb_whose_hand_holds_no_point_is_found_lost() {
    // `synth --seed 300 --rigid --height 1.7 --cut bone:l_upper_arm@0.5` (30k points, held
    // out while the lost-limb rules were built), registered as `register` does. FAKIR folds
    // the forearm back along the stump and lays the hand, which takes no point, on the chest,
    // where it is covered: nothing was found lost. A starved subtree holding no point is lost
    // ("empty", `lost_limbs`): the forearm and the hand are (0.61% of the height in joint
    // error over the joints the scan has). The guard at 2%.
    on_one_thread(|| {
        held_out_cut(
            300,
            ("l_upper_arm", 0.5),
            &["l_forearm", "l_hand"],
            &["l_elbow", "l_wrist", "l_hand_tip"],
        )
    })
}

#[test]
#[ignore = "long tier (bash tests/run.sh --include-ignored)"]
fn a_forearm_resting_on_the_thigh_is_not_taken_lost() {
    // `synth --seed 306 --rigid --height 1.7 --cut bone:l_shin@0.6` (30k points, held out
    // while the lost-limb rules were built). The left hand rests on the knee and the forearm
    // lies against the thigh: their surface is in the scan, but the thigh takes their points
    // (the forearm's subtree 142 against its mirror's 1,995). They were taken lost with the
    // foot; the forearm is covered from end to end (coverage and reach 1) and its axis lies
    // 0.87 of its radius inside the thigh on average (a forearm that FAKIR laid into the
    // trunk: 2.4 to 3.6, seeds 47 and 317), so it and the hand are kept ("covered through",
    // `lost_limbs`): the foot alone is lost (0.91% of the height in joint error over the
    // joints the scan has, 1.54% before). The guard at 2%.
    on_one_thread(|| held_out_cut(306, ("l_shin", 0.6), &["l_foot"], &["l_ankle", "l_toe"]))
}

#[test]
#[ignore = "long tier (bash tests/run.sh --include-ignored)"]
fn a_foot_cut_at_half_its_length_is_not_taken_lost() {
    // `synth --seed 316 --rigid --height 1.7 --cut bone:l_foot@0.5` (30k points, held out
    // while the lost-limb rules were built). The shin's ankle sphere explains the heel left
    // by the cut nearly as well as the foot (removal excess 0.15 of its radius), and the
    // redundancy test took the foot lost; it holds 266 points against its mirror's 767, the
    // scan covers 0.82 of it at its expected size, and it is 1.13 times its mirror's length:
    // fed and covered (`lost_limbs`), it is kept. Nothing is lost (0.55% of the height in
    // joint error over the joints the scan has, the toe left out). The guard at 2%.
    on_one_thread(|| held_out_cut(316, ("l_foot", 0.5), &[], &["l_toe"]))
}

#[test]
fn a_bone_cut_part_way_keeps_its_stump_and_loses_what_it_carried() {
    // Held out while the lost-limb rules were built (`synth --seed N --rigid --height 1.7
    // --cut bone:B@F`, 30k points). Seed 304's left shin cut at 0.2 and seed 308's left
    // forearm cut at 0.6 were taken lost with the foot and the hand: the knee's and the
    // elbow's spheres explain the stumps' points nearly as well (the redundancy test). Their
    // support reaches 0.4 and 0.3 of their length from the joint (`STUMP_REACH`): each is
    // kept as a stump, reported partial, and only the bone below it is lost. The joints the
    // scan has (the cut bone's far end and below left out) within 2% of the height.
    on_one_thread(|| {
        for (seed, cut, lost, below) in [
            (304, ("l_shin", 0.2), "l_foot", ["l_ankle", "l_toe"]),
            (308, ("l_forearm", 0.6), "l_hand", ["l_wrist", "l_hand_tip"]),
        ] {
            let s = cut_human(seed, 30_000, &[cut]);
            let fit = register_as_the_cli(&s);
            assert_eq!(fit.missing_names(), [lost], "seed {seed}");
            let t = &fit.skeleton.template;
            let partial = fit.partial();
            assert!(
                partial[t.bone_index(cut.0).unwrap()],
                "seed {seed}: {} not partial",
                cut.0
            );
            let err = joint_error_without(&fit.skeleton, &s.truth, &below, 1.7, false);
            println!("seed {seed}: joint error {:.2}%", 100.0 * err);
            assert!(err < 0.02, "seed {seed}: joint error {err}");
        }
    })
}

#[test]
#[ignore = "long tier (bash tests/run.sh --include-ignored)"]
fn a_fit_far_from_its_points_is_searched_again_about_tilted_ups() {
    // `synth --seed 303 --rigid --height 1.7 --cut bone:r_thigh@0.7` (30k points, held out
    // while the lost-limb rules were built). The placements align the template's long axis
    // with the cloud's, and this figure's trunk lies 34° from it: the fit ended with its trunk
    // tilted that far and its left arm and pelvis off (7.50% of the height in joint error over
    // the joints the scan has), its mean distance 0.70% of its size. The tilted-up check
    // (registration, level 5) searches four ups 30° from the fit's own: 0.77%, the shin and
    // foot below the cut found lost. The guard at 2%.
    on_one_thread(|| {
        held_out_cut(
            303,
            ("r_thigh", 0.7),
            &["r_shin", "r_foot"],
            &["r_knee", "r_ankle", "r_toe"],
        )
    })
}

#[test]
#[ignore = "long tier (bash tests/run.sh --include-ignored)"]
fn a_fit_far_from_its_points_is_searched_again_at_other_scales() {
    // A stylised figure (`synth --seed 207 --rigid --height 1.7 --symmetric --jitter 0.5`,
    // 30k points), its right arm raised beside the head. The placements' scale, the extent
    // along the cloud's long axis, put the pelvis block at 1.56-1.58 times the template
    // against the truth's 1.315: the trunk reached into the raised hand and the head took
    // it (9.96% of the height in joint error, mean distance 0.47% of the size), and no later
    // check moved the block. The scale search (registration, level 5) places the template
    // again at 0.8 and 1.25 times the placements' scale, and its pick ends at 2.90% (mean
    // distance 0.30% of the size; the neck and head still partial). The guard at 4%.
    on_one_thread(|| {
        let s = stylised_human(207, 30_000);
        let fit = register_as_the_cli(&s);
        let err = unswapped_joint_error(&fit.skeleton, &s.truth, "stylised seed 207");
        assert!(err < 0.04, "stylised seed 207: joint error {err}");
    })
}

/// `synth --seed SEED --rigid --height 1.7 --symmetric --jitter 0.5`: a synthetic human in a
/// random pose with ±50% proportions, the same on both sides (a stylised figure).
fn stylised_human(seed: u64, points: usize) -> SynthStatue {
    use pygmalion::anatomy::Template;
    use pygmalion::synth::{SynthOptions, generate};
    generate(
        std::sync::Arc::new(Template::builtin("human").unwrap()),
        &SynthOptions {
            points,
            seed,
            rigid: true,
            random_pose: true,
            proportion_jitter: 0.5,
            symmetric: true,
            height: 1.7,
            ..Default::default()
        },
    )
    .unwrap()
}

#[test]
#[ignore = "long tier (bash tests/run.sh --include-ignored)"]
fn arms_folded_back_onto_their_stumps_are_found_lost() {
    // A synthetic Venus, held out while the lost-limb rules were built: `synth --seed 27
    // --rigid --height 1.7 --cut bone:l_upper_arm@0.25 --cut bone:r_upper_arm@0.25` (30k
    // points before the cuts), registered as `register` does. FAKIR lays each forearm back
    // along its upper arm's stump (170° and 171° at the elbows: the template allows 125°) and
    // the hand beyond it; the scan covers them there from end to end and their axes lie only
    // 1.0–1.3 radii inside the other bones, so they were kept as limbs lying against another
    // part (covered through) and nothing was found lost. A fold the folded-limbs check did
    // not undo is a limb laid back onto its stump (`Folds::Lost`): both forearms and hands
    // are lost, the upper arms partial (1.43% of the height over the joints the scan has).
    on_one_thread(|| {
        let s = cut_human(27, 30_000, &[("l_upper_arm", 0.25), ("r_upper_arm", 0.25)]);
        let fit = register_as_the_cli(&s);
        assert_eq!(
            fit.missing_names(),
            ["l_forearm", "r_forearm", "l_hand", "r_hand"]
        );
        let t = &fit.skeleton.template;
        let partial = fit.partial();
        for arm in ["l_upper_arm", "r_upper_arm"] {
            assert!(partial[t.bone_index(arm).unwrap()], "{arm} not partial");
        }
        let err = joint_error_without(&fit.skeleton, &s.truth, &BELOW_THE_ELBOWS, 1.7, false);
        println!("joint error {:.2}%", 100.0 * err);
        assert!(err < 0.02, "joint error {err}");
    })
}

#[test]
#[ignore = "long tier (bash tests/run.sh --include-ignored)"]
fn a_venus_whose_fit_kept_one_arm_over_the_trunk_loses_both_one_bone_down() {
    // A synthetic Venus held out while the pair hypothesis was built: `synth --seed 25 --rigid
    // --height 1.7 --cut bone:l_upper_arm@0.1 --cut bone:r_upper_arm@0.1` (30k points before
    // the cuts), registered as `register` does. The whole fit lost the right forearm and hand
    // but laid the left arm along the trunk's side, covered there; the pair one bone down
    // (both forearms lost from the start, the upper arms free, started from the whole fit)
    // explains that arm's points at 1.04 times the whole fit's mean distance, both upper arms
    // lost (2026-12-04): every forearm and hand is lost, each upper arm lost or partial, and
    // the joints the scan has lie within 2% of the height (0.75%; 1.03% when the pair was
    // registered afresh).
    on_one_thread(|| {
        let s = cut_human(25, 30_000, &[("l_upper_arm", 0.1), ("r_upper_arm", 0.1)]);
        let fit = register_as_the_cli(&s);
        let t = &fit.skeleton.template;
        let partial = fit.partial();
        assert_forearms_and_hands_lost(&fit);
        for name in ["l_upper_arm", "r_upper_arm"] {
            let b = t.bone_index(name).unwrap();
            assert!(
                fit.missing[b] || partial[b],
                "{name} neither lost nor partial"
            );
        }
        let err = joint_error_without(&fit.skeleton, &s.truth, &BELOW_THE_ELBOWS, 1.7, false);
        println!("joint error {:.2}%", 100.0 * err);
        assert!(err < 0.02, "joint error {err}");
    })
}

#[test]
#[ignore = "long tier (bash tests/run.sh --include-ignored)"]
fn a_forearm_broken_part_way_whose_fit_curled_the_arm_is_fitted_again_without_its_hand() {
    // `synth --seed 333 --rigid --height 1.7 --cut bone:l_forearm@0.6` (30k points before the
    // cut), registered as `register` does. Drawn at random, before the broken-limb hypothesis
    // (`fakir::broken`) was built. The whole fit curled the left arm at the shoulder (its
    // clavicle at 0.38 of its true length, flagged shrunk) and lost nothing: 1.69% of the
    // height over the joints the scan has. Registered again with the hand lost from the start,
    // the mean distance fell to 0.68 of the whole fit's and the arm lies on its points
    // (2026-12-05: 0.36%). Only the hand is lost, and the joints the scan has lie within 1%
    // of the height on average.
    on_one_thread(|| {
        let s = cut_human(333, 30_000, &[("l_forearm", 0.6)]);
        let fit = register_as_the_cli(&s);
        assert_eq!(fit.missing_names(), vec!["l_hand"]);
        let err = joint_error_without(
            &fit.skeleton,
            &s.truth,
            &["l_wrist", "l_hand_tip"],
            1.7,
            false,
        );
        println!("joint error {:.2}%", 100.0 * err);
        assert!(err < 0.01, "joint error {err}");
    })
}

#[test]
#[ignore = "long tier (bash tests/run.sh --include-ignored)"]
fn a_venus_whose_pair_fit_keeps_her_trunk_one_bone_down() {
    // `synth --seed 23 --rigid --height 1.7 --cut bone:l_upper_arm@0.2 --cut
    // bone:r_upper_arm@0.2` (30k points before the cuts), registered as `register` does. The
    // whole fit lost the right forearm and hand and kept the left arm over the trunk; the pair
    // one bone down explains it. Registered afresh, that pair fit slid its neck and head 9.8%
    // and 7.8% of the height from their truth (2.45% over the joints the scan has); started
    // from the whole fit it keeps the whole fit's trunk: 1.12% on 2026-12-04 (the whole fit
    // 1.17%). Every forearm and hand is lost; the neck and the head's base within 4% of the
    // height, the joints the scan has within 2% on average.
    on_one_thread(|| {
        let s = cut_human(23, 30_000, &[("l_upper_arm", 0.2), ("r_upper_arm", 0.2)]);
        let fit = register_as_the_cli(&s);
        let t = &fit.skeleton.template;
        assert_forearms_and_hands_lost(&fit);
        let (got, truth) = (fit.skeleton.pose(), s.truth.pose());
        for name in ["neck", "head_base"] {
            let j = t.joint_index(name).unwrap();
            let off = got.joints[j].distance(truth.joints[j]) / 1.7;
            assert!(off < 0.04, "{name} {:.1}% of the height off", 100.0 * off);
        }
        let err = joint_error_without(&fit.skeleton, &s.truth, &BELOW_THE_ELBOWS, 1.7, false);
        println!("joint error {:.2}%", 100.0 * err);
        assert!(err < 0.02, "joint error {err}");
    })
}

#[test]
#[ignore = "long tier (bash tests/run.sh --include-ignored)"]
fn a_foot_lost_at_the_ankle_is_not_kept_as_a_stump() {
    // `synth --seed 355 --rigid --height 1.7 --cut bone:r_foot` (30k points; the whole foot
    // cut at the ankle, drawn at random with seeds 350–381 and used to build the rule). FAKIR
    // shrank the foot to half its mirror's length over the shin's end, where it held 10
    // points against its mirror's 1,133 and its support reached 0.5 of its length: it was
    // kept as a stump and nothing was lost. A stump must hold a tenth of its mirror's points
    // (`STUMP_FED`): the foot is lost (0.90% of the height in joint error over the joints the
    // scan has, as before). The guard at 2%.
    on_one_thread(|| held_out_cut(355, ("r_foot", 0.0), &["r_foot"], &["r_toe"]))
}

#[test]
#[ignore = "long tier (bash tests/run.sh --include-ignored)"]
fn a_shin_laid_across_to_the_other_foot_is_lost_with_its_foot() {
    // `synth --seed 353 --rigid --height 1.7 --cut bone:r_shin` (30k points; the right leg
    // cut at the knee, drawn at random with seeds 350–381 and used to build the rule). FAKIR
    // laid the right shin from the knee across empty space (32 points against its mirror's
    // 1,531, support reaching 0.1 of its length) and the right foot on the left foot's
    // place, where it took the left foot's points: the left foot was taken lost as empty,
    // the right leg kept. The shin is a bridge (`lost_limbs`): lost with the foot, and the
    // left foot kept (0.21% of the height in joint error over the joints the scan has, 0.32%
    // before). The guard at 2%.
    on_one_thread(|| {
        held_out_cut(
            353,
            ("r_shin", 0.0),
            &["r_shin", "r_foot"],
            &["r_ankle", "r_toe"],
        )
    })
}

#[test]
#[ignore = "long tier (bash tests/run.sh --include-ignored)"]
fn an_arm_lost_at_the_shoulder_is_lost_whole_though_its_fit_kept_the_upper_arm() {
    // `synth --seed 367 --rigid --height 1.7 --cut bone:r_upper_arm` (30k points; the right
    // arm cut at the shoulder, drawn at random with seeds 350–381 and used to build the
    // rule). The whole fit lost the forearm and the hand and kept the upper arm, shrunk over
    // the shoulder (1,159 points). The broken-limb hypothesis now also tries a limb's first
    // bone when the rest of the limb is lost and that bone is shrunk (`fakir::broken`;
    // registered with the upper arm lost, the mean distance was 0.85 times the whole fit's):
    // the whole arm is found lost, at 0.27 times the earlier mean distance (0.26% of the
    // height in joint error over the joints the scan has, 1.71% before). The guard at 2%.
    on_one_thread(|| {
        held_out_cut(
            367,
            ("r_upper_arm", 0.0),
            &["r_upper_arm", "r_forearm", "r_hand"],
            &["r_elbow", "r_wrist", "r_hand_tip"],
        )
    })
}

/// A held-out cut statue (`synth --seed SEED --rigid --height 1.7 --cut bone:B@F`, 30k
/// points) registered as the CLI does: the lost set exactly `lost`, and the joints the scan
/// has (`below`, the joints below the cut, left out) within 2% of the height.
fn held_out_cut(seed: u64, cut: (&str, f32), lost: &[&str], below: &[&str]) {
    let s = cut_human(seed, 30_000, &[cut]);
    let fit = register_as_the_cli(&s);
    assert_eq!(fit.missing_names(), lost, "seed {seed}");
    let err = joint_error_without(&fit.skeleton, &s.truth, below, 1.7, false);
    println!("seed {seed}: joint error {:.2}%", 100.0 * err);
    assert!(err < 0.02, "seed {seed}: joint error {err}");
}

/// Registers `seed` cut at `cut` as the CLI does: the joints the scan has (those below the cut
/// thigh left out) within `bound` of the height, and the fit upright (its pelvis-to-neck
/// direction within 30° of the truth's).
fn upside_down_registration(seed: u64, cut: (&str, f32), bound: f32) {
    let s = cut_human(seed, 30_000, &[cut]);
    let fit = register_as_the_cli(&s);
    let side = &cut.0[..2];
    let lost: Vec<String> = ["knee", "ankle", "toe"]
        .iter()
        .map(|j| format!("{side}{j}"))
        .collect();
    let lost: Vec<&str> = lost.iter().map(String::as_str).collect();
    let err = joint_error_without(&fit.skeleton, &s.truth, &lost, 1.7, false);
    println!(
        "seed {seed} cut through {}: joint error {:.2}%",
        cut.0,
        100.0 * err
    );
    assert!(err < bound, "seed {seed}: joint error {err}");
    let up = |k: &Skeleton| {
        let t = &k.template;
        let j = k.pose().joints;
        let at = |name: &str| j[t.joint_index(name).unwrap()];
        (at("neck") - at("pelvis")).normalize()
    };
    let cos = up(&fit.skeleton).dot(up(&s.truth));
    assert!(
        cos > 30f32.to_radians().cos(),
        "seed {seed}: up at {cos} cosine"
    );
}

#[test]
fn a_fit_with_crossed_legs_is_registered_again_uncrossed() {
    on_one_thread(crossed_registration);
}

fn crossed_registration() {
    // `synth --seed 64 --rigid --height 1.7` (30k points), registered as `register` does.
    // Without the crossed-limbs check each thigh ran from its hip to the other knee: joint
    // error 8.8% of the height. Registered again with the legs exchanged below the thighs,
    // it ends at 1.8%, with no crossed pair.
    let fit = posed_fit_within(64, 30_000, 0.025);
    let t = &fit.skeleton.template;
    let w = WorldSkeleton::from_skeleton(&fit.skeleton);
    let crossed = w.most_crossed(&t.mirror_bones(), &vec![false; t.bones.len()]);
    assert_eq!(
        crossed,
        None,
        "seed 64: {:?} crossed",
        crossed.map(|b| &t.bones[b].name)
    );
}

#[test]
fn a_folded_joint_is_found_and_unfolding_lays_the_chain_straight() {
    use pygmalion::fakir::registration::FOLDED;
    use pygmalion::fakir::solver::trunk_bones;
    let limit = FOLDED.to_radians();
    for seed in [3u64, 8, 16, 21] {
        let s = posed_human(seed, 2_000);
        let t = s.truth.template.clone();
        let trunk = trunk_bones(&t);
        let w = WorldSkeleton::from_skeleton(&s.truth);
        // The generator's poses stay within the joint ranges (measured: 122° at most).
        assert_eq!(w.most_folded(&trunk, limit), None, "seed {seed}");
        // A chain's first bone, and a bone of the block, have no fold angle.
        for name in ["l_clavicle", "l_thigh", "spine_lower", "pelvis_left"] {
            assert_eq!(w.fold_angle(t.bone_index(name).unwrap()), None, "{name}");
        }
        for (name, child) in [("l_upper_arm", "l_forearm"), ("r_shin", "r_foot")] {
            let (a, b) = (t.bone_index(name).unwrap(), t.bone_index(child).unwrap());
            // Fold `b` back along `a` (170°), as a fit that stretched `a` over the limb does.
            let mut folded = w.clone();
            let (u, v) = (w.frames[a] * Vec3::X, w.frames[b] * Vec3::X);
            let side = u
                .cross(v)
                .try_normalize()
                .unwrap_or(u.any_orthonormal_vector());
            let target = Quat::from_axis_angle(side, 170f32.to_radians()) * u;
            let swing = pygmalion::geometry::frames::rotation_arc(v, target);
            folded.rotate_subtree(b, swing);
            // The fold angle is the turn from `a`'s direction to `b`'s.
            let before = w.fold_angle(b).unwrap();
            assert!(before < limit, "seed {seed}, {child}: {before}");
            let angle = folded.fold_angle(b).unwrap();
            assert!(
                (angle - 170f32.to_radians()).abs() < 1e-3,
                "seed {seed}, {child}: {}°",
                angle.to_degrees()
            );
            assert_eq!(
                folded.most_folded(&trunk, limit),
                Some(a),
                "seed {seed}, {name}"
            );
            // Trunk bones are not examined.
            let mut skip = trunk.clone();
            skip[a] = true;
            assert_ne!(
                folded.most_folded(&skip, limit),
                Some(a),
                "seed {seed}, {name}"
            );
            // Unfolded: the chain from `a` on lies along `a`, from its first joint to its
            // end, in the template's rest proportions; everything else stays.
            let before = folded.pose();
            let after = folded.unfolded(a).pose();
            let chain = &t.chains[t.bones[a].chain.unwrap().0].bones;
            let line: Vec<usize> = chain[chain.iter().position(|&x| x == a).unwrap()..].to_vec();
            let rest: f32 = line.iter().map(|&x| w.rest_length(x)).sum();
            let reach = folded.lengths[a];
            assert!((after.bones[a].c1 - before.bones[a].c1).length() < 1e-6);
            let dir = (before.bones[a].c2 - before.bones[a].c1).normalize();
            let mut end = after.bones[a].c1;
            for &x in &line {
                let bone = after.bones[x];
                let len = (bone.c2 - bone.c1).length();
                assert!((len - reach * w.rest_length(x) / rest).abs() < 1e-4 * reach);
                assert!(
                    (bone.c2 - bone.c1).normalize().dot(dir) > 0.9999,
                    "{}",
                    t.bones[x].name
                );
                assert!((bone.c1 - end).length() < 1e-5);
                end = bone.c2;
            }
            assert!((end - before.bones[a].c2).length() < 1e-4 * reach);
            for i in (0..t.bones.len()).filter(|i| !line.contains(i)) {
                assert!((after.bones[i].c1 - before.bones[i].c1).length() < 1e-6);
                assert!((after.bones[i].c2 - before.bones[i].c2).length() < 1e-6);
            }
            assert_eq!(folded.unfolded(a).most_folded(&trunk, limit), None);
        }
    }
}

#[test]
#[ignore = "long tier (bash tests/run.sh --include-ignored)"]
fn a_fit_with_a_folded_arm_is_registered_again_unfolded() {
    on_one_thread(folded_registration);
}

fn folded_registration() {
    use pygmalion::fakir::registration::FOLDED;
    use pygmalion::fakir::solver::trunk_bones;
    // `synth --seed 12 --rigid --height 1.7` (30k points), registered as `register` does.
    // Without the folded-limbs check the right upper arm ran from the shoulder to the hand
    // and the forearm folded back along it (172°): joint error 3.3% of the height.
    // Registered again with the arm laid straight, it ends at 0.96%, folded nowhere.
    let fit = posed_fit_within(12, 30_000, 0.015);
    let t = &fit.skeleton.template;
    let w = WorldSkeleton::from_skeleton(&fit.skeleton);
    let folded = w.most_folded(&trunk_bones(t), FOLDED.to_radians());
    assert_eq!(
        folded,
        None,
        "seed 12: {:?} folded",
        folded.map(|b| &t.bones[b].name)
    );
}

#[test]
fn sliding_the_block_down_keeps_everything_off_it_in_place() {
    for seed in [3u64, 8, 16, 21] {
        let s = posed_human(seed, 2_000);
        let t = s.truth.template.clone();
        let w = WorldSkeleton::from_skeleton(&s.truth);
        let before = w.pose();
        let slid = w
            .slid_block()
            .expect("the human has a pelvis block under its spine");
        let after = slid.pose();
        let j = |name: &str| t.joint_index(name).unwrap();
        let b = |name: &str| t.bone_index(name).unwrap();
        // The block moves rigidly by minus its spine bone: the spine end lands on the root.
        let spine = b("pelvis_up");
        let delta = before.bones[spine].c1 - before.bones[spine].c2;
        for name in ["pelvis", "spine_base", "l_hip", "r_hip"] {
            let moved = after.joints[j(name)] - before.joints[j(name)];
            assert!((moved - delta).length() < 1e-5, "seed {seed}: {name}");
        }
        assert!((after.joints[j("spine_base")] - before.joints[j("pelvis")]).length() < 1e-5);
        assert_eq!(slid.block_scale, w.block_scale);
        assert!((slid.root_rotation.dot(w.root_rotation)).abs() > 1.0 - 1e-6);
        // Every joint off the block stays where it was; the bones on the block reach it.
        let block = ["pelvis", "spine_base", "l_hip", "r_hip"];
        assert_only_these_moved(&t, &before, &after, &block, &format!("seed {seed}"));
        for name in ["spine_lower", "l_thigh", "r_thigh"] {
            let (c1, c2) = (after.bones[b(name)].c1, after.bones[b(name)].c2);
            assert!(((c2 - c1).length() - slid.lengths[b(name)]).abs() < 1e-5);
            assert!((c1 - before.bones[b(name)].c1 - delta).length() < 1e-5);
        }
    }
}

#[test]
fn the_trunk_end_share_is_one_at_rest_and_halves_with_the_neck_and_head() {
    use pygmalion::anatomy::Template;
    use std::sync::Arc;
    for name in ["human", "centaur", "quadruped", "mermaid"] {
        let t = Arc::new(Template::builtin(name).unwrap());
        let placed = Skeleton::rest_placed(t.clone(), Vec3::ONE, Quat::from_rotation_z(0.7), 1.7);
        let mut w = WorldSkeleton::from_skeleton(&placed);
        let share = w.trunk_end_share().unwrap();
        assert!((share - 1.0).abs() < 1e-4, "{name} at rest: {share}");
        // The neck and head (the last two bones of every template's spine) at half length.
        for b in ["neck", "head"] {
            w.lengths[t.bone_index(b).unwrap()] *= 0.5;
        }
        let share = w.trunk_end_share().unwrap();
        assert!((share - 0.5).abs() < 1e-4, "{name} squeezed: {share}");
    }
}

#[test]
#[ignore = "long tier (bash tests/run.sh --include-ignored)"]
fn a_fit_squeezed_at_the_head_has_its_block_slid_down() {
    on_one_thread(squeezed_registration);
}

fn squeezed_registration() {
    use pygmalion::fakir::registration::SQUEEZED_END;
    // `synth --seed 6 --points 39000 --rigid --height 1.7`, registered as `register` does.
    // Without the squeezed-end trigger its pelvis sat one bone up the spine, the thighs
    // starting wide enough to cover the hips (so the uncovered-thigh trigger did not fire),
    // the neck and head squeezed to 0.43 of their share of the trunk chain: joint error
    // 3.76% of the height. Slid down, it ends at 1.42%.
    let fit = posed_fit_within(6, 39_000, 0.02);
    let share = WorldSkeleton::from_skeleton(&fit.skeleton)
        .trunk_end_share()
        .unwrap();
    println!("seed 6: trunk end share {share:.2}");
    assert!(share >= SQUEEZED_END, "seed 6: still squeezed ({share})");
}

#[test]
fn the_trunk_chain_is_the_spine_on_the_block() {
    use pygmalion::anatomy::Template;
    use std::sync::Arc;
    for name in ["human", "centaur", "quadruped", "mermaid"] {
        let t = Arc::new(Template::builtin(name).unwrap());
        let w = WorldSkeleton::from_skeleton(&Skeleton::rest(t.clone()));
        let chain = w
            .trunk_chain()
            .expect("every built-in template has a spine");
        assert_eq!(t.chains[chain].name, "spine", "{name}");
        // Its first bone hangs from the root block.
        let first = t.chains[chain].bones[0];
        let parent = t.bones[first]
            .parent
            .expect("the spine hangs from the block");
        assert_eq!(
            t.bones[parent].kind,
            pygmalion::anatomy::BoneKind::Block,
            "{name}"
        );
    }
}

#[test]
#[ignore = "long tier (bash tests/run.sh --include-ignored)"]
fn a_trunk_still_squeezed_after_the_slid_block_is_reset() {
    on_one_thread(trunk_reset_registration);
}

fn trunk_reset_registration() {
    use pygmalion::fakir::registration::SQUEEZED_END;
    // `synth --seed 6 --rigid --height 1.7` (30k points) without its normals: the
    // registration estimates them from the positions, as for any such file (100% agree in
    // sign with the true ones, median angle 0.97 degrees). Without the trunk-reset check its
    // spine slid up into the head, the neck and head squeezed above it (0.25 of their share of
    // the trunk chain), and the slid block did not mend it (the pelvis was in place): joint
    // error 4.43% of the height. With it, 1.22%.
    let mut s = posed_human(6, 30_000);
    s.cloud.normals = None;
    let fit = register_as_the_cli(&s);
    let err = unswapped_joint_error(&fit.skeleton, &s.truth, "seed 6, estimated normals");
    assert!(err < 0.02, "seed 6, estimated normals: joint error {err}");
    let share = WorldSkeleton::from_skeleton(&fit.skeleton)
        .trunk_end_share()
        .unwrap();
    assert!(share >= SQUEEZED_END, "seed 6: still squeezed ({share})");
}

#[test]
fn sliding_a_limb_down_moves_each_joint_to_the_next() {
    for seed in [3u64, 8, 16, 21] {
        let s = posed_human(seed, 2_000);
        let t = s.truth.template.clone();
        let w = WorldSkeleton::from_skeleton(&s.truth);
        let before = w.pose();
        let j = |name: &str| t.joint_index(name).unwrap();
        for (first, joints) in [
            ("l_thigh", ["l_hip", "l_knee", "l_ankle", "l_toe"]),
            (
                "r_upper_arm",
                ["r_shoulder", "r_elbow", "r_wrist", "r_hand_tip"],
            ),
        ] {
            let a = t.bone_index(first).unwrap();
            let slid = w.slid_down(a);
            let after = slid.pose();
            let at = |k: usize| after.joints[j(joints[k])];
            let was = |k: usize| before.joints[j(joints[k])];
            // The chain's first joint stays; each later joint moves to the next one's place;
            // the last continues along the last bone, at its length.
            assert!((at(0) - was(0)).length() < 1e-5, "seed {seed}: {first}");
            assert!((at(1) - was(2)).length() < 1e-4, "seed {seed}: {first}");
            assert!((at(2) - was(3)).length() < 1e-4, "seed {seed}: {first}");
            assert!(((at(3) - at(2)) - (was(3) - was(2))).length() < 1e-4);
            // Everything off the chain stays.
            let what = format!("seed {seed}: {first}");
            assert_only_these_moved(&t, &before, &after, &joints[1..], &what);
            // The last bone of a chain has nothing below to slide onto.
            let last = t.bone_index(&first.replace("thigh", "foot").replace("upper_arm", "hand"));
            let last = last.unwrap();
            let same = w.slid_down(last).pose();
            for k in 0..t.joints.len() {
                assert!((same.joints[k] - before.joints[k]).length() < 1e-6);
            }
        }
    }
}

#[test]
fn the_trunk_end_is_the_trunk_chain_past_the_last_bone_carrying_a_chain() {
    use pygmalion::anatomy::Template;
    // The human: the neck and head, beside the two arms hanging from `spine_upper`.
    let t = std::sync::Arc::new(Template::builtin("human").unwrap());
    let w = WorldSkeleton::from_skeleton(&Skeleton::rest(t.clone()));
    let (end, arms) = w.trunk_end().expect("the human has a trunk end");
    let names = |bones: &[usize]| -> Vec<String> {
        bones.iter().map(|&b| t.bones[b].name.clone()).collect()
    };
    assert_eq!(names(&end), ["neck", "head"]);
    let arms: Vec<&str> = arms.iter().map(|&c| t.chains[c].name.as_str()).collect();
    assert_eq!(arms, ["l_arm", "r_arm"]);
    // Every template: the end is the trunk chain's tail, no bone of it carries a chain, and
    // each chain beside it hangs from the bone just before it.
    for name in ["human", "quadruped", "centaur", "mermaid"] {
        let t = std::sync::Arc::new(Template::builtin(name).unwrap());
        let w = WorldSkeleton::from_skeleton(&Skeleton::rest(t.clone()));
        let Some((end, beside)) = w.trunk_end() else {
            continue;
        };
        let line = &t.chains[w.trunk_chain().unwrap()].bones;
        assert!(!end.is_empty() && line.ends_with(&end), "{name}");
        let carrier = line[line.len() - end.len() - 1];
        assert!(!beside.is_empty(), "{name}");
        for &c in &beside {
            assert_eq!(
                t.bones[t.chains[c].bones[0]].parent,
                Some(carrier),
                "{name}"
            );
        }
        for (c, chain) in t.chains.iter().enumerate() {
            let first = chain.bones[0];
            assert!(
                t.bones[first].parent.is_none_or(|p| !end.contains(&p)) || line.contains(&first),
                "{name}: chain {c} hangs from the trunk end"
            );
        }
    }
}

#[test]
fn at_rest_puts_bones_back_at_rest_and_leaves_the_others_world_directions() {
    for seed in [3u64, 11] {
        let s = posed_human(seed, 2_000);
        let t = s.truth.template.clone();
        let w = WorldSkeleton::from_skeleton(&s.truth);
        let rest = WorldSkeleton::from_skeleton(&Skeleton::rest(t.clone()));
        let trunk = t.chains[w.trunk_chain().unwrap()].bones.clone();
        let a = w.at_rest(&trunk);
        for &b in &trunk {
            // At rest relative to its parent, at rest length times the block scale.
            let angle = a
                .direction_at_rest(b)
                .angle_between(rest.direction_at_rest(b));
            assert!(angle < 1e-3, "seed {seed}: {} {angle}", t.bones[b].name);
            let want = rest.lengths[b] * w.block_scale;
            assert!((a.lengths[b] - want).abs() < 1e-5 * want.max(1.0));
        }
        // Every free bone off the trunk keeps its world direction and length (the arms and
        // the legs); the block does not move.
        let (before, after) = (w.pose(), a.pose());
        for (b, def) in t.bones.iter().enumerate() {
            if trunk.contains(&b) || def.kind != pygmalion::anatomy::template::BoneKind::Free {
                continue;
            }
            let d = |p: &pygmalion::anatomy::Posed| p.bones[b].c2 - p.bones[b].c1;
            assert!(
                (d(&before) - d(&after)).length() < 1e-4,
                "seed {seed}: {}",
                def.name
            );
        }
        let pelvis = t.joint_index("pelvis").unwrap();
        assert!((before.joints[pelvis] - after.joints[pelvis]).length() < 1e-6);
    }
}

#[test]
#[ignore = "long tier (bash tests/run.sh --include-ignored)"]
fn an_arm_slid_up_into_the_head_is_registered_again_slid_down_under_a_trunk_at_rest() {
    on_one_thread(crowded_head_registration);
}

fn crowded_head_registration() {
    // `fakir/accuracy_posed`'s seed 11 (46,500 points): without the crowded-head check its
    // right arm sat one joint up, the clavicle in the head and the head pushed onto the left
    // shoulder (the neck's coverage 0, joint error 5.29% of the height). With it, 0.22%.
    let s = posed_human(11, 46_500);
    let fit = register_as_the_cli(&s);
    let err = unswapped_joint_error(&fit.skeleton, &s.truth, "seed 11");
    assert!(err < 0.02, "seed 11: joint error {err}");
}

#[test]
#[ignore = "long tier (bash tests/run.sh --include-ignored)"]
fn a_fit_with_its_pelvis_and_a_leg_a_bone_too_high_is_registered_again_slid_down() {
    on_one_thread(slid_registration);
}

fn slid_registration() {
    use pygmalion::fakir::registration::UNCOVERED_REACH;
    // `synth --seed 31 --rigid --height 1.7` (30k points, a crouching figure), registered as
    // `register` does. Without the slid checks the pelvis sat a bone too high up the spine
    // and the left leg a bone up its own length (the knee at the hip, the ankle at the knee):
    // both thighs uncovered at the hip, joint error 3.7% of the height. Slid down, the block
    // first and then the left leg, it ends at 0.43%.
    let fit = posed_fit_within(31, 30_000, 0.01);
    for name in ["l_thigh", "r_thigh"] {
        let b = fit.skeleton.template.bone_index(name).unwrap();
        let reach = fit.support[b].reach;
        assert!(reach > UNCOVERED_REACH, "seed 31: {name} reach {reach}");
    }
}

/// Asserts that every joint of `t` but those named in `moved` is where it was (1e-5).
fn assert_only_these_moved(
    t: &pygmalion::anatomy::Template,
    before: &pygmalion::anatomy::Posed,
    after: &pygmalion::anatomy::Posed,
    moved: &[&str],
    what: &str,
) {
    for (k, joint) in t.joints.iter().enumerate() {
        if moved.contains(&joint.name.as_str()) {
            continue;
        }
        assert!(
            (after.joints[k] - before.joints[k]).length() < 1e-5,
            "{what}: {} moved",
            joint.name
        );
    }
}

/// Asserts that each joint of `names` in `fit` lies within `tol` of the 1.7-high statue's
/// height of the same joint in `truth`.
fn assert_joints_within(fit: &Skeleton, truth: &Skeleton, names: &[&str], tol: f32, what: &str) {
    let t = &fit.template;
    let (a, b) = (fit.pose(), truth.pose());
    for name in names {
        let j = t.joint_index(name).unwrap();
        let e = (a.joints[j] - b.joints[j]).length() / 1.7;
        assert!(e < tol, "{what}: {name} off by {:.2}%", 100.0 * e);
    }
}

/// Distance from `p` to the polyline through `path`.
fn distance_to_path(p: Vec3, path: &[Vec3]) -> f32 {
    path.windows(2)
        .map(|w| {
            let d = w[1] - w[0];
            let t = ((p - w[0]).dot(d) / d.length_squared().max(1e-12)).clamp(0.0, 1.0);
            (p - (w[0] + d * t)).length()
        })
        .fold(f32::INFINITY, f32::min)
}

#[test]
fn sliding_a_limb_out_keeps_its_tip_and_splits_the_last_bone() {
    for seed in [3u64, 8, 16, 21] {
        let s = posed_human(seed, 2_000);
        let t = s.truth.template.clone();
        let w = WorldSkeleton::from_skeleton(&s.truth);
        let before = w.pose();
        let j = |name: &str| t.joint_index(name).unwrap();
        for (first, joints) in [
            (
                "l_clavicle",
                [
                    "spine_top",
                    "l_shoulder",
                    "l_elbow",
                    "l_wrist",
                    "l_hand_tip",
                ],
            ),
            (
                "r_clavicle",
                [
                    "spine_top",
                    "r_shoulder",
                    "r_elbow",
                    "r_wrist",
                    "r_hand_tip",
                ],
            ),
        ] {
            let a = t.bone_index(first).unwrap();
            let side = &first[..2];
            let fore = t.bone_index(&format!("{side}forearm")).unwrap();
            let hand = t.bone_index(&format!("{side}hand")).unwrap();
            let after = w.slid_out(a).pose();
            let at = |k: usize| after.joints[j(joints[k])];
            let was = |k: usize| before.joints[j(joints[k])];
            // The first joint and the tip stay; the two joints after the first move to the
            // next one's place; the wrist splits the old hand in the rest proportions.
            assert!((at(0) - was(0)).length() < 1e-5, "seed {seed}: {first}");
            assert!((at(1) - was(2)).length() < 1e-4, "seed {seed}: {first}");
            assert!((at(2) - was(3)).length() < 1e-4, "seed {seed}: {first}");
            let share = w.rest_length(fore) / (w.rest_length(fore) + w.rest_length(hand));
            let wrist = was(3) + (was(4) - was(3)) * share;
            assert!((at(3) - wrist).length() < 1e-4, "seed {seed}: {first}");
            assert!((at(4) - was(4)).length() < 1e-4, "seed {seed}: {first}");
            let what = format!("seed {seed}: {first}");
            assert_only_these_moved(&t, &before, &after, &joints[1..], &what);
        }
        // A chain of two bones from `a` has no last pair to split: slid down.
        let shin = t.bone_index("l_shin").unwrap();
        let (x, y) = (w.slid_out(shin).pose(), w.slid_down(shin).pose());
        for k in 0..t.joints.len() {
            assert!((x.joints[k] - y.joints[k]).length() < 1e-6);
        }
    }
}

#[test]
fn splitting_a_limb_end_lays_the_last_two_bones_along_the_one_before() {
    for seed in [3u64, 8, 16, 21] {
        let s = posed_human(seed, 2_000);
        let t = s.truth.template.clone();
        let w = WorldSkeleton::from_skeleton(&s.truth);
        let before = w.pose();
        let j = |name: &str| t.joint_index(name).unwrap();
        for (last, p, [root, mid, tip]) in [
            ("r_hand", "r_forearm", ["r_elbow", "r_wrist", "r_hand_tip"]),
            ("l_hand", "l_forearm", ["l_elbow", "l_wrist", "l_hand_tip"]),
            ("l_foot", "l_shin", ["l_knee", "l_ankle", "l_toe"]),
        ] {
            let (b, pb) = (t.bone_index(last).unwrap(), t.bone_index(p).unwrap());
            let after = w.split_end(b).pose();
            let what = format!("seed {seed}: {last}");
            // The bone before keeps its first joint; the last bone ends where the bone before
            // ended; the joint between splits that vector in the rest proportions.
            let (from, to) = (before.joints[j(root)], before.joints[j(mid)]);
            assert!((after.joints[j(root)] - from).length() < 1e-5, "{what}");
            assert!((after.joints[j(tip)] - to).length() < 1e-4, "{what}");
            let share = w.rest_length(pb) / (w.rest_length(pb) + w.rest_length(b));
            let between = from + (to - from) * share;
            assert!((after.joints[j(mid)] - between).length() < 1e-4, "{what}");
            assert_only_these_moved(&t, &before, &after, &[mid, tip], &what);
        }
        // A bone first in its chain has no bone before it to share: nothing moves.
        let clavicle = t.bone_index("l_clavicle").unwrap();
        let same = w.split_end(clavicle).pose();
        assert_only_these_moved(&t, &before, &same, &[], &format!("seed {seed}: clavicle"));
    }
}

/// One flag per bone of `t`, set for the bones named.
fn marked(t: &pygmalion::anatomy::Template, names: &[&str]) -> Vec<bool> {
    let mut v = vec![false; t.bones.len()];
    for n in names {
        v[t.bone_index(n).unwrap()] = true;
    }
    v
}

#[test]
fn the_dangling_end_is_a_lost_last_bone_below_a_covered_or_folded_up_one() {
    use pygmalion::fakir::support::MISSING;
    let s = posed_human(3, 2_000);
    let t = s.truth.template.clone();
    let w = WorldSkeleton::from_skeleton(&s.truth);
    let nb = t.bones.len();
    let b = |name: &str| t.bone_index(name).unwrap();
    let none = vec![false; nb];
    let full = vec![1.0f32; nb];
    let mark = |names: &[&str]| marked(&t, names);
    // Nothing lost: nothing dangles.
    assert_eq!(
        w.most_dangling_end(&none, &none, &full, &none, MISSING),
        None
    );
    // A hand judged lost at full size below a covered forearm dangles (seeds 10, 33, 55 of
    // `synth --rigid --height 1.7` before this check).
    let lost = mark(&["r_hand"]);
    let mut coverage = full.clone();
    coverage[b("r_hand")] = 0.2;
    let found = w.most_dangling_end(&none, &lost, &coverage, &none, MISSING);
    assert_eq!(found, Some(b("r_hand")));
    // A foot is the last bone of its chain too; with both, the less covered one.
    let both = mark(&["r_hand", "l_foot"]);
    coverage[b("l_foot")] = 0.1;
    let found = w.most_dangling_end(&none, &both, &coverage, &none, MISSING);
    assert_eq!(found, Some(b("l_foot")));
    // A hand that collapsed onto the stump (FAKIR's sign of a limb cut at the wrist), a hand
    // whose forearm is lost or uncovered too (a cut higher up), a lost forearm alone (not
    // the last bone) and a skipped chain are not dangling ends.
    let shrunk = mark(&["r_hand"]);
    assert_eq!(
        w.most_dangling_end(&none, &lost, &coverage, &shrunk, MISSING),
        None
    );
    let cut = mark(&["r_forearm", "r_hand"]);
    assert_eq!(
        w.most_dangling_end(&none, &cut, &coverage, &none, MISSING),
        None
    );
    let mut bare = coverage.clone();
    bare[b("r_forearm")] = 0.1;
    assert_eq!(
        w.most_dangling_end(&none, &lost, &bare, &none, MISSING),
        None
    );
    // An uncovered forearm that collapsed too, kept by the lost-limb rules, above a lost hand
    // (collapsed or not) is an arm folded up on itself (seed 15: upper arm, forearm and hand
    // shrunk, the forearm at 0.08 coverage, the hand lost): its hand dangles. A covered
    // collapsed forearm above a collapsed hand is a cut at the wrist: it does not.
    let folded = mark(&["r_upper_arm", "r_forearm", "r_hand"]);
    assert_eq!(
        w.most_dangling_end(&none, &lost, &bare, &folded, MISSING),
        Some(b("r_hand"))
    );
    let forearm_only = mark(&["r_forearm"]);
    assert_eq!(
        w.most_dangling_end(&none, &lost, &bare, &forearm_only, MISSING),
        Some(b("r_hand"))
    );
    let wrist_cut = mark(&["r_forearm", "r_hand"]);
    assert_eq!(
        w.most_dangling_end(&none, &lost, &coverage, &wrist_cut, MISSING),
        None
    );
    let forearm = mark(&["r_forearm"]);
    assert_eq!(
        w.most_dangling_end(&none, &forearm, &full, &none, MISSING),
        None
    );
    let skip = mark(&["r_hand"]);
    assert_eq!(
        w.most_dangling_end(&skip, &lost, &coverage, &none, MISSING),
        None
    );
}

#[test]
fn sliding_a_limb_back_puts_each_bone_one_place_up_its_chain() {
    for seed in [3u64, 8, 16, 21] {
        let s = posed_human(seed, 2_000);
        let t = s.truth.template.clone();
        let w = WorldSkeleton::from_skeleton(&s.truth);
        let before = w.pose();
        let j = |name: &str| t.joint_index(name).unwrap();
        let b = |name: &str| t.bone_index(name).unwrap();
        for (a, next, [root, split, third, tip]) in [
            ("r_thigh", "r_shin", ["r_hip", "r_knee", "r_ankle", "r_toe"]),
            (
                "l_upper_arm",
                "l_forearm",
                ["l_shoulder", "l_elbow", "l_wrist", "l_hand_tip"],
            ),
        ] {
            let after = w.slid_back(b(a)).pose();
            let what = format!("seed {seed}: {a}");
            // The first joint stays; the joint after it splits the bone's old vector in rest
            // proportions; each later joint lands where the one before it was.
            let (from, to) = (before.joints[j(root)], before.joints[j(split)]);
            assert!((after.joints[j(root)] - from).length() < 1e-5, "{what}");
            let share = w.rest_length(b(a)) / (w.rest_length(b(a)) + w.rest_length(b(next)));
            let between = from + (to - from) * share;
            assert!((after.joints[j(split)] - between).length() < 1e-4, "{what}");
            assert!((after.joints[j(third)] - to).length() < 1e-4, "{what}");
            assert!(
                (after.joints[j(tip)] - before.joints[j(third)]).length() < 1e-4,
                "{what}"
            );
            assert_only_these_moved(&t, &before, &after, &[split, third, tip], &what);
        }
        // From the bone before the last it is the dangling-end check's start; from the last
        // bone nothing moves.
        for (p, last) in [("r_forearm", "r_hand"), ("l_shin", "l_foot")] {
            let (x, y) = (w.slid_back(b(p)).pose(), w.split_end(b(last)).pose());
            for k in 0..t.joints.len() {
                assert!(
                    (x.joints[k] - y.joints[k]).length() < 1e-6,
                    "seed {seed}: {p}"
                );
            }
        }
        let same = w.slid_back(b("l_hand")).pose();
        assert_only_these_moved(&t, &before, &same, &[], &format!("seed {seed}: hand"));
    }
}

#[test]
fn an_overreaching_limb_is_one_too_long_for_its_mirror_above_a_lost_tail() {
    use pygmalion::fakir::registration::OVERREACH;
    use pygmalion::fakir::support::MISSING;
    let s = posed_human(3, 2_000);
    let t = s.truth.template.clone();
    let mut w = WorldSkeleton::from_skeleton(&s.truth);
    let nb = t.bones.len();
    let b = |name: &str| t.bone_index(name).unwrap();
    // Mirrored limbs of equal lengths, then the right thigh stretched towards the shin (half
    // a foot longer than its mirror: the shin pushed down, the foot off the statue).
    for (l, r) in [
        ("l_thigh", "r_thigh"),
        ("l_shin", "r_shin"),
        ("l_foot", "r_foot"),
    ] {
        w.lengths[b(r)] = w.lengths[b(l)];
    }
    let (none, full) = (vec![false; nb], vec![1.0f32; nb]);
    let mark = |names: &[&str]| marked(&t, names);
    let lost = mark(&["r_foot"]);
    // Lengths equal to the mirror's: a foot taken lost is not a limb overreaching.
    assert_eq!(
        w.most_overreaching(&none, &lost, &full, MISSING, OVERREACH),
        None
    );
    let foot = w.lengths[b("l_foot")];
    w.lengths[b("r_thigh")] += 0.5 * foot;
    // Nothing lost: nothing to explain.
    assert_eq!(
        w.most_overreaching(&none, &none, &full, MISSING, OVERREACH),
        None
    );
    // The foot lost below a thigh half a foot too long: the thigh is the bone to slide
    // back from, and a shin grown longer still would be.
    assert_eq!(
        w.most_overreaching(&none, &lost, &full, MISSING, OVERREACH),
        Some(b("r_thigh"))
    );
    let mut longer = w.clone();
    longer.lengths[b("r_shin")] *= 1.8;
    assert_eq!(
        longer.most_overreaching(&none, &lost, &full, MISSING, OVERREACH),
        Some(b("r_shin"))
    );
    // A lost tail of two bones is examined from the bone above it: the uncovered lost shin
    // is part of the tail, and the covered thigh above it the bone to slide back from.
    let shin_and_foot = mark(&["r_shin", "r_foot"]);
    let mut tail = w.clone();
    tail.lengths[b("r_thigh")] = w.lengths[b("l_thigh")] + w.lengths[b("l_shin")];
    let mut bare_shin = full.clone();
    bare_shin[b("r_shin")] = 0.1;
    assert_eq!(
        tail.most_overreaching(&none, &shin_and_foot, &bare_shin, MISSING, OVERREACH),
        Some(b("r_thigh"))
    );
    // Not below a share of the mirror's first lost bone; not when the mirror's foot is lost
    // too (nothing to compare with), nor when the bone above the tail is uncovered (a limb
    // cut there), nor in a skipped chain.
    assert_eq!(w.most_overreaching(&none, &lost, &full, MISSING, 0.6), None);
    let both = mark(&["r_foot", "l_foot"]);
    assert_eq!(
        w.most_overreaching(&none, &both, &full, MISSING, OVERREACH),
        None
    );
    let mut bare = full.clone();
    bare[b("r_shin")] = 0.1;
    assert_eq!(
        w.most_overreaching(&none, &lost, &bare, MISSING, OVERREACH),
        None
    );
    assert_eq!(
        w.most_overreaching(&mark(&["r_thigh"]), &lost, &full, MISSING, OVERREACH),
        None
    );
}

#[test]
fn the_most_stretched_end_is_the_chain_whose_last_bone_outgrew_the_one_before() {
    use pygmalion::fakir::registration::STRETCHED_END;
    for seed in [3u64, 8, 16, 21] {
        let s = posed_human(seed, 2_000);
        let t = s.truth.template.clone();
        let none = vec![false; t.bones.len()];
        // The generator's truths stay under twice the rest ratio (1.74 at most over 72 seeds).
        let w = WorldSkeleton::from_skeleton(&s.truth);
        assert_eq!(w.most_stretched_end(&none, 2.0), None, "seed {seed}");
        for (last, first) in [("l_hand", "l_clavicle"), ("r_foot", "r_thigh")] {
            let mut stretched = s.truth.clone();
            stretched.bones[t.bone_index(last).unwrap()].length *= 4.0;
            let w = WorldSkeleton::from_skeleton(&stretched);
            let a = t.bone_index(first).unwrap();
            assert_eq!(w.most_stretched_end(&none, STRETCHED_END), Some(a));
            // Skipped chains are left out; so are trunk chains.
            let mut skip = none.clone();
            skip[a] = true;
            assert_ne!(w.most_stretched_end(&skip, 2.0), Some(a), "seed {seed}");
        }
    }
}

#[test]
fn reversing_a_limb_lays_it_back_along_its_own_path() {
    for seed in [3u64, 8, 16, 21] {
        let s = posed_human(seed, 2_000);
        let t = s.truth.template.clone();
        let w = WorldSkeleton::from_skeleton(&s.truth);
        let before = w.pose();
        let j = |name: &str| t.joint_index(name).unwrap();
        let joints = [
            "spine_top",
            "r_shoulder",
            "r_elbow",
            "r_wrist",
            "r_hand_tip",
        ];
        let a = t.bone_index("r_clavicle").unwrap();
        let after = w.reversed_below(a).pose();
        let at = |k: usize| after.joints[j(joints[k])];
        let was = |k: usize| before.joints[j(joints[k])];
        // The clavicle reaches the old tip; the arm comes back along the old arm to the old
        // shoulder, its bones in the template's rest proportions.
        assert!((at(0) - was(0)).length() < 1e-5, "seed {seed}");
        assert!((at(1) - was(4)).length() < 1e-4, "seed {seed}");
        assert!((at(4) - was(1)).length() < 1e-4, "seed {seed}");
        let path: Vec<Vec3> = (1..5).map(was).collect();
        let total: f32 = path.windows(2).map(|w| (w[1] - w[0]).length()).sum();
        let rest: f32 = ["r_upper_arm", "r_forearm", "r_hand"]
            .iter()
            .map(|b| w.rest_length(t.bone_index(b).unwrap()))
            .sum();
        for (k, b) in ["r_upper_arm", "r_forearm", "r_hand"].iter().enumerate() {
            assert!(
                distance_to_path(at(k + 2), &path) < 1e-4,
                "seed {seed}: {b}"
            );
            let len = (at(k + 2) - at(k + 1)).length();
            let share = total * w.rest_length(t.bone_index(b).unwrap()) / rest;
            // A joint laid across a bend cuts the corner: never longer than its share.
            assert!(len <= share + 1e-4, "seed {seed}: {b} {len} > {share}");
        }
        assert_only_these_moved(&t, &before, &after, &joints[1..], &format!("seed {seed}"));
        // Fewer than two bones below: nothing to reverse.
        let fore = t.bone_index("r_forearm").unwrap();
        let same = w.reversed_below(fore).pose();
        for k in 0..t.joints.len() {
            assert!((same.joints[k] - before.joints[k]).length() < 1e-6);
        }
    }
}

#[test]
fn a_limb_hanging_from_an_uncovered_bone_is_found() {
    use pygmalion::fakir::support::MISSING;
    let s = posed_human(3, 2_000);
    let t = s.truth.template.clone();
    let w = WorldSkeleton::from_skeleton(&s.truth);
    let b = |name: &str| t.bone_index(name).unwrap();
    let none = vec![false; t.bones.len()];
    let mut coverage = vec![1.0f32; t.bones.len()];
    assert_eq!(w.most_hanging(&none, &coverage, MISSING), None);
    // An uncovered clavicle with the arm below it on the scan.
    coverage[b("r_clavicle")] = 0.3;
    assert_eq!(
        w.most_hanging(&none, &coverage, MISSING),
        Some(b("r_clavicle"))
    );
    // The least covered of two.
    coverage[b("l_upper_arm")] = 0.2;
    assert_eq!(
        w.most_hanging(&none, &coverage, MISSING),
        Some(b("l_upper_arm"))
    );
    let mut skip = none.clone();
    skip[b("l_upper_arm")] = true;
    assert_eq!(
        w.most_hanging(&skip, &coverage, MISSING),
        Some(b("r_clavicle"))
    );
    // A limb lost from there on (an arm cut at the shoulder) hangs from nothing.
    coverage[b("r_hand")] = 0.1;
    assert_eq!(w.most_hanging(&skip, &coverage, MISSING), None);
    // One bone below is not enough (a lost forearm with the hand lying on the thigh).
    let mut coverage = vec![1.0f32; t.bones.len()];
    coverage[b("l_forearm")] = 0.1;
    assert_eq!(w.most_hanging(&none, &coverage, MISSING), None);
}

#[test]
fn a_fit_with_an_arm_slid_one_joint_in_is_registered_again_slid_out() {
    on_one_thread(|| {
        use pygmalion::fakir::registration::STRETCHED_END;
        // `synth --seed 43 --rigid --height 1.7` (30k points). Without the stretched-end
        // check the left arm sat one joint in (the elbow on the shoulder, the wrist on the
        // elbow) with the hand stretched over the forearm: joint error 2.2% of the height.
        // Slid out, it ends at 0.31%.
        let fit = posed_fit_within(43, 30_000, 0.01);
        let w = WorldSkeleton::from_skeleton(&fit.skeleton);
        let none = vec![false; fit.skeleton.bones.len()];
        assert_eq!(w.most_stretched_end(&none, STRETCHED_END), None);
    });
}

#[test]
#[ignore = "long tier (bash tests/run.sh --include-ignored)"]
fn a_fit_with_an_arm_run_backwards_is_registered_again_turned_around() {
    on_one_thread(|| {
        use pygmalion::fakir::support::MISSING;
        // `synth --seed 37 --rigid --height 1.7` (30k points). Without the hanging-limb check
        // the right clavicle ran from the chest to the hand, across empty space (coverage
        // 0.33), and the arm came back to the shoulder. Turned around, the right arm's joints
        // land within 0.7% of the height of the truth (the whole fit: 6.3% -> 2.4%; its
        // pelvis still sits high, a fault of its own).
        let s = posed_human(37, 30_000);
        let fit = register_as_the_cli(&s);
        let t = &fit.skeleton.template;
        let right_arm = ["r_shoulder", "r_elbow", "r_wrist", "r_hand_tip"];
        assert_joints_within(&fit.skeleton, &s.truth, &right_arm, 0.015, "seed 37");
        let c = fit.support[t.bone_index("r_clavicle").unwrap()].coverage;
        assert!(c >= MISSING, "seed 37: right clavicle coverage {c}");
        unswapped_joint_error(&fit.skeleton, &s.truth, "seed 37");
    });
}

/// Registers the complete statue `synth --seed SEED --rigid --height 1.7` (30k points) as
/// the CLI does and asserts that nothing was found lost on it.
fn register_complete_seed(seed: u64) -> (SynthStatue, pygmalion::fakir::Fit) {
    let s = posed_human(seed, 30_000);
    let fit = register_as_the_cli(&s);
    let lost = fit.missing_names();
    assert!(
        lost.is_empty(),
        "seed {seed}: found lost on a complete statue: {lost:?}"
    );
    (s, fit)
}

#[test]
#[ignore = "long tier (bash tests/run.sh --include-ignored)"]
fn a_fit_with_a_forearm_stretched_over_the_hand_is_registered_again_with_the_hand() {
    on_one_thread(|| {
        // `synth --seed 10 --rigid --height 1.7` (30k points). Without the dangling-end check
        // the right forearm reached the tip of the hand (the wrist 15 cm off) and the hand
        // hung beside it, found lost on a complete statue: joint error 1.77%. With the
        // forearm's vector shared by forearm and hand, 0.66% and nothing lost.
        let (s, fit) = register_complete_seed(10);
        let right_arm = ["r_elbow", "r_wrist", "r_hand_tip"];
        assert_joints_within(&fit.skeleton, &s.truth, &right_arm, 0.015, "seed 10");
        let err = unswapped_joint_error(&fit.skeleton, &s.truth, "seed 10");
        assert!(err < 0.01, "seed 10: joint error {err}");
    });
}

#[test]
#[ignore = "long tier (bash tests/run.sh --include-ignored)"]
fn a_fit_with_an_arm_folded_up_on_itself_is_registered_again_with_the_arm() {
    on_one_thread(|| {
        // `synth --seed 15 --rigid --height 1.7` (30k points). Its fit had the right arm
        // folded up on itself (upper arm, forearm and hand collapsed, the forearm at 0.08
        // coverage) and the hand found lost on a complete statue: joint error 6.76%. The
        // dangling-end check now takes a lost hand below a collapsed, uncovered forearm that
        // the lost-limb rules keep: 1.31% and nothing lost.
        let (s, fit) = register_complete_seed(15);
        let err = unswapped_joint_error(&fit.skeleton, &s.truth, "seed 15");
        assert!(err < 0.02, "seed 15: joint error {err}");
    });
}

#[test]
fn the_arm_checks_starts_and_detectors_hold_on_every_template() {
    use pygmalion::anatomy::Template;
    use pygmalion::fakir::registration::OVERREACH;
    use pygmalion::fakir::support::MISSING;
    for name in ["human", "centaur", "quadruped", "mermaid"] {
        let t = std::sync::Arc::new(Template::builtin(name).unwrap());
        let w = WorldSkeleton::from_skeleton(&Skeleton::rest(t.clone()));
        let nb = t.bones.len();
        let none = vec![false; nb];
        // Every bone uncovered, then each bone alone uncovered: never a panic, and a bone
        // found hanging has two covered bones or more below it.
        assert_eq!(
            w.most_hanging(&none, &vec![0.0; nb], MISSING),
            None,
            "{name}"
        );
        for b in 0..nb {
            let mut coverage = vec![1.0f32; nb];
            coverage[b] = 0.0;
            if let Some(a) = w.most_hanging(&none, &coverage, MISSING) {
                assert_eq!(a, b, "{name}");
            }
        }
        // At rest nothing is stretched.
        assert_eq!(w.most_stretched_end(&none, 1.01), None, "{name}");
        // Each bone alone lost at full size: a dangling end is a lost last bone.
        let full = vec![1.0f32; nb];
        for b in 0..nb {
            let mut lost = none.clone();
            lost[b] = true;
            if let Some(e) = w.most_dangling_end(&none, &lost, &full, &none, MISSING) {
                assert_eq!(e, b, "{name}");
                let c = t.bones[b].chain.expect("a dangling end is in a chain");
                assert_eq!(t.chains[c.0].bones.last(), Some(&b), "{name}");
            }
        }
        // At rest (mirrors of equal lengths) no limb overreaches, whichever bone is lost.
        for b in 0..nb {
            let mut lost = none.clone();
            lost[b] = true;
            assert_eq!(
                w.most_overreaching(&none, &lost, &full, MISSING, OVERREACH),
                None,
                "{name}: bone {b}"
            );
        }
        // Every start from every bone keeps a finite skeleton with the same bones.
        for b in 0..nb {
            for s in [
                w.slid_out(b),
                w.reversed_below(b),
                w.slid_down(b),
                w.split_end(b),
                w.slid_back(b),
            ] {
                let p = s.pose();
                assert!(p.joints.iter().all(|j| j.is_finite()), "{name}: bone {b}");
                assert!(s.lengths.iter().all(|l| l.is_finite() && *l >= 0.0));
            }
        }
    }
}

/// A solver on `statue`'s points, its skeleton at `skel` (the assignment refreshed).
fn solver_at<'p>(
    statue: &SynthStatue,
    skel: &Skeleton,
    settings: SolverSettings,
    pause: &'p mut NoPause,
) -> Solver<'p> {
    let n = statue.cloud.len();
    let asg = Assignment::new(
        statue.cloud.positions.clone(),
        statue.cloud.normals.clone().unwrap(),
        (0..n as u32).collect(),
        skel.template.bones.len(),
        AssignParams {
            cone_slack: 0.2,
            cone_abs: 0.0,
        },
    );
    let mut s = Solver::new(
        WorldSkeleton::from_skeleton(skel),
        asg,
        1.0,
        settings,
        pause,
    );
    s.refresh().unwrap();
    s
}

#[test]
fn every_chain_of_every_template_fits_in_one_whole_chain_group() {
    use pygmalion::anatomy::Template;
    use pygmalion::anatomy::template::BUILTIN_TEMPLATES;
    use pygmalion::fakir::lm::{MAX_PARAMS, Param};
    use pygmalion::synth::{SynthOptions, generate};
    for name in BUILTIN_TEMPLATES {
        let t = std::sync::Arc::new(Template::builtin(name).unwrap());
        let statue = generate(
            t.clone(),
            &SynthOptions {
                points: 2_000,
                seed: 1,
                ..Default::default()
            },
        )
        .unwrap();
        let mut pause = NoPause;
        let s = solver_at(
            &statue,
            &statue.truth,
            SolverSettings::default(),
            &mut pause,
        );
        for chain in &t.chains {
            let params = s.whole_chain_params(&chain.bones);
            let params = params.unwrap_or_else(|| panic!("{name}: chain {} too long", chain.name));
            // Three per bone, and each radius class of the chain once.
            let radii: Vec<usize> = params
                .iter()
                .filter_map(|p| match p {
                    Param::Radius { bone, end } => Some(s.classes.class_of(*bone, *end)),
                    _ => None,
                })
                .collect();
            let mut classes: Vec<usize> = chain
                .bones
                .iter()
                .flat_map(|&b| {
                    use pygmalion::fakir::world::End;
                    [End::First, End::Second].map(|e| s.classes.class_of(b, e))
                })
                .collect();
            classes.sort();
            classes.dedup();
            let mut sorted = radii.clone();
            sorted.sort();
            assert_eq!(sorted, classes, "{name}: chain {}", chain.name);
            assert_eq!(params.len(), 3 * chain.bones.len() + radii.len());
            assert!(params.len() <= MAX_PARAMS);
        }
    }
}

#[test]
fn the_whole_chain_fit_settles_a_chain_whose_joints_are_all_off() {
    // The papers' chain with every bone turned 0.12 rad and 8% longer: two whole-chain fits
    // (occupancy and prior off: the data term alone) against one backward and one forward
    // pass of Algorithm 1. Measured: 6.7 → 1.2e-4 (joints within 0.0043) in 138 units,
    // against 0.62 (joints up to 26 off) in 926.
    let s = chain4(5_000, 1, 0.0, 0.0, vec![]).unwrap();
    let mut start = s.truth.clone();
    for (i, b) in start.bones.iter_mut().enumerate() {
        let axis = if i % 2 == 0 { Vec3::Y } else { Vec3::Z };
        b.rotation = (b.rotation * Quat::from_axis_angle(axis, 0.12)).normalize();
        b.length *= 1.08;
    }
    let settings = SolverSettings {
        occupancy: false,
        range_prior: false,
        ..Default::default()
    };
    let chain = [0, 1, 2, 3];
    let joint_error = |solver: &Solver| {
        let (a, b) = (solver.world.pose(), s.truth.pose());
        a.joints
            .iter()
            .zip(&b.joints)
            .map(|(x, y)| (*x - *y).length())
            .fold(0.0f32, f32::max)
    };
    let mut pause = NoPause;
    let mut whole = solver_at(&s, &start, settings.clone(), &mut pause);
    let before = whole.mean_distance();
    for _ in 0..2 {
        whole.whole_chain(&chain).unwrap();
    }
    let mut pause = NoPause;
    let mut passes = solver_at(&s, &start, settings, &mut pause);
    for reverse in [true, false] {
        pygmalion::fakir::schedule::chain_pass(&mut passes, &chain, reverse).unwrap();
    }
    let (dw, dp) = (whole.mean_distance(), passes.mean_distance());
    let (ew, ep) = (joint_error(&whole), joint_error(&passes));
    println!(
        "start {before:.3}; two whole-chain fits: {dw:.6} (joints ≤ {ew:.4}, {} units); \
         two passes: {dp:.4} (joints ≤ {ep:.3}, {} units)",
        whole.units, passes.units
    );
    assert!(dw < 1e-3, "whole chain: mean distance {dw} (length 140)");
    assert!(ew < 0.01, "whole chain: joints {ew} off");
    assert!(dp > 10.0 * dw, "two passes: {dp}");
}

/// The bit patterns of some sums (to compare them exactly).
fn bits(x: &[f64]) -> Vec<u64> {
    x.iter().map(|v| v.to_bits()).collect()
}

#[test]
fn solvers_sharing_their_points_search_structure_fit_exactly_like_solvers_building_their_own() {
    use pygmalion::fakir::solver::NearPoints;
    use std::sync::Arc;
    // The papers' chain, fitted twice from the same start: once by a solver that builds its
    // own k-d tree, grid and spacing, once by two solvers in turn sharing one `NearPoints`
    // (the level-0 solvers of a registration share theirs). The same sums, bit for bit.
    let s = chain4(3_000, 2, 0.0, 0.0, vec![]).unwrap();
    let init = papers_chain_start(&s);
    let settings = ScheduleSettings::default();
    let fit = |near: Option<Arc<NearPoints>>| {
        let world = WorldSkeleton::from_skeleton(&init);
        let asg = assignment_of(&s, 0.28);
        let mut pause = NoPause;
        let mut solver = match near {
            Some(n) => Solver::with_near(world, asg, n, 1.0, SolverSettings::default(), &mut pause),
            None => Solver::new(world, asg, 1.0, SolverSettings::default(), &mut pause),
        };
        solver.free_root = true;
        register_chain(&mut solver, &[0, 1, 2, 3], &settings).unwrap();
        (
            solver.world.pose(),
            solver.mean_distance(),
            solver.occupancy(),
            solver.spacing,
        )
    };
    let own = fit(None);
    let near = Arc::new(NearPoints::new(s.cloud.positions.clone()));
    assert_eq!(near.points(), &s.cloud.positions[..]);
    assert!(near.tree().is_some());
    assert_eq!(near.spacing.to_bits(), own.3.to_bits());
    for _ in 0..2 {
        let shared = fit(Some(near.clone()));
        assert_eq!(shared.0, own.0);
        assert_eq!(shared.1.to_bits(), own.1.to_bits());
        assert_eq!(shared.2.to_bits(), own.2.to_bits());
    }
}
