//! The FAKIR solver state and its elementary optimisations: assignment refresh, one-bone and
//! two-bone Levenberg–Marquardt rounds (thesis §2.3), the root-block fit and the bootstrap of
//! an empty bone (§2.4.1). The **work units**, after each of which [`Solver::unit`] lets the
//! caller pause (see [`super::registration`]): a slice of an assignment refresh, and the
//! members' lists rebuilt after it; an LM iteration's normal equations and its trial step,
//! each cut into slices of at most [`SLICE_POINTS`] points when its bones carry more; a group
//! of seeding candidates.

use super::assign::Assignment;
use super::lm::{
    EnergyAccumulator, EnergyTerms, Limits, LmStep, MAX_PARAMS, NO_ROW, NormalAccumulator,
    OCCUPANCY_SAMPLES, OCCUPANCY_SLACK, OccupancyTerm, PRIOR_MARGIN, Param, PointRows, RangePrior,
    Rows, SLICE_POINTS, lm_decide, lm_trial,
};
use super::world::{End, RadiusClasses, WorldSkeleton};
use crate::anatomy::template::BoneKind;
use crate::cloud::grid::NearGrid;
use crate::geometry::{Bone, PreparedBone};
use crate::math::Vec3;
use rayon::prelude::*;
use std::sync::Arc;

/// Most points one slice of an assignment refresh scans (each point also reads its whole row
/// of distances, so the slice is bounded even when few bones moved).
pub const MAX_REFRESH_SLICE: usize = 8_192;

/// Raised by a pause hook to abandon the registration.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Cancelled;

/// What the solver is doing (for progress reports).
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Activity {
    /// Phase name: "setup" (between solvers), "initialisation", "seeding", "assignment",
    /// "block", "chain", "support" (which bones the scan covers, registration level 6), "done".
    pub phase: &'static str,
    /// Chain being registered.
    pub chain: Option<String>,
    /// Outer iteration (whole-skeleton pass).
    pub iteration: usize,
    /// Pass within the chain (0 = initial forward pass).
    pub pass: usize,
    /// Resolution level (0 = subsample, 1 = all points).
    pub level: usize,
    /// Estimated share of the whole registration done, in `[0, 1]`, never decreasing (see
    /// [`Activity::span`]).
    pub fraction: f32,
    /// The share of the registration the running schedule covers: `fraction` goes from
    /// `span.0` to `span.1` as its whole-skeleton iterations and chains advance.
    pub span: (f32, f32),
}

impl Activity {
    /// Sets `fraction` to the point `t ∈ [0, 1]` of the current span (never backwards).
    pub fn advance(&mut self, t: f32) {
        let (a, b) = self.span;
        let f = a + (b - a) * t.clamp(0.0, 1.0);
        if f > self.fraction {
            self.fraction = f.min(1.0);
        }
    }
}

/// Which registration of the figure runs. [`super::register`] fits the whole figure first,
/// and on some fits registers it a second time with limbs left out from the start: a bust
/// (registration level 7, [`super::bust`]) or an armless figure (level 8, [`super::pair`]).
/// Each attempt's [`Activity::fraction`] runs from 0 to 1 on its own.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Attempt {
    /// The whole figure (the only attempt of most registrations).
    #[default]
    Whole,
    /// Again without the four limbs (a bust's hypothesis).
    Bust,
    /// Again without a lost upper arm or thigh and its mirror (a Venus' hypothesis).
    Pair,
    /// Again without a lost forearm or shin and its mirror, one bone down
    /// ([`super::pair::Level::Below`]): a Venus whose whole fit kept one arm.
    PairBelow,
    /// Again with one more bone of a limb lost ([`super::broken`]): a limb broken part-way
    /// whose fit curled the bones below the break.
    Broken,
    /// Once more, from the broken-limb fit's better placement, nothing lost from the start
    /// ([`super::broken::Hypothesis::again`]).
    BrokenAgain,
}

impl Attempt {
    /// A short name for progress lines: "whole", "bust", "pair", "pair below", "broken limb",
    /// "broken limb, again".
    pub fn name(self) -> &'static str {
        match self {
            Attempt::Whole => "whole",
            Attempt::Bust => "bust",
            Attempt::Pair => "pair",
            Attempt::PairBelow => "pair below",
            Attempt::Broken => "broken limb",
            Attempt::BrokenAgain => "broken limb, again",
        }
    }
}

/// Called after every work unit; returning `Err(Cancelled)` stops the registration.
pub trait Pause {
    /// Called before each registration of the figure but the first ([`Attempt`]): the
    /// solvers' progress fraction starts again from 0. Hooks that publish progress say so.
    fn attempt(&mut self, _attempt: Attempt) {}

    /// `solver`: the solver whose unit ended, or `None` for a unit of set-up work between
    /// solvers (placing the candidates, starting a level). Its skeleton and distances are in
    /// the registration's working units ([`super::frame`]), not necessarily the cloud's.
    fn unit(&mut self, solver: Option<&Solver>) -> Result<(), Cancelled>;

    /// True when the hook never pauses, never cancels and reads nothing: the registration may
    /// then run independent solvers at the same time, each with a [`NoPause`] of its own
    /// (the finalists, the scale restarts, the starts of a refit round), and compute exactly
    /// what it computes one solver after the other.
    fn never_pauses(&self) -> bool {
        false
    }
}

/// A pause hook that never pauses.
pub struct NoPause;
impl Pause for NoPause {
    fn unit(&mut self, _: Option<&Solver>) -> Result<(), Cancelled> {
        Ok(())
    }

    fn never_pauses(&self) -> bool {
        true
    }
}

/// Iteration counts and tolerances of the solver.
#[derive(Clone, Debug, PartialEq)]
pub struct SolverSettings {
    /// LM iterations per parameter group and round.
    pub lm_iterations: usize,
    /// Rounds (LM groups + assignment refresh) of a one-bone fit.
    pub one_bone_rounds: usize,
    /// Rounds of a two-bone fit.
    pub two_bone_rounds: usize,
    /// Relative energy decrease under which an LM loop stops.
    pub lm_tolerance: f64,
    /// Projections per slice of an assignment refresh (points × bones refreshed; 20,000: at
    /// most 1.5 ms on this 2-core machine, `bench --only fakir/unit_100k`).
    pub refresh_budget: usize,
    /// Add the occupancy term (model → data, [`super::lm::OccupancyTerm`]) to every fit.
    pub occupancy: bool,
    /// Add the joint-range prior ([`super::lm::RangePrior`]) to every fit.
    pub range_prior: bool,
    /// Seed each limb chain's directions before its initial pass ([`Solver::seed_chain`]).
    pub seed_chains: bool,
    /// A pass over an energy's points at the state of the last pass reads that pass's
    /// residuals and gradients instead of projecting again (`RowCache`). The same sums bit for
    /// bit either way (a test registers with and without).
    pub reuse_rows: bool,
    /// Before each of Algorithm 1's forward or backward passes on a template of one chain
    /// and no root block, fit the whole chain at once ([`Solver::whole_chain`]; see
    /// [`super::schedule`]).
    pub whole_chain: bool,
}

impl Default for SolverSettings {
    fn default() -> Self {
        SolverSettings {
            lm_iterations: 10,
            one_bone_rounds: 4,
            two_bone_rounds: 4,
            lm_tolerance: 1e-6,
            refresh_budget: 20_000,
            occupancy: true,
            seed_chains: true,
            range_prior: true,
            reuse_rows: true,
            whole_chain: true,
        }
    }
}

