//! Poses and proportions as data: what a statue is re-posed *to*.
//!
//! A [`Pose`] says, for a few named bones of a template, which way each bone should point; a
//! [`Proportions`] says how much longer or thicker bones should be. Both are small RON files
//! (`config/poses/*.ron`, `config/proportions/*.ron`) that a curator can edit, and plain structs
//! that code can build. Applying either to a fitted [`Skeleton`] gives a new skeleton of the same
//! template — the *target* that point-set skinning ([`crate::skinning`]) deforms the statue to.
//!
//! ## The pose format
//!
//! ```ron
//! // config/poses/arms_raised.ron
//! (
//!     name: "arms_raised",
//!     description: "Both arms raised overhead in a V.",
//!     base: Rest,                 // or Fitted (the default)
//!     bones: {
//!         "l_upper_arm": (direction: (0.35, 1.0, 0.05)),
//!         "l_forearm":   (direction: (0.25, 1.0, 0.05), twist: 10.0),
//!         "r_thigh":     (rotate: (1.0, 0.0, 0.0, -30.0)),
//!     },
//! )
//! ```
//!
//! * `base`: where the bones that the pose does not name come from. `Fitted` starts from the
//!   statue's fitted rotations (relative to each parent), so a pose that names only the arms
//!   leaves the legs as the sculptor made them; `Rest` starts from the template's rest pose.
//!   Either way the root placement (position, orientation, block scale) and every bone's length
//!   and radii stay those of the fitted skeleton: a pose changes rotations only.
//! * `direction: (x, y, z)`: the bone's target direction, from its first joint to its second,
//!   in the **template frame** (`+Y` up, `+Z` the figure's front, `+X` the figure's own left),
//!   so a pose reads the same whatever the statue's orientation in its scan: the world target
//!   is `skeleton.root_rotation · direction`. Need not be normalised; must be finite and
//!   non-zero. The bone is turned by the *minimal swing* from its current direction
//!   ([`crate::geometry::frames::rotation_arc`]), so its twist about its own axis is the one it
//!   had (from `base` and its parents).
//! * `rotate: (ax, ay, az, degrees)`: instead of a direction, turn the bone rigidly by `degrees`
//!   about the axis `(ax, ay, az)` (template frame, right-hand rule) from its current world
//!   orientation — handy for "bend the knee 30° more". Giving both `direction` and `rotate` is an
//!   error.
//! * `twist: degrees`: then spin the bone about its own axis (right-hand rule about the
//!   direction from its first joint to its second), e.g. to turn the head.
//!
//! Bones are processed parents first (the template's bone order), and a bone's children keep
//! their rotation relative to it unless they are named too: naming only `l_upper_arm` carries
//! the forearm and hand along; naming `l_forearm` as well sets its absolute direction. Block
//! bones (the pelvis) and follower bones (the neck link) cannot be named: they keep their
//! constraints ([`Skeleton::enforce_constraints`]); turn the whole statue with the root instead.
//!
//! Built-in poses for the human template ([`Pose::builtin_names`]) are compiled in; besides the
//! files, `identity` is the fitted pose unchanged (for round trips) and `rest` the template's
//! rest pose. [`Pose::resolve`] takes a built-in name or a file path.
//!
//! ## The proportions format
//!
//! ```ron
//! (
//!     scale: 1.0,                              // uniform, on every length and radius
//!     lengths: { "l_thigh": 1.2, "r_thigh": 1.2 },
//!     radii: { "l_upper_arm": 1.3 },           // both radii of the bone
//! )
//! ```
//!
//! Factors multiply the fitted values and must be finite and in `(0.1, 10]`. A radius factor
//! scales both spheres of that bone only: neighbouring bones keep theirs, so to thicken a whole
//! limb list every bone of it. Lengths of block and follower bones cannot be named (they follow
//! the block scale and their leader).
//!
//! Animation between two skeletons of the same template is [`interpolate`].

use super::skeleton::Skeleton;
use super::template::{BoneKind, Template};
use crate::error::{Error, Result};
use crate::geometry::frames::rotation_arc;
use crate::math::{Quat, Vec3};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Where the bones a pose does not name start from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum PoseBase {
    /// The statue's fitted rotations (relative to each parent).
    #[default]
    Fitted,
    /// The template's rest rotations.
    Rest,
}

