//! A world-space view of a [`Skeleton`] that FAKIR's parameters edit directly.
//!
//! The skeleton stores rotations relative to the parent; FAKIR's moves are easier to state in
//! world space ("rotate this bone about an axis through its first joint, its descendants
//! following", "move the joint between two bones while both outer joints stay put").
//! [`WorldSkeleton`] keeps each bone's **world frame**, length and radii, the root placement and
//! block scale; joints are derived by forward kinematics (`c1` of a bone is the end of its
//! parent, or the root). [`WorldSkeleton::to_skeleton`] converts back.
//!
//! Constraints are re-applied after every edit ([`WorldSkeleton::enforce`]): block bones keep
//! their rest frames relative to the root frame and `rest length × block scale`; followers
//! keep their rest frame relative to their leader and `ratio × leader length`; radii shared
//! along chains stay equal ([`RadiusClasses`]).

use crate::anatomy::template::{BoneKind, ChainDef, Template};
use crate::anatomy::{Posed, Skeleton};
use crate::geometry::Bone;
use crate::math::{Quat, Vec3};
use std::sync::Arc;

/// Which end of a bone.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum End {
    /// `c1`, `r1`.
    First,
    /// `c2`, `r2`.
    Second,
}

/// Classes of bone ends whose radius is one shared variable: consecutive bones of a chain
/// (possibly through a follower bone) share their joint radius (thesis §2.1).
#[derive(Clone, Debug)]
pub struct RadiusClasses {
    /// Class id of `(bone, End::First)` at `2 * bone`, of `(bone, End::Second)` at `2 * bone + 1`.
    class: Vec<usize>,
    /// Members of each class.
    pub members: Vec<Vec<(usize, End)>>,
}

impl RadiusClasses {
    /// Builds the classes of a template.
    pub fn new(t: &Template) -> Self {
        let n = t.bones.len() * 2;
        let mut parent: Vec<usize> = (0..n).collect();
        fn find(p: &mut [usize], mut x: usize) -> usize {
            while p[x] != x {
                p[x] = p[p[x]];
                x = p[x];
            }
            x
        }
        let chain_of = |b: usize| -> Option<usize> {
            match t.bones[b].kind {
                BoneKind::Follower { leader, .. } => t.bones[leader].chain.map(|c| c.0),
                _ => t.bones[b].chain.map(|c| c.0),
            }
        };
        for (c, def) in t.bones.iter().enumerate() {
            let Some(p) = def.parent else { continue };
            let follower_of_p =
                matches!(def.kind, BoneKind::Follower { leader, .. } if leader == p);
            let same_chain = chain_of(c).is_some() && chain_of(c) == chain_of(p);
            if follower_of_p || same_chain {
                let (a, b) = (find(&mut parent, 2 * p + 1), find(&mut parent, 2 * c));
                parent[a] = b;
            }
        }
        let mut ids = std::collections::BTreeMap::new();
        let mut class = vec![0; n];
        let mut members: Vec<Vec<(usize, End)>> = Vec::new();
        for (x, slot) in class.iter_mut().enumerate() {
            let r = find(&mut parent, x);
            let next = ids.len();
            let id = *ids.entry(r).or_insert(next);
            if id == members.len() {
                members.push(Vec::new());
            }
            *slot = id;
            members[id].push((x / 2, if x % 2 == 0 { End::First } else { End::Second }));
        }
        RadiusClasses { class, members }
    }

    /// The class of a bone end.
    pub fn class_of(&self, bone: usize, end: End) -> usize {
        self.class[2 * bone + (end == End::Second) as usize]
    }
}

/// World-space skeleton state (see the module docs).
#[derive(Clone, Debug)]
pub struct WorldSkeleton {
    pub template: Arc<Template>,
    pub root_position: Vec3,
    pub root_rotation: Quat,
    pub block_scale: f32,
    /// World frame of each bone (X along the bone).
    pub frames: Vec<Quat>,
    pub lengths: Vec<f32>,
    pub r1: Vec<f32>,
    pub r2: Vec<f32>,
    /// Rest rotation of each bone relative to its parent (constraints use it); shared, as
    /// the LM clones the world skeleton several times per iteration.
    rest_relative: Arc<[Quat]>,
    /// World frames of the template's rest pose (the joint-range prior compares against them).
    pub rest_frames: Arc<[Quat]>,
    /// Rest lengths and radii of the template (unscaled).
    rest_lengths: Arc<[f32]>,
}

/// The trunk's first free bone hanging from the root block (the human's `spine_lower`) and
/// the block bone carrying it (`pelvis_up`): `(block bone, free bone)`, the first in bone
/// order; `None` when the template has no block or no trunk chain on it.
fn trunk_on_block(t: &Template) -> Option<(usize, usize)> {
    let trunk = super::solver::trunk_bones(t);
    t.bones.iter().enumerate().find_map(|(b, def)| {
        let p = def.parent?;
        (def.kind == BoneKind::Free && trunk[b] && t.bones[p].kind == BoneKind::Block)
            .then_some((p, b))
    })
}

