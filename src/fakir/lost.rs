//! Level 6 of the registration ([`super::registration`]): which bones of the fit are
//! **lost**, and the fit settled without them.
//!
//! The support of every bone ([`super::support`]: how much of its surface, at its expected
//! size, the scan covers) is measured on the level-0 points ([`support_points`],
//! [`examine_support`]); [`lost_limbs`] judges each limb bone from the tips inwards by its
//! support, its points and how well the other bones explain them (the rules, each with what
//! it was measured on, are in its docs); [`settle_lost_limbs`] gives the lost bones their
//! expected size and pose (thesis ch. 5: the healthy mirror limb's, else the template's)
//! and refines the rest of the skeleton without them. The checks of level 5 ask the same
//! rules about the fit as it stands ([`Folds`]). The papers leave this open: FAKIR "cannot
//! predict the right length or angle" of a bone whose data is missing (thesis §2.5.1).
//!
//! Every step is cut into work units like the rest of the registration: one per slice of
//! the mean spacing, per bone examined, per bone judged.

use super::registration::{FOLDED, RegistrationOptions, cancelled};
use super::schedule::{ScheduleSettings, register_skeleton};
use super::solver::{NearPoints, Solver};
use super::support::{
    BoneSupport, SPACING_CHUNK, SupportExam, add_spacings, better, complete_with, spacing_samples,
};
use super::world::WorldSkeleton;
use crate::anatomy::template::BoneKind;
use crate::error::{Error, Result};
use crate::geometry::{Bone, PreparedBone};
use std::sync::Arc;

/// The points support is judged on (the level-0 points, a subsample of the figure: support
/// is judged relative to the sampling density), searchable, and their mean spacing: the
/// level-0 solvers' own [`NearPoints`] (the same points, the same k-d tree: building it again
/// here took a work unit of up to 3 ms on 100k points), the spacing in units of
/// `SPACING_SLICE` points.
pub(super) fn support_points(
    s: &mut Solver,
    near: &Arc<NearPoints>,
) -> Result<(Arc<NearPoints>, f32)> {
    s.activity.phase = "support";
    let tree = near
        .tree()
        .ok_or_else(|| Error::input("support: no point to judge support on"))?;
    let points = near.points();
    // The mean spacing (`mean_spacing`, the same bytes) in slices of `SPACING_SLICE` points.
    let n = spacing_samples(points.len());
    let mut sum = 0.0;
    for start in (0..n).step_by(SPACING_SLICE) {
        add_spacings(points, tree, start..start + SPACING_SLICE, &mut sum);
        s.unit().map_err(cancelled)?;
    }
    Ok((near.clone(), (sum / n.max(1) as f64) as f32))
}

/// Points whose nearest-neighbour distance one work unit of [`support_points`] measures
/// (a multiple of [`SPACING_CHUNK`]): 8000 take about 2 ms on this 2-core machine.
const SPACING_SLICE: usize = 8 * SPACING_CHUNK;

/// The support of every bone of the fit `s` ([`super::support`]) on the points of `tree`
/// (mean spacing `rho`, [`support_points`]): one work unit for the set-up, then one per
/// examination of a bone ([`SupportExam::tries`]: two for a shrunk bone). The solver's
/// assignment is refreshed first (nothing to do when no bone moved since), so the lost-limb
/// rules that read it after the support see the fit the support was measured on.
pub(super) fn examine_support(
    s: &mut Solver,
    near: &NearPoints,
    rho: f32,
) -> Result<Vec<BoneSupport>> {
    s.refresh().map_err(cancelled)?;
    let tree = near
        .tree()
        .ok_or_else(|| Error::input("support: no point to judge support on"))?;
    s.activity.phase = "support";
    let fitted = s.world.to_skeleton();
    let exam = SupportExam::new(tree, rho, &fitted);
    s.unit().map_err(cancelled)?;
    let mut out = Vec::with_capacity(fitted.bones.len());
    for k in 0..fitted.bones.len() {
        let mut best = (0.0, 0.0);
        for &e in exam.tries(k) {
            best = better(best, exam.coverage(k, e));
            s.unit().map_err(cancelled)?;
        }
        out.push(exam.support(k, best));
    }
    Ok(out)
}