/// The solver state: skeleton, assignment and bookkeeping.
pub struct Solver<'p> {
    pub world: WorldSkeleton,
    pub classes: RadiusClasses,
    pub limits: Limits,
    /// Tighter length bounds used while `calibrating`.
    pub calibration_limits: Limits,
    /// True during a chain's initial forward pass (Algorithm 1, lines 1–10).
    pub calibrating: bool,
    pub assignment: Assignment,
    /// Points of each bone (indices into the assignment).
    pub members: Vec<Vec<u32>>,
    /// Statue scale (template units → statue units).
    pub scale: f32,
    /// Size of the statue (length units): the scaled template's extent.
    pub size: f32,
    pub settings: SolverSettings,
    pub activity: Activity,
    /// Work units done.
    pub units: u64,
    /// Bones as of the last assignment refresh.
    assigned_bones: Vec<Bone>,
    /// The points the solver started with, searchable ([`NearPoints`]; shared by the
    /// solvers of one registration's level 0).
    near: Arc<NearPoints>,
    /// Median distance between a point and its nearest neighbour (sampled; `near`'s).
    pub spacing: f32,
    /// Anchor of the root may move (chains whose first joint is free, e.g. the papers' chain).
    pub free_root: bool,
    /// The template's trunk bones ([`trunk_bones`]), which carry the occupancy term.
    trunk: Vec<bool>,
    /// Bones of a limb the statue has lost ([`Solver::set_absent`]): they take no points and
    /// the schedule does not fit them.
    pub absent: Vec<bool>,
    /// The rows of the last pass over an energy's members, for the next pass at the same
    /// state ([`RowCache`]).
    rows: RowCache,
    /// Room for the rows of a pass under way.
    scratch: PointRows,
    /// Changes whenever the members change (a refresh, the absent bones, a new assignment).
    epoch: u64,
    pause: Option<&'p mut dyn Pause>,
}

/// The [`PointRows`] of the last pass over the members of an energy's bones, and the state
/// they belong to: which bones, their geometry, and the members' epoch. A pass at the same
/// state reads them instead of projecting (`reuse_rows`): the LM loop's next parameter group
/// starts where the last one ended, and a round's first group where the round's energy was
/// summed.
#[derive(Default)]
struct RowCache {
    bones: Vec<usize>,
    geometry: Vec<Bone>,
    epoch: u64,
    rows: PointRows,
    valid: bool,
}

/// A pass under way ([`Solver::begin_pass`]): it reads `cached` (`fits`) or writes `room`
/// (`write`), or neither (rows not reused).
struct Pass {
    fits: bool,
    write: bool,
    was_valid: bool,
    cached: PointRows,
    room: PointRows,
}

impl Pass {
    /// Where the pass's next slice reads or writes its rows.
    fn rows(&mut self) -> Rows<'_> {
        Rows {
            read: self.fits.then_some(&self.cached[..]),
            write: self.write.then_some(&mut self.room[..]),
        }
    }
}

impl<'p> Solver<'p> {
    /// A solver for `world` on the points of `assignment` (distances not yet computed).
    pub fn new(
        world: WorldSkeleton,
        assignment: Assignment,
        scale: f32,
        settings: SolverSettings,
        pause: &'p mut dyn Pause,
    ) -> Self {
        let near = Arc::new(NearPoints::new(assignment.positions.clone()));
        Self::with_near(world, assignment, near, scale, settings, pause)
    }

    /// [`Solver::new`] with the searchable points `near` already built (they must be
    /// `assignment`'s positions): the solvers started on the same points share them, and
    /// their start is not a search structure's build.
    pub fn with_near(
        world: WorldSkeleton,
        assignment: Assignment,
        near: Arc<NearPoints>,
        scale: f32,
        settings: SolverSettings,
        pause: &'p mut dyn Pause,
    ) -> Self {
        debug_assert_eq!(near.points.len(), assignment.positions.len());
        let classes = RadiusClasses::new(&world.template);
        let trunk = trunk_bones(&world.template);
        let limits = Limits::new(&world, scale);
        let calibration_limits = Limits::with_length_range(&world, scale, 0.75, 1.33);
        let n = world.template.bones.len();
        let size = scale * template_extent(&world.template);
        let spacing = near.spacing;
        Solver {
            size,
            classes,
            limits,
            calibration_limits,
            calibrating: false,
            members: vec![Vec::new(); n],
            assigned_bones: vec![
                Bone::new(Vec3::splat(f32::NAN), 0.0, Vec3::splat(f32::NAN), 0.0);
                n
            ],
            world,
            assignment,
            scale,
            settings,
            activity: Activity::default(),
            units: 0,
            free_root: false,
            trunk,
            absent: vec![false; n],
            near,
            spacing,
            rows: RowCache::default(),
            scratch: Vec::new(),
            epoch: 0,
            pause: Some(pause),
        }
    }

    /// Marks the bones of lost limbs (`absent[b]`): the assignment stops giving them points
    /// (every point is relabelled, in slices of at most [`MAX_REFRESH_SLICE`] points, one work
    /// unit each) and the schedule leaves them where they are
    /// ([`Solver::present_prefix`]).
    pub fn set_absent(&mut self, absent: &[bool]) -> Result<(), Cancelled> {
        self.start_absent(absent);
        let n = self.assignment.len();
        for start in (0..n).step_by(MAX_REFRESH_SLICE) {
            self.assignment
                .relabel(start..(start + MAX_REFRESH_SLICE).min(n));
            self.unit()?;
        }
        self.rebuild_members();
        Ok(())
    }

    /// Rebuilds each bone's members from the labels; the rows cached for the old members
    /// no longer fit (the epoch moves on).
    fn rebuild_members(&mut self) {
        self.assignment.members_into(&mut self.members);
        self.epoch += 1;
    }

    /// [`Solver::set_absent`] for a solver whose distances are not computed yet (the first
    /// refresh labels every point): no work unit.
    pub fn start_absent(&mut self, absent: &[bool]) {
        self.absent = absent.to_vec();
        self.enable_present();
    }

    /// Lets the assignment give points to the present bones only.
    fn enable_present(&mut self) {
        for (b, &lost) in self.absent.iter().enumerate() {
            self.assignment.enabled[b] = !lost;
        }
    }

    /// What the points of bone `b`'s subtree would lose if the subtree were gone: the mean, over at most
    /// [`EXCESS_POINTS`] of its points (a fixed stride), of how much farther each lies from
    /// the nearest other bone (normal-constrained distance, lost bones excluded) than from
    /// its own. `None` when the subtree holds no point. A limb bone that FAKIR laid over
    /// another part — the hand of a forearm cut at the wrist folded back onto the upper arm —
    /// costs almost nothing to remove; a real limb costs about its own thickness.
    pub fn removal_excess(&self, b: usize, lost: &[bool]) -> Option<f64> {
        self.removal_excess_with(b, lost, None)
    }