impl WorldSkeleton {
    /// The world view of a skeleton.
    pub fn from_skeleton(s: &Skeleton) -> Self {
        let posed = s.pose();
        let rest = Skeleton::rest(s.template.clone());
        WorldSkeleton {
            template: s.template.clone(),
            root_position: s.root_position,
            root_rotation: s.root_rotation,
            block_scale: s.block_scale,
            frames: posed.frames,
            lengths: s.bones.iter().map(|b| b.length).collect(),
            r1: s.bones.iter().map(|b| b.r1).collect(),
            r2: s.bones.iter().map(|b| b.r2).collect(),
            rest_frames: crate::anatomy::skeleton::rest_frames(&s.template).into(),
            rest_relative: rest
                .bones
                .iter()
                .map(|b| b.rotation)
                .collect::<Vec<_>>()
                .into(),
            rest_lengths: rest
                .bones
                .iter()
                .map(|b| b.length)
                .collect::<Vec<_>>()
                .into(),
        }
    }

    /// Back to a relative-rotation skeleton.
    pub fn to_skeleton(&self) -> Skeleton {
        let t = &self.template;
        let bones = t
            .bones
            .iter()
            .enumerate()
            .map(|(i, def)| {
                let parent = def
                    .parent
                    .map(|p| self.frames[p])
                    .unwrap_or(self.root_rotation);
                crate::anatomy::BoneState {
                    rotation: (parent.inverse() * self.frames[i]).normalize(),
                    length: self.lengths[i],
                    r1: self.r1[i],
                    r2: self.r2[i],
                }
            })
            .collect();
        Skeleton {
            template: t.clone(),
            root_position: self.root_position,
            root_rotation: self.root_rotation,
            block_scale: self.block_scale,
            bones,
        }
    }

    /// World bones and joints by forward kinematics over the world frames.
    pub fn pose(&self) -> Posed {
        let t = &self.template;
        let mut bones = Vec::with_capacity(t.bones.len());
        let mut joints = vec![Vec3::ZERO; t.joints.len()];
        joints[t.root] = self.root_position;
        for (i, def) in t.bones.iter().enumerate() {
            let c1: Vec3 = match def.parent {
                Some(p) => {
                    let b: &Bone = &bones[p];
                    b.c2
                }
                None => self.root_position,
            };
            let c2 = c1 + self.frames[i] * Vec3::new(self.lengths[i], 0.0, 0.0);
            bones.push(Bone::new(c1, self.r1[i], c2, self.r2[i]));
            joints[def.to] = c2;
        }
        Posed {
            bones,
            frames: self.frames.clone(),
            joints,
        }
    }

    /// World bones only.
    pub fn bones(&self) -> Vec<Bone> {
        self.pose().bones
    }

    /// Re-applies block and follower constraints (see the module docs).
    pub fn enforce(&mut self) {
        let t = self.template.clone();
        for (i, def) in t.bones.iter().enumerate() {
            match def.kind {
                BoneKind::Free => {}
                BoneKind::Block => {
                    self.frames[i] = (self.root_rotation * self.rest_relative[i]).normalize();
                    self.lengths[i] = self.rest_lengths[i] * self.block_scale;
                }
                BoneKind::Follower { leader, ratio } => {
                    self.frames[i] = (self.frames[leader] * self.rest_relative[i]).normalize();
                    self.lengths[i] = ratio * self.lengths[leader];
                }
            }
        }
    }

    /// Rotates bone `b` by the world rotation `q` about its first joint; its descendants follow.
    pub fn rotate_subtree(&mut self, b: usize, q: Quat) {
        for d in self.template.subtree(b) {
            self.frames[d] = (q * self.frames[d]).normalize();
        }
    }

    /// Points bone `b` (first joint fixed) at `target`: minimal rotation of its frame and new
    /// length; descendants keep their world frames (they translate with the bone's end).
    pub fn aim(&mut self, b: usize, c1: Vec3, target: Vec3) {
        let d = target - c1;
        let len = d.length();
        if len < 1e-12 {
            return;
        }
        let axis = self.frames[b] * Vec3::X;
        let q = crate::geometry::frames::rotation_arc(axis, d / len);
        self.frames[b] = (q * self.frames[b]).normalize();
        self.lengths[b] = len;
    }

    /// The skeleton **turned around**: the same figure fitted facing the other way, with left
    /// and right exchanged (the hypothesis of the registration's facing check). The root
    /// block turns half a turn about the figure's up axis through the root joint, so its left
    /// and right sides change places; every bone of a mirrored pair (`mirror`, see
    /// [`crate::anatomy::Template::mirror_bones`]) takes its mirror's direction, length and
    /// radii, so the limbs stay where they lay with their labels exchanged; an unpaired bone
    /// keeps its own. Frames as in [`WorldSkeleton::untwisted`]. The block's own bones turn with it
    /// and take their mirror's radii, as the limbs hanging from them do.
    pub fn turned_around(&self, mirror: &[Option<usize>]) -> WorldSkeleton {
        let up = self.up();
        let root =
            (Quat::from_axis_angle(up, std::f32::consts::PI) * self.root_rotation).normalize();
        self.rebuilt(root, mirror)
    }

    /// The same bones without twist: each free bone's frame is its rest frame relative to its
    /// parent swung minimally onto its direction (lengths and radii unchanged, and positions,
    /// except a follower's that leaves its leader's axis: it follows the leader's new frame).
    /// FAKIR moves a bone by rotations about axes across it, which leave its twist to chance,
    /// and a hinge's range is stated in its parent's frame: a knee measured against a thigh
    /// twisted by a quarter turn seems bent sideways. Untwisted, the hinge axes follow the
    /// trunk's frame down each chain, as at rest.
    pub fn untwisted(&self) -> WorldSkeleton {
        self.rebuilt(self.root_rotation, &vec![None; self.template.bones.len()])
    }

    /// The figure's up direction: the root frame's `+Y` (as [`Skeleton::up`]).
    pub fn up(&self) -> Vec3 {
        self.root_rotation * Vec3::Y
    }