/// The bones of lost limbs, from the tips inwards: a limb bone (neither the root block nor a trunk
/// bone, [`super::solver::trunk_bones`]) all of whose children are lost is lost when its subtree is
/// **redundant** — its points lie almost as close to the other bones ([`Solver::removal_excess`]
/// under [`REDUNDANT`] times the bone's mean radius): the bones of a cut limb that FAKIR folded
/// onto other parts are covered by their points, but explain nothing the others do not — or when it
/// is **bare**: its support says missing ([`super::support`]: little of its surface, at its
/// expected size, has scan points near it) and the fit gave it no point either. A **starved**
/// subtree, holding fewer than [`STARVED`] (a quarter) of the points of its mirror's subtree, is
/// redundant under the looser [`STARVED_REDUNDANT`] (half the mean radius): the bones below a cut
/// that FAKIR folds back onto the stump or lays into the trunk take a few points that the stump or
/// the trunk explains nearly as well, but not always within a quarter of the radius (a foot folded
/// onto a shin's stump: 0.34; a forearm and hand laid into the trunk: 0.29), while a healthy limb
/// and its mirror hold about as many points. On 20 synthetic statues cut part-way through a limb
/// (30k points, seeds 40–59) the lost set came out right on 17 instead of 14; on 32 complete ones
/// it also took seed 15's right hand, which the fit had laid off the statue (a fifth of its
/// mirror's points, no support; completed from the left one, its joint error went from 5.6% to
/// 6.8%), besides the hands of seeds 10 and 12 the redundancy bound already took. **Empty** (our
/// choice): a starved subtree holding no point at all is lost, whatever its support: its removal
/// costs nothing (the redundancy test has no point to average over). On seed 300 cut through the
/// left upper arm at 0.5 FAKIR folded the forearm back along the stump and laid the hand, without a
/// point, on the chest (covered there): nothing was found lost; now the forearm and hand are
/// (`synth --seed 300 --rigid --height 1.7 --cut bone:l_upper_arm@0.5`, 30k points). **Covered
/// through** (our choice): a bone carrying others, taken lost though it holds points, is kept when
/// the scan covers it from end to end ([`covered_through`]: coverage at least
/// [`super::support::PARTIAL`], reach at least [`THROUGH_REACH`]) and its axis is not buried in the
/// other bones ([`buried_depth`] under [`THROUGH_DEPTH`] of its radius), and so is every bone below
/// it (the whole limb below is then kept). A forearm resting on a thigh and a hand on the knee keep
/// their surface in the scan, but the thigh takes most of their points: on seed 306 (cut through
/// the left shin at 0.6) the healthy left forearm and hand held 142 points against their mirrors'
/// 1,995 and were taken lost with the foot (forearm coverage and reach 1, its axis 0.87 radii deep
/// on average: the synthetic arm sinks into the thigh); on seed 311 (right shin at 0.5) the left
/// forearm, not starved, 0.38 deep. A cut limb that FAKIR laid into the trunk is covered from end
/// to end too, but its axis lies deep inside: seed 47's forearm (right upper arm cut at 0.3) 3.6
/// radii, seed 317's (the same cut) 2.4, so they stay lost; and so does the upper arm above them,
/// whose stump FAKIR had laid along the trunk (0.75 radii deep: kept alone, the forearm completed
/// below it lay on the trunk). The removal excess does not tell them apart (0.06 and 0.16 of the
/// radius for the resting forearms, 0.044 and 0.010 for the buried ones). The reach keeps a limb
/// folded back onto its stump lost (seed 300's forearm: reach 0.1). **Folded back** (our choice,
/// 2026-12-04): on the verdicts of level 6 and of the checks after the folded-limbs check
/// ([`Folds::Lost`]), a bone turned back from its parent's direction by more than [`FOLDED`]
/// ([`WorldSkeleton::fold_angle`]) is not covered through, nor is a limb with such a bone below:
/// the human's joint ranges allow 125°, and a fold that the folded-limbs check did not undo (the
/// unfolded start, reaching into empty space, scored higher) is a limb laid back onto its stump,
/// not one lying against another part. The synthetic Venus seed 27 (both upper arms cut at 0.25)
/// had both forearms laid back along the stumps at 170° and 171°, covered through with their axes
/// 1.06 and 1.31 radii deep, and nothing was found lost; now both forearms and hands are, the upper
/// arms partial. The folded-limbs check asks with [`Folds::Unfoldable`]: a complete arm folded by
/// the fit must stay a candidate for unfolding. Support alone is not enough: on real scans a fitted
/// bone thicker than a draped limb, a foot on a plinth set aside, or a hand that FAKIR shrank, has
/// little coverage but points of its own that nothing else explains (measured on `../shared/data`:
/// the feet of Theodoric, Zenobia and Maria, the Faun's left arm and hand). **Laid over its
/// parent** (our choice): a last bone (a hand, a foot) without support, whose mirror has support,
/// and whose points its parent would explain as well if it reached to that bone's end
/// ([`Solver::removal_excess_with`]: the parent from its first joint to the last bone's end, with
/// its own radii, under the same bound), is lost. Below a cut at the wrist FAKIR can shorten the
/// forearm and lay the hand over the forearm's far half: the hand is covered, has no support at its
/// expected size, and its points are far from the shortened forearm's end, so the redundancy test
/// kept it (seed 98: forearm 0.185 against 0.307). The mirror's support tells a break from a scan
/// or a fit that covers neither side: without it, the *Dancing Faun*'s left foot (both feet on the
/// plinth, each with 15% coverage) was taken lost. And a cut takes length away: the last bone and
/// its parent must be shorter together than [`OVER_PARENT_SHORTER`] times their mirrors (seed 98:
/// 0.27 against 0.46); without that, the complete seed 23 lost its right hand (forearm and hand
/// 0.40 against 0.38). **Both sides broken** (our choice): a statue that lost both hands (or both
/// feet) has no healthy mirror to compare with. A last bone not lost whose mirror was taken lost
/// after it was examined (bones are examined once, from the last) is examined again: it is lost
/// when it holds no point of its own (a foot folded back along its shin, whose points the shin
/// takes), or when it is laid over its parent with both ends shrunk ([`laid_over_parent`]).
/// Measured on synthetic statues cut at both wrists or ankles (`synth --seed N --rigid --height 1.7
/// --cut bone:l_hand@0 --cut bone:r_hand@0`, 30k points; joint error over the joints the scan has):
/// seeds 120 and 121 lost the left hand and reported the right one partial, its forearm shortened
/// with the hand laid over its end (right wrist 6.8% and 6.5% of the height off); now both are lost
/// and the forearm refitted without the hand reaches the cut (0.81% → 0.33%, 0.63% → 0.25%). Seed
/// 123 without its feet reported the right one partial with no point of its own; now both lost
/// (1.96% both ways). On 21 other cut statues (one or both hands, feet, forearms or shins; seeds
/// 101–110, 120–124) it changed nothing. **Fed and covered** (our choice): a last bone taken lost
/// by the redundancy test alone (not bare, not laid over its parent, not empty) is kept when it has
/// what a present end has ([`fed_and_covered`]): its parent present, its mirror present and
/// covered, at least [`STARVED`] of its mirror's points, coverage at least
/// [`super::support::PARTIAL`] at its expected size, and a fitted length within [`FED_LENGTH`] of
/// its mirror's. The bone it joins can explain an end's points nearly as well: seed 316's left
/// foot, cut at half its length (`synth --seed 316 --rigid --height 1.7 --cut bone:l_foot@0.5`),
/// 266 points against its mirror's 767, coverage 0.82, 1.13 times its mirror's length, removal
/// excess 0.15 of its radius (the shin's ankle sphere explains the heel); the stylised seed 208's
/// healthy right hand (`synth --seed 208 --rigid --height 1.7 --symmetric --jitter 0.5`), 471
/// against 1,078, coverage 1.0, 1.16 times, 0.18. Both were taken lost; now neither is (316 0.57% →
/// 0.55% of the height in joint error over the joints the scan has, 208 4.57% → 4.53%). The true
/// losses it must spare are starved, uncovered or stretched: on 30 statues (twelve held-out cuts:
/// 300, 304, 305, 307–310, 312, 315–318; ten hands and feet cut at 0–0.6 of their length or below a
/// forearm or shin cut at 0.9, seeds 320–329; the stylised 201–208), examined with temporary
/// prints, the lost ends whose parent was present were starved (nine, coverage 0.00–0.71) or under
/// 0.75 coverage (309's half hand 0.24, 320's hand cut at the wrist 0.23), and the rule fires on
/// 316 and 208 alone. The length guards an end stretched over its parent (308's lost hand: 1.88
/// times its mirror's length, coverage 1.0, lost with its forearm), and a statue that lost both
/// hands has no present mirror (seed 122's right hand, coverage 1.0, 539 points against 1,114). The
/// fed-and-covered end is kept before the both-sides-broken examination below. **A stump** (our
/// choice; last, on every verdict, the checks' of level 5 included): the first lost bone of a limb,
/// its parent present, not known lost and not taken by the laid-over-parent rule, is kept when its
/// support reaches [`STUMP_REACH`] (0.3 to 0.5) of its length from its first joint and its parent
/// is not stretched past its mirror ([`is_stump`]); the bones below it stay lost, and
/// [`Fit::partial`](super::registration::Fit::partial) names it (its support does not reach through
/// it). The parent's end sphere explains a short stump's points nearly as well as the bone does, so
/// the redundancy test takes it with what it carried; where the support reaches tells them apart.
/// Measured with temporary prints (2026-12-02, `synth --seed N --rigid --height 1.7 --cut
/// bone:B@F`, 30k points, `register`'s defaults): stumps taken lost reached 0.4 (seed 304's shin
/// cut at 0.2), 0.3 (308's forearm at 0.6), 0.5 (332's shin at 0.3); truly lost bones 0.0 (304's
/// and 332's feet, 334's shin), 0.6 (313's shin below a thigh cut at 0.5, laid over another part),
/// 0.8 (120's left hand cut at the wrist) and 1.0 (308's hand, stretched to 1.88 times its mirror
/// over the trunk). The healthy right hand of the complete seed 10, hanging beside a forearm
/// stretched over it to 1.85 times its mirror's length, reaches 0.3: kept, it would stop the
/// dangling-end check from mending that fit, hence the parent's guard. The laid-over-parent rule's
/// hands (seeds 98, 120, 309: 0.4, 0.8, 0.4) lie over their parents' far half, the parent shortened
/// to make room, so they stay lost (309's hand, cut at half its length, with them). A trial with
/// the reach 0.3 to 0.9 and no guard (2026-11-29) lost seed 10's mended fit. A stump must also be
/// fed: at least [`STUMP_FED`] of its present mirror's points (a bone lost whole at its joint,
/// shrunk onto the joint's surface, holds almost none), or, its mirror lost too, at least
/// [`STUMP_FED_ALONE`] of the points the template's proportions give a bone of its size
/// (seeds 121 and 396 cut at both wrists had one hand kept as a stump, now lost; seed 393
/// cut at both shoulders its right upper arm, now lost, but its fit now ends with the left
/// arm laid on the chest, covered through, and keeps it). **A bridge** (our choice, 2026-12-05): a
/// limb bone not hanging from the trunk, carrying bones not all lost, holding under [`STUMP_FED`]
/// of its present mirror's points with its support reaching at most [`BRIDGE_REACH`] of its length,
/// is lost with all it carries ([`is_bridge`]), and a mirror of a bone below it taken lost as empty
/// is kept: the bones below the bridge lay on that mirror's place and took its points (they take
/// them back when the skeleton is settled without the lost bones). A bone is examined as a bridge
/// only when its children are not all lost (otherwise the tests above judge it). One work unit per
/// bone, and one per bone examined again or taken as a bridge.
pub(super) fn lost_limbs(
    s: &mut Solver,
    support: &[BoneSupport],
    known: &[bool],
    folds: Folds,
) -> Result<Vec<bool>> {
    let t = s.world.template.clone();
    let trunk = super::solver::trunk_bones(&t);
    let nb = t.bones.len();
    let mut lost = known.to_vec();
    let mirror = t.mirror_bones();
    // Bones taken lost by the redundancy test alone (not bare, not laid over their parent,
    // not empty).
    let mut only_redundant = vec![false; nb];
    // Bones taken by the laid-over-parent rule (never kept as a stump).
    let mut over_taken = vec![false; nb];
    // Bones taken lost as empty (starved of every point), and bridges (see below).
    let mut empty_taken = vec![false; nb];
    let mut bridges = Vec::new();
    // Parents come before their children in a template's bone order.
    for b in (0..nb).rev() {
        let limb = t.bones[b].kind != BoneKind::Block && !trunk[b];
        if lost[b] || !limb {
            continue;
        }
        if !t.bones[b].children.iter().all(|&c| lost[c]) {
            // A bridge: the limb was lost at this bone's joint, and the fit laid the bone
            // across empty space so that the bones below it reach another part.
            if is_bridge(s, support, (&mirror, &trunk), &lost, b) {
                for c in t.subtree(b) {
                    lost[c] = true;
                }
                bridges.push(b);
                s.unit().map_err(cancelled)?;
            }
            continue;
        }
        let bone = s.world.bones()[b];
        let radius = 0.5 * (bone.r1 + bone.r2) as f64;
        let bare = support[b].missing && s.members_of(&[b]) == 0;
        // A limb's first bone hangs from the trunk (a shoulder girdle, a thigh at the hip):
        // its points are the trunk's surface as much as the limb's, so it is lost only when
        // bare (on the *Venus de Milo*, told her arms were lost, the redundancy test took her
        // right shoulder too and a restoration grafted a donor's chest onto hers).
        let hangs_from_trunk = t.bones[b].parent.is_some_and(|p| trunk[p]);
        // Starved: its subtree holds a small fraction of the points its mirror's subtree
        // holds (a healthy limb and its mirror are about the same size).
        let own = s.members_of(&t.subtree(b));
        let starved = mirror[b]
            .map(|m| s.members_of(&t.subtree(m)))
            .is_some_and(|theirs| (own as f64) < STARVED * theirs as f64);
        let limit = if starved {
            STARVED_REDUNDANT
        } else {
            REDUNDANT
        };
        // Empty: starved of every point (its mirror's subtree holds some); its removal costs
        // nothing ([`Solver::removal_excess`] has no point to average over).
        let empty = starved && own == 0;
        // Each test runs only when the ones before it did not take the bone (as the
        // short-circuiting `||` did before `only_redundant` needed the redundancy verdict).
        let over_parent =
            !bare && laid_over_parent(s, support, (&mirror, &trunk), &lost, b, limit * radius);
        let redundant = !bare
            && !over_parent
            && !hangs_from_trunk
            && !empty
            && s.removal_excess(b, &lost)
                .is_some_and(|e| e < limit * radius);
        lost[b] = bare || over_parent || (!hangs_from_trunk && empty) || redundant;
        empty_taken[b] = !bare && !over_parent && !hangs_from_trunk && empty;
        only_redundant[b] = redundant;
        over_taken[b] = over_parent;
        // Covered through: a limb bone carrying others, taken lost though it holds points,
        // lies against another part when the scan covers it and every bone below it from end
        // to end and none of their axes is buried in the other bones (a forearm resting on a
        // thigh and its hand on the knee: their surface is there, most of their points shared
        // with that part). The whole limb below it is then kept. A lost limb that FAKIR laid
        // into the trunk is covered too, but some of its axes lie deep inside.
        // A bone folded back onto its parent (at level 6, [`Folds::Lost`]) is not lying
        // against another part.
        let folded_back = |c: usize| {
            folds == Folds::Lost
                && s.world
                    .fold_angle(c)
                    .is_some_and(|a| a > FOLDED.to_radians())
        };
        if lost[b]
            && !empty
            && !t.bones[b].children.is_empty()
            && covered_through(&support[b])
            && !folded_back(b)
            && buried_depth(s, b, &lost) < THROUGH_DEPTH
        {
            // Examined from `b` down, each bone with those above it kept.
            let mut kept = lost.clone();
            kept[b] = false;
            let mut whole = true;
            for c in t.subtree(b).into_iter().skip(1) {
                whole = whole
                    && !known[c]
                    && covered_through(&support[c])
                    && !folded_back(c)
                    && buried_depth(s, c, &kept) < THROUGH_DEPTH;
                kept[c] = false;
            }
            if whole {
                lost = kept;
            }
        }
        s.unit().map_err(cancelled)?;
    }
    // Below a bridge the fit laid the lost bones on another part, often on their mirrors'
    // place: a mirror taken lost as empty had its points taken by them, and is kept (the
    // bones settled without the lost ones take their points back).
    let mut revived = vec![false; nb];
    for &b in &bridges {
        for c in t.subtree(b).into_iter().skip(1) {
            if let Some(m) = mirror[c].filter(|&m| empty_taken[m] && !known[m]) {
                lost[m] = false;
                revived[m] = true;
            }
        }
    }
    // Fed and covered: a last bone taken lost by the redundancy test alone, at its healthy
    // size, fed and covered like a present end, beside a present mirror, is kept.
    for b in 0..nb {
        if only_redundant[b] && fed_and_covered(s, support, &mirror, &lost, b) {
            lost[b] = false;
        }
    }
    // Both sides broken: a last bone examined before its mirror was taken lost is examined
    // again: lost with no point of its own, or by the laid-over-parent rule, which then has
    // no healthy mirror to compare with and asks both ends to have shrunk instead.
    for b in (0..nb).rev() {
        let again = !lost[b]
            && !revived[b]
            && t.bones[b].children.is_empty()
            && mirror[b].is_some_and(|m| lost[m]);
        if again {
            let bone = s.world.bones()[b];
            let radius = 0.5 * (bone.r1 + bone.r2) as f64;
            let empty = s.members_of(&[b]) == 0;
            let over = !empty
                && laid_over_parent(s, support, (&mirror, &trunk), &lost, b, REDUNDANT * radius);
            lost[b] = empty || over;
            over_taken[b] = over;
            s.unit().map_err(cancelled)?;
        }
    }
    // A stump: the first lost bone of a limb whose support reaches part-way along it is
    // kept (partial), the bones below it lost.
    let first: Vec<bool> = (0..nb)
        .map(|b| lost[b] && !known[b] && t.bones[b].parent.is_some_and(|p| !lost[p]))
        .collect();
    for b in 0..nb {
        if first[b] && !over_taken[b] && is_stump(s, support, &mirror, &lost, b) {
            lost[b] = false;
        }
    }
    Ok(lost)
}