    /// [`Solver::removal_excess`] with one other bone replaced (`(index, bone)`): what the
    /// subtree's points would lose if it were gone and that bone were this one.
    pub fn removal_excess_with(
        &self,
        b: usize,
        lost: &[bool],
        replaced: Option<(usize, Bone)>,
    ) -> Option<f64> {
        let t = &self.world.template;
        let gone: Vec<usize> = t.subtree(b);
        let mut members: Vec<u32> = gone
            .iter()
            .flat_map(|&x| self.members[x].iter().copied())
            .collect();
        if members.is_empty() {
            return None;
        }
        members.sort_unstable();
        let stride = members.len().div_ceil(EXCESS_POINTS).max(1);
        let bones = self.world.bones();
        let others: Vec<PreparedBone> = (0..bones.len())
            .filter(|x| !gone.contains(x) && !lost[*x])
            .map(|x| match replaced {
                Some((q, bone)) if q == x => bone.prepare(),
                _ => bones[x].prepare(),
            })
            .collect();
        if others.is_empty() {
            return None;
        }
        let a = &self.assignment;
        let sample: Vec<u32> = members.into_iter().step_by(stride).collect();
        let excess: f64 = sample
            .par_chunks(256)
            .map(|chunk| {
                chunk
                    .iter()
                    .map(|&i| {
                        let i = i as usize;
                        let (p, n) = (a.positions[i], a.normals[i]);
                        let near = others
                            .iter()
                            .map(|o| o.project_constrained(p, n).distance)
                            .fold(f32::INFINITY, f32::min);
                        (near - a.own_distance(i)).max(0.0) as f64
                    })
                    .sum::<f64>()
            })
            .collect::<Vec<f64>>()
            .iter()
            .sum();
        Some(excess / sample.len() as f64)
    }