/// What a pose asks of one bone. See the [module documentation](self) for the semantics.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BonePose {
    /// Target direction from `c1` to `c2`, template frame (`+Y` up, `+Z` front, `+X` left).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub direction: Option<[f32; 3]>,
    /// Rigid turn: axis (template frame, 3 values) and angle in degrees.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotate: Option<[f32; 4]>,
    /// Extra rotation about the bone's own axis, in degrees, applied last.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub twist: Option<f32>,
}

/// A pose: per-bone target directions over a base. See the [module documentation](self).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pose {
    pub name: String,
    #[serde(default)]
    pub description: String,
    #[serde(default)]
    pub base: PoseBase,
    #[serde(default)]
    pub bones: BTreeMap<String, BonePose>,
}

/// The built-in pose files (`config/poses/NAME.ron`), compiled in.
const BUILTIN_POSE_FILES: [(&str, &str); 7] = [
    ("rest", include_str!("../../config/poses/rest.ron")),
    (
        "contrapposto",
        include_str!("../../config/poses/contrapposto.ron"),
    ),
    (
        "arms_raised",
        include_str!("../../config/poses/arms_raised.ron"),
    ),
    ("walking", include_str!("../../config/poses/walking.ron")),
    ("seated", include_str!("../../config/poses/seated.ron")),
    ("thinker", include_str!("../../config/poses/thinker.ron")),
    ("greeting", include_str!("../../config/poses/greeting.ron")),
];

/// Every built-in pose name: `identity` and the files of `config/poses/`.
const BUILTIN_POSE_NAMES: [&str; 8] = [
    "identity",
    "rest",
    "contrapposto",
    "arms_raised",
    "walking",
    "seated",
    "thinker",
    "greeting",
];

/// RON with `implicit_some`: files write `direction: (0, 1, 0)` rather than
/// `direction: Some((0, 1, 0))` (both are accepted).
fn ron_options() -> ron::Options {
    ron::Options::default().with_default_extension(ron::extensions::Extensions::IMPLICIT_SOME)
}

fn read_text(path: &Path) -> Result<String> {
    std::fs::read_to_string(path).map_err(|e| Error::Io {
        path: path.to_path_buf(),
        source: e,
    })
}

/// Levenshtein distance, to suggest the closest bone names.
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut cur = vec![i + 1; b.len() + 1];
        for (j, &cb) in b.iter().enumerate() {
            cur[j + 1] = (prev[j] + usize::from(ca != cb))
                .min(prev[j + 1] + 1)
                .min(cur[j] + 1);
        }
        prev = cur;
    }
    prev[b.len()]
}

/// "unknown bone 'x' …" with the closest names among `candidates`.
pub(crate) fn unknown_bone(
    what: &str,
    name: &str,
    template: &Template,
    candidates: &[usize],
) -> String {
    let mut names: Vec<&str> = candidates
        .iter()
        .map(|&i| template.bones[i].name.as_str())
        .collect();
    names.sort_by_key(|n| (edit_distance(name, n), *n));
    let shown = names.len().min(5);
    format!(
        "{what}: unknown bone '{name}' in template '{}' (closest: {}{}; {} bones can be named)",
        template.name,
        names[..shown].join(", "),
        if names.len() > shown { ", …" } else { "" },
        names.len()
    )
}

/// Indices of the free bones (the ones a pose or a length factor may name).
fn free_bones(t: &Template) -> Vec<usize> {
    (0..t.bones.len())
        .filter(|&i| t.bones[i].kind == BoneKind::Free)
        .collect()
}

impl Pose {
    /// The identity pose: the fitted skeleton unchanged.
    pub fn identity() -> Pose {
        Pose {
            name: "identity".into(),
            description: "The fitted pose unchanged (round trips).".into(),
            base: PoseBase::Fitted,
            bones: BTreeMap::new(),
        }
    }