/// The stump exception of [`lost_limbs`] for bone `b`, the first lost bone of a limb (its
/// parent present) not taken by the laid-over-parent rule: its support reaches
/// [`STUMP_REACH`] of its length from its first joint (counted in [`super::support::BINS`]
/// axial bins without a gap), and its parent is not longer than [`FED_LENGTH`]'s upper end
/// times its mirror's (when the mirror is present). Such a bone was cut part-way: its stump's
/// points lie along its first part, and its parent's end sphere explains them nearly as well
/// as the bone does, so the redundancy test took it; the bones below it are lost. A truly lost
/// bone's support reaches 0.0–0.2 (nothing past the joint), or 0.6–1.0 when FAKIR laid it
/// over another part; and a parent stretched over the bone (a forearm reaching the tip of
/// its hand, the hand hanging beside it) leaves the bone a stub of support at its root.
/// A stump also holds at least [`STUMP_FED`] of its present mirror's points: a bone lost
/// whole at its joint, shrunk onto the surface there, holds almost none. With its mirror lost
/// too (both sides broken), at least [`STUMP_FED_ALONE`] of the points expected of a bone of
/// its size ([`unfed_alone`]).
fn is_stump(
    s: &Solver,
    support: &[BoneSupport],
    mirror: &[Option<usize>],
    lost: &[bool],
    b: usize,
) -> bool {
    let t = &s.world.template;
    let Some(p) = t.bones[b].parent else {
        return false;
    };
    let l = &s.world.lengths;
    let parent_stretched = mirror[p]
        .filter(|&m| !lost[m])
        .is_some_and(|m| l[p] > FED_LENGTH.1 * l[m]);
    // A stump holds the points of the part the cut left: an end holding almost none of what
    // its present mirror holds is a bone of a limb lost at its joint, shrunk onto the joint's
    // surface (which its support then reaches part-way).
    // Both sides broken: without a healthy mirror, what a bone of its size would hold.
    let unfed = match mirror[b] {
        Some(m) if !lost[m] => unfed(s, b, m),
        Some(_) => unfed_alone(s, lost, b),
        None => false,
    };
    (STUMP_REACH.0..=STUMP_REACH.1).contains(&support[b].reach) && !parent_stretched && !unfed
}