    /// The most **crossed** pair of mirrored limb bones (`mirror`, see
    /// [`crate::anatomy::Template::mirror_bones`]), by the lower index of the two, or `None`.
    /// Two bones `a`, `b` starting at different joints are crossed when exchanging their ends
    /// makes them shorter: `|a.c1 − b.c2| + |b.c1 − a.c2| < |a| + |b|` (segments that
    /// intersect always are, by the triangle inequality); the most crossed has the lowest
    /// ratio of the two sums. Only free bones are examined, and pairs whose subtrees hold a
    /// bone of `skip` (known lost, collapsed) are left out. A fit with crossed bones has laid
    /// each limb's lower part on the other limb (a thigh from its hip to the other knee):
    /// limbs do not pass through one another, and no synthetic statue's true skeleton has
    /// such a pair.
    pub fn most_crossed(&self, mirror: &[Option<usize>], skip: &[bool]) -> Option<usize> {
        let t = &self.template;
        let posed = self.pose();
        let skipped = |b: usize| t.subtree(b).iter().any(|&i| skip[i]);
        let mut best: Option<(usize, f32)> = None;
        for (a, def) in t.bones.iter().enumerate() {
            let Some(b) = mirror[a] else { continue };
            if b <= a
                || def.kind != BoneKind::Free
                || t.bones[b].kind != BoneKind::Free
                || def.from == t.bones[b].from
                || skipped(a)
                || skipped(b)
            {
                continue;
            }
            let (p, q) = (posed.bones[a], posed.bones[b]);
            let straight = self.lengths[a] + self.lengths[b];
            let exchanged = (p.c1 - q.c2).length() + (q.c1 - p.c2).length();
            if straight <= 0.0 || !exchanged.is_finite() || exchanged >= straight {
                continue;
            }
            let ratio = exchanged / straight;
            if best.is_none_or(|(_, r)| ratio < r) {
                best = Some((a, ratio));
            }
        }
        best.map(|(a, _)| a)
    }

    /// The limb that has **crossed over** onto its mirror's place, as the bone to exchange
    /// below ([`WorldSkeleton::exchanged_below`]), or `None`.
    ///
    /// A limb bone `b` with a parent `p`, whose subtree holds fewer than `starved` times the
    /// points of its mirror `m`'s subtree (`points`: each bone's point count), while `p` and
    /// its mirror `p'` end closer together than `near` times the longer of their two lengths
    /// (one of the two may have collapsed): `p'` has reached over to `p`'s end and `m`'s
    /// subtree lies where `b`'s should, on `b`'s points. The four bones must be free and none
    /// of them in `skip` (the trunk, bones known lost). On a statue cut through the left
    /// thigh, FAKIR can lay the left leg from its hip over to the right knee and down the
    /// right leg, and leave the right leg's shin and foot folded at that knee with almost no
    /// points; the lost-limb rules then take nothing, or the right leg. Of several such pairs
    /// the one nearest the root wins (the fewest bones above `p`: exchanging below it moves
    /// the others too), then the most starved `b` (the lowest ratio of the two subtrees'
    /// points).
    pub fn most_crossed_over(
        &self,
        mirror: &[Option<usize>],
        skip: &[bool],
        points: &[usize],
        starved: f64,
        near: f32,
    ) -> Option<usize> {
        let t = &self.template;
        let posed = self.pose();
        let count = |b: usize| t.subtree(b).iter().map(|&i| points[i]).sum::<usize>() as f64;
        let free = |b: usize| t.bones[b].kind == BoneKind::Free && !skip[b];
        let depth = |mut b: usize| {
            let mut d = 0;
            while let Some(p) = t.bones[b].parent {
                (b, d) = (p, d + 1);
            }
            d
        };
        let mut best: Option<(usize, usize, f64)> = None;
        for b in 0..t.bones.len() {
            let (Some(p), Some(m)) = (t.bones[b].parent, mirror[b]) else {
                continue;
            };
            let Some(q) = mirror[p] else { continue };
            if q == p || ![b, p, m, q].into_iter().all(free) {
                continue;
            }
            let ratio = count(b) / count(m).max(1.0);
            let longer = self.lengths[p].max(self.lengths[q]);
            let apart = (posed.bones[p].c2 - posed.bones[q].c2).length();
            let key = (depth(p), ratio);
            if ratio < starved
                && longer > 0.0
                && apart < near * longer
                && best.is_none_or(|(_, d, r)| key < (d, r))
            {
                best = Some((p, key.0, ratio));
            }
        }
        best.map(|(p, ..)| p)
    }

    /// The skeleton with the limbs below the mirrored bones `a` and `mirror[a]` exchanged
    /// (the start that uncrosses a pair found by [`WorldSkeleton::most_crossed`]): each of the
    /// two bones keeps its first joint and reaches to the other's end (its end radius with
    /// it), and every bone below takes its mirror's direction, length and radii, its frame
    /// swung minimally from rest relative to its new parent (as in
    /// [`WorldSkeleton::turned_around`]). Everything else is unchanged. `None` when `a` has no
    /// mirror or a bone below has none.
    pub fn exchanged_below(&self, a: usize, mirror: &[Option<usize>]) -> Option<WorldSkeleton> {
        let b = mirror[a]?;
        let t = self.template.clone();
        let posed = self.pose();
        let mut out = self.clone();
        for (top, other) in [(a, b), (b, a)] {
            out.aim(top, posed.bones[top].c1, posed.bones[other].c2);
            out.r2[top] = self.r2[other];
            for i in t.subtree(top).into_iter().skip(1) {
                let m = mirror[i]?;
                out.lengths[i] = self.lengths[m];
                out.r1[i] = self.r1[m];
                out.r2[i] = self.r2[m];
                let parent = t.bones[i]
                    .parent
                    .map_or(out.root_rotation, |p| out.frames[p]);
                let (m1, m2) = (posed.bones[m].c1, posed.bones[m].c2);
                out.frames[i] = self.swung_from_rest(i, parent, m2 - m1);
            }
        }
        out.enforce();
        Some(out)
    }

