//! The FAKIR schedule: Algorithm 1 on each chain (thesis §2.4.1) and the whole-skeleton order
//! with backtracking (§2.4.2).
//!
//! ## A chain (Algorithm 1)
//! 1. *Initial forward pass*: one-bone fit of the first bone (rotation, both radii, length);
//!    then for each next bone, a one-bone fit (rotation about the shared joint, length, free
//!    radius) followed by the two-bone fit of the joint it shares with its predecessor; the last
//!    bone's length and free radius come from its one-bone fit.
//! 2. *Forward and backward passes*: the order is reversed, every consecutive pair gets a
//!    two-bone fit, then the extremity bone at the end of the pass gets a one-bone fit (its
//!    free end: the chain's tip after a forward pass, the chain's anchor after a backward pass
//!    — which only moves when the anchor is free, as in the papers' chain experiment).
//! 3. **Convergence (our choice):** passes stop when the chain's energy decreases by less
//!    than `chain_tolerance` (relative, default 1e-3) over a pass, or after `max_passes`.
//! 4. **Whole-chain fit (our addition, for speed; setting `whole_chain`), on a template of one
//!    chain and no root block only:** before each forward or backward pass, one LM group over every
//!    parameter of the chain at once ([`Solver::whole_chain`]: each bone's two swings and length,
//!    each radius class once). A pass moves one joint with its neighbours held, so a chain whose
//!    joints are all off settles by a fraction per pass (on the papers' chain about 0.6 of the mean
//!    distance is left after each pass, and 10 passes left 0.023 of a length of 140); the whole
//!    chain's Gauss–Newton step moves every joint together (test
//!    `the_whole_chain_fit_settles_a_chain_whose_joints_are_all_off`). `fakir/chain4_5k`: 8,161 →
//!    4,080 work units, mean distance 0.0091 → 0.0103, joint error 0.017% → 0.032% of the length
//!    (the mean distance still under the papers' 10⁻⁴ of the length, 0.014). **Not on templates of
//!    several chains:** on the 16 posed humans of `fakir/accuracy_posed` (run after each pass, with
//!    the occupancy slack at 4 spacings instead of 2, see [`super::lm::OCCUPANCY_SLACK`]) it took
//!    the statues under 2% of the height from 13 to 12, the 90th percentile from 4.4% to 5.0%, and
//!    the median time per statue from 32 s to 42 s (likely because a chain's step there also swings
//!    the chains hanging from it, whose points are not in its energy; not checked). With a noisy
//!    tip it may also slide the last joint along the chain (σ = 2 on the papers' chain: the tip 2.9
//!    off against 0.8), where the data term is flat (a longer, thinner last bone fits the noisy cap
//!    as well).
//!
//! ## Seeding (our addition)
//! A fresh registration first **seeds** every limb chain (every chain after the first, the
//! trunk): each bone is aimed, from the anchor out, at the direction and length that best
//! explain the points nothing trusted explains yet, with a model → data cost
//! ([`Solver::seed_chains`]); a chain and its mirror are seeded together. Two rounds: in the
//! first, a chain trusts the bones of the chains before it; in the second, every other
//! chain. FAKIR's least squares only converge from a nearby start — the papers place the
//! template by hand — and a statue's arms are rarely where the rest pose has them.
//!
//! ## The whole skeleton
//! Chains are registered in the template's order (spine, legs, arms for the human). The root
//! block (pelvis: position, orientation and common scale) is refitted after each spine pass
//! ("the spine chain is registered, refining the pelvis position and scale"). Limb chains keep
//! their anchor joint fixed while they are registered. **Choice:** the block is not fitted
//! before the spine: on its own points alone (a blob inside the hips) its orientation is
//! undetermined and a fit tilts the whole skeleton; after the spine's passes the attached
//! bones pin it. After all chains, the whole order is
//! repeated (**backtracking**: the spine is questioned again with the points the limbs have
//! taken, then the limbs from their moved anchors) until the mean distance (eq. 2.16) improves
//! by less than `skeleton_tolerance` (relative, default 1e-3) or `max_iterations` is reached.
//! **Choice:** a template of one chain and no root block (the papers' chain experiment) is not
//! iterated: with nothing to backtrack to, a second iteration only runs the chain's passes
//! again after their own tolerance stopped them (`fakir/chain4_5k`: the same joint error at
//! three quarters of the work).