/// Whether bone `b`, whose mirror is lost too, holds under [`STUMP_FED_ALONE`] of the points
/// expected of it: the points of the present bones (not `lost`) shared out among them and
/// `b` in proportion to their surface areas at rest (the template's spheres; the statue's
/// scale cancels). The stump rule of [`lost_limbs`] when both sides are broken, with no
/// healthy mirror to count against.
fn unfed_alone(s: &Solver, lost: &[bool], b: usize) -> bool {
    let t = &s.world.template;
    let rest_area = |c: usize| {
        let d = &t.bones[c];
        Bone::new(t.joints[d.from].rest, d.r1, t.joints[d.to].rest, d.r2).area() as f64
    };
    let present: Vec<usize> = (0..t.bones.len()).filter(|&c| !lost[c]).collect();
    let area: f64 = present.iter().map(|&c| rest_area(c)).sum();
    let expected = s.members_of(&present) as f64 * rest_area(b) / area;
    (s.members_of(&[b]) as f64) < STUMP_FED_ALONE * expected
}

/// The least share of the points expected of it ([`unfed_alone`]) that the first lost bone of
/// a limb whose mirror is lost too must hold to be kept as a stump. Our choice (2026-12-07),
/// looser evidence asking for a wider margin than [`STUMP_FED`]: the expected count comes
/// from the template's proportions, not from a healthy mirror. Measured with temporary
/// prints (`synth --seed N --rigid --height 1.7` with two `--cut bone:B@F`, 30k points,
/// `register`'s defaults), three bones cut whole at their joint on both sides were kept as
/// stumps holding 0.19 (seed 121's right hand, both hands cut at the wrists), 0.12 (seed
/// 396's left hand, the same cuts) and 0.02 (seed 393's right upper arm, both cut at the
/// shoulders) of their expected points; bones cut part-way on both sides and taken lost
/// held 0.03 and 0.10 (seed 401's feet cut at 0.4, beyond the stump rule's reach) and the
/// kept ones were not taken lost at all (seed 400's hands at 0.4, seed 390's forearms at
/// 0.5). A stump holding under a quarter of its share beside a lost mirror is lost whole.
pub const STUMP_FED_ALONE: f64 = 0.25;