    /// The most **folded** joint inside a chain: the bone `a`, by index, whose child `b` in
    /// the same chain turns back from `a`'s direction by more than `limit` radians (the angle
    /// between the two directions), the largest such angle first, or `None`. Free bones only;
    /// bones of `skip` (trunk bones, known-lost bones) and their chain children are left out.
    /// A fit folded this way has stretched `a` over the limb below it and laid `b` back
    /// along it (an upper arm from the shoulder to the hand, the forearm back to the elbow).
    pub fn most_folded(&self, skip: &[bool], limit: f32) -> Option<usize> {
        let t = &self.template;
        let mut best: Option<(usize, f32)> = None;
        for b in 0..t.bones.len() {
            let Some(a) = t.bones[b].parent else { continue };
            if skip[a] || skip[b] {
                continue;
            }
            if let Some(angle) = self.fold_angle(b)
                && angle > limit
                && best.is_none_or(|(_, g)| angle > g)
            {
                best = Some((a, angle));
            }
        }
        best.map(|(a, _)| a)
    }

    /// How far bone `b` turns back from its parent's direction (radians, the angle between
    /// the two directions: 0 straight on, π folded flat back), when both are free bones of
    /// one chain with a length; `None` otherwise (a chain's first bone, a block or follower
    /// bone, a collapsed bone). [`WorldSkeleton::most_folded`]'s measure.
    pub fn fold_angle(&self, b: usize) -> Option<f32> {
        let t = &self.template;
        let def = &t.bones[b];
        let a = def.parent?;
        let same_chain =
            def.chain.is_some() && def.chain.map(|c| c.0) == t.bones[a].chain.map(|c| c.0);
        if !same_chain
            || def.kind != BoneKind::Free
            || t.bones[a].kind != BoneKind::Free
            || self.lengths[a] <= 0.0
            || self.lengths[b] <= 0.0
        {
            return None;
        }
        let (u, v) = (self.frames[a] * Vec3::X, self.frames[b] * Vec3::X);
        Some(u.dot(v).clamp(-1.0, 1.0).acos())
    }

    /// The skeleton with the chain from bone `a` to its end **unfolded** (the start that
    /// undoes a fold found by [`WorldSkeleton::most_folded`]): those bones laid in a straight
    /// line along `a`'s direction, from `a`'s first joint to `a`'s end (the reach the fit
    /// found), their lengths in the template's rest proportions; each frame is swung
    /// minimally onto the line; radii and everything else unchanged.
    pub fn unfolded(&self, a: usize) -> WorldSkeleton {
        let mut out = self.clone();
        let line = self.chain_from(a);
        let rest: f32 = line.iter().map(|&b| self.rest_lengths[b]).sum();
        if rest <= 0.0 {
            return out;
        }
        let reach = self.lengths[a];
        let d = self.frames[a] * Vec3::X;
        for &b in line {
            out.swing_onto(b, d, reach * self.rest_lengths[b] / rest);
        }
        out.enforce();
        out
    }

    /// The bones of `a`'s chain from `a` to the chain's end (empty when `a` is in no chain).
    fn chain_from(&self, a: usize) -> &[usize] {
        let t = &self.template;
        let Some(bones) = t.bones[a].chain.map(|c| &t.chains[c.0].bones) else {
            return &[];
        };
        bones
            .iter()
            .position(|&b| b == a)
            .map_or(&[], |k| &bones[k..])
    }

    /// Swings bone `b`'s frame minimally onto the unit direction `d` and gives it length
    /// `len` (its descendants keep their world frames).
    fn swing_onto(&mut self, b: usize, d: Vec3, len: f32) {
        let axis = self.frames[b] * Vec3::X;
        self.frames[b] =
            (crate::geometry::frames::rotation_arc(axis, d) * self.frames[b]).normalize();
        self.lengths[b] = len;
    }

    /// The root block **slid** one bone down (the start of the slid-block check): the block
    /// moved rigidly by minus its *spine bone*'s vector (the block bone that carries the
    /// trunk's chain, the human's `pelvis_up`), so its spine end lands where its root joint
    /// was; each free bone hanging from the block (the spine's first bone, the thighs) keeps
    /// its far end and is re-aimed from its moved first joint, so everything below and above
    /// stays where it was. `None` when the template has no block or no trunk chain on it.
    /// A fit that has sat the pelvis one bone too high along the spine has the thighs
    /// starting above the legs, where no points cover them; this start puts it back.
    pub fn slid_block(&self) -> Option<WorldSkeleton> {
        let t = self.template.clone();
        let is_block = |b: usize| t.bones[b].kind == BoneKind::Block;
        let (spine, _) = trunk_on_block(&t)?;
        let posed = self.pose();
        let delta = posed.bones[spine].c1 - posed.bones[spine].c2;
        if delta.length() <= 0.0 {
            return None;
        }
        let mut out = self.clone();
        out.root_position += delta;
        for (b, def) in t.bones.iter().enumerate() {
            if let Some(p) = def.parent
                && is_block(p)
                && def.kind == BoneKind::Free
            {
                let bone = &posed.bones[b];
                out.aim(b, bone.c1 + delta, bone.c2);
            }
        }
        out.enforce();
        Some(out)
    }

