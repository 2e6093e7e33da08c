//! The resumable registration: [`Registration::new`], [`Registration::step`] with a time
//! budget, [`Registration::run_to_convergence`].
//!
//! ## Levels
//! 0. **Base** (our addition; [`crate::cloud::base`]): a plinth under the figure is found
//!    (option `base`), set aside, and the figure alone is registered; its top face's normal
//!    becomes the up hint (it replaces a given hint within 30° of it: a scan tilted on its
//!    plinth gets its true up). The base's points get [`BASE_LABEL`].
//! 1. **Initialisation** ([`super::init`]): candidate placements, each tried with a short
//!    registration on a small subsample; the best is kept.
//! 2. **Level 0**: the whole-skeleton schedule ([`super::schedule`]) on a random subsample
//!    (`subsample` points, default 8000) until convergence, from each of the `finalists`
//!    (default 5) best candidates; the lowest two-sided score (mean distance + occupancy,
//!    [`super::solver::Solver::occupancy`]) is kept, near-ties going to the most plausible
//!    pose ([`super::init::implausibility`]).
//! 3. **Scale restarts** ([`super::init`], step 7): the chosen finalist's orientation is
//!    registered again on the same points from each of `rescales` times its scale; the
//!    lowest two-sided score among these and the finalist wins (ties to the finalist).
//!    **Facing check** (our choice; skipped with a facing hint or a given skeleton): the
//!    winner is turned around ([`WorldSkeleton::turned_around`]: the same limbs with left
//!    and right exchanged, the trunk facing the other way) and registered again on the same
//!    points; the finalists' rule decides between the two (`preferred`). A human seen from
//!    the front or the back is nearly the same surface, so the two facings' scores are close
//!    and a fit can settle facing backwards; facing the wrong way its knees, elbows and feet
//!    bend outside their ranges.
//! 4. **Level 1** (clouds larger than the subsample): the assignment is redone on all points
//!    and the schedule refines the skeleton (`final_iterations` whole-skeleton iterations,
//!    default 2: over 32 synthetic statues a second one lowered the mean joint error from
//!    3.54% to 3.47% of the height for 2% more time).
//! 5. **Refits and limb resets** (our choice): the fit is registered again at level 0 from
//!    itself, as a fresh start — its limbs seeded again and its chains recalibrated by the
//!    initial forward pass from where they settled — and, beside it, from each **limb
//!    reset** ([`limb_reset`]): the fit with one limb chain (a chain of no trunk bone; the
//!    human's legs and arms) put back at the template's rest pose relative to the joint it
//!    hangs from, with the template's proportions at the fit's scale, so the seeding aims it
//!    afresh and its lengths are found again. The lowest two-sided score on the level-0
//!    points among these starts (ties to the plain refit) replaces the fit when it is lower
//!    than the fit's own, and is refined at level 1 again. Rounds go on while one lowers the
//!    score, at most `refits` (default 4). FAKIR's passes slide a joint along a smooth trunk
//!    or limb slowly and stop when a pass gains little, and a limb that settled on the wrong
//!    part keeps its wrong lengths through every later pass: started from the true
//!    skeleton, synthetic statues end with a mean distance 10 to 280 times lower than the
//!    fits found from the automatic placement. Over 32 synthetic statues (`synth --seed N
//!    --rigid --height 1.7`, seeds 1–32, 30k points) the statues under 2% of the height in
//!    mean joint error went from 19 (2 plain refits) to 21 (2 rounds with limb resets) and
//!    24 (4 rounds), the median error from 1.67% to 0.98% and 0.77%, the mean from 3.08%
//!    to 2.56% and 2.14%. Limb resets are skipped from a given skeleton (it is kept as
//!    started) and for lost limbs.
//!
//!    **Up-down check** (our choice; option `flip`, skipped from a given skeleton): the
//!    placements come in pairs of opposite up directions along the cloud's long axis
//!    ([`super::init`]), and the finalists' rule can keep an upside-down one when the
//!    upright finalists' level-0 fits are worse. A figure that lost a leg through the
//!    thigh is the usual case: upright, the lost leg's bones have no points and wander
//!    onto the other leg, and the level-0 fits from the upright placements score above
//!    the upside-down ones (the arms in the legs, the one leg in the head and neck). Told
//!    its up (`--up`), such a statue is fitted with a mean distance half to a ninth of the
//!    upside-down fit's. So when a finalist of the other up direction than the chosen one
//!    was registered, the best of them (lowest score) is registered again from its
//!    level-0 fit through level 1 and the refit rounds, and wins with the lower score. It
//!    runs first, before the second facing check; with an up hint (given, or a plinth's)
//!    every placement has the same up and it never runs. Measured on 12 synthetic statues
//!    cut through a thigh (`synth --seed N --rigid --height 1.7 --cut bone:l_thigh@0.5`
//!    and the like, 30k points; seeds 43–49, 68, 70, 73, 74, 81), joint error over the
//!    joints the scan has: seed 68 47.5% → 9.2%, seed 81 42.0% → 4.8%, seed 46 27.4% →
//!    48.2% (wrong either way), nine unchanged. On the 24 posed complete statues of seeds
//!    1–24 (`fakir/accuracy_posed`'s kind) it ran on six and lost each time, the upside-down
//!    fit scoring 3.2 to 15 times the fit's, so none changed; those six pay one more
//!    registration.
//!    The flipped finalist's level-0 fit can be poor where the other up holds a much better
//!    one: seed 47 cut through the right thigh, told its up, scored 0.0175 after the refit
//!    rounds, against 0.0393 for the upside-down fit kept and 0.052 for the flipped
//!    finalist registered again. So the check goes on: the other up direction is searched
//!    as a given up hint is (`FullRun::search`: the placements about it, their short
//!    registrations, the best `finalists` at level 0), and the finalists' rule's pick is
//!    registered again through level 1 and the refit rounds; it too wins with the lower
//!    score. Over the same 12 statues (joints the scan has): seed 47 46.7% → 4.1%, seed 68
//!    9.2% → 0.9%, seed 81 4.8% → 6.4% (a lower score, but its right hand now taken lost),
//!    43, 44, 45, 48, 49, 70 and 73 unchanged; 46 (still wrong, 48.2% → 41.1%) and 74
//!    (unchanged) were run with a first version only (45, 46 and 74 are upright and wrong;
//!    told their up, a search finds scores 0.0083, 0.0283 and 0.0185 against their fits'
//!    0.0167, 0.031 and 0.0276). A search about the up of the fit's own trunk was built
//!    and measured on the 12 (README, "A search about the fit's own up"): it mended seed 74
//!    (29.1% → 2.2%) but broke seed 49 (3.8% → 22.0%) and got the lost set right on 6
//!    instead of 8, for 1.1 to 2.3 times the work units; not kept. On the six posed
//!    complete statues where the check runs the fits are the same, for 1.05 to 1.39 times
//!    the work units.
//!
//!    **Tilted-up check** (our choice; option `flip`, run only when nothing gave the up: no up
//!    hint, no plinth, no anchor, no given skeleton): the placements align the template's long
//!    axis with the cloud's, and a posed figure's trunk can lie far from that axis (a leg lost
//!    through the thigh, limbs spread). FAKIR then settles the trunk tilted, with its limbs on
//!    the wrong parts, and no later pass turns it back: seed 303 cut through the right thigh
//!    ended with its trunk 34° off (7.50% of the height in joint error over the joints the
//!    scan has), and told its true up it is fitted at 0.54%. A fit whose mean distance after
//!    the up-down check is above [`POOR_FIT`] (0.4%) of the statue's size is searched again
//!    about four ups tilted [`TILT`] (30°) from its own, towards its front, back and sides
//!    (`FullRun::search`: each up's placements, their short registrations, the best
//!    `finalists` of them all at level 0); the finalists' rule's pick is registered through
//!    level 1 and the refit rounds and wins with the lower score. A fit with no level-1 pass
//!    (a cloud within the subsample) is always searched, by this check and by the scale
//!    search below ([`poor`]: its distances are not measured yet there, and judging it by
//!    them made small statues' fits worse). Measured (30k points, CLI defaults; the mean
//!    distance at the check, as a fraction of the size, in brackets): seed 303 (0.70%)
//!    7.50% → 0.77%; seed 318, left shin cut at 0.8 (0.45%), 8.26% → 0.53%;
//!    stylised figures (`--symmetric --jitter 0.5`) seed 204 (0.59%) 27.5% → 1.26%, no longer
//!    reporting a healthy foot lost, and ±50% proportions (`--jitter 0.5`) seed 10 (0.44%)
//!    9.77% → 2.14%, no longer reporting a healthy arm lost, seed 11 (0.55%) 14.1% → 6.6%,
//!    seed 1 (0.80%) unchanged at 3.13% (the challenger lost). But seed 309, right hand cut at
//!    0.5 (0.44%), went from 1.21% to 1.84% and now reports that hand lost: its lower score
//!    went to a worse fit. At 0.5% instead of 0.4% the check would have left 318, 10 and 309
//!    alone. It did not run on the 13 other statues measured (seeds 5, 6 and 8, complete, at
//!    0.06–0.20%; cuts 301, 305 and 315 at 0.20–0.34%; stylised 205 and 208, ±50% 4 and 7 at
//!    0.16–0.40%).
//!
//!    **Scale search** (our choice; option `search_scales`, default ×0.8 and ×1.25; skipped
//!    from a given skeleton): the placements take their scale from the cloud's extent along
//!    its long axis ([`super::init`], step 2), and a figure whose proportions are far from
//!    the template's can settle at a wrong scale that neither the scale restarts (×0.88,
//!    ×1.12 of the chosen orientation, before the refits) nor any later pass leaves: the
//!    stylised seed 207 (`synth --seed 207 --rigid --height 1.7 --symmetric --jitter 0.5`)
//!    ended with its pelvis block at 1.56–1.58 times the template against its truth's 1.315,
//!    the trunk reaching into the raised right hand (9.96% of the height in joint error), and
//!    the squat stylised 213 upside down at 2.29 against 1.36 (44.6%). A fit whose mean
//!    distance after the tilted-up check is still above [`POOR_FIT`] of the statue's size is
//!    searched again from the statue's own placements (its `Init`: every principal-axis
//!    alignment, or the headings about its up hint) rescaled by each factor about the
//!    scale restarts' pivot (`FullRun::search`: their short registrations, the best
//!    `finalists` of them all at level 0); the finalists' rule's pick is registered through
//!    level 1 and the refit rounds and wins with the lower score. Measured (30k points, CLI
//!    defaults, stylised `--symmetric --jitter 0.5`; joint error): 202 2.39% → 0.68%, 207
//!    9.96% → 2.90%, 210 3.09% → 1.82% (its healthy right hand no longer taken lost), 213
//!    44.6% → 2.64%, 215 4.62% → 0.80%, for 0.73 to 2.28 times the work units. These five
//!    were every fit above the bound among 40 statues (posed 1–16, stylised 201–216, posed 1–8
//!    with normal noise); the others end at 0.37% of their size or less. More placements
//!    from the start instead (every alignment at ×0.8, ×1 and ×1.25, the finalists picked
//!    among all 48) mended 202 but broke 204 (1.26% → 4.66%): they crowded the right
//!    placement out of the finalists.
//!
//!    **Second facing check** (our choice; skipped like the first): a fit that ends the
//!    rounds with its joints far outside their ranges ([`super::init::implausibility`] above
//!    `recheck_facing_above`, default 3 rad) is turned around and registered again from
//!    there through level 0, level 1 and the refit rounds. The turned fit replaces it only
//!    when it has both the lower two-sided score on the level-0 points and the lower
//!    implausibility. The first check compares a turned fit registered once against the
//!    best of the finalists and scale restarts, before the refits have put the limbs right,
//!    and implausibility is high on both sides while the limbs are still wrong. After the
//!    refits both facings have had the same treatment. Neither measure suffices alone: a
//!    human's front and back are nearly the same surface, and a mediocre fit facing front
//!    can score worse than a neat one facing backwards (seed 13 below: 0.0240 against
//!    0.0137, with implausibilities 4.7 and 6.3 rad), while the score tells a better fit
//!    from a worse one of the same facing. Good fits of synthetic statues end at 0–3.6
//!    rad (hands and feet are rarely exact), fits facing backwards at 5.4 and 7.8 rad.
//!    Over the 32 synthetic statues above it ran on 8 and turned one (seed 14: 21.8% →
//!    0.73% joint error): under 2% 24 → 25, under 5% 29 → 30, mean 2.14% → 1.48%. On 40
//!    more (seeds 33–72) it turned one (seed 35: 22.3% → 3.0%), mean 2.16% → 1.68%.
//!    Real scans end the rounds at 3.9–17.9 rad (stylised or broken figures, animals), so
//!    the check runs on each of them (about 1.4–1.8 times the time); of the 18 in
//!    `../shared/data` it turned TOSCA *Michael 1*, fitted facing backwards before (7.2 →
//!    2.5 rad), and kept six fits whose turned versions scored lower but bent further out of
//!    range.
//!
//!    **Crossed-limbs check** (our choice; option `uncross`, skipped from a given skeleton):
//!    a fit in which a pair of mirrored limb bones is crossed
//!    ([`WorldSkeleton::most_crossed`]: exchanging the two bones' ends would make them
//!    shorter, as it always does for segments that intersect) has laid each limb's lower
//!    part on the other limb — a thigh from its hip to the other knee. Limbs do not pass
//!    through one another, and the refit rounds had not undone it on the statues below.
//!    The most crossed pair's lower limbs are exchanged ([`WorldSkeleton::exchanged_below`]:
//!    each of the two bones reaches to the other's end, what hangs below takes its mirror's
//!    place and sizes) and that start goes through level 0, level 1 and the refit rounds;
//!    it replaces the fit when it has the lower two-sided score on the level-0 points. No
//!    true skeleton of the generator's statues has a crossed pair (the lowest ratio of
//!    exchanged to straight lengths over 72 of them: 1.1), so the check costs nothing on a
//!    fit that is not crossed; on one that is, it costs about as much again.
//!
//!    **Crossed-over-limb check** (our choice; same option, run after the crossing check): on
//!    a statue cut through a thigh FAKIR can lay the cut leg from its hip over to the other
//!    knee and down the healthy leg, and leave the healthy leg's shin and foot folded at that
//!    knee with almost no points. Nothing is crossed (the two thighs end together), and
//!    level 6 then takes nothing lost, or the healthy leg. Trigger
//!    ([`WorldSkeleton::most_crossed_over`]): a limb bone whose subtree holds fewer than
//!    [`STARVED`] times the points of its mirror's, below a bone that ends within
//!    [`CROSSED_OVER_NEAR`] of the longer length from its own mirror's end. Start: the limbs
//!    below that pair exchanged ([`WorldSkeleton::exchanged_below`]); lower score wins.
//!    Measured (30k points, CLI defaults): on 13 statues cut through a thigh it fired on
//!    four: seed 62 cut at 0.3 3.54% → 0.94% (the joints the scan has), its left shin and
//!    foot now found lost; seed 72 2.48% → 0.12%, the cut leg found lost instead of the
//!    healthy one (whose thigh the fit had collapsed: measured against the shorter length
//!    the check missed it); seed 68 cut at 0.3 4.44% → 1.42%, no longer taking the healthy
//!    leg lost; seed 73 13.88% → 7.87%, but with a healthy forearm and hand now lost. It
//!    fired on none of the 72 complete statues nor on four arm and shin cuts.
//!
//!    **Folded-limbs check** (our choice; option `unfold`, skipped likewise): a fit in which
//!    a joint inside a limb chain turns back by more than [`FOLDED`] (150°;
//!    [`WorldSkeleton::most_folded`]) has stretched a bone over the limb below it and laid
//!    the next bone back along it — an upper arm from the shoulder to the hand, the forearm
//!    back to the elbow. The built-in human's joint ranges allow 125° at most, and the
//!    generator's statues reach 122°. The chain from the folded bone on is laid straight
//!    from its first joint to its end, in the template's rest proportions
//!    ([`WorldSkeleton::unfolded`]), and that start goes through levels 0, 1 and the refit
//!    rounds, winning with the lower score. A limb reset does not do this: it puts the limb
//!    back at the template's lengths at rest, where the seeding aims it onto the same part
//!    again. Below a cut, FAKIR folds the limb's remaining bones back onto the stump too,
//!    and there the unfolded fit also scores lower (its bones share the stump's points)
//!    but hides the loss from level 6: on a statue cut through the right upper arm (seed 21,
//!    6000 points) the lost arm was no longer found. So folds whose bones the lost-limb
//!    rules of level 6 take on the fit as it stands are left out. The three checks run after
//!    the second facing check: crossing, crossing over, folding.
//!
//!    Measured (`synth --seed N --rigid --height 1.7`, 30k points): on seeds 1–32 the
//!    crossing check ran on seed 13 (crossed shins; joint error 6.45% → 0.89%) and the
//!    folding check on seeds 12 (3.34% → 0.96%) and 25 (4.48% → 1.21%): under 2% 25 → 28,
//!    under 5% 30 → 31, mean 1.52% → 1.17%. Of seeds 33–72, the folding check won on 38
//!    (3.56% → 0.49%) and 46 (2.76% → 0.38%) and lost on 35, and the crossing check won on
//!    64 (8.84% → 1.79%). On the 18 scans of `../shared/data` the fits of four changed (mean
//!    distance: *Dancing Faun* 0.83% → 0.72% of its size, its legs now reaching both feet;
//!    *Dancing Girl* 1.11% → 1.06%; TOSCA *Victoria 2* 1.12% → 1.09%; *Michael 12* 0.90% →
//!    0.88%), and no lost set did.
//!    On statues cut part-way through a limb (seeds 40–69) the crossing check ran on three
//!    cut through a thigh and won on one (seed 55: 0.83% → 0.30% over the joints the scan
//!    has). The folding check, run again on the four cut statues whose fits showed a fold
//!    (the others were not run again with it), won on seeds 40 (0.43% → 0.18%) and 57
//!    (3.15% → 3.16%; it now reports its forearm, cut at a tenth of its length, with the
//!    hand), lost on seed 64 and did not run on 65.
//!
//!    **Slid-block and slid-limb checks** (our choice; option `slide`, skipped from a given
//!    skeleton): a limb bone hanging from the root block (a thigh) whose support does not
//!    reach its first joint ([`super::support`]: `reach` under [`UNCOVERED_REACH`], while
//!    its coverage says it is there) starts where there is no limb. On crouching figures
//!    FAKIR can sit the pelvis one bone too high up the spine — the whole block moved by
//!    its spine bone, the thighs starting above the legs, a knee bent where there is none —
//!    or a leg one bone up its own length (the knee at the hip, the ankle at the knee, the
//!    thigh in the trunk): local minima that FAKIR's passes do not leave, and the refit
//!    rounds had not undone them. When every limb bone on the block is uncovered, the
//!    block is slid one bone down ([`WorldSkeleton::slid_block`]: moved by minus its spine
//!    bone, the bones hanging from it re-aimed at their old ends); then, when a limb bone on
//!    the block is still uncovered, the least covered one's chain is slid one bone down
//!    ([`WorldSkeleton::slid_down`]: each joint moved to where the next one was). They run
//!    last, after the folding check. Each start goes through levels 0, 1 and the refit
//!    rounds and wins with the lower score, as the other checks' do; the support is
//!    measured once for both (and its k-d tree kept for level 6), so a fit where neither
//!    runs pays a few milliseconds. On the fits of seeds 1–32 made without the checks only
//!    seeds 1 and 31 had a thigh whose reach was under 0.5 (both thighs at 0): seed 1's
//!    block slid down (4.61% → 1.90%), seed 31's block and then its left leg (3.71% →
//!    0.43%). Of seeds 33–72, 52 (2.72% → 1.30%, but now with a right foot wrongly found
//!    lost), 67 (2.24%, unchanged) and 68 had one. A missing limb (coverage under
//!    [`super::support::MISSING`]) and a limb known lost are left to level 6. On real scans
//!    a thigh under drapery, or an animal's hind leg, is often uncovered at its root too,
//!    and the checks run there (see the README's figures), at the cost of one or two more
//!    registrations.
//!    **A squeezed end** (our choice, 2026-11-28) runs the slid-block check too: a pelvis
//!    sat one bone up the spine leaves the chain above it one bone short, and its last two
//!    bones (the neck and head) are squeezed into what is left. When they take less than
//!    [`SQUEEZED_END`] of their share of the trunk chain at rest
//!    ([`WorldSkeleton::trunk_end_share`]) the block is slid down whatever the thighs'
//!    cover. Seed 6 (39k points) had its thighs starting wide enough to cover the hips, so
//!    the uncovered-thigh trigger missed it, and its neck and head at 0.43 of their share:
//!    3.76% → 1.42% of the height. Of 20 more complete figures (seeds 1–12 at ±30%,
//!    201–208 symmetric at ±50%) it ran on seed 12 (1.33% → 1.25%); of the 12 thigh cuts on
//!    43 and 49 (unchanged) and 44 (4.00% → 2.62% over the joints the scan has), for 1.13 to
//!    1.46 times the work units. (Seed 202's final fit measures 0.50 but the check did not
//!    run: the share is taken when the check runs, and the fit changes after it; the other
//!    figures' final fits measure 0.70 and more and were not run again.)
//!    **The trunk reset** (our choice, 2026-11-29; same option): a trunk still squeezed at
//!    its end after the slid-block check ([`WorldSkeleton::trunk_end_share`] under
//!    [`SQUEEZED_END`], measured again on the fit as that check left it) has its spine slid
//!    up past a pelvis that sits in place: the spine's top in the head, the neck and head
//!    shrunk above it. The trunk chain and all it carries are put back at the template's rest
//!    pose and proportions on the block ([`limb_reset`] of [`WorldSkeleton::trunk_chain`],
//!    at the fit's block scale), and that start goes through levels 0, 1 and the refit
//!    rounds, winning with the lower score. Seed 6 (30k points) read without its normals
//!    (estimated from the positions, as `register` does) ended so, its neck and head at 0.25
//!    of their share: 4.43% → 1.22% of the height.
//!
//!    **Hanging-limb and stretched-end checks** (our choice; same option, run after the
//!    slid checks, on their support measured again after the slid-limb check, whose fit may
//!    have won): two faults of the arms. A fit can run an arm
//!    backwards — the clavicle out to the hand across empty space, the arm coming back to
//!    the shoulder — or sit it one joint in — the elbow on the shoulder, the wrist on the
//!    elbow, the hand stretched over the forearm and the hand. *Hanging*: a limb bone under
//!    `MISSING` coverage with at least two bones below it in its chain, all covered
//!    ([`WorldSkeleton::most_hanging`]; a limb cannot hang from a bone that is not there; a
//!    lost limb has its tips uncovered too); the chain below it is turned around
//!    ([`WorldSkeleton::reversed_below`]: the bone reaches the old tip, the bones below are
//!    laid back along the old path). *Stretched end*: a limb chain of three bones or more
//!    whose last bone is longer, relative to the bone before it, than [`STRETCHED_END`]
//!    times the template's rest ratio ([`WorldSkeleton::most_stretched_end`]); the chain is
//!    slid one bone out ([`WorldSkeleton::slid_out`]: each joint to the next one's place, the
//!    old last bone split between the last two in rest proportions, the tip kept). The
//!    trigger is loose on purpose: on the generator's truths 26 of 288 limb chains exceed
//!    it (their ±30% jitter reaches 1.74), so it runs on some well-fitted limbs too and the
//!    lower score decides, as for every check. Measured (30k points, CLI defaults):
//!    seed 33 6.30% → 2.30%, 35 2.99% → 1.73%, 41 3.72% → 0.84%, 43 2.20% → 0.31% and 1
//!    1.90% → 0.28% (its right leg) by the stretched-end check; seed 37 6.28% → 2.38% by the
//!    hanging-limb check (its pelvis still sits a bone high, with the thighs stretched to the
//!    knees and covered, so the slid-block check does not see it).
//!
//!    **Crowded-head check** (our choice, 2026-12-05; same option, run after the
//!    stretched-end check): a fit can sit an arm one joint up its own length — the clavicle
//!    reaching into the head, the upper arm from the head to the true shoulder, each joint on
//!    the place of the one before — and push the head aside, onto the other shoulder or a
//!    raised arm. FAKIR's passes do not leave that minimum, and neither the limb resets
//!    (the arm reset alone finds the head's points taken) nor a reset of the neck and head
//!    alone (the spine below them is bent towards where the head went) nor the trunk reset
//!    (trunk and arms at rest together: the seeding aims the arm into the head again) did.
//!    Trigger: a bone of the trunk's end ([`WorldSkeleton::trunk_end`]: the trunk chain past
//!    the last bone carrying another chain, the human's neck and head) under
//!    [`super::support::PARTIAL`] coverage. Start, for each chain beside the end in turn (the
//!    arms) while the end is still under it: the trunk chain put back at rest on the block
//!    ([`WorldSkeleton::at_rest`]: the arms keep their world directions and hang from the
//!    moved spine top), that arm slid one bone down ([`WorldSkeleton::slid_down`]). Lower score
//!    wins. Measured (release `register`, CLI defaults) on the 16 statues of
//!    `fakir/accuracy_posed` and the stylised 201–208: it fires on five — seed 11 (46,500
//!    points, its right arm slid into the head) 5.29% → 0.22%, seed 5 0.80% → 0.75%, seed 6
//!    1.13% → 0.53% (no longer a healthy left hand found lost), stylised 208 4.53% → 2.05% —
//!    but stylised 207 goes from 6.01% to 9.96%: its right arm, raised above the head, slid
//!    down by the second start, which scores lower. 1.36 to 1.72 times their work units; the
//!    19 others are the same fits. Seed 11, from its true skeleton (`--start`), ends at a mean
//!    distance 36 times lower than the fit before the check: a search fault, not the
//!    energy's.
//!
//!    **Dangling-end check** (our choice; same option, run last): a fit can stretch a
//!    forearm over the hand, its far end on the true hand's tip, and leave the hand beside
//!    it, off the statue or on points the forearm explains as well — level 6 then finds a
//!    hand lost on a complete statue. Trigger: the last bone of a limb chain that the
//!    lost-limb rules of level 6 (`lost_limbs`, run here on the current fit) would take,
//!    at full size (not shrunk: FAKIR shrinks the bones of a limb cut at the wrist onto the
//!    stump), below a bone neither lost nor under `MISSING` coverage; or below a bone that
//!    is not lost but collapsed and under `MISSING` coverage, an arm folded up on itself
//!    ([`WorldSkeleton::most_dangling_end`]). Start: that bone and the last share its vector
//!    in rest proportions ([`WorldSkeleton::split_end`]: the last bone ends where the bone
//!    before it ended). Lower score wins. Of the 72 seeds only the four with a hand found
//!    lost trigger it: 10 (1.77% → 0.66%), 33 (2.30% → 0.75%) and 55 (1.37% → 1.53%, its
//!    arm now right to 0.8% but its head refitted worse) lose their false loss; 15 (its arm
//!    folded up: upper arm, forearm and hand collapsed, the forearm uncovered) triggers
//!    through the folded-up case: 6.76% → 1.31%, nothing lost. On 8 statues cut through a
//!    hand, a forearm or a foot (seeds 101–108) it fired once (a foot cut at the ankle), and
//!    the foot was still found lost; the folded-up case fires on none of 14 (101–114).
//!
//!    **Overreaching-limb check** (our choice; same option, in the dangling-end check's
//!    place when that one does not fire): a fit can stretch a limb bone over the next one —
//!    a thigh from the hip to the ankle, the shin laid on the foot, the foot pushed off the
//!    statue — and level 6 then takes the limb's end lost. Trigger
//!    ([`WorldSkeleton::most_overreaching`]): a limb chain whose last bones level 6 would
//!    take (the *tail*, below a bone neither lost nor under `MISSING` coverage, their
//!    mirrors not lost) and whose bones above the tail are longer together than their
//!    mirrors by [`OVERREACH`] of the mirror of the tail's first bone or more. Start: the
//!    chain slid back one bone from the bone above the tail longest relative to its mirror
//!    ([`WorldSkeleton::slid_back`]: it and the next share its vector in rest proportions,
//!    each later bone takes the vector of the one before). Lower score wins. It runs only
//!    where the lost-limb rules would take a limb lost, so it changes none of the 72
//!    complete statues' fits (none has a limb taken lost). Where the dangling-end check
//!    fires first (an end left at full size below a covered bone) that check's start is
//!    taken, so this one mostly sees ends FAKIR has shrunk. To see it at work the fits were
//!    perturbed: with an LM loop stopped early (a trial change tried and not kept, see the
//!    README), 7 complete statues out of 128 fits had an end taken lost; on those it fired
//!    on three and won on two (seed 24: a forearm stretched over the hand, 1.45% → 0.39%, nothing lost;
//!    seed 36: an upper arm stretched over the forearm, forearm and hand lost, 2.66% →
//!    0.54%, nothing lost) and lost on the third (a thigh over the shin). On the 10
//!    statues cut below the knee or elbow (seeds 90–99) it fires on none, on 2 of 17 cut
//!    through a thigh, an upper arm, a shin or a forearm (seeds 43, 62, 68, 70–81; one kept
//!    the old fit, 0.40% → 0.43% on the other).
//!    Of five real scans it fired on *Maria* only: its right clavicle had stretched to 0.82
//!    against 0.15 for the left, and is 0.22 now.
//! 6. **Lost limbs** (our choice; option `missing`; the rules live in [`super::lost`]): the
//!    papers note that FAKIR "cannot predict the right length or angle" of a bone whose data is
//!    missing (thesis §2.5.1); in practice the bones of a cut limb fold back onto the stump or
//!    wander onto other parts and take their points. The support of every bone is measured on the
//!    level-0 points ([`super::support`]), and from the tips inwards a limb bone whose children are
//!    all lost is lost when its subtree is redundant (its points lie almost as close to the other
//!    bones; more loosely so when it is starved, with a quarter of the points of its mirror's
//!    subtree) or when it is bare (no support and no points of its own: `lost_limbs`). A hand or
//!    foot laid over its parent is lost too, and one whose mirror was taken lost is examined again
//!    (both hands or both feet broken: `lost_limbs`); one taken lost by the redundancy test alone
//!    is kept when it has the points, coverage and length of a present end beside a present mirror
//!    (fed and covered: `lost_limbs`). The first lost bone of a limb whose support reaches 0.3 to
//!    0.5 of its length from its first joint is kept as a stump, the bones below it lost
//!    (`is_stump`: not a hand laid over its parent, nor below a parent stretched past its mirror,
//!    and holding at least a tenth of its mirror's points). A limb bone carrying present bones is a
//!    **bridge**, lost with all it carries, when it holds under a tenth of its mirror's points and
//!    its support does not reach past its joint (`is_bridge`: the limb was lost at that joint and
//!    the fit laid the bones below on another part); a mirror bone taken lost as empty below it is
//!    kept (they had taken its points). A limb taken lost though the scan covers it from end to end
//!    is kept (covered through: a forearm resting on a thigh), unless its axis lies deep in the
//!    other bones or one of its bones is folded back onto its parent beyond [`FOLDED`] (a limb laid
//!    back onto its stump). Lost bones get the expected size and pose of the thesis' ch. 5 (the
//!    healthy mirror limb's, else the template's), take no points, and the rest of the skeleton is
//!    refined without them (`final_iterations` whole-skeleton iterations, each limb fitted up to
//!    where it broke); the support is then measured again on the completed skeleton, so a bone
//!    broken part-way shows how far its support reaches. [`Fit::missing`] lists them. **Limbs known
//!    lost** (`RegistrationOptions::lost`, a curator's knowledge) are left out from the start
//!    instead: every solver has them absent and every start has them collapsed into the joint they
//!    hang from ([`super::support::collapse`]), so they never take the points of other parts (on
//!    the *Venus de Milo* the automatic run laid the arms along the drapery, where nothing tells
//!    them from legs); level 6 completes them with those it finds. On 20 synthetic statues cut
//!    part-way through a limb (seeds 40–59) the lost set is right on 17. The automatic detection is
//!    weak on real scans and on fits that went wrong: on 32 complete synthetic statues it flags a
//!    hand on 3 (seeds 10, 12 and 15, the last laid off the statue by its fit); on the *Venus de
//!    Milo* it finds the left arm only (level 8 finds the right one), and none of the bust's limbs
//!    on its own (level 7 does).
//! 7. **The bust hypothesis** ([`super::bust`], after the levels above): a whole fit squeezed
//!    into its points (its figure would stand over [`super::bust::SQUEEZE`] times taller
//!    than they reach) is registered again, levels 0–6, with the template's bust limbs lost
//!    from the start; that fit is the result when it explains the points those limbs had
//!    taken ([`super::bust::limb_excess`] under [`super::bust::EXPLAINED`]) at a mean
//!    distance under [`super::bust::COST`] times the whole fit's. The wreathed bust then
//!    reports both arms and both legs missing.
//! 8. **The pair hypothesis** ([`super::pair`], when no bust fit was kept): a whole fit that
//!    lost an upper arm or a thigh with all it carries, its mirror limb whole, is registered
//!    again with both lost from the start (afresh, then, that fit not kept, from the whole
//!    fit's skeleton: [`super::pair::from_whole`]); that fit is the result when it explains
//!    the points the mirror had taken ([`super::bust::limb_excess`] under
//!    [`super::pair::EXPLAINED`]) at a mean distance under [`super::pair::COST`] times the
//!    whole fit's. The *Venus de Milo* then reports both arms missing. When that does not
//!    apply or its fit is not kept, the same one bone down ([`super::pair::Level::Below`]): a
//!    whole fit that lost a forearm or a shin with what it carries, its mirror whole, is
//!    registered again with both lost from there, from the whole fit's skeleton, the upper
//!    arms or thighs free to take a stump; that fit is the result on the same excess, a
//!    mean distance under [`super::pair::COST_BELOW`] times the whole fit's, and the
//!    mirror's upper arm (thigh) lost or shrunk in it. Either registration runs only when it is worth it
//!    ([`super::pair::Hypothesis::worth_trying`]): without the mirror limb, the whole fit's
//!    other bones must stay near enough to the points (a healthy mirror limb is not).
//!
//! ## Incremental by design
//! The algorithm is written as plain sequential code whose elementary steps are **work
//! units**; after each one the solver calls a [`Pause`] hook. A unit is bounded by the points
//! it touches, not by the statue's size: a slice of an assignment refresh; an LM iteration's
//! normal equations, its trial step and an energy evaluation, each cut into slices of at most
//! [`super::lm::SLICE_POINTS`] points; the members' lists rebuilt after a refresh; a group of
//! seeding candidates; the support's k-d tree, its mean spacing in slices of `SPACING_SLICE`
//! points, and one examination of a bone's support; and, between solvers, the set-up
//! (placing the candidates; starting a solver in three units: what the caller did since its
//! last unit, the assignment's copy of the points, the solver's own k-d tree; building the
//! level-1 assignment in slices of `LEVEL1_SLICE` points). `bench --only fakir/unit_100k` measures
//! the longest unit on 100k points: 1.62 ms (a chain fit's first slice at level 1; set-up
//! 1.53 ms, support 0.66 ms), each unit at its shortest of four runs; `fakir/unit_100k_plinth`
//! 1.51 ms (set-up; support 1.29 ms, a shrunk bone's two examinations being two units).
//! [`Registration::step`] runs the algorithm on a worker thread that stops at the first unit
//! boundary after the budget is spent and waits there for the next `step`;
//! [`Registration::run_to_convergence`] runs it with a hook that never pauses. Pausing never
//! changes what is computed, and every parallel reduction sums fixed-size chunks in a fixed
//! order, so any sequence of budgets gives exactly the same skeleton, bit for bit, as an
//! uninterrupted run on any number of threads. An uninterrupted run (a hook that
//! [`Pause::never_pauses`]) registers the finalists at the same time, then the scale
//! restarts, then the five starts of each refit round, each with its own solver
//! (`FullRun::run_all`): the same bytes, sooner (10k points on this 2-core machine, before
//! the limb resets: 22.2 s → 15.9 s).