/// The least share of its present mirror's points (the bone's own, not its subtree's) that
/// the first lost bone of a limb must hold to be kept as a stump (`is_stump`). Our choice
/// (2026-12-05): the stumps kept by the rule held 0.17 to 0.59 of their mirror's points at
/// the end of their registrations (seeds 304, 308, 332, 335: a shin cut at 0.2, a forearm at
/// 0.6, a shin at 0.3, a foot at 0.4). Bones lost whole at their joint (`--cut bone:B`) and
/// kept partial held 0.009 (seed 355's right foot, shrunk to half its mirror's length over
/// the shin's end, its support reaching 0.5), 0.053 and 0.072 (seeds 374 and 372: a shin and
/// a thigh, reaching 0.4).
pub const STUMP_FED: f64 = 0.1;

/// The bridge rule of [`lost_limbs`] for limb bone `b`, not lost, carrying bones not all
/// lost, not hanging from the trunk: `b` holds under [`STUMP_FED`] of its present mirror's
/// points (its own, not its subtree's) and its support reaches at most [`BRIDGE_REACH`] of
/// its length from its first joint. `mirror` and `trunk`: each bone's mirror and whether it
/// is a trunk bone. The limb was lost at `b`'s joint and the fit laid `b` across empty space to reach
/// another part with the bones below it (seed 365, `synth --seed 365 --rigid --height 1.7
/// --cut bone:l_shin`: the shin 50 points against 2,150, reaching 0.1, its foot on other
/// points; seed 353, the right shin 32 against 1,531, its foot on the left foot's place and
/// the left foot taken lost as empty). Our choice (2026-12-05): `b` and all it carries are
/// lost. Over the 200-odd `FIT.json` files of this project's evaluation runs (complete posed
/// statues, real scans, cut statues), present bones carrying present bones with this
/// signature were found only on statues whose limb was lost at that bone's joint (seeds
/// 353, 356, 365).
fn is_bridge(
    s: &Solver,
    support: &[BoneSupport],
    (mirror, trunk): (&[Option<usize>], &[bool]),
    lost: &[bool],
    b: usize,
) -> bool {
    let t = &s.world.template;
    let Some(m) = mirror[b].filter(|&m| m != b && !lost[m]) else {
        return false;
    };
    // Not a limb's first bone hanging from the trunk (whose points are the trunk's surface
    // as much as the limb's; see `lost_limbs`).
    t.bones[b].parent.is_some_and(|p| !lost[p] && !trunk[p])
        && support[b].reach <= BRIDGE_REACH
        && unfed(s, b, m)
}