    /// How much of the trunk chain its last two bones take, relative to the template's rest
    /// proportions (the trigger of the slid-block check on a squeezed end, level 5 in the
    /// registration's module docs): `(l_{n−1} + l_n) / (l_1 + … + l_{n−2})` over the fitted
    /// lengths of the chain carried by the root block ([`WorldSkeleton::slid_block`]'s), the
    /// same ratio at rest dividing it. 1 at the template's proportions; the human's neck and
    /// head against its two spine bones. `None` when the template has no such chain of at
    /// least three bones, or a length is zero.
    pub fn trunk_end_share(&self) -> Option<f32> {
        let (_, first) = trunk_on_block(&self.template)?;
        let line = self.chain_from(first);
        let n = line.len();
        if n < 3 {
            return None;
        }
        let share = |len: &dyn Fn(usize) -> f32| -> Option<f32> {
            let end = len(line[n - 2]) + len(line[n - 1]);
            let start: f32 = line[..n - 2].iter().map(|&b| len(b)).sum();
            (start > 0.0 && end > 0.0).then(|| end / start)
        };
        Some(share(&|b| self.lengths[b])? / share(&|b| self.rest_lengths[b])?)
    }

    /// The template's trunk chain carried by the root block (the human's spine: the chain of
    /// the slid-block check and of [`WorldSkeleton::trunk_end_share`]), or `None`.
    pub fn trunk_chain(&self) -> Option<usize> {
        let (_, first) = trunk_on_block(&self.template)?;
        self.template.bones[first].chain.map(|(c, _)| c)
    }

    /// The **end of the trunk** and the chains beside it (the crowded-head check): the bones
    /// of the trunk chain ([`WorldSkeleton::trunk_chain`]) after the last one that carries
    /// another chain — a chain whose first bone has it as parent — and the chains that bone
    /// carries. The human's neck and head, and the arms hanging from `spine_upper`. `None`
    /// without a trunk chain, when no bone of it carries a chain, or when its last bone does.
    pub fn trunk_end(&self) -> Option<(Vec<usize>, Vec<usize>)> {
        let t = &self.template;
        let trunk = self.trunk_chain()?;
        let line = &t.chains[trunk].bones;
        let carried = |b: usize| -> Vec<usize> {
            (0..t.chains.len())
                .filter(|&c| {
                    c != trunk
                        && t.chains[c]
                            .bones
                            .first()
                            .is_some_and(|&f| t.bones[f].parent == Some(b))
                })
                .collect()
        };
        let k = line.iter().rposition(|&b| !carried(b).is_empty())?;
        (k + 1 < line.len()).then(|| (line[k + 1..].to_vec(), carried(line[k])))
    }

    /// The chain from free bone `a` to its end **slid one bone down** (the start of the
    /// slid-limb check): `a` reaches from its first joint to the end of the next bone of its
    /// chain, each later bone takes the direction and length of the one after it, and the
    /// last keeps its own, continuing from its new first joint; each frame is swung
    /// minimally onto its new direction; radii and everything else unchanged. `a` itself
    /// when it is the last of its chain. A fit whose leg sat one bone up the limb (the knee
    /// at the hip, the ankle at the knee) has its thigh in the trunk, uncovered at its root;
    /// this start moves each joint down to where the next one was.
    pub fn slid_down(&self, a: usize) -> WorldSkeleton {
        let mut out = self.clone();
        let line = self.chain_from(a);
        if line.len() < 2 {
            return out;
        }
        let posed = self.pose();
        let reach = posed.bones[line[1]].c2 - posed.bones[a].c1;
        if reach.length() <= 0.0 {
            return out;
        }
        out.swing_onto(a, reach.normalize(), reach.length());
        for w in line[1..].windows(2) {
            let next = w[1];
            out.swing_onto(w[0], self.frames[next] * Vec3::X, self.lengths[next]);
        }
        out.enforce();
        out
    }

    /// The chain from free bone `a` to its end **slid one bone out** (the start of the
    /// stretched-end check): like [`WorldSkeleton::slid_down`], except that the chain's
    /// last two bones share the old last bone's vector, in the template's rest proportions,
    /// so the chain's tip stays where it was. [`WorldSkeleton::slid_down`] itself when the
    /// chain from `a` has fewer than three bones. A fit whose arm sat one joint in (the
    /// elbow on the shoulder, the wrist on the elbow) has stretched its hand over the
    /// forearm and the hand; this start moves each joint out to where the next one was and
    /// splits that long last bone in two.
    pub fn slid_out(&self, a: usize) -> WorldSkeleton {
        let mut out = self.slid_down(a);
        let line = self.chain_from(a);
        let n = line.len();
        if n < 3 {
            return out;
        }
        let (p, last) = (line[n - 2], line[n - 1]);
        if out.split_along(p, last, self.frames[last] * Vec3::X, self.lengths[last]) {
            out.enforce();
        }
        out
    }

    /// Bones `p` and `last` (consecutive in a chain) laid along the unit direction `d` with
    /// lengths summing to `total`, in the template's rest proportions; `false` (nothing
    /// changed) when their rest lengths sum to zero.
    fn split_along(&mut self, p: usize, last: usize, d: Vec3, total: f32) -> bool {
        let rest = self.rest_lengths[p] + self.rest_lengths[last];
        if rest <= 0.0 {
            return false;
        }
        self.swing_onto(p, d, total * self.rest_lengths[p] / rest);
        self.swing_onto(last, d, total * self.rest_lengths[last] / rest);
        true
    }