use super::assign::{AssignParams, Assignment};
use super::frame::WorkingFrame;
use super::init::{Candidate, Init, candidates, rescaled};
use super::lost::{
    Folds, STARVED, THROUGH_REACH, examine_support, lost_limbs, settle_lost_limbs, support_points,
};
use super::schedule::{ScheduleSettings, register_skeleton};
use super::solver::{
    Activity, Attempt, Cancelled, NearPoints, NoPause, Pause, Solver, SolverSettings,
    template_extent,
};
use super::support::{BoneSupport, collapse, lost_from_names};
use super::world::WorldSkeleton;
use crate::anatomy::template::BoneKind;
use crate::anatomy::{Skeleton, Template};
use crate::cloud::PointCloud;
use crate::cloud::base::{Base, BaseOptions, detect_base_stepwise};
use crate::cloud::normals::{NormalOptions, estimate_normals};
use crate::error::{Error, Result};
use crate::math::{Quat, Vec3};
use crate::rng::Rng;
use rayon::prelude::*;
use std::sync::mpsc::{Receiver, Sender, channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Options of a registration.
#[derive(Clone, Debug)]
pub struct RegistrationOptions {
    pub init: Init,
    /// Points of level 0 (random subsample).
    pub subsample: usize,
    /// Points of each candidate's short registration.
    pub init_subsample: usize,
    /// Whole-skeleton iterations at level 1.
    pub final_iterations: usize,
    /// Candidates (best short registrations first) that get a full level-0 registration.
    pub finalists: usize,
    /// Scale factors of the scale restarts (empty: none; see [`super::init`], step 7).
    pub rescales: Vec<f32>,
    /// Scale factors of the scale search (level 5 in the module docs; empty: none): a fit
    /// still above [`POOR_FIT`] after the tilted-up check is searched again from the
    /// statue's placements at each of these times their scale. Skipped from a given
    /// skeleton.
    pub search_scales: Vec<f32>,
    /// Refit rounds (level 5 in the module docs): at most this many rounds of fresh level-0
    /// registrations started from the fit and from its limb resets, the best kept only when
    /// it scores lower.
    pub refits: usize,
    /// Seed of the subsampling.
    pub seed: u64,
    pub solver: SolverSettings,
    pub schedule: ScheduleSettings,
    /// Cone preference slack (relative).
    pub cone_slack: f32,
    /// Cone preference slack (fraction of the statue's size).
    pub cone_abs: f32,
    /// Find a base (plinth) and register the figure without it (`None`: register every
    /// point).
    pub base: Option<BaseOptions>,
    /// Detect lost limbs and settle the fit without them (level 6 in the module docs).
    pub missing: bool,
    /// Bones the statue is known to have lost, by name, each with the bones it carries (a
    /// curator's knowledge: `register --missing`, the kiosk's `missing`). They are left out
    /// from the very start, so they never take the points of other parts, and completed at
    /// the end like the lost limbs found (level 6). Only limb bones can be named
    /// ([`super::support::lost_from_names`]).
    pub lost: Vec<String>,
    /// The direction the figure faces, when known (a curator's knowledge: `register
    /// --front`, the kiosk's `front`): only headings near it are tried ([`super::init`],
    /// step 3).
    pub front: Option<Vec3>,
    /// Limb resets beside each refit (level 5 in the module docs).
    pub limb_resets: bool,
    /// The second facing check (level 5 in the module docs): a fit that ends the refit
    /// rounds with an [`super::init::implausibility`] above this (radians) is turned around
    /// and registered again through levels 0, 1 and the refit rounds; the turned fit wins
    /// only with both the lower two-sided score and the lower implausibility.
    /// `f64::INFINITY`: never. Skipped, like the first, with a facing hint or a given
    /// skeleton.
    pub recheck_facing_above: f64,
    /// The up-down check (level 5 in the module docs): when a finalist of the opposite up
    /// direction to the chosen one was registered, the best of them (lowest score) is
    /// registered again from its level-0 fit through level 1 and the refit rounds, then the
    /// best of a search of the opposite up's placements likewise; each wins with the lower
    /// two-sided score. Skipped from a given skeleton; with an up hint (given or a
    /// plinth's) every finalist has the same up, so it never runs.
    pub flip: bool,
    /// The crossed-limbs check (level 5 in the module docs): a fit with a pair of crossed
    /// mirrored limb bones ([`WorldSkeleton::most_crossed`]) is registered again with the
    /// limbs below them exchanged ([`WorldSkeleton::exchanged_below`]) through levels 0, 1
    /// and the refit rounds; the uncrossed fit wins with the lower two-sided score. Then the
    /// crossed-over-limb check, likewise: a starved limb whose mirror reached over to its
    /// place ([`WorldSkeleton::most_crossed_over`]) has the limbs below the two exchanged.
    /// Skipped from a given skeleton.
    pub uncross: bool,
    /// The folded-limbs check (level 5 in the module docs): a fit with a joint inside a
    /// chain folded back further than [`FOLDED`] ([`WorldSkeleton::most_folded`]) is
    /// registered again with the chain below it laid straight
    /// ([`WorldSkeleton::unfolded`]) through levels 0, 1 and the refit rounds; the unfolded
    /// fit wins with the lower two-sided score. Skipped from a given skeleton.
    pub unfold: bool,
    /// The slid-block and slid-limb checks (level 5 in the module docs): a fit in which
    /// every limb hanging from the root block is uncovered at its root ([`UNCOVERED_REACH`]),
    /// or whose trunk chain is squeezed at its end ([`SQUEEZED_END`]), is registered again
    /// with the block slid one bone down ([`WorldSkeleton::slid_block`]), then one still
    /// squeezed with its trunk chain put back at rest (the trunk reset, [`limb_reset`]),
    /// then one in which such a limb still is, with that limb slid one bone down its chain
    /// ([`WorldSkeleton::slid_down`]), each through levels 0, 1 and the refit rounds; a slid
    /// fit wins with the lower two-sided score. The same option runs the hanging-limb and
    /// stretched-end checks after them (a limb chain hanging from an uncovered bone turned
    /// around, [`WorldSkeleton::reversed_below`]; one whose last bone is stretched slid one
    /// bone out, [`WorldSkeleton::slid_out`]), and last the dangling-end check (a limb's
    /// last bone that level 6 would find lost at full size below a covered bone: both laid
    /// along that bone, [`WorldSkeleton::split_end`]) or, when it does not fire, the
    /// overreaching-limb check (a limb too long for its mirror above the bones level 6 would
    /// find lost: slid back one bone, [`WorldSkeleton::slid_back`]). Skipped from a given
    /// skeleton.
    pub slide: bool,
}

impl Default for RegistrationOptions {
    fn default() -> Self {
        RegistrationOptions {
            init: Init::Auto,
            subsample: 8000,
            init_subsample: 1500,
            final_iterations: 2,
            finalists: 5,
            rescales: vec![0.88, 1.12],
            search_scales: vec![0.8, 1.25],
            refits: 4,
            seed: 7,
            solver: SolverSettings::default(),
            schedule: ScheduleSettings::default(),
            cone_slack: 0.2,
            cone_abs: 0.002,
            base: Some(BaseOptions::default()),
            missing: true,
            lost: Vec::new(),
            front: None,
            limb_resets: true,
            recheck_facing_above: 3.0,
            flip: true,
            uncross: true,
            unfold: true,
            slide: true,
        }
    }
}

/// Progress of a registration.
#[derive(Clone, Debug, Default)]
pub struct Progress {
    /// What runs now; `activity.fraction` estimates the share of the current [`attempt`]
    /// done (0.15 for the candidates' short registrations, up to 0.85 for the finalists and
    /// the scale restarts, the rest for level 1 and the refit rounds, whose second half goes
    /// to the second facing check when it may run (it jumps to the end when the check is not
    /// needed); each part advances with its whole-skeleton iterations and chains), never
    /// decreasing within an attempt.
    ///
    /// [`attempt`]: Progress::attempt
    pub activity: Activity,
    /// Which registration of the figure runs: the whole figure's, or a second one with limbs
    /// left out (a bust's or an armless figure's hypothesis, levels 7 and 8). The fraction
    /// starts again from 0 when a second attempt begins; the skeleton shown is that
    /// attempt's. When it is done, the fit kept is either attempt's.
    pub attempt: Attempt,
    /// Work units done so far.
    pub units: u64,
    /// Mean distance (eq. 2.16) over the points of the current level.
    pub mean_distance: f64,
    /// Current skeleton.
    pub skeleton: Option<Skeleton>,
    /// Finished (successfully or not).
    pub done: bool,
}

/// Label of the base's points in [`Fit::labels`].
pub const BASE_LABEL: u32 = u32::MAX;

/// The result of a registration.
#[derive(Clone, Debug)]
pub struct Fit {
    pub skeleton: Skeleton,
    /// Bone of every point of the cloud ([`BASE_LABEL`] for the base's points).
    pub labels: Vec<u32>,
    /// Mean distance of the figure's points to their bones (thesis eq. 2.16).
    pub mean_distance: f64,
    /// The base set aside, if one was found.
    pub base: Option<Base>,
    /// Points per bone.
    pub bone_counts: Vec<usize>,
    /// Whole-skeleton iterations (level 0 + level 1).
    pub iterations: usize,
    /// Work units.
    pub units: u64,
    /// Index of the placement kept. When the up-down or the tilted-up check won, a placement
    /// of its search, numbered after the initial placements (so past the end of
    /// `candidate_distances`), or the flipped finalist's.
    pub candidate: usize,
    /// Two-sided score (mean distance + occupancy) of each candidate's short registration.
    pub candidate_distances: Vec<f64>,
    /// Support of every bone (level 6; empty when `missing` detection is off).
    pub support: Vec<BoneSupport>,
    /// Bones of lost limbs (`lost_limbs`), completed to their expected size and pose; no
    /// point is labelled with them.
    pub missing: Vec<bool>,
}

impl Fit {
    /// The names of the bones in [`Fit::missing`].
    pub fn missing_names(&self) -> Vec<&str> {
        let t = &self.skeleton.template;
        (0..t.bones.len())
            .filter(|&b| self.missing.get(b).copied().unwrap_or(false))
            .map(|b| t.bones[b].name.as_str())
            .collect()
    }

    /// The bones only partly there, by index (empty when the support was not examined): not
    /// [`Fit::missing`], and either under [`super::support::PARTIAL`] coverage (a trunk bone
    /// under [`super::support::MISSING`] included: the trunk is never lost), or the bone a
    /// lost limb broke on — it carries a missing bone and its support does not reach through
    /// it ([`THROUGH_REACH`]; a bone whose child was cut at their joint is whole): a bone
    /// refitted on its stump can be covered well enough while its support reaches only part
    /// of it.
    pub fn partial(&self) -> Vec<bool> {
        let t = &self.skeleton.template;
        let missing = |b: usize| self.missing.get(b).copied().unwrap_or(false);
        self.support
            .iter()
            .enumerate()
            .map(|(b, s)| {
                let broken_on =
                    t.bones[b].children.iter().any(|&c| missing(c)) && s.reach < THROUGH_REACH;
                !missing(b) && (s.partial || s.missing || broken_on)
            })
            .collect()
    }
}

/// Refuses clouds with fewer than 20 points per bone of the template (`what` names them).
fn check_point_count(count: usize, template: &Template, what: &str) -> Result<()> {
    let min_points = 20 * template.bones.len();
    if count < min_points {
        return Err(Error::input(format!(
            "too few points to fit the '{}' template: {count} {what} (at least {min_points} \
             needed)",
            template.name,
        )));
    }
    Ok(())
}

/// Checks a cloud for registration and returns its normals (estimated when absent).
fn prepare(cloud: &PointCloud, template: &Template) -> Result<Vec<Vec3>> {
    check_point_count(cloud.len(), template, "points")?;
    if let Some(i) = cloud.positions.iter().position(|p| !p.is_finite()) {
        return Err(Error::input(format!(
            "point {i} has a non-finite coordinate"
        )));
    }
    check_spread(&cloud.positions)?;
    match &cloud.normals {
        Some(n) if n.len() == cloud.len() => Ok(n.clone()),
        _ => estimate_normals(&cloud.positions, &NormalOptions::default()),
    }
}

/// The least principal spread of a cloud that can be a figure, relative to its largest
/// (standard deviations along the principal axes): a cloud flatter than this is refused as
/// a plane. **Our choice**, with a margin of 14: over the scans and TOSCA shapes of
/// `../shared/data` (a figure lying prone included) the ratio is 0.14 to 0.53, and over
/// synthetic statues (humans and mermaids posed, seeds 1–8; a human, a centaur and a
/// quadruped at rest) 0.23 to 0.47. A relief or a flat scan gives no anatomy to fit.
pub const FLAT_SPREAD: f32 = 0.01;

/// The least second principal spread, relative to the largest, of a cloud that is not a line
/// (in any direction: a bounding-box test, used before, only caught lines along an axis).
pub const LINE_SPREAD: f32 = 1e-3;

/// Refuses clouds whose points coincide, or lie (nearly) on a line or a plane, in any
/// direction, by their principal spreads ([`LINE_SPREAD`], [`FLAT_SPREAD`]); [`register`]
/// checks the whole cloud before it estimates normals, and the figure again once a base is
/// set aside (a flat panel on a block plinth). An empty cloud passes (the point count is
/// checked apart); spreads that are not finite (coordinates past `f32`'s squares, or NaN)
/// are refused.
pub fn check_spread(positions: &[Vec3]) -> Result<()> {
    let Some(p) = crate::geometry::pca::pca(positions) else {
        return Ok(());
    };
    let [s0, s1, s2] = p.variances.map(|v| v.max(0.0).sqrt());
    if !s0.is_finite() {
        return Err(Error::input(
            "degenerate cloud: the spread of its points is not finite",
        ));
    }
    if !(s0 > 0.0) {
        return Err(Error::input("degenerate cloud: all points coincide"));
    }
    if !(s1 > LINE_SPREAD * s0) {
        return Err(Error::input("degenerate cloud: the points lie on a line"));
    }
    if !(s2 > FLAT_SPREAD * s0) {
        return Err(Error::input(format!(
            "degenerate cloud: the points lie on a plane (their spread across it is {:.3}% of \
             their spread along it; every statue and figure measured is over 14%)",
            100.0 * s2 / s0,
        )));
    }
    Ok(())
}

/// `k` distinct indices out of `n`, sorted (all of them when `k ≥ n`).
fn subsample(n: usize, k: usize, seed: u64) -> Vec<u32> {
    if k >= n {
        return (0..n as u32).collect();
    }
    let mut idx: Vec<u32> = (0..n as u32).collect();
    let mut rng = Rng::new(seed);
    for i in 0..k {
        let j = i + rng.below(n - i);
        idx.swap(i, j);
    }
    let mut out = idx[..k].to_vec();
    out.sort_unstable();
    out
}

/// Points added to the level-1 assignment per work unit: their rows (22 distances, flags) are
/// fresh memory, written for the first time, and 16,384 points took up to 4 ms.
const LEVEL1_SLICE: usize = 4_096;

/// Share of the progress fraction given to the candidates' short registrations.
const INIT_SHARE: f32 = 0.15;
/// Where level 0 (the finalists) ends and level 1 begins, when there is a level 1.
const LEVEL0_END: f32 = 0.85;

/// Part `i` of `count` equal parts of `[a, b]`.
fn span(a: f32, b: f32, i: usize, count: usize) -> (f32, f32) {
    let w = (b - a) / count.max(1) as f32;
    (a + w * i as f32, a + w * (i + 1) as f32)
}

fn assignment_of(
    positions: &[Vec3],
    normals: &[Vec3],
    idx: &[u32],
    n_bones: usize,
    params: AssignParams,
) -> Assignment {
    Assignment::new(
        idx.iter().map(|&i| positions[i as usize]).collect(),
        idx.iter().map(|&i| normals[i as usize]).collect(),
        idx.to_vec(),
        n_bones,
        params,
    )
}

/// The registration algorithm, run to the end with the pause hook `pause`, in the working
/// units of [`super::frame`] (the fit comes back in the cloud's).
pub fn register(
    cloud: &PointCloud,
    template: Arc<Template>,
    opts: &RegistrationOptions,
    pause: &mut dyn Pause,
) -> Result<Fit> {
    register_in(working_frame(cloud), cloud, template, opts, pause)
}

/// The working units of [`register`] for `cloud`; `None` when they are the cloud's own.
fn working_frame(cloud: &PointCloud) -> Option<WorkingFrame> {
    WorkingFrame::of(&cloud.positions).filter(|f| !f.is_identity())
}

/// [`register`] in the working units `frame` ([`working_frame`]; `None`: the cloud's), with
/// the bust hypothesis ([`super::bust`]): a whole fit squeezed into its points is registered
/// again without the template's bust limbs, and that fit is kept when it explains the points
/// the limbs had taken at a mean distance not far above the whole fit's; then (no bust fit
/// kept) the pair hypotheses ([`super::pair::hypotheses`]): a fit that lost an upper arm or a
/// thigh beside a whole mirror is registered again with both lost (afresh, then from the
/// whole fit), kept on the same two tests; else one that lost a forearm or a shin, one bone
/// down, kept on [`super::pair::Hypothesis::keeps`]'s. Each only when
/// [`super::pair::Hypothesis::worth_trying`]. Last (no other fit kept), the broken-limb
/// hypothesis ([`super::broken`]): a limb pulled short by its fit is registered again with
/// one more of its bones lost, kept when its mean distance falls clearly.
fn register_in(
    frame: Option<WorkingFrame>,
    cloud: &PointCloud,
    template: Arc<Template>,
    opts: &RegistrationOptions,
    pause: &mut dyn Pause,
) -> Result<Fit> {
    let whole = register_once(frame, cloud, template.clone(), opts, pause)?;
    // Between registrations each pass over the cloud is a unit of its own (the bust's
    // squeeze, each pair hypothesis' test; on 100k points they and the end of the fit had
    // made one unit of 3.4 ms).
    pause.unit(None).map_err(cancelled)?;
    let bust = super::bust::hypothesis(&template, opts)
        .map(|o| (o, super::bust::squeeze(&whole, &cloud.positions)));
    pause.unit(None).map_err(cancelled)?;
    if let Some((bust_opts, squeeze)) = bust
        && squeeze > super::bust::SQUEEZE
    {
        pause.attempt(Attempt::Bust);
        let bust = register_once(frame, cloud, template.clone(), &bust_opts, pause)?;
        let excess = super::bust::limb_excess(&whole, &bust, &cloud.positions, &template.bust)?;
        if excess < super::bust::EXPLAINED
            && bust.mean_distance < super::bust::COST * whole.mean_distance
        {
            return Ok(bust);
        }
    }
    // The last judgement of worth_trying, by level and mirror: the hypothesis started from
    // the whole fit shares its level and mirror with the one afresh before it.
    let mut judged: Option<(super::pair::Level, String, bool)> = None;
    for hypothesis in super::pair::hypotheses(&template, opts, &whole) {
        // Not worth a registration when the mirror limb explains points that no other bone
        // of the whole fit comes near (a healthy arm or leg).
        let worth = match &judged {
            Some((level, mirror, worth))
                if *level == hypothesis.level && *mirror == hypothesis.mirror =>
            {
                *worth
            }
            _ => {
                let worth = hypothesis.worth_trying(&whole, &cloud.positions)?;
                pause.unit(None).map_err(cancelled)?;
                judged = Some((hypothesis.level, hypothesis.mirror.clone(), worth));
                worth
            }
        };
        if !worth {
            continue;
        }
        // Each level its own attempt: the kiosk's bar starts again from 0 for the second.
        pause.attempt(match hypothesis.level {
            super::pair::Level::Limb => Attempt::Pair,
            super::pair::Level::Below => Attempt::PairBelow,
        });
        let pair = register_once(frame, cloud, template.clone(), &hypothesis.opts, pause)?;
        if hypothesis.keeps(&whole, &pair, &cloud.positions)? {
            return Ok(pair);
        }
    }
    if let Some(hypothesis) = super::broken::hypothesis(&template, opts, &whole) {
        pause.attempt(Attempt::Broken);
        let broken = register_once(frame, cloud, template.clone(), &hypothesis.opts, pause)?;
        if hypothesis.keeps(&whole, &broken) {
            if super::broken::trunk_shift(&whole, &broken, &cloud.positions)
                < super::broken::TRUNK_MOVED
            {
                return Ok(broken);
            }
            // A better placement, not a lost bone: fitted again from it, nothing lost from
            // the start.
            pause.attempt(Attempt::BrokenAgain);
            let again = register_once(
                frame,
                cloud,
                template.clone(),
                &hypothesis.again(&broken),
                pause,
            )?;
            if again.mean_distance < super::broken::COST * whole.mean_distance {
                return Ok(again);
            }
        }
    }
    Ok(whole)
}

/// One registration of [`register_in`] (no bust or pair hypothesis).
fn register_once(
    frame: Option<WorkingFrame>,
    cloud: &PointCloud,
    template: Arc<Template>,
    opts: &RegistrationOptions,
    pause: &mut dyn Pause,
) -> Result<Fit> {
    match frame {
        Some(f) => {
            let working = f.cloud_to_working(cloud);
            pause.unit(None).map_err(cancelled)?;
            let fit = register_here(&working, template, &f.options_to_working(opts), pause)?;
            pause.unit(None).map_err(cancelled)?;
            Ok(f.fit_from_working(fit))
        }
        None => register_here(cloud, template, opts, pause),
    }
}

/// [`register`] in the cloud's own units.
fn register_here(
    cloud: &PointCloud,
    template: Arc<Template>,
    opts: &RegistrationOptions,
    pause: &mut dyn Pause,
) -> Result<Fit> {
    let all_normals = prepare(cloud, &template)?;
    // Limbs known to be lost: left out from the start (see `RegistrationOptions::lost`).
    let given_lost = lost_from_names(&template, &opts.lost)?;
    let any_given = given_lost.iter().any(|&l| l);
    // The set-up between solvers is cut into units too (none of them may hold a kiosk frame).
    pause.unit(None).map_err(cancelled)?;
    let base = match &opts.base {
        Some(bo) => find_base(&cloud.positions, &all_normals, &opts.init, bo, pause)?,
        None => None,
    };
    // The figure: every point, or those off the base (copied, in order).
    let figure: Option<Vec<u32>> = base.as_ref().map(|b| {
        let mask = b.mask(cloud.len());
        (0..cloud.len() as u32)
            .filter(|&i| !mask[i as usize])
            .collect()
    });
    let (fig_positions, normals) = match &figure {
        Some(f) => (
            f.iter().map(|&i| cloud.positions[i as usize]).collect(),
            f.iter().map(|&i| all_normals[i as usize]).collect(),
        ),
        None => (Vec::new(), all_normals),
    };
    let positions: &[Vec3] = match &figure {
        Some(_) => &fig_positions,
        None => &cloud.positions,
    };
    let n = positions.len();
    if figure.is_some() {
        check_point_count(n, &template, "off the base")?;
        check_spread(positions)
            .map_err(|e| Error::input(format!("the figure off the base: {e}")))?;
    }
    let init = match (&opts.init, &base) {
        (Init::Auto | Init::Up(_), Some(b)) => Init::Up(b.up),
        (Init::Anchor { anchor, .. }, Some(b)) => Init::Anchor {
            anchor: *anchor,
            up: Some(b.up),
        },
        (i, _) => i.clone(),
    };
    let nb = template.bones.len();
    let level0 = subsample(n, opts.subsample, opts.seed);
    let level0_points: Vec<Vec3> = level0.iter().map(|&i| positions[i as usize]).collect();
    pause.unit(None).map_err(cancelled)?;
    // Candidates.
    let mut cands: Vec<Candidate> = match &init {
        Init::Given(s) => {
            let scale = s.block_scale;
            vec![Candidate {
                skeleton: s.clone(),
                scale,
            }]
        }
        init => candidates(&template, &level0_points, init, opts.front, &given_lost),
    };
    if any_given {
        for c in &mut cands {
            collapse(&mut c.skeleton, &given_lost);
        }
    }
    if cands.is_empty() {
        return Err(Error::input("cannot place the template on this cloud"));
    }
    pause.unit(None).map_err(cancelled)?;
    let scale = cands[0].scale;
    let size = scale * template_extent(&template);
    let params = AssignParams {
        cone_slack: opts.cone_slack,
        cone_abs: opts.cone_abs * size,
    };
    let free_root = template.block_bones().next().is_none();
    let full = FullRun {
        positions,
        normals: &normals,
        idx: &level0,
        nb,
        params,
        opts,
        free_root,
        lost: &given_lost,
        level0_points: &level0_points,
        near: std::sync::OnceLock::new(),
    };
    let mut distances = Vec::new();
    let mut chosen = 0;
    // The progress fraction (`Activity::fraction`): candidates, finalists and level 1 share it.
    let mut fraction = 0.0f32;
    let finalists_start = if cands.len() > 1 { INIT_SHARE } else { 0.0 };
    let level1_start = if level0.len() < n { LEVEL0_END } else { 1.0 };
    if cands.len() > 1 {
        distances = full.quick_scores(&cands, pause, &mut fraction, (0.0, INIT_SHARE))?;
        for (i, d) in distances.iter().enumerate() {
            if *d < distances[chosen] {
                chosen = i;
            }
        }
    }
    // Finalists: the best candidates by the short registration each get the full level-0
    // registration; the lowest two-sided score wins (ties to the better short score).
    let mut order: Vec<usize> = (0..cands.len()).collect();
    order.sort_by(|&a, &b| {
        distances
            .get(a)
            .unwrap_or(&0.0)
            .total_cmp(distances.get(b).unwrap_or(&0.0))
            .then(a.cmp(&b))
    });
    order.truncate(opts.finalists.max(1));
    // Without a choice of placement (a given skeleton) there is nothing to restart.
    let rescales: &[f32] = if !matches!(opts.init, Init::Given(_)) {
        &opts.rescales
    } else {
        &[]
    };
    let runs = order.len() + rescales.len() + 1;
    let starts: Vec<Start> = order
        .iter()
        .enumerate()
        .map(|(j, &ci)| {
            let sp = span(finalists_start, level1_start, j, runs);
            (ci, cands[ci].clone(), sp)
        })
        .collect();
    let mut finals = full.run_all(&starts, pause, &mut fraction)?;
    // Near-ties are decided by anatomy (see `init`): a well-fitted figure facing the right
    // way keeps its knees, elbows and feet in range.
    let pick = preferred(&finals);
    let mut best = finals.swap_remove(pick);
    let chosen = best.candidate;
    // The up-down check's start: the best finalist whose up is opposite to the chosen one's.
    let up = cands[chosen].skeleton.up();
    let flipped = finals
        .into_iter()
        .filter(|f| opts.flip && cands[f.candidate].skeleton.up().dot(up) < 0.0)
        .min_by(|a, b| {
            a.score
                .total_cmp(&b.score)
                .then(a.candidate.cmp(&b.candidate))
        });
    // Scale restarts of the chosen orientation (see `init`, step 7): the lowest score wins.
    let pivot = match &init {
        Init::Anchor { anchor, .. } => *anchor,
        _ => centroid(&level0_points),
    };
    let starts: Vec<Start> = rescales
        .iter()
        .enumerate()
        .map(|(j, &f)| {
            let sp = span(finalists_start, level1_start, order.len() + j, runs);
            (chosen, rescaled(&cands[chosen], pivot, f), sp)
        })
        .collect();
    for r in full.run_all(&starts, pause, &mut fraction)? {
        if r.score < best.score {
            best = r;
        }
    }
    // The facing check (see the module docs): the fit turned around, registered again.
    if opts.front.is_none() && !matches!(opts.init, Init::Given(_)) {
        let c = full.turned(&best.world, best.scale);
        let sp = span(finalists_start, level1_start, runs - 1, runs);
        let r = full.run(chosen, &c, pause, &mut fraction, sp)?;
        let mut pair = vec![best, r];
        best = pair.swap_remove(preferred(&pair));
    }
    let FullFit {
        world,
        units: units0,
        mut iterations,
        scale,
        ..
    } = best;
    // Level 1, then the refits (see the module docs), each followed by level 1 again.
    let rounds = opts.refits + 1;
    // Limb resets join the refits (not from a given skeleton: it is kept as started).
    let reset_chains = if opts.limb_resets && !matches!(opts.init, Init::Given(_)) {
        resettable_chains(&template, &given_lost)
    } else {
        Vec::new()
    };
    // The checks that follow the refit rounds (the up-down and tilted-up checks, the scale search,
    // the second facing check, the crossed- and folded-limbs checks, the slid-block and slid-limb
    // checks), when they may run, share the second half of what follows level 0.
    let recheck = opts.front.is_none()
        && !matches!(opts.init, Init::Given(_))
        && opts.recheck_facing_above.is_finite();
    // (A given skeleton is the only candidate: no finalist is flipped.)
    let flip = flipped.is_some();
    let uncross = opts.uncross && !matches!(opts.init, Init::Given(_));
    let unfold = opts.unfold && !matches!(opts.init, Init::Given(_));
    let slide = opts.slide && !matches!(opts.init, Init::Given(_));
    // The tilted-up check runs when nothing gave the up (no hint, no plinth, no anchor).
    let tilt = opts.flip && matches!(init, Init::Auto);
    // The scale search: the statue's own placements at other scales.
    let rescan = !opts.search_scales.is_empty() && !matches!(opts.init, Init::Given(_));
    // Each check that may run gets an equal share of that half, in this order.
    let checks = [
        flip, tilt, rescan, recheck, uncross, uncross, unfold, slide, slide, slide, slide, slide,
        slide, slide,
    ];
    let ran = checks.iter().filter(|&&c| c).count();
    let checks_start = if ran > 0 {
        0.5 * (level1_start + 1.0)
    } else {
        1.0
    };
    let check_span = |k: usize| {
        let i = checks[..k].iter().filter(|&&c| c).count();
        span(checks_start, 1.0, i, ran.max(1))
    };
    let rr = RefitRounds {
        reset_chains: &reset_chains,
        rounds,
        chosen,
        span: (level1_start, checks_start),
    };
    let level1_span = span(level1_start, checks_start, 0, rounds);
    let (mut s, its) = full.refine(world, scale, units0, pause, fraction, level1_span, &rr)?;
    iterations += its;
    let ch = Challenge { scale, rr: &rr };
    // The rule of every check but the second facing check: the challenger wins with the
    // lower score.
    let lower = |kept: f64, other: f64, _: &WorldSkeleton| other < kept;
    // The up-down check (see the module docs): the best finalist of the other up direction,
    // refined like the fit; the lower score wins.
    let mut candidate = chosen;
    if flip && let Some(f) = flipped {
        let (lo, hi) = check_span(0);
        let (a, b) = (lo + (hi - lo) / 3.0, lo + 2.0 * (hi - lo) / 3.0);
        // First the flipped finalist, refined like the fit.
        let c = full.start_at(&f.world, f.scale);
        s = full.challenge(s, &ch, (&c, (lo, a)), &mut iterations, lower)?;
        if s.world.up().dot(up) < 0.0 {
            candidate = f.candidate;
        }
        // Then the other up searched as if it were given: its placements (appended to
        // `cands`), their short registrations, the best `finalists` registered at level 0;
        // the finalists' rule picks the start, refined like the fit.
        s = full.challenge_about(
            s,
            &ch,
            (&template, &level0_points, (&[(Init::Up(-up), 1.0)], pivot)),
            &mut cands,
            (a, b, hi),
            &mut iterations,
            &mut candidate,
        )?;
    }
    // The tilted-up check (see the module docs): a fit still far from its points is searched
    // again about ups tilted from its own; the lower score wins.
    if tilt && poor(&s, size) {
        let (lo, hi) = check_span(1);
        let up = s.world.up();
        let ups: Vec<(Init, f32)> = [Vec3::X, Vec3::NEG_X, Vec3::Z, Vec3::NEG_Z]
            .iter()
            .map(|a| {
                let tilt = Quat::from_axis_angle(s.world.root_rotation * *a, TILT.to_radians());
                (Init::Up(tilt * up), 1.0)
            })
            .collect();
        s = full.challenge_about(
            s,
            &ch,
            (&template, &level0_points, (&ups, pivot)),
            &mut cands,
            (lo, 0.5 * (lo + hi), hi),
            &mut iterations,
            &mut candidate,
        )?;
    }
    // The scale search (see the module docs): a fit still far from its points is searched
    // again from the statue's own placements at other scales; the lower score wins.
    if rescan && poor(&s, size) {
        let (lo, hi) = check_span(2);
        let searches: Vec<(Init, f32)> = opts
            .search_scales
            .iter()
            .map(|&f| (init.clone(), f))
            .collect();
        s = full.challenge_about(
            s,
            &ch,
            (&template, &level0_points, (&searches, pivot)),
            &mut cands,
            (lo, 0.5 * (lo + hi), hi),
            &mut iterations,
            &mut candidate,
        )?;
    }
    // The second facing check (see the module docs): the turned fit wins with both the
    // lower score and the lower implausibility.
    let implausible = super::init::implausibility(&s.world.to_skeleton());
    if recheck && implausible > opts.recheck_facing_above {
        let c = full.turned(&s.world, s.world.block_scale);
        s = full.challenge(
            s,
            &ch,
            (&c, check_span(3)),
            &mut iterations,
            |kept, other, t| {
                other < kept && super::init::implausibility(&t.to_skeleton()) < implausible
            },
        )?;
    }
    // The crossed-limbs check (see the module docs): the limbs below the most crossed pair
    // exchanged; the uncrossed fit wins with the lower score.
    let mirror = template.mirror_bones();
    if uncross
        && let Some(b) = s.world.most_crossed(&mirror, &given_lost)
        && let Some(w) = s.world.exchanged_below(b, &mirror)
    {
        let c = full.start_at(&w, s.world.block_scale);
        s = full.challenge(s, &ch, (&c, check_span(4)), &mut iterations, lower)?;
    }
    // The checks on limbs below all leave out the trunk's bones and the bones known lost
    // (`settled`).
    let mut settled = super::solver::trunk_bones(&template);
    for (k, l) in settled.iter_mut().zip(&given_lost) {
        *k |= *l;
    }
    // The crossed-over-limb check (see the module docs): a starved limb whose mirror reached
    // over to its place has the limbs below the two exchanged; lower score wins.
    if uncross {
        s.refresh().map_err(cancelled)?;
        let points: Vec<usize> = s.members.iter().map(Vec::len).collect();
        if let Some(p) =
            s.world
                .most_crossed_over(&mirror, &settled, &points, STARVED, CROSSED_OVER_NEAR)
            && let Some(w) = s.world.exchanged_below(p, &mirror)
        {
            let c = full.start_at(&w, s.world.block_scale);
            s = full.challenge(s, &ch, (&c, check_span(5)), &mut iterations, lower)?;
        }
    }
    // The folded-limbs check (see the module docs): the chain below the most folded joint
    // laid straight; the unfolded fit wins with the lower score. A limb folded back onto
    // the stump of a cut is lost, not misfitted: folds whose bones the lost-limb rules of
    // level 6 would take on this fit are left out.
    let mut skip = settled.clone();
    let limit = FOLDED.to_radians();
    let mut folded = if unfold {
        s.world.most_folded(&skip, limit)
    } else {
        None
    };
    // The support points' k-d tree, built once for this and level 6.
    let mut support_tree = None;
    if folded.is_some() && opts.missing {
        let (tree, rho) = support_points(&mut s, full.near())?;
        let support = examine_support(&mut s, &tree, rho)?;
        support_tree = Some((tree, rho));
        let lost = lost_limbs(&mut s, &support, &given_lost, Folds::Unfoldable)?;
        for (k, l) in skip.iter_mut().zip(&lost) {
            *k |= *l;
        }
        folded = s.world.most_folded(&skip, limit);
    }
    if let Some(a) = folded {
        let c = full.start_at(&s.world.unfolded(a), s.world.block_scale);
        s = full.challenge(s, &ch, (&c, check_span(6)), &mut iterations, lower)?;
    }
    // The slid-block and slid-limb checks (see the module docs): a limb hanging from the
    // block uncovered at its root (neither known lost nor missing) says the block sits a bone
    // too high, or the limb a bone up its own length.
    let t = &template;
    // The limb bones hanging from the block (not known lost), and which of them are
    // uncovered at their root (a missing one, below `MISSING`, is left to level 6).
    let limbs: Vec<usize> = (0..t.bones.len())
        .filter(|&b| {
            let def = &t.bones[b];
            def.kind == BoneKind::Free
                && def
                    .parent
                    .is_some_and(|p| t.bones[p].kind == BoneKind::Block)
                && !settled[b]
        })
        .collect();
    let uncovered = |support: &[BoneSupport], b: usize| {
        support[b].reach < UNCOVERED_REACH && support[b].coverage >= super::support::MISSING
    };
    // The support and the lost bones measured on the fit as level 6 will find it, when the
    // last check left the fit as it was (see the dangling-end check).
    let mut measured = None;
    if slide && !limbs.is_empty() {
        let (tree, rho) = match support_tree.take() {
            Some(t) => t,
            None => support_points(&mut s, full.near())?,
        };
        let mut support = examine_support(&mut s, &tree, rho)?;
        // The block check when every limb on it is uncovered; the limb check on the least
        // covered one that still is.
        let squeezed = s
            .world
            .trunk_end_share()
            .is_some_and(|share| share < SQUEEZED_END);
        if (squeezed || limbs.iter().all(|&b| uncovered(&support, b)))
            && let Some(w) = s.world.slid_block()
        {
            let c = full.start_at(&w, s.world.block_scale);
            s = full.challenge(s, &ch, (&c, check_span(7)), &mut iterations, lower)?;
            support = examine_support(&mut s, &tree, rho)?;
        }
        // The trunk-reset check: a trunk still squeezed at its end has its chain, and all it
        // carries, put back at rest on the block.
        if s.world
            .trunk_end_share()
            .is_some_and(|share| share < SQUEEZED_END)
            && let Some(chain) = s.world.trunk_chain()
        {
            // Through the world view again, as measured (the start collapsed on the lost
            // bones by `start_at`); collapsing `limb_reset`'s skeleton directly starts from
            // other roundings, and seed 6 without normals then ends at 1.26%, not 1.22%.
            let reset = limb_reset(&s.world, chain).skeleton;
            let c = full.start_at(&WorldSkeleton::from_skeleton(&reset), s.world.block_scale);
            s = full.challenge(s, &ch, (&c, check_span(8)), &mut iterations, lower)?;
            support = examine_support(&mut s, &tree, rho)?;
        }
        if let Some(b) = limbs
            .iter()
            .copied()
            .filter(|&b| uncovered(&support, b))
            .min_by(|&x, &y| support[x].coverage.total_cmp(&support[y].coverage))
        {
            let c = full.start_at(&s.world.slid_down(b), s.world.block_scale);
            s = full.challenge(s, &ch, (&c, check_span(9)), &mut iterations, lower)?;
            // The hanging-limb check reads the support of the fit as it now is.
            support = examine_support(&mut s, &tree, rho)?;
        }
        // The hanging-limb check: a limb bone across empty space with the rest of its chain
        // on the scan (neither known lost nor trunk) turns the chain below it around.
        let coverage: Vec<f32> = support.iter().map(|x| x.coverage).collect();
        if let Some(a) = s
            .world
            .most_hanging(&settled, &coverage, super::support::MISSING)
        {
            let c = full.start_at(&s.world.reversed_below(a), s.world.block_scale);
            s = full.challenge(s, &ch, (&c, check_span(10)), &mut iterations, lower)?;
            support = examine_support(&mut s, &tree, rho)?;
        }
        // The stretched-end check: a limb whose last bone is too long for the one before it
        // (neither known lost, trunk, nor missing on the support above) slid one bone out.
        // (The support measured again when the hanging-limb check ran.)
        let skip: Vec<bool> = settled
            .iter()
            .zip(&support)
            .map(|(&k, x)| k || x.coverage < super::support::MISSING)
            .collect();
        // `fresh`: the support of the fit as it now is, while no check has challenged it
        // since (a challenge may change the fit, and the support is measured again).
        let mut fresh = Some(support);
        if let Some(a) = s.world.most_stretched_end(&skip, STRETCHED_END) {
            let c = full.start_at(&s.world.slid_out(a), s.world.block_scale);
            s = full.challenge(s, &ch, (&c, check_span(11)), &mut iterations, lower)?;
            fresh = None;
        }
        // The crowded-head check: a trunk end (neck, head) under `PARTIAL` coverage has an
        // arm slid one joint up into it, the head pushed aside; the trunk chain is put back
        // at rest on the block and each arm beside the end in turn, while the end is still
        // crowded, slid one bone down.
        if let Some((end, arms)) = s.world.trunk_end()
            && let Some(chain) = s.world.trunk_chain()
        {
            let (lo, hi) = check_span(12);
            for (i, &arm) in arms.iter().enumerate() {
                let bones = &template.chains[arm].bones;
                if bones.iter().any(|&b| settled[b]) {
                    continue;
                }
                let support = match fresh.take() {
                    Some(support) => support,
                    None => examine_support(&mut s, &tree, rho)?,
                };
                if end
                    .iter()
                    .all(|&b| support[b].coverage >= super::support::PARTIAL)
                {
                    fresh = Some(support);
                    break;
                }
                let w = s
                    .world
                    .at_rest(&template.chains[chain].bones)
                    .slid_down(bones[0]);
                let c = full.start_at(&w, s.world.block_scale);
                let sp = span(lo, hi, i, arms.len());
                s = full.challenge(s, &ch, (&c, sp), &mut iterations, lower)?;
            }
        }
        // The dangling-end check: a limb whose last bone hangs at full size below a covered
        // bone, and that the lost-limb rules of level 6 would take, has the two share that
        // bone's vector (the trunk and the bones known lost left out). The support of the fit
        // as it now is, as level 6 will measure it (measured again only when a check above
        // challenged the fit since the last measure).
        let support = match fresh {
            Some(support) => support,
            None => examine_support(&mut s, &tree, rho)?,
        };
        let lost = lost_limbs(&mut s, &support, &given_lost, Folds::Lost)?;
        let coverage: Vec<f32> = support.iter().map(|x| x.coverage).collect();
        let shrunk: Vec<bool> = support.iter().map(|x| x.shrunk).collect();
        let dangling =
            s.world
                .most_dangling_end(&settled, &lost, &coverage, &shrunk, super::support::MISSING);
        // Else the overreaching-limb check: a limb whose bones above its lost tail are too
        // long for their mirrors is slid back one bone from the one most overgrown.
        let start = match dangling {
            Some(b) => Some(s.world.split_end(b)),
            None => s
                .world
                .most_overreaching(
                    &settled,
                    &lost,
                    &coverage,
                    super::support::MISSING,
                    OVERREACH,
                )
                .map(|a| s.world.slid_back(a)),
        };
        match start {
            Some(w) => {
                let c = full.start_at(&w, s.world.block_scale);
                s = full.challenge(s, &ch, (&c, check_span(13)), &mut iterations, lower)?;
            }
            // The fit stays as it is: level 6 takes this support and these lost bones.
            None => measured = Some((support, lost)),
        }
        support_tree = Some((tree, rho));
    }
    s.refresh().map_err(cancelled)?;
    // Missing limbs (level 6): those known, and those found when `missing` is on.
    let (support, missing) = if opts.missing || any_given {
        let (tree, rho) = match support_tree {
            Some(t) => t,
            None => support_points(&mut s, full.near())?,
        };
        let (mut support, lost) = match measured {
            Some((support, lost)) => (support, Some(lost)),
            None => (examine_support(&mut s, &tree, rho)?, None),
        };
        let missing = match lost {
            _ if !opts.missing => given_lost.clone(),
            Some(lost) => lost,
            None => lost_limbs(&mut s, &support, &given_lost, Folds::Lost)?,
        };
        if missing.iter().any(|&m| m) {
            iterations += settle_lost_limbs(&mut s, &missing, opts)?;
            // What the scan covers of the completed skeleton: a limb broken part-way along
            // a bone shows how far its support reaches.
            support = examine_support(&mut s, &tree, rho)?;
        }
        (support, missing)
    } else {
        (Vec::new(), vec![false; nb])
    };
    s.activity.phase = "done";
    s.activity.fraction = 1.0;
    // The labels are a pass over every point: a unit of their own (the solver's release
    // after them falls into the caller's next unit).
    s.unit().map_err(cancelled)?;
    let mut labels = vec![BASE_LABEL; cloud.len()];
    let mut bone_counts = vec![0usize; nb];
    for (k, &src) in s.assignment.source.iter().enumerate() {
        let i = match &figure {
            Some(f) => f[src as usize],
            None => src,
        };
        let l = s.assignment.label[k];
        labels[i as usize] = l;
        bone_counts[l as usize] += 1;
    }
    s.unit().map_err(cancelled)?;
    Ok(Fit {
        skeleton: s.world.to_skeleton(),
        labels,
        mean_distance: s.mean_distance(),
        base,
        bone_counts,
        iterations,
        units: s.units,
        candidate,
        candidate_distances: distances,
        support,
        missing,
    })
}

/// What the refit rounds (level 5 in the module docs) need of the registration around them.
#[derive(Clone, Copy)]
struct RefitRounds<'a> {
    /// Chains that limb resets restart.
    reset_chains: &'a [usize],
    /// Level 1 and the refit rounds (`refits + 1`): the progress spans' count.
    rounds: usize,
    /// The chosen candidate.
    chosen: usize,
    /// The progress span of level 1 and the rounds (each round gets `1 / rounds` of it).
    span: (f32, f32),
}