use super::solver::{Cancelled, Solver};
use super::world::End;

/// Schedule settings.
#[derive(Clone, Debug, PartialEq)]
pub struct ScheduleSettings {
    /// Forward/backward passes per chain visit after the first.
    pub max_passes: usize,
    /// Relative chain-energy decrease under which the passes stop.
    pub chain_tolerance: f64,
    /// Whole-skeleton iterations.
    pub max_iterations: usize,
    /// Relative mean-distance decrease under which the whole-skeleton loop stops.
    pub skeleton_tolerance: f64,
}

impl Default for ScheduleSettings {
    fn default() -> Self {
        ScheduleSettings {
            max_passes: 10,
            chain_tolerance: 1e-3,
            max_iterations: 4,
            skeleton_tolerance: 1e-3,
        }
    }
}

/// Algorithm 1, lines 1–10: the initial forward pass over `chain`.
pub fn chain_initial_pass(s: &mut Solver, chain: &[usize]) -> Result<(), Cancelled> {
    s.activity.pass = 0;
    s.calibrating = true;
    let r = (|| {
        s.one_bone(chain[0], End::Second, true)?;
        for k in 0..chain.len().saturating_sub(1) {
            s.one_bone(chain[k + 1], End::Second, false)?;
            s.two_bone(chain[k], chain[k + 1])?;
        }
        Ok(())
    })();
    s.calibrating = false;
    r
}

/// One forward (`reverse = false`) or backward pass of two-bone fits, then the one-bone fit of
/// the extremity reached (Algorithm 1, lines 13–19).
///
/// **Our choice: a chain of one anchored bone refits its free end both ways.** A limb lost
/// below its first bone (an arm lost at the shoulder, a shin lost at the knee) is fitted up
/// to where it broke ([`Solver::present_prefix`]): one bone, hanging from the trunk. Such a
/// chain has no two-bone fit, and the backward pass's extremity is its first end, which only
/// a bone leaving a free root may move ([`Solver::first_end_free`]): the pass did nothing,
/// [`chain_passes`] stopped after it, and the bone kept the length of the initial forward
/// pass, clamped to `[0.75, 1.33]` times the template's proportion (a synthetic statue
/// whose upper arms were cut at the shoulders, registered with them lost: both clavicles
/// ended at 0.75 times their expected length, 0.199 against the truth's 0.252 and 0.254).
/// Its backward pass now fits the free end, like the forward pass.
pub fn chain_pass(s: &mut Solver, chain: &[usize], reverse: bool) -> Result<(), Cancelled> {
    let k = chain.len();
    if reverse && k == 1 && !s.first_end_free(chain[0]) {
        s.one_bone(chain[0], End::Second, false)?;
    } else if reverse {
        for i in (0..k.saturating_sub(1)).rev() {
            s.two_bone(chain[i], chain[i + 1])?;
        }
        s.one_bone(chain[0], End::First, false)?;
    } else {
        for i in 0..k.saturating_sub(1) {
            s.two_bone(chain[i], chain[i + 1])?;
        }
        s.one_bone(chain[k - 1], End::Second, false)?;
    }
    Ok(())
}

/// A template of one chain and no root block (the papers' chain experiment).
pub fn single_chain(t: &crate::anatomy::Template) -> bool {
    t.chains.len() == 1 && t.block_bones().next().is_none()
}

/// Energy of a chain's points (bones and their followers).
pub fn chain_energy(s: &mut Solver, chain: &[usize]) -> Result<f64, Cancelled> {
    let bones = s.chain_with_followers(chain);
    s.energy_of(&bones)
}

/// Forward/backward passes until the chain energy stops decreasing (see the module docs).
/// The first pass after the initial forward pass goes backward. Returns the passes run.
pub fn chain_passes(
    s: &mut Solver,
    chain: &[usize],
    settings: &ScheduleSettings,
    mut reverse: bool,
) -> Result<usize, Cancelled> {
    let mut before = chain_energy(s, chain)?;
    let mut passes = 0;
    while passes < settings.max_passes {
        s.activity.pass = passes + 1;
        if s.settings.whole_chain && single_chain(&s.world.template) {
            s.whole_chain(chain)?;
        }
        chain_pass(s, chain, reverse)?;
        passes += 1;
        reverse = !reverse;
        let after = chain_energy(s, chain)?;
        if before - after <= settings.chain_tolerance * before.max(1e-30) {
            break;
        }
        before = after;
    }
    Ok(passes)
}

