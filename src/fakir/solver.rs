//! The FAKIR solver state and its elementary optimisations: assignment refresh, one-bone and
//! two-bone Levenberg–Marquardt rounds (thesis §2.3), the root-block fit and the bootstrap of
//! an empty bone (§2.4.1). Each LM iteration and each slice of an assignment refresh is one
//! **work unit**, after which [`Solver::unit`] lets the caller pause (see
//! [`super::registration`]).

use super::assign::Assignment;
use super::lm::{EnergyTerms, Limits, OCCUPANCY_SAMPLES, OccupancyTerm, Param, lm_iteration};
use super::world::{End, RadiusClasses, WorldSkeleton};
use crate::anatomy::template::BoneKind;
use crate::geometry::{Bone, PreparedBone};
use crate::math::Vec3;

/// Most points one slice of an assignment refresh scans (each point also reads its whole row
/// of distances, so the slice is bounded even when few bones moved).
pub const MAX_REFRESH_SLICE: usize = 16_384;

/// Raised by a pause hook to abandon the registration.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Cancelled;

/// What the solver is doing (for progress reports).
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Activity {
    /// Phase name: "initialisation", "assignment", "block", "chain", "refinement", "done".
    pub phase: &'static str,
    /// Chain being registered.
    pub chain: Option<String>,
    /// Outer iteration (whole-skeleton pass).
    pub iteration: usize,
    /// Pass within the chain (0 = initial forward pass).
    pub pass: usize,
    /// Resolution level (0 = subsample, 1 = all points).
    pub level: usize,
}

/// Called after every work unit; returning `Err(Cancelled)` stops the registration.
pub trait Pause {
    fn unit(&mut self, solver: &Solver) -> Result<(), Cancelled>;
}

/// A pause hook that never pauses.
pub struct NoPause;
impl Pause for NoPause {
    fn unit(&mut self, _: &Solver) -> Result<(), Cancelled> {
        Ok(())
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
    /// Points per slice of an assignment refresh (times bones refreshed).
    pub refresh_budget: usize,
    /// Add the occupancy term (model → data, [`super::lm::OccupancyTerm`]) to every fit.
    pub occupancy: bool,
}

impl Default for SolverSettings {
    fn default() -> Self {
        SolverSettings {
            lm_iterations: 10,
            one_bone_rounds: 4,
            two_bone_rounds: 4,
            lm_tolerance: 1e-6,
            refresh_budget: 120_000,
            occupancy: true,
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
    /// k-d tree of the points the solver started with (for the free-cap term).
    tree: Option<kiddo::ImmutableKdTree<f32, 3>>,
    tree_points: Vec<Vec3>,
    /// Median distance between a point and its nearest neighbour (sampled).
    pub spacing: f32,
    /// Anchor of the root may move (chains whose first joint is free, e.g. the papers' chain).
    pub free_root: bool,
    pause: Option<&'p mut dyn Pause>,
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
        let classes = RadiusClasses::new(&world.template);
        let limits = Limits::new(&world, scale);
        let calibration_limits = Limits::with_length_range(&world, scale, 0.75, 1.33);
        let n = world.template.bones.len();
        let size = scale * template_extent(&world.template);
        let tree_points = assignment.positions.clone();
        let arr: Vec<[f32; 3]> = tree_points.iter().map(|p| p.to_array()).collect();
        let tree = kiddo::ImmutableKdTree::new_from_slice(&arr).ok();
        let spacing = tree.as_ref().map_or(0.0, |t| median_spacing(t, &arr));
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
            tree,
            tree_points,
            spacing,
            pause: Some(pause),
        }
    }

    /// Marks the end of a work unit and lets the pause hook act.
    pub fn unit(&mut self) -> Result<(), Cancelled> {
        self.units += 1;
        // The hook reads the solver: take it out while it runs.
        let Some(pause) = self.pause.take() else {
            return Ok(());
        };
        let r = pause.unit(self);
        self.pause = Some(pause);
        r
    }

    /// Replaces the assignment (e.g. moving to all points) and forgets cached distances.
    pub fn set_assignment(&mut self, a: Assignment) {
        self.assignment = a;
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
            (self.settings.refresh_budget / moved.len().max(1)).clamp(1024, MAX_REFRESH_SLICE);
        let mut start = 0;
        let prev_phase = self.activity.phase;
        self.activity.phase = "assignment";
        while start < n {
            let end = (start + slice).min(n);
            self.assignment
                .update_columns(&prepared, &moved, start..end);
            self.assignment.relabel(start..end);
            start = end;
            self.unit()?;
        }
        self.activity.phase = prev_phase;
        self.assigned_bones = bones;
        self.members = self.assignment.members();
        Ok(())
    }