/// What every challenger to a finished fit shares ([`FullRun::challenge`]).
struct Challenge<'a> {
    /// The scale its level 1 and refit rounds run at (the level-0 fit's).
    scale: f32,
    /// The refit rounds it goes through (their span replaced by the challenger's).
    rr: &'a RefitRounds<'a>,
}

impl FullRun<'_> {
    /// The start of a facing check (levels 3 and 5 in the module docs): `world` turned around
    /// ([`WorldSkeleton::turned_around`]) at `scale`, its known-lost bones collapsed.
    fn turned(&self, world: &WorldSkeleton, scale: f32) -> Candidate {
        self.start_at(&world.turned_around(&world.template.mirror_bones()), scale)
    }

    /// A start from `world` at `scale`, its known-lost bones collapsed (every start of a
    /// check of level 5).
    fn start_at(&self, world: &WorldSkeleton, scale: f32) -> Candidate {
        let mut skeleton = world.to_skeleton();
        collapse(&mut skeleton, self.lost);
        Candidate { skeleton, scale }
    }

    /// Level 1 from the level-0 fit `world` (progress in `level1_span`), then the refit rounds
    /// of `rr` (level 5 in the module docs): the fit they end with and the whole-skeleton
    /// iterations run.
    #[allow(clippy::too_many_arguments)]
    fn refine<'p>(
        &self,
        world: WorldSkeleton,
        scale: f32,
        units: u64,
        pause: &'p mut dyn Pause,
        fraction: f32,
        level1_span: (f32, f32),
        rr: &RefitRounds,
    ) -> Result<(Solver<'p>, usize)> {
        let (s, mut iterations) = self.level1(
            world,
            scale,
            units,
            self.opts.final_iterations,
            pause,
            fraction,
            level1_span,
        )?;
        let s = self.refit_rounds(s, rr, &mut iterations)?;
        Ok((s, iterations))
    }

    /// A **challenger** to the fit `s` (the checks of level 5 in the module docs): `start`
    /// registered through level 0, level 1 and the refit rounds of `ch.rr`, its progress in
    /// `progress`. Returns the challenger's solver when `wins(kept, other, challenger)` says so
    /// (`kept` and `other`: the two-sided scores of the fit and the challenger on the level-0
    /// points), adding its iterations to `iterations`; otherwise `s`, as it was.
    fn challenge<'p>(
        &self,
        mut s: Solver<'p>,
        ch: &Challenge,
        (start, progress): (&Candidate, (f32, f32)),
        iterations: &mut usize,
        wins: impl Fn(f64, f64, &WorldSkeleton) -> bool,
    ) -> Result<Solver<'p>> {
        let Some(hook) = s.take_pause() else {
            return Ok(s);
        };
        let (lo, hi) = progress;
        let kept = self.score(&s.world, s.world.block_scale, hook, lo)?;
        let rr = RefitRounds {
            span: progress,
            ..*ch.rr
        };
        let first = span(lo, hi, 0, rr.rounds);
        let half = (first.0, 0.5 * (first.0 + first.1));
        let mut fraction = lo;
        let r = self.run(rr.chosen, start, hook, &mut fraction, half)?;
        let (mut t, its) = self.refine(
            r.world,
            ch.scale,
            s.units + r.units,
            hook,
            fraction,
            (half.1, first.1),
            &rr,
        )?;
        let its = r.iterations + its;
        // (The refit rounds end with the hook in the solver they return.)
        if let Some(hook) = t.take_pause() {
            let fraction = t.activity.fraction;
            let other = self.score(&t.world, t.world.block_scale, hook, fraction)?;
            if wins(kept, other, &t.world) {
                t.give_pause(hook);
                *iterations += its;
                return Ok(t);
            }
            s.units = t.units;
            s.activity.fraction = fraction;
            s.give_pause(hook);
        }
        Ok(s)
    }

    /// A search of the placements `searches` about a pivot ([`FullRun::search`] on `points`,
    /// progress in the first part of `progress` = `(lo, mid, hi)`) whose pick by the finalists'
    /// rule challenges the fit `s` (progress in the second part) and wins with the lower score: the
    /// up-down, tilted-up and scale-search checks (level 5 in the module docs). The placements are
    /// appended to `cands`, and `candidate` becomes the pick's when it won.
    #[allow(clippy::too_many_arguments)]
    fn challenge_about<'p>(
        &self,
        mut s: Solver<'p>,
        ch: &Challenge,
        (template, points, searches): (&Arc<Template>, &[Vec3], Searches),
        cands: &mut Vec<Candidate>,
        (lo, mid, hi): (f32, f32, f32),
        iterations: &mut usize,
        candidate: &mut usize,
    ) -> Result<Solver<'p>> {
        let Some(hook) = s.take_pause() else {
            return Ok(s);
        };
        let mut at = s.activity.fraction;
        let (more, mut fits) = self.search(
            template,
            points,
            searches,
            cands.len(),
            hook,
            &mut at,
            (lo, mid),
        )?;
        s.give_pause(hook);
        cands.extend(more);
        if !fits.is_empty() {
            let g = fits.swap_remove(preferred(&fits));
            let c = self.start_at(&g.world, g.scale);
            let before = s.world.up();
            let lower = |kept: f64, other: f64, _: &WorldSkeleton| other < kept;
            s = self.challenge(s, ch, (&c, (mid, hi)), iterations, lower)?;
            // The fit now comes from that placement when it won.
            if s.world.up() != before {
                *candidate = g.candidate;
            }
        }
        Ok(s)
    }

    /// The refit rounds (level 5 in the module docs) from the level-1 fit `s`: returns the
    /// fit they end with, adding their iterations to `iterations`.
    fn refit_rounds<'p>(
        &self,
        mut s: Solver<'p>,
        rr: &RefitRounds,
        iterations: &mut usize,
    ) -> Result<Solver<'p>> {
        let RefitRounds {
            reset_chains,
            rounds,
            chosen,
            span: (lo, hi),
        } = *rr;
        let round_starts = 1 + reset_chains.len();
        for round in 1..rounds {
            // The fit's solver is kept (its level-1 assignment is still good if the refit is
            // dropped); its pause hook runs the refit meanwhile.
            let Some(hook) = s.take_pause() else { break };
            let start = s.world.clone();
            let mut fraction = s.activity.fraction;
            let current = self.score(&start, start.block_scale, hook, fraction)?;
            let c = Candidate {
                skeleton: start.to_skeleton(),
                scale: start.block_scale,
            };
            let sp = span(lo, hi, round, rounds);
            let half = (sp.0, 0.5 * (sp.0 + sp.1));
            // The refit from the fit itself, then one limb reset per limb chain.
            let mut restarts = vec![c];
            restarts.extend(reset_chains.iter().map(|&ch| limb_reset(&start, ch)));
            let starts: Vec<Start> = restarts
                .into_iter()
                .enumerate()
                .map(|(i, c)| (chosen, c, span(half.0, half.1, i, round_starts)))
                .collect();
            let mut runs = self.run_all(&starts, hook, &mut fraction)?;
            let units: u64 = runs.iter().map(|r| r.units).sum();
            // The lowest score (ties to the earlier start: the plain refit first).
            let k = (0..runs.len())
                .min_by(|&a, &b| runs[a].score.total_cmp(&runs[b].score).then(a.cmp(&b)))
                .expect("at least the plain refit");
            let r = runs.swap_remove(k);
            if r.score < current {
                *iterations += r.iterations;
                let (next, its) = self.level1(
                    r.world,
                    start.block_scale,
                    s.units + units,
                    self.opts.final_iterations,
                    hook,
                    fraction,
                    (half.1, sp.1),
                )?;
                s = next;
                *iterations += its;
            } else {
                // Not better: the fit before it stays, as it was.
                s.units += units;
                s.activity.fraction = s.activity.fraction.max(fraction);
                s.give_pause(hook);
                break;
            }
        }
        Ok(s)
    }
}