/// Registers a single chain from scratch (the papers' chain experiment): initial forward pass
/// then passes to convergence.
pub fn register_chain(
    s: &mut Solver,
    chain: &[usize],
    settings: &ScheduleSettings,
) -> Result<usize, Cancelled> {
    s.activity.phase = "chain";
    s.refresh()?;
    chain_initial_pass(s, chain)?;
    let passes = chain_passes(s, chain, settings, true)?;
    Ok(passes + 1)
}

/// Bones registered before chain `ci` in the template's order: every bone except those of
/// the chains of `group`, of chain `ci` and of later chains (and their followers).
fn trusted_before(s: &Solver, ci: usize, group: &[usize]) -> Vec<bool> {
    let t = &s.world.template;
    let mut trusted = vec![true; t.bones.len()];
    for (c, chain) in t.chains.iter().enumerate() {
        if c >= ci || group.contains(&c) {
            for &b in &chain.bones {
                for x in s.with_followers(b) {
                    trusted[x] = false;
                }
            }
        }
    }
    trusted
}

/// Every bone except those of the chains of `group` (and their followers).
fn trusted_except(s: &Solver, group: &[usize]) -> Vec<bool> {
    let t = &s.world.template;
    let mut trusted = vec![true; t.bones.len()];
    for &c in group {
        for &b in &t.chains[c].bones {
            for x in s.with_followers(b) {
                trusted[x] = false;
            }
        }
    }
    trusted
}

/// Registers the whole skeleton (see the module docs). Returns the iterations run.
pub fn register_skeleton(
    s: &mut Solver,
    settings: &ScheduleSettings,
    fresh: bool,
) -> Result<usize, Cancelled> {
    let t = s.world.template.clone();
    s.refresh()?;
    let mut before = s.mean_distance();
    let mut iterations = 0;
    if fresh && s.settings.seed_chains {
        // Every limb chain gets a first guess before any least-squares fit, so the trunk is
        // not fitted to the points of limbs that are still far away.
        s.activity.phase = "seeding";
        for round in 0..2 {
            for ci in 1..t.chains.len() {
                // A chain whose mirror comes earlier was seeded with it.
                if t.chains[ci].mirror.is_some_and(|m| m < ci) {
                    continue;
                }
                let group: Vec<usize> = match t.chains[ci].mirror {
                    Some(m) if m > ci => vec![ci, m],
                    _ => vec![ci],
                };
                let trusted = if round == 0 {
                    trusted_before(s, ci, &group)
                } else {
                    trusted_except(s, &group)
                };
                // A lost limb is seeded up to where it broke.
                let chains: Vec<&[usize]> = group
                    .iter()
                    .map(|&c| s.present_prefix(&t.chains[c].bones))
                    .filter(|c| !c.is_empty())
                    .collect();
                if !chains.is_empty() {
                    s.seed_chains(&chains, &trusted)?;
                }
            }
        }
        before = s.mean_distance();
    }
    let (iterations_max, chains) = (settings.max_iterations.max(1), t.chains.len().max(1));
    let single_chain = single_chain(&t);
    for it in 0..settings.max_iterations {
        s.activity.iteration = it;
        for (ci, chain) in t.chains.iter().enumerate() {
            s.activity.phase = "chain";
            s.activity.chain = Some(chain.name.clone());
            s.activity
                .advance((it as f32 + ci as f32 / chains as f32) / iterations_max as f32);
            // A lost limb is fitted up to where it broke.
            let bones = s.present_prefix(&chain.bones);
            if it == 0 && fresh && !bones.is_empty() {
                chain_initial_pass(s, bones)?;
            }
            if !bones.is_empty() {
                chain_passes(s, bones, settings, true)?;
            }
            if ci == 0 {
                s.block()?;
            }
        }
        s.activity.chain = None;
        s.block()?;
        iterations += 1;
        s.activity.advance((it + 1) as f32 / iterations_max as f32);
        // One chain and no block: nothing to backtrack to, so another iteration would only
        // run the chain's passes again past the point their own tolerance stopped them.
        if single_chain {
            break;
        }
        let after = s.mean_distance();
        if before - after <= settings.skeleton_tolerance * before.max(1e-30) {
            break;
        }
        before = after;
    }
    s.activity.advance(1.0);
    Ok(iterations)
}