    /// The bones of `chain` up to its first absent bone (a lost limb ends where it broke).
    pub fn present_prefix<'c>(&self, chain: &'c [usize]) -> &'c [usize] {
        let end = chain
            .iter()
            .position(|&b| self.absent[b])
            .unwrap_or(chain.len());
        &chain[..end]
    }

    /// Marks the end of a work unit and lets the pause hook act.
    pub fn unit(&mut self) -> Result<(), Cancelled> {
        self.units += 1;
        // The hook reads the solver: take it out while it runs.
        let Some(pause) = self.pause.take() else {
            return Ok(());
        };
        let r = pause.unit(Some(self));
        self.pause = Some(pause);
        r
    }

    /// Takes the pause hook out of the solver (its units then never pause), so the caller can
    /// run other solvers with it and keep this one, assignment and cached distances included
    /// (the registration's refits); [`Solver::give_pause`] puts it back.
    pub fn take_pause(&mut self) -> Option<&'p mut dyn Pause> {
        self.pause.take()
    }

    /// Puts back a pause hook taken by [`Solver::take_pause`].
    pub fn give_pause(&mut self, pause: &'p mut dyn Pause) {
        self.pause = Some(pause);
    }

    /// Replaces the assignment (e.g. moving to all points) and forgets cached distances; absent
    /// bones stay absent.
    pub fn set_assignment(&mut self, a: Assignment) {
        self.assignment = a;
        self.epoch += 1;
        self.enable_present();
        let n = self.world.template.bones.len();
        self.assigned_bones =
            vec![Bone::new(Vec3::splat(f32::NAN), 0.0, Vec3::splat(f32::NAN), 0.0); n];
    }

    /// Recomputes the distances to the bones that moved since the last refresh and the labels,
    /// in slices of bounded work.
    pub fn refresh(&mut self) -> Result<(), Cancelled> {
        let bones = self.world.bones();
        let moved: Vec<usize> = (0..bones.len())
            .filter(|&b| bones[b] != self.assigned_bones[b])
            .collect();
        if moved.is_empty() {
            return Ok(());
        }
        let prepared: Vec<PreparedBone> = bones.iter().map(|b| b.prepare()).collect();
        let n = self.assignment.len();
        // Bounded work per slice: projections (budget / bones moved) and rows scanned.
        let slice =
            (self.settings.refresh_budget / moved.len().max(1)).clamp(512, MAX_REFRESH_SLICE);
        let mut start = 0;
        let prev_phase = self.activity.phase;
        self.activity.phase = "assignment";
        while start < n {
            let end = (start + slice).min(n);
            self.assignment.update(&prepared, &moved, start..end);
            start = end;
            self.unit()?;
        }
        self.assigned_bones = bones;
        self.rebuild_members();
        // The members' lists are a pass over every point: a unit of their own, so the unit
        // after the refresh starts with them built.
        self.unit()?;
        self.activity.phase = prev_phase;
        Ok(())
    }

    /// Mean distance of the assigned points to their bones (thesis eq. 2.16), as of the last
    /// refresh (0 with no point). Before the first refresh of its assignment (a solver just
    /// started, or given a new assignment by [`Solver::set_assignment`]) every distance is
    /// infinite, and so is this.
    pub fn mean_distance(&self) -> f64 {
        self.assignment.mean_distance()
    }

    /// The bone plus the followers that move with it (their points join its energy).
    pub fn with_followers(&self, b: usize) -> Vec<usize> {
        let mut v = vec![b];
        for (i, def) in self.world.template.bones.iter().enumerate() {
            if matches!(def.kind, BoneKind::Follower { leader, .. } if leader == b) {
                v.push(i);
            }
        }
        v
    }

    /// The bones of `chain` and their followers (a chain's energy).
    pub fn chain_with_followers(&self, chain: &[usize]) -> Vec<usize> {
        chain.iter().flat_map(|&b| self.with_followers(b)).collect()
    }

    /// Runs LM iterations of `params` on the energy of `energy_bones` (their points, plus the
    /// occupancy of their surface when enabled) until they stop improving; returns the final
    /// energy.
    pub fn lm(
        &mut self,
        params: &[Param],
        energy_bones: &[usize],
        clamp_bones: &[usize],
    ) -> Result<f64, Cancelled> {
        let mut lambda = 0.01f64;
        let mut last = f64::INFINITY;
        let mut normal_eq = None;
        // Occupancy weights (see `OccupancyTerm`), fixed for this LM loop.
        // Which bones carry the occupancy term: see `OccupancyTerm`.
        let t = self.world.template.clone();
        let occupied: Vec<usize> = energy_bones
            .iter()
            .copied()
            .filter(|&b| {
                self.trunk[b]
                    || t.bones[b].children.is_empty()
                    || (self.free_root && t.bones[b].parent.is_none())
            })
            .collect();
        let weights: Vec<f64> = {
            let bones = self.world.bones();
            let total_area: f64 = bones.iter().map(|b| b.area() as f64).sum();
            let density = self.assignment.len() as f64 / total_area.max(1e-30);
            occupied
                .iter()
                .map(|&b| {
                    (density * bones[b].area() as f64 / OCCUPANCY_SAMPLES as f64)
                        .max(1.0)
                        .sqrt()
                })
                .collect()
        };
        let prior = self.settings.range_prior.then(|| {
            let bones = self.world.bones();
            let total_area: f64 = bones.iter().map(|b| b.area() as f64).sum();
            let density = self.assignment.len() as f64 / total_area.max(1e-30);
            RangePrior {
                bones: energy_bones
                    .iter()
                    .filter(|&&b| {
                        let d = &t.bones[b];
                        d.kind == BoneKind::Free && (d.bend.is_some() || d.swing_deg > 0.0)
                    })
                    .map(|&b| {
                        let n = density * bones[b].area() as f64;
                        (b, n.sqrt() * 0.5 * (bones[b].r1 + bones[b].r2) as f64)
                    })
                    .collect(),
                margin: PRIOR_MARGIN,
                ratios: {
                    let mut r: Vec<(usize, usize, f32, f64)> = Vec::new();
                    let weight = |b: usize| {
                        let n = density * bones[b].area() as f64;
                        n.sqrt() * 0.5 * (bones[b].r1 + bones[b].r2) as f64
                    };
                    for &b in energy_bones {
                        if let Some((prev, ratio)) = self.limits.prev_ratio[b] {
                            r.push((b, prev, ratio, weight(b)));
                        }
                        for (n, pr) in self.limits.prev_ratio.iter().enumerate() {
                            if let Some((prev, ratio)) = pr
                                && *prev == b
                                && !r.iter().any(|x| x.0 == n)
                            {
                                r.push((n, b, *ratio, weight(n)));
                            }
                        }
                    }
                    r
                },
            }
        });
        // The energy terms borrow the solver, which a work unit needs whole: they are built
        // afresh around each unit (references only, no allocation).
        macro_rules! terms {
            () => {
                EnergyTerms {
                    assignment: &self.assignment,
                    members: &self.members,
                    bones: energy_bones,
                    occupancy: match (
                        &self.near.tree,
                        self.settings.occupancy && !self.calibrating && !occupied.is_empty(),
                    ) {
                        (Some(tree), true) => Some(OccupancyTerm {
                            bones: &occupied,
                            weights: &weights,
                            tree,
                            grid: self.near.grid.as_ref(),
                            positions: &self.near.points,
                            slack: OCCUPANCY_SLACK * self.spacing,
                        }),
                        _ => None,
                    },
                    prior: prior.as_ref(),
                }
            };
        }
        for _ in 0..self.settings.lm_iterations {
            // The normal equations and the trial's energy are sums over the points of the
            // energy's bones: each is cut into work units of at most `SLICE_POINTS` points (the
            // kiosk's frames are cut at unit boundaries; a 100k-point level 1 gives a bone pair
            // tens of thousands of points).
            if normal_eq.is_none() {
                let mut acc = {
                    let terms = terms!();
                    if terms.count() == 0 && terms.occupancy.is_none() {
                        return Ok(0.0);
                    }
                    NormalAccumulator::new(&self.world, &self.classes, params, &terms, self.size)
                };
                let geometry = self.world.bones();
                let mut pass = self.begin_pass(energy_bones, &geometry);
                while !acc.feed_rows(&terms!(), SLICE_POINTS, &mut pass.rows()) {
                    self.unit()?;
                }
                self.end_pass(pass, Some((energy_bones, geometry)));
                normal_eq = Some(acc.finish(&self.world, &terms!()));
                self.unit()?;
            }
            let ne = normal_eq.as_ref().expect("normal equations just summed");
            let energy_before = ne.energy;
            let limits = if self.calibrating {
                &self.calibration_limits
            } else {
                &self.limits
            };
            let trial = lm_trial(
                &self.world,
                &self.classes,
                limits,
                params,
                ne,
                &mut lambda,
                clamp_bones,
            );
            let step = match trial {
                // The trial's pass keeps its rows: accepted, the next normal equations read
                // them instead of projecting again.
                Some((trial, norm)) => {
                    let geometry = trial.bones();
                    let mut acc = EnergyAccumulator::new(geometry.clone());
                    let mut pass = self.begin_pass(energy_bones, &geometry);
                    while !acc.feed_rows(&terms!(), SLICE_POINTS, &mut pass.rows()) {
                        self.unit()?;
                    }
                    let after = acc.finish(&terms!(), &trial);
                    let step = lm_decide(
                        &mut self.world,
                        trial,
                        norm,
                        after,
                        &mut lambda,
                        &mut normal_eq,
                    );
                    self.end_pass(pass, step.accepted.then_some((energy_bones, geometry)));
                    step
                }
                // A singular system: a rejected step.
                None => LmStep {
                    energy_before,
                    energy_after: energy_before,
                    accepted: false,
                    step_norm: 0.0,
                },
            };
            self.unit()?;
            last = step.energy_after;
            if step.accepted {
                let rel = (step.energy_before - step.energy_after) / step.energy_before.max(1e-30);
                if rel < self.settings.lm_tolerance {
                    break;
                }
            } else if lambda > 1e6 {
                break;
            }
        }
        Ok(last)
    }

    /// Two unit axes orthogonal to bone `b`.
    fn swing_axes(&self, b: usize) -> (Vec3, Vec3) {
        let f = self.world.frames[b];
        (f * Vec3::Y, f * Vec3::Z)
    }

    /// One-bone fit (thesis §2.3.1): rotation about the fixed joint (two angles), length, and
    /// the free radius, in turn, with an assignment refresh after each round. `free` is the
    /// free end (`Second`: pivot at `c1`, descendants follow). `both_radii` also frees the
    /// radius at the pivot (first bone of a chain).
    pub fn one_bone(&mut self, b: usize, free: End, both_radii: bool) -> Result<(), Cancelled> {
        let energy = self.with_followers(b);
        if free == End::Second && self.members_of(&energy) == 0 && self.is_lost(b) {
            self.bootstrap(b)?;
        }

        // Each round starts from the energy the last one ended with (same state, same
        // assignment).
        let mut start = None;
        for _ in 0..self.settings.one_bone_rounds {
            let before = match start {
                Some(e) => e,
                None => self.energy_of(&energy)?,
            };
            match free {
                End::Second => {
                    let (a1, a2) = self.swing_axes(b);
                    self.lm(
                        &[
                            Param::Swing { bone: b, axis: a1 },
                            Param::Swing { bone: b, axis: a2 },
                        ],
                        &energy,
                        &[b],
                    )?;
                    self.lm(&[Param::Length { bone: b }], &energy, &[b])?;
                }
                End::First => {
                    // Free first joint: only a bone leaving a free root can move it.
                    if !self.first_end_free(b) {
                        break;
                    }
                    let axes =
                        [Vec3::X, Vec3::Y, Vec3::Z].map(|axis| Param::AnchorMove { bone: b, axis });
                    self.lm(&axes, &energy, &[b])?;
                }
            }
            self.lm(&[Param::Radius { bone: b, end: free }], &energy, &[b])?;
            if both_radii {
                let other = if free == End::Second {
                    End::First
                } else {
                    End::Second
                };
                self.lm(
                    &[Param::Radius {
                        bone: b,
                        end: other,
                    }],
                    &energy,
                    &[b],
                )?;
            }
            match self.end_round(&energy, before)? {
                None => break,
                after => start = after,
            }
        }
        Ok(())
    }

    /// Ends a round of a fit: refreshes the assignment; `None` when the energy of `bones`
    /// changed by less than 1e-4 (relative) since `before`, else the energy the next round
    /// starts from.
    fn end_round(&mut self, bones: &[usize], before: f64) -> Result<Option<f64>, Cancelled> {
        self.refresh()?;
        let after = self.energy_of(bones)?;
        let settled = (before - after).abs() <= 1e-4 * before.max(1e-30);
        Ok((!settled).then_some(after))
    }

    /// Two-bone fit of the joint between `a` and its chain successor `b` (thesis §2.3.2): the
    /// rotation about the axis through the outer joints, the two lengths and the shared radius,
    /// in turn, with an assignment refresh after each round.
    pub fn two_bone(&mut self, a: usize, b: usize) -> Result<(), Cancelled> {
        let mut energy = self.with_followers(a);
        energy.push(b);
        let clamp = [a, b];
        self.fit_rounds(&energy, |s| {
            s.lm(&[Param::PairRotate { a, b }], &energy, &clamp)?;
            s.lm(&[Param::PairLength { a, b, first: true }], &energy, &clamp)?;
            s.lm(&[Param::PairLength { a, b, first: false }], &energy, &clamp)?;
            s.lm(
                &[Param::Radius {
                    bone: a,
                    end: End::Second,
                }],
                &energy,
                &clamp,
            )?;
            Ok(())
        })
    }

    /// Rounds of a fit on the points of `energy` (at most `two_bone_rounds`): `round`'s LM
    /// groups, then an assignment refresh; they end when a round changes the energy by under
    /// 10⁻⁴ (relative, [`Solver::end_round`]) or no point is left.
    fn fit_rounds(
        &mut self,
        energy: &[usize],
        mut round: impl FnMut(&mut Self) -> Result<(), Cancelled>,
    ) -> Result<(), Cancelled> {
        let mut start = None;
        for _ in 0..self.settings.two_bone_rounds {
            if self.members_of(energy) == 0 {
                break;
            }
            let before = match start {
                Some(e) => e,
                None => self.energy_of(energy)?,
            };
            round(self)?;
            match self.end_round(energy, before)? {
                None => break,
                after => start = after,
            }
        }
        Ok(())
    }

    /// The parameters of [`Solver::whole_chain`] on `chain`: each bone's two swings about its
    /// first joint and its length, every radius class of the chain once, and the anchor's
    /// translation when it is a free root. `None` past [`MAX_PARAMS`].
    pub fn whole_chain_params(&self, chain: &[usize]) -> Option<Vec<Param>> {
        let t = &self.world.template;
        let mut params = Vec::new();
        let first = *chain.first()?;
        if self.free_root && t.bones[first].parent.is_none() {
            params.extend(
                [Vec3::X, Vec3::Y, Vec3::Z].map(|axis| Param::AnchorMove { bone: first, axis }),
            );
        }
        let mut classes = Vec::new();
        for &b in chain {
            let (a1, a2) = self.swing_axes(b);
            params.push(Param::Swing { bone: b, axis: a1 });
            params.push(Param::Swing { bone: b, axis: a2 });
            params.push(Param::Length { bone: b });
            for end in [End::First, End::Second] {
                let c = self.classes.class_of(b, end);
                if !classes.contains(&c) {
                    classes.push(c);
                    params.push(Param::Radius { bone: b, end });
                }
            }
        }
        (params.len() <= MAX_PARAMS).then_some(params)
    }

    /// **Whole-chain fit** (our addition, for speed; the papers fit one bone or one pair at a
    /// time): one LM group over every parameter of `chain` at once
    /// ([`Solver::whole_chain_params`]) on the energy of the chain's points (bones and
    /// followers), with an assignment refresh after each round (at most `two_bone_rounds`,
    /// ending when a round changes the energy by under 10⁻⁴); why and where it runs: step 4
    /// of [`super::schedule`]. A chain of more than [`MAX_PARAMS`] parameters is left as it
    /// is.
    pub fn whole_chain(&mut self, chain: &[usize]) -> Result<(), Cancelled> {
        let Some(params) = self.whole_chain_params(chain) else {
            return Ok(());
        };
        let energy = self.chain_with_followers(chain);
        self.fit_rounds(&energy, |s| s.lm(&params, &energy, chain).map(|_| ()))
    }

    /// Fit of the root block (position, orientation, common scale) on the points of the block
    /// bones and of the bones attached to them (the first bones of the spine and the legs, whose
    /// directions are what pins the block's orientation); the rest of the skeleton follows
    /// rigidly.
    pub fn block(&mut self) -> Result<(), Cancelled> {
        let t = self.world.template.clone();
        let block: Vec<usize> = t.block_bones().collect();
        if block.is_empty() {
            return Ok(());
        }
        let mut energy = block.clone();
        for &b in &block {
            energy.extend(t.bones[b].children.iter().copied());
        }
        let prev = self.activity.phase;
        self.activity.phase = "block";
        let params = [
            Param::RootMove { axis: Vec3::X },
            Param::RootMove { axis: Vec3::Y },
            Param::RootMove { axis: Vec3::Z },
            Param::RootRotate { axis: Vec3::X },
            Param::RootRotate { axis: Vec3::Y },
            Param::RootRotate { axis: Vec3::Z },
            Param::BlockScale,
        ];
        for _ in 0..2 {
            self.lm(&params, &energy, &[])?;
            self.refresh()?;
        }
        self.activity.phase = prev;
        Ok(())
    }

    /// Number of points in the energy of `bones`.
    pub fn members_of(&self, bones: &[usize]) -> usize {
        bones.iter().map(|&b| self.members[b].len()).sum()
    }

    /// Current energy of `bones`' points (assignment fixed), summed in work units of at most
    /// [`SLICE_POINTS`] points.
    pub fn energy_of(&mut self, bones: &[usize]) -> Result<f64, Cancelled> {
        let geometry = self.world.bones();
        let mut acc = EnergyAccumulator::new(geometry.clone());
        let mut pass = self.begin_pass(bones, &geometry);
        loop {
            let terms = EnergyTerms {
                assignment: &self.assignment,
                members: &self.members,
                bones,
                occupancy: None,
                prior: None,
            };
            if acc.feed_rows(&terms, SLICE_POINTS, &mut pass.rows()) {
                self.end_pass(pass, Some((bones, geometry)));
                return Ok(acc.data);
            }
            self.unit()?;
        }
    }

    /// Starts a pass over the members of `bones` at the state whose bones are `geometry`:
    /// it reads the cached rows when they are this state's, else it writes its own (when
    /// rows are reused). The cache is out of the solver until [`Solver::end_pass`].
    fn begin_pass(&mut self, bones: &[usize], geometry: &[Bone]) -> Pass {
        let reuse = self.settings.reuse_rows;
        let c = &self.rows;
        let fits = reuse
            && c.valid
            && c.epoch == self.epoch
            && c.bones == bones
            && bones
                .iter()
                .all(|&b| c.geometry.get(b) == Some(&geometry[b]));
        let was_valid = std::mem::replace(&mut self.rows.valid, false);
        let cached = std::mem::take(&mut self.rows.rows);
        let mut room = std::mem::take(&mut self.scratch);
        let write = reuse && !fits;
        if write {
            let count = bones.iter().map(|&b| self.members[b].len()).sum();
            room.clear();
            room.resize(count, NO_ROW);
        }
        Pass {
            fits,
            write,
            was_valid,
            cached,
            room,
        }
    }

    /// Ends a pass: with `adopt` (the bones and geometry of the pass's state, when that state
    /// is now the solver's), the rows it wrote become the cache; otherwise the cache stays.
    fn end_pass(&mut self, pass: Pass, adopt: Option<(&[usize], Vec<Bone>)>) {
        match adopt {
            Some((bones, geometry)) if pass.write => {
                self.rows = RowCache {
                    bones: bones.to_vec(),
                    geometry,
                    epoch: self.epoch,
                    rows: pass.room,
                    valid: true,
                };
                self.scratch = pass.cached;
            }
            _ => {
                self.rows.rows = pass.cached;
                self.rows.valid = pass.was_valid;
                self.scratch = pass.room;
            }
        }
    }

    /// Model → data term: mean of `max(0, |s − q| − spacing)` over samples `s` of the bones'
    /// visible surface (outside every other bone), `q` the nearest data point. Zero when every
    /// part of the model lies on the data; large when bones stick out into empty space. With
    /// the mean distance (data → model) it makes a two-sided fit measure.
    pub fn occupancy(&self) -> f64 {
        let Some(tree) = &self.near.tree else {
            return 0.0;
        };
        let bones = self.world.bones();
        let prepared: Vec<PreparedBone> = bones.iter().map(|b| b.prepare()).collect();
        let mut rng = crate::rng::Rng::new(0x0ccu64);
        let total_area: f32 = prepared
            .iter()
            .map(|b| b.part_areas().iter().sum::<f32>())
            .sum();
        let samples = 1500usize;
        let (mut sum, mut count) = (0.0f64, 0usize);
        for (x, pb) in prepared.iter().enumerate() {
            let area: f32 = pb.part_areas().iter().sum();
            let k = ((samples as f32 * area / total_area.max(1e-30)).ceil() as usize).max(4);
            for _ in 0..k {
                let (sp, _) = pb.sample_surface(&mut rng);
                if prepared
                    .iter()
                    .enumerate()
                    .any(|(o, q)| o != x && q.sdf_fast(sp) < 0.0)
                {
                    continue;
                }
                count += 1;
                // Nearer than the spacing: the term is zero (the grid's "yes" is exact).
                if self
                    .near
                    .grid
                    .as_ref()
                    .is_some_and(|g| g.within_below(sp, self.spacing))
                {
                    continue;
                }
                let nn = tree
                    .query(&sp.to_array())
                    .nearest_one::<kiddo::SquaredEuclidean<f32>>()
                    .execute();
                sum += (nn.distance.sqrt() - self.spacing).max(0.0) as f64;
            }
        }
        if count == 0 { 0.0 } else { sum / count as f64 }
    }

    /// Whether the one-bone fit may move bone `b`'s first joint: only a bone leaving a free
    /// root (the papers' chain experiment) can; every other first joint is held by its
    /// parent or by the root block.
    pub fn first_end_free(&self, b: usize) -> bool {
        self.free_root && self.world.template.bones[b].parent.is_none()
    }

    /// Whether bone `b` lies in empty space: fewer than a quarter of the samples of its
    /// visible surface (outside every other bone) have a data point within
    /// `3 × spacing + r/2` (`r` the bone's smaller radius). A bone hidden inside its
    /// neighbours (a short spine bone between the pelvis and the thorax) has no visible
    /// surface and is not lost, even when its `P_k` is empty.
    pub fn is_lost(&self, b: usize) -> bool {
        let Some(tree) = &self.near.tree else {
            return false;
        };
        let bones = self.world.bones();
        let prepared: Vec<PreparedBone> = bones.iter().map(|x| x.prepare()).collect();
        let limit = 3.0 * self.spacing + 0.5 * bones[b].r1.min(bones[b].r2);
        let mut rng = crate::rng::Rng::new(0x1057 ^ b as u64);
        let (mut visible, mut near) = (0usize, 0usize);
        for _ in 0..64 {
            let (sp, _) = prepared[b].sample_surface(&mut rng);
            if prepared
                .iter()
                .enumerate()
                .any(|(o, q)| o != b && q.sdf_fast(sp) < 0.0)
            {
                continue;
            }
            visible += 1;
            let nn = tree
                .query(&sp.to_array())
                .nearest_one::<kiddo::SquaredEuclidean<f32>>()
                .execute();
            if nn.distance.sqrt() <= limit {
                near += 1;
            }
        }
        visible > 0 && 4 * near < visible
    }

    /// Bootstrap of a lost bone (§2.4.1: "rotated around the three axes until some input
    /// points are projected onto it"): the bone is re-aimed by the chain seeding
    /// ([`Solver::seed_chain`]) with every bone outside its subtree trusted, so it turns
    /// towards points that nothing else explains. It keeps its direction when no direction
    /// does better (a missing limb).
    pub fn bootstrap(&mut self, b: usize) -> Result<(), Cancelled> {
        let t = self.world.template.clone();
        let mut trusted = vec![true; t.bones.len()];
        for x in t.subtree(b) {
            trusted[x] = false;
        }
        self.seed_chain(&[b], &trusted)
    }
}