/// Whether bone `b` holds under [`STUMP_FED`] of the points bone `m` (its mirror) holds,
/// each counting its own points only (the stump and bridge rules of [`lost_limbs`]).
fn unfed(s: &Solver, b: usize, m: usize) -> bool {
    (s.members_of(&[b]) as f64) < STUMP_FED * s.members_of(&[m]) as f64
}

/// The largest reach of its support (a share of its length, from its first joint) of a
/// bridge ([`is_bridge`]): one bin of [`super::support::BINS`] at most, nothing past the
/// joint.
pub const BRIDGE_REACH: f32 = 0.1;

/// The reach of its support (a share of its length, from its first joint) within which the
/// first lost bone of a limb is a stump and kept (`is_stump`).
pub const STUMP_REACH: (f32, f32) = (0.3, 0.5);

/// The laid-over-parent rule of [`lost_limbs`]: last bone `b` without support (at its
/// expected size) whose mirror has support, shorter with its parent than their mirrors (a cut
/// takes length away), and whose points the parent explains within `bound` once it reaches
/// to `b`'s end — the hand of a forearm cut at the wrist, the forearm shortened to make room.
/// When the mirror is lost (both sides broken), `b` and its mirror must both have shrunk
/// ([`super::support::SHRUNK`]) instead: the shrunk end lies on its parent's surface, so its
/// support says nothing, and there is no healthy length to compare with.
/// `mirror` and `trunk`: each bone's mirror and whether it is a trunk bone.
fn laid_over_parent(
    s: &Solver,
    support: &[BoneSupport],
    (mirror, trunk): (&[Option<usize>], &[bool]),
    lost: &[bool],
    b: usize,
    bound: f64,
) -> bool {
    let t = &s.world.template;
    let (Some(p), Some(mb)) = (t.bones[b].parent, mirror[b]) else {
        return false;
    };
    let Some(mp) = mirror[p] else {
        return false;
    };
    if !t.bones[b].children.is_empty() || trunk[p] || lost[p] || t.bones[p].kind == BoneKind::Block
    {
        return false;
    }
    // Both ends broken: the mirror was taken lost, and both ends shrank (a cut takes length
    // away on both sides; the shrunk end is covered by the parent's surface it lies on, so
    // its support says nothing).
    let both_broken = lost[mb] && support[b].shrunk && support[mb].shrunk;
    if !both_broken {
        let l = &s.world.lengths;
        if !support[b].missing
            || support[mb].missing
            || l[p] + l[b] >= OVER_PARENT_SHORTER * (l[mp] + l[mb])
        {
            return false;
        }
    }
    let all = s.world.bones();
    let reach = Bone::new(all[p].c1, all[p].r1, all[b].c2, all[p].r2);
    s.removal_excess_with(b, lost, Some((p, reach)))
        .is_some_and(|e| e < bound)
}