/// The limb chains that limb resets restart (see the module docs): chains of no trunk bone
/// ([`super::solver::trunk_bones`]) and no lost bone.
pub fn resettable_chains(t: &Template, lost: &[bool]) -> Vec<usize> {
    let trunk = super::solver::trunk_bones(t);
    (0..t.chains.len())
        .filter(|&c| {
            let bones = &t.chains[c].bones;
            !bones.is_empty() && bones.iter().all(|&b| !trunk[b] && !lost[b])
        })
        .collect()
}

/// The start of a **limb reset** (see the module docs): `world` with chain `chain` and
/// everything hanging from it back at the template's rest pose relative to its parent, rest
/// lengths and rest radii at the fit's block scale (the radius of the chain's first joint,
/// shared with the trunk, is kept).
pub fn limb_reset(world: &WorldSkeleton, chain: usize) -> Candidate {
    let t = world.template.clone();
    let rest = Skeleton::rest_placed(
        t.clone(),
        world.root_position,
        world.root_rotation,
        world.block_scale,
    );
    let mut sk = world.to_skeleton();
    let first = t.chains[chain].bones[0];
    for b in t.subtree(first) {
        let keep_r1 = sk.bones[b].r1;
        sk.bones[b] = rest.bones[b];
        if b == first {
            sk.bones[b].r1 = keep_r1;
        }
    }
    // Through the world view and back, as the figures in the module docs were measured
    // (`Skeleton::enforce_constraints` applies the same constraints with other roundings, and
    // the fit that follows, chaotic in its start, then differs: 0.43% against 0.28% joint
    // error on the 10k-point statue of `bench`).
    let mut w = WorldSkeleton::from_skeleton(&sk);
    w.enforce();
    Candidate {
        skeleton: w.to_skeleton(),
        scale: world.block_scale,
    }
}