/// Points of a subtree that [`Solver::removal_excess`] examines.
pub const EXCESS_POINTS: usize = 2048;

/// Points a chain's seeding scores (a fixed stride over the assignment).
pub const SEED_POINTS: usize = 1500;
/// Candidate directions of a bone's seeding (plus its current direction).
pub const SEED_DIRECTIONS: usize = 64;
/// How far (radians) a seeded direction may leave the bone's joint range (the template's
/// `bend`/`swing`, which shape the generator's poses), so statue poses beyond the
/// generator's ranges stay reachable while a left arm cannot be seeded onto the right one
/// (45°).
pub const SEED_RANGE_MARGIN: f32 = std::f32::consts::FRAC_PI_4;
/// Weight of the seeding's prior towards the rest direction: turning a limb around costs
/// this fraction of what the limb would gain by covering points at full distance, so
/// directions the data cannot tell apart (a forearm against the chest, folded inside the
/// upper arm or lying on the ribs) keep the template's.
pub const SEED_PRIOR: f32 = 0.05;
/// Lengths tried for each seeded direction (× the bone's current length): proportions vary
/// by ±30% between statues, and a knee seeded at the wrong distance sends the shin astray.
pub const SEED_LENGTHS: [f32; 3] = [0.8, 1.0, 1.25];
/// Directions whose candidates (each at the [`SEED_LENGTHS`]) one work unit of the seeding
/// evaluates: two (six candidates). Four made units of 1.6–2.1 ms on a 100k-point statue
/// (`bench --only fakir/unit_100k`, 2026-12-05); two, 1.19 ms at most. Each candidate's
/// sample seed is its index over all directions, so the grouping changes no result.
const SEED_GROUP: usize = 2;
/// Candidates of each side that enter the joint search of a mirrored pair.
pub const SEED_PAIR_SHORTLIST: usize = 16;
/// Surface samples of a candidate limb (the seeded bone and the rest of its chain) for the
/// model → data term of the seeding, shared among its bones by area.
const SEED_SURFACE_SAMPLES: usize = 64;