/// The fed-and-covered exception of [`lost_limbs`] for last bone `b` (a hand, a foot, taken
/// lost by the redundancy test alone): its parent and its mirror are not `lost`, it holds at
/// least [`STARVED`] of its mirror's points (not starved), the scan covers at least
/// [`super::support::PARTIAL`] of its surface at its expected size, and its fitted length
/// lies within [`FED_LENGTH`] of its mirror's (neither shrunk onto a stump nor stretched over
/// its parent). The mirror must look present too (covered as much, not shrunk): a mirror
/// not yet taken lost may be the other end of a statue broken on both sides, which the
/// both-sides-broken examination of [`lost_limbs`] takes later. Such an end has the points,
/// the surface and the size of a present one; the redundancy test took it because the bone
/// it joins explains its points nearly as well (a foot cut at half its length, whose heel
/// the shin's ankle sphere explains).
fn fed_and_covered(
    s: &Solver,
    support: &[BoneSupport],
    mirror: &[Option<usize>],
    lost: &[bool],
    b: usize,
) -> bool {
    let t = &s.world.template;
    let (Some(p), Some(m)) = (t.bones[b].parent, mirror[b]) else {
        return false;
    };
    if !t.bones[b].children.is_empty() || lost[p] || lost[m] {
        return false;
    }
    let (own, theirs) = (s.members_of(&[b]), s.members_of(&[m]));
    let l = &s.world.lengths;
    let ratio = l[b] / l[m].max(f32::MIN_POSITIVE);
    own as f64 >= STARVED * theirs as f64
        && support[b].coverage >= super::support::PARTIAL
        && (FED_LENGTH.0..=FED_LENGTH.1).contains(&ratio)
        && support[m].coverage >= super::support::PARTIAL
        && !support[m].shrunk
}