/// The base of the statue (see [`crate::cloud::base`]), one direction per work unit: along
/// the up hint of `init` if it has one, else along each principal direction.
fn find_base(
    positions: &[Vec3],
    normals: &[Vec3],
    init: &Init,
    opts: &BaseOptions,
    pause: &mut dyn Pause,
) -> Result<Option<Base>> {
    let hint = match init {
        Init::Up(u) => Some(*u),
        Init::Anchor { up, .. } => *up,
        Init::Auto => None,
        // A given skeleton carries its own orientation; its up is the root frame's.
        Init::Given(s) => Some(s.up()),
    };
    detect_base_stepwise(positions, normals, hint, opts, || {
        pause.unit(None).map_err(cancelled)
    })
}

/// Mean of `points` (the origin for none).
fn centroid(points: &[Vec3]) -> Vec3 {
    let sum = points.iter().fold(Vec3::ZERO, |a, p| a + *p);
    sum / points.len().max(1) as f32
}

/// The placements of a search ([`FullRun::search`]): each statue placement ([`Init`]) with the
/// factor its scale is multiplied by, and the pivot of that rescaling ([`rescaled`]).
type Searches<'a> = (&'a [(Init, f32)], Vec3);

/// What a full level-0 registration needs besides its start.
struct FullRun<'a> {
    positions: &'a [Vec3],
    normals: &'a [Vec3],
    idx: &'a [u32],
    nb: usize,
    params: AssignParams,
    opts: &'a RegistrationOptions,
    free_root: bool,
    /// Bones known lost (`RegistrationOptions::lost`), absent in every solver.
    lost: &'a [bool],
    /// The level-0 points (`positions` at `idx`).
    level0_points: &'a [Vec3],
    /// The level-0 points made searchable, built at the first solver's start and shared by
    /// every solver after it (the same points: the same tree, grid and spacing).
    near: std::sync::OnceLock<Arc<NearPoints>>,
}