/// `n` directions spread evenly over the unit sphere (Fibonacci lattice; deterministic).
pub fn sphere_directions(n: usize) -> Vec<Vec3> {
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    (0..n)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
            let r = (1.0 - y * y).max(0.0).sqrt();
            let phi = golden * i as f32;
            Vec3::new(r * phi.cos(), y, r * phi.sin())
        })
        .collect()
}

/// What a seeding candidate is scored against (see [`Solver::seed_chain`]).
struct SeedContext<'a> {
    /// Assignment indices of the scored points.
    idx: &'a [usize],
    /// Distance of each scored point to the trusted bones, capped.
    base: &'a [f32],
    /// The trusted bones, prepared.
    trusted: Vec<PreparedBone>,
    /// Scored points per unit of bone area (for the weight of a surface sample).
    density: f32,
    cap: f32,
}

/// Distances of the scored points to a candidate limb (bones `limb`) and its model → data
/// cost (see [`Solver::seed_chains`]). A point whose distance to the limb's bounding spheres
/// is not below its distance to the trusted bones cannot gain and is not projected.
fn seed_eval(
    a: &Assignment,
    tree: &kiddo::ImmutableKdTree<f32, 3>,
    grid: Option<&NearGrid>,
    spacing: f32,
    limb: &[PreparedBone],
    ctx: &SeedContext,
    seed: u64,
) -> (Vec<f32>, f32) {
    let spheres: Vec<(Vec3, f32)> = limb.iter().map(|b| b.bone.bounding_sphere()).collect();
    let dist: Vec<f32> = ctx
        .idx
        .iter()
        .zip(ctx.base)
        .map(|(&i, &e)| {
            let p = a.positions[i];
            let mut d = f32::INFINITY;
            for (b, (c, r)) in limb.iter().zip(&spheres) {
                if (p - *c).length() - r < e.min(d) {
                    d = d.min(b.project_constrained(p, a.normals[i]).distance);
                }
            }
            d
        })
        .collect();
    let area: f32 = limb.iter().map(|b| b.bone.area()).sum();
    let mut rng = crate::rng::Rng::new(0x5eed ^ seed);
    let mut cost = 0.0f32;
    for (x, b) in limb.iter().enumerate() {
        let share = b.bone.area() / area.max(1e-30);
        let k = ((SEED_SURFACE_SAMPLES as f32 * share).ceil() as usize).max(2);
        let weight = ctx.density * b.bone.area() / k as f32;
        for _ in 0..k {
            let (sp, _) = b.sample_surface(&mut rng);
            if ctx.trusted.iter().any(|q| q.sdf_fast(sp) < 0.0)
                || limb
                    .iter()
                    .enumerate()
                    .any(|(o, q)| o != x && q.sdf_fast(sp) < 0.0)
            {
                continue;
            }
            // Nearer than the spacing: no cost (the grid's "yes" is exact).
            if grid.is_some_and(|g| g.within_below(sp, spacing)) {
                continue;
            }
            let nn = tree
                .query(&sp.to_array())
                .nearest_one::<kiddo::SquaredEuclidean<f32>>()
                .execute();
            cost += weight * (nn.distance.sqrt() - spacing).clamp(0.0, ctx.cap);
        }
    }
    (dist, cost)
}