/// The range of fitted length, as a share of the mirror's, within which a last bone can be
/// fed and covered (`fed_and_covered`): [`super::support::SHRUNK`] to its inverse.
pub const FED_LENGTH: (f32, f32) = (super::support::SHRUNK, 1.0 / super::support::SHRUNK);

/// Whether the scan covers a bone from end to end: coverage at least
/// [`super::support::PARTIAL`] and reach at least [`THROUGH_REACH`] ([`lost_limbs`]).
fn covered_through(support: &BoneSupport) -> bool {
    support.coverage >= super::support::PARTIAL && support.reach >= THROUGH_REACH
}

/// The reach from which a bone counts as covered from end to end (`covered_through`).
pub const THROUGH_REACH: f32 = 0.9;

/// The depth (in the bone's mean radii, `buried_depth`) from which a bone covered through
/// is buried in the other bones and stays lost (`lost_limbs`).
pub const THROUGH_DEPTH: f32 = 1.5;

/// How deep bone `b`'s axis lies inside the other bones (those not below it and not
/// `lost`), in `b`'s mean radii: the mean, over 9 points evenly spaced along the axis
/// (a tenth to nine tenths), of the smallest signed distance to those bones, negated
/// (positive inside, negative outside; 0 when there is no other bone). The exact signed
/// distance ([`PreparedBone::signed_distance`]), not [`crate::geometry::bone::nearest_bone`]'s
/// `sdf_fast`, which only bounds the depth inside from below ([`THROUGH_DEPTH`] was measured
/// with the exact one).
fn buried_depth(s: &Solver, b: usize, lost: &[bool]) -> f32 {
    let t = &s.world.template;
    let below = t.subtree(b);
    let all = s.world.bones();
    let others: Vec<PreparedBone> = (0..all.len())
        .filter(|x| !below.contains(x) && !lost[*x])
        .map(|x| all[x].prepare())
        .collect();
    if others.is_empty() {
        return 0.0;
    }
    let bone = all[b];
    let radius = 0.5 * (bone.r1 + bone.r2);
    let depth: f32 = (1..10)
        .map(|k| {
            let q = bone.c1.lerp(bone.c2, k as f32 / 10.0);
            let d = others
                .iter()
                .map(|o| o.signed_distance(q))
                .fold(f32::INFINITY, f32::min);
            -d
        })
        .sum();
    depth / 9.0 / radius.max(f32::MIN_POSITIVE)
}

/// A last bone laid over its parent (`lost_limbs`) is only lost when the two together are
/// shorter than this fraction of their mirrors.
pub const OVER_PARENT_SHORTER: f32 = 0.8;

/// A subtree whose removal costs its points less than this fraction of the bone's mean
/// radius on average is redundant (`lost_limbs`).
pub const REDUNDANT: f64 = 0.25;

/// A limb subtree holding fewer than this fraction of the points its mirror's subtree holds
/// is **starved** (`lost_limbs`).
pub const STARVED: f64 = 0.25;

/// The redundancy bound (a fraction of the bone's mean radius, like [`REDUNDANT`]) of a
/// starved subtree (`lost_limbs`).
pub const STARVED_REDUNDANT: f64 = 0.5;

/// Level 6: the lost bones (`missing`) are given their expected size and pose
/// ([`super::support::complete`]: the healthy mirror limb's, or the template's), stop taking
/// points, and the rest of the skeleton is refined at the current level without them
/// (`final_iterations` whole-skeleton iterations, each limb fitted up to where it broke); the
/// lost bones are completed again from the refined mirror. Returns the iterations run.
pub(super) fn settle_lost_limbs(
    s: &mut Solver,
    missing: &[bool],
    opts: &RegistrationOptions,
) -> Result<usize> {
    let healthy: Vec<bool> = missing.iter().map(|m| !m).collect();
    let completed = |s: &Solver| {
        WorldSkeleton::from_skeleton(&complete_with(
            &s.world.to_skeleton(),
            missing,
            Some(&healthy),
        ))
    };
    s.world = completed(s);
    s.set_absent(missing).map_err(cancelled)?;
    let fine = ScheduleSettings {
        max_iterations: opts.final_iterations.max(1),
        ..opts.schedule.clone()
    };
    let iterations = register_skeleton(s, &fine, false).map_err(cancelled)?;
    s.world = completed(s);
    s.refresh().map_err(cancelled)?;
    Ok(iterations)
}

/// How [`lost_limbs`] treats a limb bone folded back onto its parent beyond [`FOLDED`]
/// ([`WorldSkeleton::fold_angle`]) when the covered-through exception would keep it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Folds {
    /// As any other bone: the folded-limbs check (level 5) asks which folds the rules take
    /// before it tries to unfold the others, and a complete limb folded by the fit (an upper
    /// arm stretched to the hand, the forearm laid back along it) is one it must still try.
    Unfoldable,
    /// Not covered through (level 6 and the checks after the folded-limbs check): a fold
    /// that the check did not undo, or that it left to these rules, is a limb laid back
    /// onto its stump, not one lying against another part.
    Lost,
}