/// The finalists' rule: among the fits within [`NEAR_TIE`] of the lowest two-sided score,
/// the most plausible pose ([`super::init::implausibility`]), then the lowest score, then
/// the first. Returns its index; `fits` must not be empty.
fn preferred(fits: &[FullFit]) -> usize {
    let best_score = fits.iter().map(|f| f.score).fold(f64::INFINITY, f64::min);
    fits.iter()
        .enumerate()
        .filter(|(_, f)| f.score <= NEAR_TIE * best_score)
        .min_by(|(_, a), (_, b)| {
            a.implausible
                .total_cmp(&b.implausible)
                .then(a.score.total_cmp(&b.score))
        })
        .map(|(i, _)| i)
        .expect("at least one fit")
}

/// How much longer than their mirrors the bones above a limb's lost tail must be together,
/// as a fraction of the mirror of the tail's first bone, for the overreaching-limb check to
/// slide the limb back ([`WorldSkeleton::most_overreaching`]). Only a trigger, loose on
/// purpose (the generator jitters each side's lengths by up to ±30% on its own, so mirrors
/// differ by more than this on healthy limbs): the lower score decides. It runs only where
/// the lost-limb rules would take a limb lost.
pub const OVERREACH: f32 = 0.25;

/// The mean distance (a fraction of the statue's size: the placement's scale times the
/// template's extent) above which a fit is poor (`poor`) and the tilted-up check and the
/// scale search run (module docs).
pub const POOR_FIT: f64 = 0.004;