/// One candidate of a seeding level: the seeded bone's direction and length, the distance of
/// every scored point to the candidate limb, and the limb's model → data cost.
struct SeedCandidate {
    dir: Vec3,
    len: f32,
    dist: Vec<f32>,
    cost: f32,
}

impl Solver<'_> {
    /// The candidates of bone `chain[level]` (its direction within the joint range widened by
    /// [`SEED_RANGE_MARGIN`], current direction first, each of [`SEED_LENGTHS`]), the rest of
    /// the chain following rigidly.
    fn seed_candidates(
        &mut self,
        chain: &[usize],
        level: usize,
        ctx: &SeedContext,
    ) -> Result<Vec<SeedCandidate>, Cancelled> {
        let t = self.world.template.clone();
        let rest_frames = crate::anatomy::skeleton::rest_frames(&t);
        let b = chain[level];
        let bones = self.world.bones();
        let c0 = bones[b].c1;
        let len = self.world.lengths[b];
        let axis = self.world.frames[b] * Vec3::X;
        // The joint range is measured relative to the parent's current frame.
        let to_rest = match t.bones[b].parent {
            Some(p) => (self.world.frames[p] * rest_frames[p].inverse()).inverse(),
            None => self.world.root_rotation.inverse(),
        };
        let rest_axis = rest_frames[b] * Vec3::X;
        let mut dirs = vec![axis];
        dirs.extend(sphere_directions(SEED_DIRECTIONS).into_iter().filter(|d| {
            super::init::range_excess(&t, &rest_frames, b, to_rest * *d) <= SEED_RANGE_MARGIN
        }));
        let mut out = Vec::with_capacity(dirs.len() * SEED_LENGTHS.len());
        for (group, ds) in dirs.chunks(SEED_GROUP).enumerate() {
            let Some(tree) = &self.near.tree else {
                break;
            };
            let jobs: Vec<(Vec3, f32, u64)> = ds
                .iter()
                .enumerate()
                .flat_map(|(k, d)| {
                    SEED_LENGTHS.iter().enumerate().map(move |(m, f)| {
                        (
                            *d,
                            len * f,
                            ((group * SEED_GROUP + k) * SEED_LENGTHS.len() + m) as u64,
                        )
                    })
                })
                .collect();
            let (a, spacing, grid) = (&self.assignment, self.spacing, self.near.grid.as_ref());
            let evaluated: Vec<SeedCandidate> = jobs
                .par_iter()
                .map(|&(d, l, seed)| {
                    let q = crate::geometry::frames::rotation_arc(axis, d);
                    let shift = (l - len) * d;
                    let limb: Vec<PreparedBone> = chain[level..]
                        .iter()
                        .map(|&j| {
                            let bj = bones[j];
                            let (c1, c2) = if j == b {
                                (c0, c0 + d * l)
                            } else {
                                (c0 + q * (bj.c1 - c0) + shift, c0 + q * (bj.c2 - c0) + shift)
                            };
                            Bone::new(c1, bj.r1, c2, bj.r2).prepare()
                        })
                        .collect();
                    let (dist, mut cost) = seed_eval(a, tree, grid, spacing, &limb, ctx, seed);
                    // The prior: leaving the rest direction (relative to the parent) costs up
                    // to `SEED_PRIOR` of what the whole limb could gain.
                    let area: f32 = limb.iter().map(|x| x.bone.area()).sum();
                    let turn = 0.5 * (1.0 - (to_rest * d).dot(rest_axis));
                    cost += SEED_PRIOR * turn * ctx.density * area * ctx.cap;
                    SeedCandidate {
                        dir: d,
                        len: l,
                        dist,
                        cost,
                    }
                })
                .collect();
            out.extend(evaluated);
            self.unit()?;
        }
        Ok(out)
    }

    /// Aims bone `b` along `dir` with length `len` (its subtree follows).
    fn seed_apply(&mut self, b: usize, dir: Vec3, len: f32) {
        let axis = self.world.frames[b] * Vec3::X;
        if dir != axis || len != self.world.lengths[b] {
            self.world
                .rotate_subtree(b, crate::geometry::frames::rotation_arc(axis, dir));
            self.world.lengths[b] = len;
            self.world.enforce();
        }
    }

    /// **Chain seeding** (our addition to the bootstrap of §2.4.1, for statues whose limbs are
    /// far from the template's rest pose: raised arms, crossed legs, a hand on the head).
    /// Before any least-squares fit, the bones of `chains` (one chain, or a chain and its
    /// mirror, seeded together) are aimed level by level from the anchor out: each bone takes
    /// the best of [`SEED_DIRECTIONS`] directions spread over the sphere (within its joint
    /// range widened by [`SEED_RANGE_MARGIN`]; its current direction first, ties keep it) and
    /// of [`SEED_LENGTHS`]. The rest of its chain follows rigidly and is scored with it, so a
    /// bone cannot steal the points of the bones after it (a clavicle stretched down the arm).
    /// A candidate limb is scored two-sidedly on [`SEED_POINTS`] points:
    ///
    /// * **gain** (data → model): `Σ_p max(0, min(e_p, cap) − d_p)`, where `d_p` is the
    ///   normal-constrained distance of `p` to the candidate limb and `e_p` its distance to the
    ///   *trusted* bones (`trusted`, plus the bones already seeded); `cap` = 10% of the statue's
    ///   size, so points far from everything count alike;
    /// * **cost** (model → data): for samples of the limb's surface outside the trusted bones,
    ///   `min(max(0, q_s − spacing), cap)` times the points a sample stands for at the cloud's
    ///   mean density (`q_s`: distance to the nearest data point), so a limb in empty space pays
    ///   what it would gain by covering points.
    ///
    /// The lowest `cost − gain` wins. A mirrored pair is chosen jointly (every pair of
    /// candidates, the gain counting each point once, for the nearer limb), so the left leg
    /// cannot take the right leg's points and push the right leg elsewhere. Every 4 directions
    /// of a bone, every 4 rows of a pair search, and the distances to the trusted bones are one
    /// work unit each.
    pub fn seed_chains(&mut self, chains: &[&[usize]], trusted: &[bool]) -> Result<(), Cancelled> {
        let n = self.assignment.len();
        if n == 0 || self.near.tree.is_none() {
            return Ok(());
        }
        let stride = n.div_ceil(SEED_POINTS).max(1);
        let idx: Vec<usize> = (0..n).step_by(stride).collect();
        let cap = 0.1 * self.size;
        let mut trusted = trusted.to_vec();
        let levels = chains.iter().map(|c| c.len()).max().unwrap_or(0);
        for level in 0..levels {
            let bones = self.world.bones();
            let trusted_prepared: Vec<PreparedBone> = (0..bones.len())
                .filter(|&x| trusted[x])
                .map(|x| bones[x].prepare())
                .collect();
            let a = &self.assignment;
            let base: Vec<f32> = idx
                .iter()
                .map(|&i| {
                    trusted_prepared
                        .iter()
                        .map(|x| x.project_constrained(a.positions[i], a.normals[i]).distance)
                        .fold(cap, f32::min)
                })
                .collect();
            // The distances to the trusted bones are a unit of their own.
            self.unit()?;
            // Points already explained by the trusted bones cannot gain (much): left out.
            let min_gain = 2.0 * self.spacing;
            let (idx_active, base): (Vec<usize>, Vec<f32>) = idx
                .iter()
                .zip(&base)
                .filter(|(_, e)| **e > min_gain)
                .map(|(i, e)| (*i, *e))
                .unzip();
            let total_area: f32 = bones.iter().map(|x| x.area()).sum();
            let ctx = SeedContext {
                idx: &idx_active,
                base: &base,
                trusted: trusted_prepared,
                density: idx.len() as f32 / total_area.max(1e-30),
                cap,
            };
            let active: Vec<&[usize]> =
                chains.iter().copied().filter(|c| level < c.len()).collect();
            let mut sets = Vec::with_capacity(active.len());
            for c in &active {
                sets.push(self.seed_candidates(c, level, &ctx)?);
            }
            let gain =
                |d: &[f32]| -> f32 { base.iter().zip(d).map(|(e, d)| (e - d).max(0.0)).sum() };
            let choice: Vec<usize> = if sets.len() == 2 {
                let (sa, sb) = (&sets[0], &sets[1]);
                // The pair search runs over each side's best `SEED_PAIR_SHORTLIST` candidates
                // on their own.
                let shortlist = |set: &[SeedCandidate]| -> Vec<usize> {
                    let mut order: Vec<(f32, usize)> = set
                        .iter()
                        .enumerate()
                        .map(|(i, c)| (c.cost - gain(&c.dist), i))
                        .collect();
                    order.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
                    order.truncate(SEED_PAIR_SHORTLIST);
                    order.into_iter().map(|(_, i)| i).collect()
                };
                let (la, lb) = (shortlist(sa), shortlist(sb));
                let mut best = (f32::INFINITY, la[0], lb[0]);
                for (row, &ia) in la.iter().enumerate() {
                    let ca = &sa[ia];
                    for &ib in &lb {
                        let cb = &sb[ib];
                        let g: f32 = base
                            .iter()
                            .zip(ca.dist.iter().zip(&cb.dist))
                            .map(|(e, (x, y))| (e - x.min(*y)).max(0.0))
                            .sum();
                        let score = ca.cost + cb.cost - g;
                        if score < best.0 {
                            best = (score, ia, ib);
                        }
                    }
                    if row % 4 == 3 {
                        self.unit()?;
                    }
                }
                vec![best.1, best.2]
            } else {
                sets.iter()
                    .map(|set| {
                        let mut best = (f32::INFINITY, 0usize);
                        for (i, c) in set.iter().enumerate() {
                            let score = c.cost - gain(&c.dist);
                            if score < best.0 {
                                best = (score, i);
                            }
                        }
                        best.1
                    })
                    .collect()
            };
            for ((c, set), k) in active.iter().zip(&sets).zip(choice) {
                let b = c[level];
                self.seed_apply(b, set[k].dir, set[k].len);
                for x in self.with_followers(b) {
                    trusted[x] = true;
                }
            }
        }
        self.refresh()
    }

    /// One chain's seeding ([`Solver::seed_chains`] with a single chain).
    pub fn seed_chain(&mut self, chain: &[usize], trusted: &[bool]) -> Result<(), Cancelled> {
        self.seed_chains(&[chain], trusted)
    }
}