    /// The last bone `last` of a chain and the bone before it **sharing that bone's
    /// vector** (the start of the dangling-end check): both laid along the direction of the
    /// bone before, in the template's rest proportions, so `last` ends where the bone before
    /// it ended; each frame swung minimally onto it; radii and everything else unchanged. A
    /// clone when `last` has no bone before it in its chain. A fit that stretched a forearm
    /// over the hand (its far end on the true hand's tip) leaves the hand hanging off the
    /// statue; this start gives the hand back its place at the end of the arm.
    pub fn split_end(&self, last: usize) -> WorldSkeleton {
        let mut out = self.clone();
        let t = &self.template;
        let Some((c, k)) = t.bones[last].chain.filter(|&(_, k)| k > 0) else {
            return out;
        };
        let p = t.chains[c].bones[k - 1];
        if out.split_along(p, last, self.frames[p] * Vec3::X, self.lengths[p]) {
            out.enforce();
        }
        out
    }

    /// The chain from free bone `a` **slid back** one bone (the start of the
    /// overreaching-limb check): `a` and the bone after it share `a`'s vector in the
    /// template's rest proportions, each later bone takes the vector (direction and length)
    /// of the bone before it, and the last bone's vector is dropped; each frame swung
    /// minimally onto its new direction; radii and everything else unchanged. A clone when
    /// `a` is the last bone of its chain (or in none). From the bone before the last it is
    /// [`WorldSkeleton::split_end`] of the last. A fit that stretched a thigh over the shin
    /// has the shin on the foot and the foot off the statue; this start puts each bone back
    /// one place up the limb. The bones below take their vectors as the fit left them, those
    /// of bones taken lost (shrunk or folded) included: the registration from this start
    /// finds their sizes again.
    pub fn slid_back(&self, a: usize) -> WorldSkeleton {
        let mut out = self.clone();
        let line = self.chain_from(a);
        if line.len() < 2 {
            return out;
        }
        let old: Vec<(Vec3, f32)> = line
            .iter()
            .map(|&b| (self.frames[b] * Vec3::X, self.lengths[b]))
            .collect();
        if !out.split_along(line[0], line[1], old[0].0, old[0].1) {
            return out;
        }
        for i in 2..line.len() {
            out.swing_onto(line[i], old[i - 1].0, old[i - 1].1);
        }
        out.enforce();
        out
    }

    /// The chain below free bone `a` **reversed** (the start of the hanging-limb check):
    /// `a` reaches from its first joint to where the chain's tip was, and the bones below
    /// it are laid back along the fit's own path from that tip to `a`'s old end, in the
    /// template's rest proportions (the chain's tip lands on `a`'s old end); each frame is
    /// swung minimally onto its new direction; radii and everything else unchanged. `a`
    /// itself when fewer than two bones hang below it in its chain. A fit that ran an arm
    /// backwards (the clavicle out to the hand, the arm coming back to the shoulder) has a
    /// clavicle across empty space; this start turns the arm around.
    pub fn reversed_below(&self, a: usize) -> WorldSkeleton {
        let mut out = self.clone();
        let line = self.chain_from(a);
        if line.len() < 3 {
            return out;
        }
        let posed = self.pose();
        // The path back from the tip: the chain's joints below `a`, last first.
        let mut path: Vec<Vec3> = line[1..].iter().map(|&b| posed.bones[b].c2).collect();
        path.reverse();
        path.push(posed.bones[a].c2);
        let seg: Vec<f32> = path.windows(2).map(|w| (w[1] - w[0]).length()).collect();
        let total: f32 = seg.iter().sum();
        let rest: f32 = line[1..].iter().map(|&b| self.rest_lengths[b]).sum();
        let root = posed.bones[a].c1;
        let reach = path[0] - root;
        if total <= 0.0 || rest <= 0.0 || reach.length() <= 0.0 {
            return out;
        }
        // The point at arc length `s` along the path.
        let at = |s: f32| -> Vec3 {
            let mut left = s;
            for (w, &l) in path.windows(2).zip(&seg) {
                if left <= l && l > 0.0 {
                    return w[0] + (w[1] - w[0]) * (left / l);
                }
                left -= l;
            }
            path[path.len() - 1]
        };
        out.swing_onto(a, reach.normalize(), reach.length());
        let (mut from, mut walked) = (path[0], 0.0);
        for &b in &line[1..] {
            walked += total * self.rest_lengths[b] / rest;
            let to = at(walked);
            let d = to - from;
            if d.length() > 0.0 {
                out.swing_onto(b, d.normalize(), d.length());
            }
            from = to;
        }
        out.enforce();
        out
    }

    /// The free bone of a limb chain most clearly **hanging in the air**: a bone (none in
    /// `skip`) whose support coverage is under `missing`, while at least two bones hang
    /// below it in its chain and every one of them is covered (at least `missing`); the
    /// least covered such bone, or `None`. A limb cannot hang from a bone that is not
    /// there: a fit that ran an arm backwards (see [`WorldSkeleton::reversed_below`]) has
    /// its clavicle across empty space and the arm on the scan.
    pub fn most_hanging(&self, skip: &[bool], coverage: &[f32], missing: f32) -> Option<usize> {
        let t = &self.template;
        let mut best: Option<(usize, f32)> = None;
        for (a, def) in t.bones.iter().enumerate() {
            if skip[a] || def.kind != BoneKind::Free || coverage[a] >= missing {
                continue;
            }
            let below = self.chain_from(a).get(1..).unwrap_or(&[]);
            if below.len() < 2 || below.iter().any(|&b| skip[b] || coverage[b] < missing) {
                continue;
            }
            if best.is_none_or(|(_, c)| coverage[a] < c) {
                best = Some((a, coverage[a]));
            }
        }
        best.map(|(a, _)| a)
    }