/// Whether the fit `s` is poor (the tilted-up check and the scale search then run): its mean
/// distance, as of the solver's last refresh, above [`POOR_FIT`] of the statue's `size`.
///
/// A fit whose solver was never refreshed has no distances yet (all infinite: above any
/// bound) and is taken poor. That is the case of a fit with no level-1 pass (a cloud within
/// the level-0 `subsample`, or `final_iterations` 0): [`FullRun::level1`] starts its solver
/// afresh, and the refresh at the end of the registration has not run yet. So both searches
/// run on every such fit without an up hint. Found on 2026-12-08 and kept on purpose:
/// judged by their refreshed distances, five statues (`synth --seed N --rigid --height 1.7
/// --points 3000`, seeds 4-8, CLI defaults) ran neither search and were fitted 1.0 to 3.8
/// times faster (seed 4: 26.1 s down to 6.8 s), but seeds 4 and 5 ended at 0.69% and 0.63%
/// of the height in joint error against 0.23% and 0.42% with the searches (seeds 6-8: the
/// same fits). A fit with a level 1 keeps its distances as of its last level-1 pass, as
/// when [`POOR_FIT`] was measured; forcing both searches on one that passed the bound
/// (stylised seed 208, 10k points) gave the same fit for 1.85 times the work units.
fn poor(s: &Solver, size: f32) -> bool {
    s.mean_distance() > POOR_FIT * size as f64
}

/// How far (degrees) the tilted-up check tilts the fit's up (module docs).
pub const TILT: f32 = 30.0;

/// How near the ends of two mirrored limb bones must be, as a fraction of the longer one's
/// length, for the crossed-over-limb check to examine the limbs below them
/// ([`WorldSkeleton::most_crossed_over`]).
pub const CROSSED_OVER_NEAR: f32 = 0.5;

/// The fold (degrees between two consecutive bones' directions) beyond which the
/// folded-limbs check runs ([`RegistrationOptions::unfold`]). The built-in human's joint
/// ranges bend a limb by at most 125° (the elbow's 120° and its 5° swing); the generator's
/// statues, posed within them, reach 122° at most over 72 seeds.
pub const FOLDED: f32 = 150.0;

/// The support `reach` under which a limb bone hanging from the root block is uncovered at
/// its root (the slid-block check, level 5 in the module docs): no axial tenth of it from
/// its first joint is half covered. Measured on the fits of 32 complete synthetic statues
/// (seeds 1–32): only the two whose pelvis sat a bone too high (seeds 1 and 31) had a thigh
/// below 0.5, both at 0.
pub const UNCOVERED_REACH: f32 = 0.1;

/// A trunk chain whose last two bones take less than this fraction of their share at rest
/// ([`WorldSkeleton::trunk_end_share`]) is **squeezed** at its end, and the slid-block check
/// runs (level 5 in the module docs). Synthetic truths (±30% and ±50% proportions, 20
/// figures) measure 0.83 to 2.0, and their fits under 2% of the height 0.89 to 2.1 except
/// seed 12 (0.53, its head partial); seed 6, whose pelvis sat one bone up the spine, 0.43.
pub const SQUEEZED_END: f32 = 0.6;

/// The stretched-end check's limit (level 5, see the module docs): a limb chain's last bone
/// longer, relative to the bone before it, than this times the template's rest ratio. The
/// arms slid one joint in of seeds 33, 35 and 43 had 1.82, 1.51 and 1.81: the limit sits
/// just under the lowest. It is only a trigger: the generator's truths (each bone's length
/// jittered by up to ±30%) exceed it on 26 of their 288 limb chains over 72 seeds (1.74 at
/// most), and there the lower score decides whether the slid fit is kept.
pub const STRETCHED_END: f32 = 1.45;

/// Near-ties of two-sided scores (factor) that anatomy decides ([`preferred`]).
const NEAR_TIE: f64 = 1.5;

/// A full level-0 registration to run ([`FullRun::run_all`]): the candidate it comes from,
/// its start and its progress span.
type Start = (usize, Candidate, (f32, f32));

/// The outcome of a full level-0 registration.
struct FullFit {
    /// Two-sided score (mean distance + occupancy).
    score: f64,
    /// [`super::init::implausibility`] of the pose.
    implausible: f64,
    /// Index of the candidate orientation it started from.
    candidate: usize,
    /// Scale of its start (template units → statue units).
    scale: f32,
    world: WorldSkeleton,
    units: u64,
    iterations: usize,
}