/// The **trunk** bones of a template: the root block's bones and every bone of a chain from
/// which another chain hangs (the human's spine, neck and head, from whose thorax the arms
/// hang), followers included. A trunk bone carries the occupancy term everywhere, not only at
/// a chain's tip (see [`super::lm::OccupancyTerm`]).
pub fn trunk_bones(t: &crate::anatomy::Template) -> Vec<bool> {
    let chain_of = |b: usize| -> Option<usize> {
        match t.bones[b].kind {
            BoneKind::Follower { leader, .. } => t.bones[leader].chain.map(|c| c.0),
            _ => t.bones[b].chain.map(|c| c.0),
        }
    };
    let mut carries = vec![false; t.chains.len()];
    for def in &t.bones {
        if let (Some(p), Some((c, _))) = (def.parent, def.chain)
            && let Some(pc) = chain_of(p)
            && pc != c
        {
            carries[pc] = true;
        }
    }
    (0..t.bones.len())
        .map(|b| t.bones[b].kind == BoneKind::Block || chain_of(b).is_some_and(|c| carries[c]))
        .collect()
}

/// The largest extent of a template's rest pose, radii included (template units).
pub fn template_extent(t: &crate::anatomy::Template) -> f32 {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for b in &t.bones {
        for (j, r) in [(b.from, b.r1), (b.to, b.r2)] {
            lo = lo.min(t.joints[j].rest - Vec3::splat(r));
            hi = hi.max(t.joints[j].rest + Vec3::splat(r));
        }
    }
    (hi - lo).max_element()
}

/// A solver's points made searchable: their k-d tree, their [`NearGrid`] (cells of the
/// occupancy slack: samples near the data skip the tree's query) and their median spacing.
/// Built once per point set: every solver of a registration's level 0 starts on the same
/// subsample, and shares them (an `Arc`) instead of building them again at each start (on
/// 8,000 points the build took a work unit of about 2–3.5 ms, the kiosk's longest).
pub struct NearPoints {
    /// k-d tree of the points (for the free-cap and occupancy terms, the seeding and the
    /// support); `None` when it could not be built.
    tree: Option<kiddo::ImmutableKdTree<f32, 3>>,
    grid: Option<NearGrid>,
    points: Vec<Vec3>,
    /// Median distance between a point and its nearest neighbour (sampled).
    pub spacing: f32,
}

impl NearPoints {
    /// The k-d tree of the points (`None` when it could not be built).
    pub fn tree(&self) -> Option<&kiddo::ImmutableKdTree<f32, 3>> {
        self.tree.as_ref()
    }

    /// The points, in the order they were given.
    pub fn points(&self) -> &[Vec3] {
        &self.points
    }

    /// Builds the tree, the spacing and the grid of `points`.
    pub fn new(points: Vec<Vec3>) -> Self {
        let arr: Vec<[f32; 3]> = points.iter().map(|p| p.to_array()).collect();
        let tree = kiddo::ImmutableKdTree::new_from_slice(&arr).ok();
        let spacing = tree.as_ref().map_or(0.0, |t| median_spacing(t, &arr));
        let grid = NearGrid::new(&points, OCCUPANCY_SLACK * spacing);
        NearPoints {
            tree,
            grid,
            points,
            spacing,
        }
    }
}

/// Median nearest-neighbour distance over up to 1000 evenly spread points.
fn median_spacing(tree: &kiddo::ImmutableKdTree<f32, 3>, pts: &[[f32; 3]]) -> f32 {
    if pts.len() < 2 {
        return 0.0;
    }
    let step = (pts.len() / 1000).max(1);
    let two = std::num::NonZeroUsize::new(2).expect("2 > 0");
    let mut d: Vec<f32> = pts
        .iter()
        .step_by(step)
        .map(|p| {
            let r = tree
                .query(p)
                .nearest_n::<kiddo::SquaredEuclidean<f32>>(two)
                .execute();
            r.iter().map(|n| n.distance).fold(0.0f32, f32::max).sqrt()
        })
        .collect();
    d.sort_by(f32::total_cmp);
    d[d.len() / 2]
}