    /// Every built-in pose name (`identity` and the human poses of `config/poses/`).
    pub fn builtin_names() -> &'static [&'static str] {
        &BUILTIN_POSE_NAMES
    }

    /// A built-in pose by name.
    pub fn builtin(name: &str) -> Option<Pose> {
        if name == "identity" {
            return Some(Pose::identity());
        }
        let (_, text) = BUILTIN_POSE_FILES.iter().find(|(n, _)| *n == name)?;
        let path = Pose::source_path(name);
        Some(
            Pose::from_ron_str(text, &path)
                .unwrap_or_else(|e| panic!("built-in pose {name} is invalid: {e}")),
        )
    }

    /// The path that names the pose `name_or_path` in messages: `config/poses/NAME.ron` for a
    /// built-in pose, the path itself otherwise.
    pub fn source_path(name_or_path: &str) -> PathBuf {
        if BUILTIN_POSE_NAMES.contains(&name_or_path) {
            PathBuf::from(format!("config/poses/{name_or_path}.ron"))
        } else {
            PathBuf::from(name_or_path)
        }
    }

    /// A built-in pose name, else a pose file.
    pub fn resolve(name_or_path: &str) -> Result<Pose> {
        if let Some(p) = Pose::builtin(name_or_path) {
            return Ok(p);
        }
        let path = Path::new(name_or_path);
        if !path.is_file() {
            return Err(Error::config(
                path,
                format!(
                    "no such pose: neither a built-in pose ({}) nor a file",
                    BUILTIN_POSE_NAMES.join(", ")
                ),
            ));
        }
        Pose::load(path)
    }

    /// Reads a pose file.
    pub fn load(path: impl AsRef<Path>) -> Result<Pose> {
        let path = path.as_ref();
        Pose::from_ron_str(&read_text(path)?, path)
    }

    /// Parses a pose from RON text; `source` names it in error messages.
    pub fn from_ron_str(text: &str, source: &Path) -> Result<Pose> {
        let pose: Pose = ron_options()
            .from_str(text)
            .map_err(|e| Error::config(source, format!("invalid pose: {e}")))?;
        pose.check_numbers(source)?;
        Ok(pose)
    }

    /// The checks that need no template: finite, non-zero vectors and angles, and not both
    /// `direction` and `rotate`.
    fn check_numbers(&self, source: &Path) -> Result<()> {
        let err = |bone: &str, m: String| {
            Error::config(source, format!("pose '{}', bone '{bone}': {m}", self.name))
        };
        for (bone, bp) in &self.bones {
            if bp.direction.is_some() && bp.rotate.is_some() {
                return Err(err(
                    bone,
                    "give either 'direction' or 'rotate', not both".into(),
                ));
            }
            if let Some(d) = bp.direction {
                if !d.iter().all(|v| v.is_finite()) {
                    return Err(err(bone, format!("direction {d:?} is not finite")));
                }
                if !(Vec3::from(d).length() > 1e-6) {
                    return Err(err(bone, format!("direction {d:?} has zero length")));
                }
            }
            if let Some(r) = bp.rotate {
                if !r.iter().all(|v| v.is_finite()) {
                    return Err(err(
                        bone,
                        format!("rotate {r:?}: the axis and the angle must be finite"),
                    ));
                }
                if !(Vec3::new(r[0], r[1], r[2]).length() > 1e-6) {
                    return Err(err(bone, format!("rotate {r:?}: the axis has zero length")));
                }
            }
            if let Some(t) = bp.twist
                && !t.is_finite()
            {
                return Err(err(bone, format!("twist {t} is not finite")));
            }
        }
        Ok(())
    }

    /// Checks the pose against a template: every named bone exists and is a free bone.
    pub fn validate(&self, template: &Template, source: &Path) -> Result<()> {
        self.check_numbers(source)?;
        let free = free_bones(template);
        for name in self.bones.keys() {
            match template.bone_index(name) {
                None => {
                    return Err(Error::config(
                        source,
                        unknown_bone(&format!("pose '{}'", self.name), name, template, &free),
                    ));
                }
                Some(i) if template.bones[i].kind != BoneKind::Free => {
                    return Err(Error::config(
                        source,
                        format!(
                            "pose '{}': bone '{name}' is a {} bone and keeps its constraint; \
                             pose the free bones around it instead",
                            self.name,
                            if template.bones[i].kind == BoneKind::Block {
                                "block"
                            } else {
                                "follower"
                            }
                        ),
                    ));
                }
                Some(_) => {}
            }
        }
        Ok(())
    }

    /// The fitted skeleton re-posed: same template, root placement, lengths and radii; rotations
    /// from [`Pose::base`], then each named bone turned (parents first), then the block and
    /// follower constraints re-applied. `source` names the pose in error messages.
    ///
    /// The identity pose (`Fitted` base, no bones) returns `fitted` unchanged, bit for bit.
    pub fn apply(&self, fitted: &Skeleton, source: &Path) -> Result<Skeleton> {
        let t = fitted.template.clone();
        self.validate(&t, source)?;
        let mut out = fitted.clone();
        if self.base == PoseBase::Fitted && self.bones.is_empty() {
            return Ok(out);
        }
        if self.base == PoseBase::Rest {
            let rest = Skeleton::rest(t.clone());
            for (b, r) in out.bones.iter_mut().zip(&rest.bones) {
                b.rotation = r.rotation;
            }
        }
        let root = out.root_rotation;
        let mut frames = vec![Quat::IDENTITY; t.bones.len()];
        for (i, def) in t.bones.iter().enumerate() {
            let parent = def.parent.map(|p| frames[p]).unwrap_or(root);
            let mut frame = (parent * out.bones[i].rotation).normalize();
            if let Some(bp) = self.bones.get(&def.name) {
                if let Some(d) = bp.direction {
                    let current = frame * Vec3::X;
                    let target = root * Vec3::from(d).normalize();
                    frame = (rotation_arc(current, target) * frame).normalize();
                }
                if let Some(r) = bp.rotate {
                    let axis = root * Vec3::new(r[0], r[1], r[2]).normalize();
                    frame = (Quat::from_axis_angle(axis, r[3].to_radians()) * frame).normalize();
                }
                if let Some(tw) = bp.twist {
                    frame = (frame * Quat::from_rotation_x(tw.to_radians())).normalize();
                }
                out.bones[i].rotation = (parent.inverse() * frame).normalize();
            }
            frames[i] = frame;
        }
        out.enforce_constraints();
        Ok(out)
    }
}