impl FullRun<'_> {
    /// The short registration of each placement of `cands` (level 1 in the module docs) on
    /// the `init_subsample` points: one whole-skeleton iteration of one pass, with short LM
    /// loops; returns each one's two-sided score, its progress shared out over `span_all`.
    fn quick_scores(
        &self,
        cands: &[Candidate],
        pause: &mut dyn Pause,
        fraction: &mut f32,
        span_all: (f32, f32),
    ) -> Result<Vec<f64>> {
        let opts = self.opts;
        let idx = subsample(
            self.positions.len(),
            opts.init_subsample,
            opts.seed ^ 0x9e37,
        );
        let quick = ScheduleSettings {
            max_passes: 1,
            max_iterations: 1,
            ..opts.schedule.clone()
        };
        let quick_solver = SolverSettings {
            lm_iterations: 3,
            one_bone_rounds: 2,
            two_bone_rounds: 1,
            ..opts.solver.clone()
        };
        // The candidates' solvers share one search structure over the subsample, built in a
        // unit of its own (each solver's start is then a copy of the points).
        pause.unit(None).map_err(cancelled)?;
        let near = Arc::new(NearPoints::new(
            idx.iter().map(|&i| self.positions[i as usize]).collect(),
        ));
        let mut scores = Vec::with_capacity(cands.len());
        for (i, c) in cands.iter().enumerate() {
            pause.unit(None).map_err(cancelled)?;
            let a = assignment_of(self.positions, self.normals, &idx, self.nb, self.params);
            let mut s = Solver::with_near(
                WorldSkeleton::from_skeleton(&c.skeleton),
                a,
                near.clone(),
                c.scale,
                quick_solver.clone(),
                pause,
            );
            s.free_root = self.free_root;
            s.start_absent(self.lost);
            s.activity.phase = "initialisation";
            s.activity.fraction = *fraction;
            s.activity.span = span(span_all.0, span_all.1, i, cands.len());
            register_skeleton(&mut s, &quick, true).map_err(cancelled)?;
            *fraction = s.activity.fraction;
            scores.push(s.mean_distance() + s.occupancy());
            s.unit().map_err(cancelled)?;
        }
        Ok(scores)
    }

    /// The placements of `searches`, each searched as registration levels 1 and 2 search
    /// the statue's own ([`super::init::candidates`] with its `Init`, one search's placements
    /// after the other's, each rescaled by its factor about the `pivot`, [`rescaled`]): their
    /// short registrations ([`FullRun::quick_scores`], progress in the first half of
    /// `span_all`), then the best `finalists` of them all registered at level 0 (the second
    /// half). Returns the placements and the finalists' fits, the placements numbered from
    /// `first`. The up-down and tilted-up checks search ups ([`Init::Up`], factor 1), the
    /// scale search the statue's own placements at other scales.
    #[allow(clippy::too_many_arguments)]
    fn search(
        &self,
        template: &Arc<Template>,
        points: &[Vec3],
        (searches, pivot): Searches,
        first: usize,
        pause: &mut dyn Pause,
        fraction: &mut f32,
        span_all: (f32, f32),
    ) -> Result<(Vec<Candidate>, Vec<FullFit>)> {
        // Each search's placements are a unit of their own (on a 100k-point statue four ups
        // took 2 to 4 ms in one).
        let mut cands: Vec<Candidate> = Vec::new();
        for (init, f) in searches {
            pause.unit(None).map_err(cancelled)?;
            let placed = candidates(template, points, init, self.opts.front, self.lost);
            // (Factor 1 keeps the placements as they are, bit for bit.)
            cands.extend(placed.into_iter().map(|c| {
                if *f == 1.0 {
                    c
                } else {
                    rescaled(&c, pivot, *f)
                }
            }));
        }
        for c in &mut cands {
            collapse(&mut c.skeleton, self.lost);
        }
        if cands.is_empty() {
            return Ok((cands, Vec::new()));
        }
        let mid = 0.5 * (span_all.0 + span_all.1);
        let scores = self.quick_scores(&cands, pause, fraction, (span_all.0, mid))?;
        let mut order: Vec<usize> = (0..cands.len()).collect();
        order.sort_by(|&a, &b| scores[a].total_cmp(&scores[b]).then(a.cmp(&b)));
        order.truncate(self.opts.finalists.max(1));
        let starts: Vec<Start> = order
            .iter()
            .enumerate()
            .map(|(j, &ci)| {
                let sp = span(mid, span_all.1, j, order.len());
                (first + ci, cands[ci].clone(), sp)
            })
            .collect();
        let fits = self.run_all(&starts, pause, fraction)?;
        Ok((cands, fits))
    }

    /// The level-0 points made searchable ([`NearPoints`]), built at the first call.
    fn near(&self) -> &Arc<NearPoints> {
        self.near
            .get_or_init(|| Arc::new(NearPoints::new(self.level0_points.to_vec())))
    }

    /// A solver for `world` on the level-0 points, its progress at `fraction` within `span`,
    /// after three set-up units: whatever the caller did since its last unit, the
    /// assignment's copy of the points, then the solver's k-d tree and spacing.
    fn start<'p>(
        &self,
        world: WorldSkeleton,
        scale: f32,
        pause: &'p mut dyn Pause,
        fraction: f32,
        span: (f32, f32),
    ) -> Result<Solver<'p>> {
        pause.unit(None).map_err(cancelled)?;
        let a0 = assignment_of(self.positions, self.normals, self.idx, self.nb, self.params);
        pause.unit(None).map_err(cancelled)?;
        let near = self.near().clone();
        let mut s = Solver::with_near(world, a0, near, scale, self.opts.solver.clone(), pause);
        s.free_root = self.free_root;
        s.start_absent(self.lost);
        s.activity.fraction = fraction;
        s.activity.span = span;
        s.activity.phase = "setup";
        s.unit().map_err(cancelled)?;
        Ok(s)
    }

    /// The two-sided score (mean distance + occupancy) of `world` on the level-0 points (the
    /// progress stays at `fraction`).
    fn score(
        &self,
        world: &WorldSkeleton,
        scale: f32,
        pause: &mut dyn Pause,
        fraction: f32,
    ) -> Result<f64> {
        let mut s = self.start(world.clone(), scale, pause, fraction, (fraction, fraction))?;
        s.refresh().map_err(cancelled)?;
        let score = s.mean_distance() + s.occupancy();
        // The score is a unit of its own (a refit's set-up follows).
        s.unit().map_err(cancelled)?;
        Ok(score)
    }

    /// Level 1 (clouds larger than the level-0 subsample): the assignment redone on all
    /// points, in work units of `LEVEL1_SLICE` points, and `iterations` whole-skeleton
    /// iterations from `world`. Smaller clouds keep the level-0 points and get no iteration.
    /// Returns the solver (its assignment not yet refreshed after the last iteration) and the
    /// iterations run.
    #[allow(clippy::too_many_arguments)]
    fn level1<'p>(
        &self,
        world: WorldSkeleton,
        scale: f32,
        units: u64,
        iterations: usize,
        pause: &'p mut dyn Pause,
        fraction: f32,
        span: (f32, f32),
    ) -> Result<(Solver<'p>, usize)> {
        let n = self.positions.len();
        let mut s = self.start(world, scale, pause, fraction, span)?;
        s.units += units;
        let mut done = 0;
        // (No refresh on the level-0 points first: level 1 replaces the assignment and its
        // schedule refreshes it whole, and without a level 1 the caller's final refresh is the
        // only one needed.)
        if self.idx.len() < n {
            s.activity.level = 1;
            let mut all = Assignment::with_capacity(n, self.nb, self.params);
            for start in (0..n).step_by(LEVEL1_SLICE) {
                let end = (start + LEVEL1_SLICE).min(n);
                let source: Vec<u32> = (start as u32..end as u32).collect();
                all.push(
                    &self.positions[start..end],
                    &self.normals[start..end],
                    &source,
                );
                s.unit().map_err(cancelled)?;
            }
            s.set_assignment(all);
            if iterations > 0 {
                let fine = ScheduleSettings {
                    max_iterations: iterations,
                    ..self.opts.schedule.clone()
                };
                done = register_skeleton(&mut s, &fine, false).map_err(cancelled)?;
            }
        }
        Ok((s, done))
    }

    /// [`FullRun::run`] from each start (candidate index, start, progress span), in order.
    /// When `pause` never pauses ([`Pause::never_pauses`]: `run_to_convergence`, `register`
    /// with [`NoPause`]) the runs go at the same time, each with a `NoPause` of its own: they
    /// are independent and each computes the same bytes either way (their parallel sums
    /// are cut in fixed chunks). On this 2-core machine one run keeps only about 1.2 cores
    /// busy. Stepped registrations (the kiosk, the CLI on a terminal) run them one by one,
    /// so every work unit stays short and the progress shows each.
    fn run_all(
        &self,
        starts: &[Start],
        pause: &mut dyn Pause,
        fraction: &mut f32,
    ) -> Result<Vec<FullFit>> {
        if pause.never_pauses() && starts.len() > 1 {
            let from = *fraction;
            let fits = starts
                .par_iter()
                .map(|(ci, c, sp)| {
                    let mut f = from;
                    self.run(*ci, c, &mut NoPause, &mut f, *sp)
                })
                .collect::<Result<Vec<_>>>()?;
            // Every run ends at the end of its span, as one after the other would.
            *fraction = starts.iter().fold(from, |f, s| f.max(s.2.1));
            return Ok(fits);
        }
        starts
            .iter()
            .map(|(ci, c, sp)| self.run(*ci, c, pause, fraction, *sp))
            .collect()
    }

    /// Registers the whole skeleton from `c` (candidate `ci`, or a restart of it), with its
    /// progress in `span`.
    fn run(
        &self,
        ci: usize,
        c: &Candidate,
        pause: &mut dyn Pause,
        fraction: &mut f32,
        span: (f32, f32),
    ) -> Result<FullFit> {
        let world = WorldSkeleton::from_skeleton(&c.skeleton);
        let mut s = self.start(world, c.scale, pause, *fraction, span)?;
        let iterations = register_skeleton(&mut s, &self.opts.schedule, true).map_err(cancelled)?;
        *fraction = s.activity.fraction;
        let score = s.mean_distance() + s.occupancy();
        s.unit().map_err(cancelled)?;
        Ok(FullFit {
            score,
            implausible: super::init::implausibility(&s.world.to_skeleton()),
            candidate: ci,
            scale: c.scale,
            world: s.world.clone(),
            units: s.units,
            iterations,
        })
    }
}

pub(super) fn cancelled(_: Cancelled) -> Error {
    Error::input("registration cancelled")
}

enum Cmd {
    Run(Instant),
    Cancel,
}

enum Msg {
    Paused,
    Finished(Box<Result<Fit>>),
}

/// Pause hook of the worker thread: publishes progress and waits at the deadline.
struct ChannelPause {
    deadline: Instant,
    cmds: Receiver<Cmd>,
    msgs: Sender<Msg>,
    progress: Arc<Mutex<Progress>>,
    units: u64,
    /// The registration's working units, when they are not the cloud's: the published
    /// skeleton and mean distance are mapped back.
    frame: Option<WorkingFrame>,
}

impl Pause for ChannelPause {
    fn attempt(&mut self, attempt: Attempt) {
        if let Ok(mut p) = self.progress.lock() {
            p.attempt = attempt;
            p.activity.fraction = 0.0;
        }
    }

    fn unit(&mut self, s: Option<&Solver>) -> Result<(), Cancelled> {
        self.units += 1;
        if Instant::now() >= self.deadline {
            // Progress is only read while the worker waits, so it is published here, not after
            // every unit (the mean distance is a pass over all points). A set-up unit (no
            // solver) leaves the last published state.
            if let Ok(mut p) = self.progress.lock() {
                p.units = self.units;
                if let Some(s) = s {
                    p.activity = s.activity.clone();
                    let skeleton = s.world.to_skeleton();
                    (p.mean_distance, p.skeleton) = match &self.frame {
                        Some(f) => (
                            s.mean_distance() / f.scale as f64,
                            Some(f.skeleton_from_working(&skeleton)),
                        ),
                        None => (s.mean_distance(), Some(skeleton)),
                    };
                }
            }
            if self.msgs.send(Msg::Paused).is_err() {
                return Err(Cancelled);
            }
            match self.cmds.recv() {
                Ok(Cmd::Run(deadline)) => self.deadline = deadline,
                Ok(Cmd::Cancel) | Err(_) => return Err(Cancelled),
            }
        }
        Ok(())
    }
}

/// A registration that can run in bounded steps (see the module docs).
pub struct Registration {
    cloud: Arc<PointCloud>,
    template: Arc<Template>,
    opts: RegistrationOptions,
    worker: Option<(Sender<Cmd>, Receiver<Msg>, JoinHandle<()>)>,
    progress: Arc<Mutex<Progress>>,
    result: Option<Result<Fit>>,
}

impl Registration {
    /// Prepares a registration (validates the cloud; nothing runs yet).
    pub fn new(
        cloud: Arc<PointCloud>,
        template: Arc<Template>,
        opts: RegistrationOptions,
    ) -> Result<Self> {
        check_point_count(cloud.len(), &template, "points")?;
        Ok(Registration {
            cloud,
            template,
            opts,
            worker: None,
            progress: Arc::default(),
            result: None,
        })
    }

    /// Runs work units until `budget` is spent (at least one unit), then returns the progress.
    pub fn step(&mut self, budget: Duration) -> Progress {
        if self.result.is_some() {
            return self.progress();
        }
        let deadline = Instant::now() + budget;
        if self.worker.is_none() {
            let (cmd_tx, cmd_rx) = channel();
            let (msg_tx, msg_rx) = channel();
            let (cloud, template, opts, progress) = (
                self.cloud.clone(),
                self.template.clone(),
                self.opts.clone(),
                self.progress.clone(),
            );
            let handle = std::thread::spawn(move || {
                let frame = working_frame(&cloud);
                let mut pause = ChannelPause {
                    deadline,
                    cmds: cmd_rx,
                    msgs: msg_tx.clone(),
                    progress,
                    units: 0,
                    frame,
                };
                let r = register_in(frame, &cloud, template, &opts, &mut pause);
                let _ = msg_tx.send(Msg::Finished(Box::new(r)));
            });
            self.worker = Some((cmd_tx, msg_rx, handle));
        } else if let Some((tx, _, _)) = &self.worker {
            let _ = tx.send(Cmd::Run(deadline));
        }
        let msg = self.worker.as_ref().map(|(_, rx, _)| rx.recv());
        match msg {
            Some(Ok(Msg::Paused)) => {}
            Some(Ok(Msg::Finished(r))) => self.finish(*r),
            Some(Err(_)) | None => self.finish(Err(Error::input(
                "the registration worker stopped unexpectedly",
            ))),
        }
        self.progress()
    }

    fn finish(&mut self, r: Result<Fit>) {
        if let Ok(mut p) = self.progress.lock() {
            p.done = true;
            if let Ok(fit) = &r {
                p.skeleton = Some(fit.skeleton.clone());
                p.mean_distance = fit.mean_distance;
                p.activity.phase = "done";
                p.activity.fraction = 1.0;
            }
        }
        if let Some((_, _, h)) = self.worker.take() {
            let _ = h.join();
        }
        self.result = Some(r);
    }

    /// The latest progress.
    pub fn progress(&self) -> Progress {
        self.progress.lock().map(|p| p.clone()).unwrap_or_default()
    }

    /// True when finished.
    pub fn is_done(&self) -> bool {
        self.result.is_some()
    }

    /// The result, once finished.
    pub fn result(&self) -> Option<&Result<Fit>> {
        self.result.as_ref()
    }

    /// Takes the result, once finished.
    pub fn take_result(&mut self) -> Option<Result<Fit>> {
        self.result.take()
    }

    /// Runs the whole registration on the calling thread (no pauses).
    pub fn run_to_convergence(self) -> Result<Fit> {
        register(&self.cloud, self.template.clone(), &self.opts, &mut NoPause)
    }
}

impl Drop for Registration {
    fn drop(&mut self) {
        if let Some((tx, rx, h)) = self.worker.take() {
            let _ = tx.send(Cmd::Cancel);
            drop(rx);
            let _ = h.join();
        }
    }
}