    /// The chain whose **end is most stretched**: among the chains of at least three free
    /// bones (none in `skip`), the one whose last bone is longer, relative to the bone before
    /// it, than `limit` times the template's rest ratio, the largest such excess first;
    /// returned as the chain's first bone, or `None`. An arm slid one joint in (see
    /// [`WorldSkeleton::slid_out`]) has a hand as long as a forearm and a hand together.
    pub fn most_stretched_end(&self, skip: &[bool], limit: f32) -> Option<usize> {
        let mut best: Option<(usize, f32)> = None;
        for c in self.free_chains(skip, 3).map(|c| c.bones.as_slice()) {
            let n = c.len();
            let (p, last) = (c[n - 2], c[n - 1]);
            let rest = self.rest_lengths[last] / self.rest_lengths[p].max(1e-12);
            if self.lengths[p] <= 0.0 || rest <= 0.0 {
                continue;
            }
            let ratio = self.lengths[last] / self.lengths[p] / rest;
            if ratio > limit && best.is_none_or(|(_, r)| ratio > r) {
                best = Some((c[0], ratio));
            }
        }
        best.map(|(a, _)| a)
    }

    /// The template's chains of at least `min` bones, all free and none in `skip` (the limb
    /// chains the end checks examine).
    fn free_chains<'a>(
        &'a self,
        skip: &'a [bool],
        min: usize,
    ) -> impl Iterator<Item = &'a ChainDef> + 'a {
        let t = &self.template;
        t.chains.iter().filter(move |c| {
            c.bones.len() >= min
                && c.bones
                    .iter()
                    .all(|&b| !skip[b] && t.bones[b].kind == BoneKind::Free)
        })
    }

    /// The chain whose **end dangles below a covered or a folded-up bone**: among the chains
    /// of at least two free bones (none in `skip`), those whose last bone is judged `lost`
    /// while the bone before it is not, and either
    /// - the last bone has not collapsed (`shrunk` false: FAKIR shrinks the bones of a lost
    ///   limb onto the stump) and the bone before it reaches `missing` support coverage: a
    ///   fit that stretched a forearm over the hand (see [`WorldSkeleton::split_end`]) leaves
    ///   the hand, at full size, off the statue or on points the forearm explains as well; or
    /// - the bone before it has collapsed (`shrunk`) and is under `missing` coverage, yet the
    ///   lost-limb rules keep it for points that nothing else explains: an arm folded up on
    ///   itself, its bones shrunk where the scan has a whole arm (a limb cut part-way is taken
    ///   lost down from the cut, or keeps a covered stump);
    ///
    /// the least covered such last bone, or `None`.
    pub fn most_dangling_end(
        &self,
        skip: &[bool],
        lost: &[bool],
        coverage: &[f32],
        shrunk: &[bool],
        missing: f32,
    ) -> Option<usize> {
        let mut best: Option<(usize, f32)> = None;
        for c in self.free_chains(skip, 2).map(|c| c.bones.as_slice()) {
            let n = c.len();
            let (p, last) = (c[n - 2], c[n - 1]);
            let covered = coverage[p] >= missing;
            let stretched_over = !shrunk[last] && covered;
            let folded_up = shrunk[p] && !covered;
            if !lost[last] || lost[p] || !(stretched_over || folded_up) {
                continue;
            }
            if best.is_none_or(|(_, v)| coverage[last] < v) {
                best = Some((last, coverage[last]));
            }
        }
        best.map(|(b, _)| b)
    }

    /// The bone from which a limb **overreaches**: among the chains of at least two free
    /// bones (none in `skip`) that end in a run of bones judged `lost` (the *tail*) below a
    /// bone neither lost nor under `missing` coverage, whose mirror chain has none of the
    /// tail's mirrors lost, those whose bones above the tail are longer together than their
    /// mirrors by at least `share` of the length of the tail's first bone's mirror. The limb
    /// has a bone's worth of length too much above where it seems to end: a thigh stretched
    /// over the shin, the shin laid on the foot, the foot pushed off the statue and taken
    /// lost. Of the chain with the largest excess (in those mirror lengths), the bone above
    /// the tail longest relative to its mirror, or `None`.
    pub fn most_overreaching(
        &self,
        skip: &[bool],
        lost: &[bool],
        coverage: &[f32],
        missing: f32,
        share: f32,
    ) -> Option<usize> {
        let t = &self.template;
        let mut best: Option<(usize, f32)> = None;
        for chain in self.free_chains(skip, 2) {
            let c = chain.bones.as_slice();
            // The tail: the chain's lost bones from the last one up.
            let tail = c.len() - c.iter().rev().take_while(|&&b| lost[b]).count();
            if tail == 0 || tail == c.len() || coverage[c[tail - 1]] < missing {
                continue;
            }
            let Some(m) = chain.mirror.map(|mc| t.chains[mc].bones.as_slice()) else {
                continue;
            };
            // (Template loading rejects mirror chains of another length.)
            if m.len() != c.len() || m[tail..].iter().any(|&x| lost[x]) {
                continue;
            }
            let above: f32 = c[..tail].iter().map(|&b| self.lengths[b]).sum();
            let mirrored: f32 = m[..tail].iter().map(|&b| self.lengths[b]).sum();
            let unit = self.lengths[m[tail]];
            if !(unit > 0.0) {
                continue;
            }
            let excess = (above - mirrored) / unit;
            if !(excess >= share) || !best.is_none_or(|(_, e)| excess > e) {
                continue;
            }
            // (`tail ≥ 1`: there is a bone above the tail.)
            let ratio = |k: usize| self.lengths[c[k]] / self.lengths[m[k]].max(f32::MIN_POSITIVE);
            let longest = (0..tail).max_by(|&i, &j| ratio(i).total_cmp(&ratio(j)));
            best = longest.map(|k| (c[k], excess));
        }
        best.map(|(b, _)| b)
    }

    /// The frame of free bone `i` under a parent frame `parent`: its rest frame relative to
    /// the parent swung minimally onto `direction` (the rest axis when `direction` is zero).
    fn swung_from_rest(&self, i: usize, parent: Quat, direction: Vec3) -> Quat {
        let base = parent * self.rest_relative[i];
        let axis = base * Vec3::X;
        let d = direction.try_normalize().unwrap_or(axis);
        (crate::geometry::frames::rotation_arc(axis, d) * base).normalize()
    }

    /// The skeleton with root rotation `root`, each bone `i` taking the direction, length and
    /// radii of bone `mirror[i]` (itself when `None`), free frames swung minimally from rest.
    fn rebuilt(&self, root: Quat, mirror: &[Option<usize>]) -> WorldSkeleton {
        let t = self.template.clone();
        let posed = self.pose();
        let mut out = self.clone();
        out.root_rotation = root;
        for (i, m) in mirror.iter().enumerate() {
            let src = m.unwrap_or(i);
            out.lengths[i] = self.lengths[src];
            out.r1[i] = self.r1[src];
            out.r2[i] = self.r2[src];
        }
        // Two passes: a follower's leader may come after its children in bone order.
        for _ in 0..2 {
            for (i, def) in t.bones.iter().enumerate() {
                let parent = def.parent.map_or(out.root_rotation, |p| out.frames[p]);
                match def.kind {
                    BoneKind::Free => {
                        let b = posed.bones[mirror[i].unwrap_or(i)];
                        out.frames[i] = self.swung_from_rest(i, parent, b.c2 - b.c1);
                    }
                    BoneKind::Block => {
                        out.frames[i] = (out.root_rotation * self.rest_relative[i]).normalize();
                    }
                    BoneKind::Follower { leader, .. } => {
                        out.frames[i] = (out.frames[leader] * self.rest_relative[i]).normalize();
                    }
                }
            }
        }
        out.enforce();
        out
    }

    /// `bones` (each after its parent) put back at the template's rest pose relative to
    /// their parents, at rest length times the block scale; every other bone keeps its world
    /// frame (its joints move with the bones above it), but for followers, which follow their
    /// leaders before the next bone is placed (the human's neck hangs from `neck_link`, which
    /// follows `spine_upper`). The crowded-head check's trunk.
    pub fn at_rest(&self, bones: &[usize]) -> WorldSkeleton {
        let mut out = self.clone();
        for &b in bones {
            let from_rest = match self.template.bones[b].parent {
                Some(p) => out.frames[p] * self.rest_frames[p].inverse(),
                None => self.root_rotation,
            };
            out.frames[b] = (from_rest * self.rest_frames[b]).normalize();
            out.lengths[b] = self.rest_lengths[b] * self.block_scale;
            out.enforce();
        }
        out
    }

    /// Direction of bone `b` relative to its parent, expressed in the template's rest frame
    /// (what [`crate::fakir::init::range_excess`] measures).
    pub fn direction_at_rest(&self, b: usize) -> Vec3 {
        let to_rest = match self.template.bones[b].parent {
            Some(p) => (self.frames[p] * self.rest_frames[p].inverse()).inverse(),
            None => self.root_rotation.inverse(),
        };
        to_rest * (self.frames[b] * Vec3::X)
    }

    /// Sets the radius of a bone end and of every end sharing it.
    pub fn set_radius(&mut self, classes: &RadiusClasses, bone: usize, end: End, value: f32) {
        let c = classes.class_of(bone, end);
        for &(b, e) in &classes.members[c] {
            match e {
                End::First => self.r1[b] = value,
                End::Second => self.r2[b] = value,
            }
        }
    }

    /// Radius of a bone end.
    pub fn radius(&self, bone: usize, end: End) -> f32 {
        match end {
            End::First => self.r1[bone],
            End::Second => self.r2[bone],
        }
    }

    /// Rotates the whole skeleton about the root joint by `q`.
    pub fn rotate_all(&mut self, q: Quat) {
        self.root_rotation = (q * self.root_rotation).normalize();
        for f in &mut self.frames {
            *f = (q * *f).normalize();
        }
    }

    /// Scales the root block by `k` about the root (block lengths and radii).
    pub fn scale_block(&mut self, k: f32) {
        self.block_scale *= k;
        let t = self.template.clone();
        for (i, def) in t.bones.iter().enumerate() {
            if def.kind == BoneKind::Block {
                self.r1[i] *= k;
                self.r2[i] *= k;
            }
        }
        self.enforce();
    }

    /// Rest length of bone `b` in template units.
    pub fn rest_length(&self, b: usize) -> f32 {
        self.rest_lengths[b]
    }
}