    /// Total energy over all assigned points (thesis eq. 2.4), as of the last refresh.
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
        // Occupancy weights (see `OccupancyTerm`), fixed for this LM loop.
        // Only chain extremities get the occupancy term (see `OccupancyTerm`): bones without
        // children, and bones leaving a free root.
        let t = self.world.template.clone();
        let tips: Vec<usize> = energy_bones
            .iter()
            .copied()
            .filter(|&b| {
                t.bones[b].children.is_empty() || (self.free_root && t.bones[b].parent.is_none())
            })
            .collect();
        let weights: Vec<f64> = {
            let bones = self.world.bones();
            let total_area: f64 = bones.iter().map(|b| b.area() as f64).sum();
            let density = self.assignment.len() as f64 / total_area.max(1e-30);
            tips.iter()
                .map(|&b| {
                    (density * bones[b].area() as f64 / OCCUPANCY_SAMPLES as f64)
                        .max(1.0)
                        .sqrt()
                })
                .collect()
        };
        for _ in 0..self.settings.lm_iterations {
            let occupancy = match (
                &self.tree,
                self.settings.occupancy && !self.calibrating && !tips.is_empty(),
            ) {
                (Some(tree), true) => Some(OccupancyTerm {
                    bones: tips.clone(),
                    weights: weights.clone(),
                    tree,
                    positions: &self.tree_points,
                    slack: 2.0 * self.spacing,
                }),
                _ => None,
            };
            let terms = EnergyTerms {
                assignment: &self.assignment,
                members: &self.members,
                bones: energy_bones,
                occupancy,
            };
            if terms.count() == 0 && terms.occupancy.is_none() {
                return Ok(0.0);
            }
            let limits = if self.calibrating {
                &self.calibration_limits
            } else {
                &self.limits
            };
            let step = lm_iteration(
                &mut self.world,
                &self.classes,
                limits,
                params,
                &terms,
                &mut lambda,
                self.size,
                clamp_bones,
            );
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
        if self.members_of(&energy) == 0 {
            self.bootstrap(b)?;
        }

        for _ in 0..self.settings.one_bone_rounds {
            let before = self.energy_of(&energy);
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
                    if !(self.free_root && self.world.template.bones[b].parent.is_none()) {
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
            if self.end_round(&energy, before)? {
                break;
            }
        }
        Ok(())
    }

    /// Ends a round of a fit: refreshes the assignment and tells whether the energy of `bones`
    /// changed by less than 1e-4 (relative) since `before`.
    fn end_round(&mut self, bones: &[usize], before: f64) -> Result<bool, Cancelled> {
        self.refresh()?;
        let after = self.energy_of(bones);
        Ok((before - after).abs() <= 1e-4 * before.max(1e-30))
    }

    /// Two-bone fit of the joint between `a` and its chain successor `b` (thesis §2.3.2): the
    /// rotation about the axis through the outer joints, the two lengths and the shared radius,
    /// in turn, with an assignment refresh after each round.
    pub fn two_bone(&mut self, a: usize, b: usize) -> Result<(), Cancelled> {
        let mut energy = self.with_followers(a);
        energy.push(b);
        let clamp = [a, b];
        for _ in 0..self.settings.two_bone_rounds {
            if self.members_of(&energy) == 0 {
                break;
            }
            let before = self.energy_of(&energy);
            self.lm(&[Param::PairRotate { a, b }], &energy, &clamp)?;
            self.lm(&[Param::PairLength { a, b, first: true }], &energy, &clamp)?;
            self.lm(&[Param::PairLength { a, b, first: false }], &energy, &clamp)?;
            self.lm(
                &[Param::Radius {
                    bone: a,
                    end: End::Second,
                }],
                &energy,
                &clamp,
            )?;
            if self.end_round(&energy, before)? {
                break;
            }
        }
        Ok(())
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

    /// Current energy of `bones`' points (assignment fixed).
    pub fn energy_of(&self, bones: &[usize]) -> f64 {
        EnergyTerms {
            assignment: &self.assignment,
            members: &self.members,
            bones,
            occupancy: None,
        }
        .energy(&self.world.bones())
    }

    /// Model → data term: mean of `max(0, |s − q| − spacing)` over samples `s` of the bones'
    /// visible surface (outside every other bone), `q` the nearest data point. Zero when every
    /// part of the model lies on the data; large when bones stick out into empty space. With
    /// the mean distance (data → model) it makes a two-sided fit measure.
    pub fn occupancy(&self) -> f64 {
        let Some(tree) = &self.tree else { return 0.0 };
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
                let nn = tree
                    .query(&sp.to_array())
                    .nearest_one::<kiddo::SquaredEuclidean<f32>>()
                    .execute();
                sum += (nn.distance.sqrt() - self.spacing).max(0.0) as f64;
                count += 1;
            }
        }
        if count == 0 { 0.0 } else { sum / count as f64 }
    }

    /// Bootstrap of a bone without points (§2.4.1: "rotated around the three axes until some
    /// input points are projected onto it"): tries 26 directions (the cube's face, edge and
    /// corner directions) about its first joint and keeps the one that would capture the most
    /// points (ties: the first in a fixed order). Keeps the current direction when none
    /// captures any point (a missing limb).
    pub fn bootstrap(&mut self, b: usize) -> Result<(), Cancelled> {
        let mut dirs = Vec::new();
        for x in -1i32..=1 {
            for y in -1i32..=1 {
                for z in -1i32..=1 {
                    if x != 0 || y != 0 || z != 0 {
                        dirs.push(Vec3::new(x as f32, y as f32, z as f32).normalize());
                    }
                }
            }
        }
        let axis = self.world.frames[b] * Vec3::X;
        let n = self.assignment.len();
        let mut best = (0usize, None::<Vec3>);
        for d in dirs {
            let mut trial = self.world.clone();
            trial.rotate_subtree(b, crate::geometry::frames::rotation_arc(axis, d));
            trial.enforce();
            let pb = trial.bones()[b].prepare();
            let a = &self.assignment;
            let captured = (0..n)
                .filter(|&i| {
                    pb.project_constrained(a.positions[i], a.normals[i])
                        .distance
                        < a.own_distance(i)
                })
                .count();
            if captured > best.0 {
                best = (captured, Some(d));
            }
            self.unit()?;
        }
        if let Some(d) = best.1 {
            self.world
                .rotate_subtree(b, crate::geometry::frames::rotation_arc(axis, d));
            self.world.enforce();
            self.refresh()?;
        }
        Ok(())
    }
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