/// Uniform and per-bone size changes. See the [module documentation](self).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Proportions {
    /// Free text.
    pub description: String,
    /// Uniform factor on every length and radius (and the block scale).
    pub scale: f32,
    /// Per-bone length factors.
    pub lengths: BTreeMap<String, f32>,
    /// Per-bone radius factors (both radii of the bone).
    pub radii: BTreeMap<String, f32>,
}

impl Default for Proportions {
    fn default() -> Self {
        Proportions {
            description: String::new(),
            scale: 1.0,
            lengths: BTreeMap::new(),
            radii: BTreeMap::new(),
        }
    }
}

/// True for a valid factor: finite and in `(0.1, 10]`.
fn valid_factor(k: f32) -> bool {
    k.is_finite() && k > 0.1 && k <= 10.0
}

impl Proportions {
    /// Reads a proportions file.
    pub fn load(path: impl AsRef<Path>) -> Result<Proportions> {
        let path = path.as_ref();
        Proportions::from_ron_str(&read_text(path)?, path)
    }

    /// Parses proportions from RON text; `source` names them in error messages.
    pub fn from_ron_str(text: &str, source: &Path) -> Result<Proportions> {
        let p: Proportions = ron_options()
            .from_str(text)
            .map_err(|e| Error::config(source, format!("invalid proportions: {e}")))?;
        p.check_factors(source)?;
        Ok(p)
    }

    fn check_factors(&self, source: &Path) -> Result<()> {
        if !valid_factor(self.scale) {
            return Err(Error::config(
                source,
                format!(
                    "proportions: scale {} must be finite and in (0.1, 10]",
                    self.scale
                ),
            ));
        }
        for (what, map) in [("length", &self.lengths), ("radius", &self.radii)] {
            for (bone, &k) in map {
                if !valid_factor(k) {
                    return Err(Error::config(
                        source,
                        format!(
                            "proportions: {what} factor {k} of bone '{bone}' must be finite and in (0.1, 10]"
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    /// `skel` with the sizes changed: the uniform scale first, then the per-bone factors, then
    /// the block and follower constraints re-applied. Rotations and the root placement are
    /// kept. `source` names the proportions in error messages.
    pub fn apply(&self, skel: &Skeleton, source: &Path) -> Result<Skeleton> {
        self.check_factors(source)?;
        let t = skel.template.clone();
        let free = free_bones(&t);
        let all: Vec<usize> = (0..t.bones.len()).collect();
        let mut out = skel.clone();
        out.scale_sizes(self.scale);
        for (bone, &k) in &self.lengths {
            let i = t.bone_index(bone).ok_or_else(|| {
                Error::config(source, unknown_bone("proportions", bone, &t, &free))
            })?;
            if t.bones[i].kind != BoneKind::Free {
                return Err(Error::config(
                    source,
                    format!(
                        "proportions: the length of '{bone}' follows the block scale or its \
                         leader bone and cannot be set (use 'scale' or the leader)"
                    ),
                ));
            }
            out.bones[i].length *= k;
        }
        for (bone, &k) in &self.radii {
            let i = t.bone_index(bone).ok_or_else(|| {
                Error::config(source, unknown_bone("proportions", bone, &t, &all))
            })?;
            out.bones[i].r1 *= k;
            out.bones[i].r2 *= k;
        }
        out.enforce_constraints();
        for (def, b) in t.bones.iter().zip(&out.bones) {
            if (b.r2 - b.r1).abs() >= b.length {
                return Err(Error::config(
                    source,
                    format!(
                        "proportions: bone '{}' would have one sphere inside the other \
                         (radii {:.4} and {:.4}, length {:.4})",
                        def.name, b.r1, b.r2, b.length
                    ),
                ));
            }
        }
        Ok(out)
    }
}

/// Smooth ease-in-out for pose changes: the cubic `3t² − 2t³` on `[0, 1]` (zero speed at
/// both ends; the same cubic as the thesis' `α_p` of baseline skinning).
pub fn ease(t: f32) -> f32 {
    let t = t.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// The skeleton between `a` (`t = 0`) and `b` (`t = 1`), two skeletons of the same template:
/// per-bone slerp of the relative rotations, lerp of lengths and radii, and the same for the
/// root placement and block scale. `t` is clamped to `[0, 1]` (ease it before calling); the
/// endpoints return `a` and `b` exactly.
///
/// # Panics
/// When the two skeletons have different numbers of bones.
pub fn interpolate(a: &Skeleton, b: &Skeleton, t: f32) -> Skeleton {
    let mut out = a.clone();
    interpolate_into(a, b, t, &mut out);
    out
}

/// [`interpolate`] into an existing skeleton of the same template (no allocation: the kiosk
/// calls it every frame of a pose change).
///
/// # Panics
/// When the three skeletons do not have the same number of bones.
pub fn interpolate_into(a: &Skeleton, b: &Skeleton, t: f32, out: &mut Skeleton) {
    assert!(
        a.bones.len() == b.bones.len() && a.bones.len() == out.bones.len(),
        "interpolate: the skeletons must share their template"
    );
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    if t == 0.0 || t == 1.0 {
        let src = if t == 0.0 { a } else { b };
        out.root_position = src.root_position;
        out.root_rotation = src.root_rotation;
        out.block_scale = src.block_scale;
        out.bones.copy_from_slice(&src.bones);
        return;
    }
    let lerp = |x: f32, y: f32| x + (y - x) * t;
    out.root_position = a.root_position.lerp(b.root_position, t);
    out.root_rotation = a.root_rotation.slerp(b.root_rotation, t).normalize();
    out.block_scale = lerp(a.block_scale, b.block_scale);
    for (o, (x, y)) in out.bones.iter_mut().zip(a.bones.iter().zip(&b.bones)) {
        o.rotation = x.rotation.slerp(y.rotation, t).normalize();
        o.length = lerp(x.length, y.length);
        o.r1 = lerp(x.r1, y.r1);
        o.r2 = lerp(x.r2, y.r2);
    }
}
