//! Anatomy templates: the articulated sphere-mesh models FAKIR fits (thesis §2.1, fig. 2.3).
//!
//! A template is a data file in `config/templates/` (TOML), loaded with serde and validated
//! here. The built-in templates (`human`, `centaur`, `quadruped`, `mermaid`) are also compiled
//! into the binary so the CLI and the kiosk work from any directory.
//!
//! ## The model
//! * **Joints** are named points of the rest pose, in the *template frame*: `+Y` up, the figure
//!   faces `+Z`, `+X` is the figure's own left; sizes in a normalised unit where the figure's
//!   height is about 1 (radii included). One joint is the **root** (the pelvis for humans).
//! * **Bones** join a parent joint (`from`) to a child joint (`to`); every joint but the root
//!   is the `to` of exactly one bone, so joints and bones form a tree. Each bone carries the
//!   radii of its two spheres, `r1` at `from` and `r2` at `to`.
//! * **The root block** (`block = true`): the bones leaving the root that move as one rigid,
//!   uniformly scaled block (the human pelvis triplet: "three bones correspond to the pelvis
//!   and have no relative motion: their length is fixed up to a common scale parameter").
//! * **Follower bones** (`follows = "bone"`): bones whose length and direction follow another
//!   bone (the human connection bone between the spine and the neck: "its length and
//!   orientation directly depend on the adjacent spine bone"). A follower starts where its
//!   leader ends; its direction relative to the leader and its length ratio are those of the
//!   rest pose.
//! * **Chains**: ordered lists of consecutive bones (each bone's `from` is the previous bone's
//!   `to`); consecutive bones of a chain share their joint radius (`r2` of one equals `r1` of
//!   the next). Chains are listed in registration order (thesis §2.4.2: spine, legs, arms).
//!   Every bone is in exactly one chain, except block and follower bones, which are in none.
//!   `mirror` names the chain's left/right counterpart (used for symmetric restoration).
//! * **Random-pose ranges** (`swing`, `bend`): used only by the synthetic-statue generator to
//!   draw plausible poses: a random swing of at most `swing` degrees about a random axis
//!   orthogonal to the bone, and a hinge bend of `min..max` degrees about `bend_axis`
//!   (template frame, applied at the rest pose and carried by the parent's motion).

use crate::error::{Error, Result};
use crate::math::Vec3;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// The names of the templates shipped in `config/templates/` (and compiled in).
pub const BUILTIN_TEMPLATES: [&str; 4] = ["human", "centaur", "quadruped", "mermaid"];

fn builtin_source(name: &str) -> Option<&'static str> {
    Some(match name {
        "human" => include_str!("../../config/templates/human.toml"),
        "centaur" => include_str!("../../config/templates/centaur.toml"),
        "quadruped" => include_str!("../../config/templates/quadruped.toml"),
        "mermaid" => include_str!("../../config/templates/mermaid.toml"),
        _ => return None,
    })
}

/// A template file as written on disk.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TemplateFile {
    pub name: String,
    #[serde(default)]
    pub description: String,
    /// Name of the root joint.
    pub root: String,
    pub joints: Vec<JointSpec>,
    pub bones: Vec<BoneSpec>,
    pub chains: Vec<ChainSpec>,
    /// The limb bones a bust of this figure has lost, each with the bones it carries (see
    /// [`Template::bust`]). Optional.
    #[serde(default)]
    pub bust: Vec<String>,
}

/// A joint of a template file.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointSpec {
    pub name: String,
    /// Rest position in the template frame.
    pub at: [f32; 3],
    #[serde(default)]
    pub doc: String,
}

/// A bone of a template file.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoneSpec {
    pub name: String,
    pub from: String,
    pub to: String,
    pub r1: f32,
    pub r2: f32,
    /// Part of the rigid, uniformly scaled root block.
    #[serde(default)]
    pub block: bool,
    /// Name of the bone whose length and direction this bone follows.
    #[serde(default)]
    pub follows: Option<String>,
    /// Largest random swing (degrees) for synthetic poses.
    #[serde(default)]
    pub swing: f32,
    /// Hinge axis (template frame) for synthetic poses.
    #[serde(default)]
    pub bend_axis: Option<[f32; 3]>,
    /// Hinge range `[min, max]` in degrees for synthetic poses.
    #[serde(default)]
    pub bend: Option<[f32; 2]>,
}

/// A chain of a template file.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChainSpec {
    pub name: String,
    pub bones: Vec<String>,
    #[serde(default)]
    pub mirror: Option<String>,
}

/// How a bone moves during registration and posing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BoneKind {
    /// Free rotation, length and radii.
    Free,
    /// Part of the rigid, uniformly scaled root block.
    Block,
    /// Follows `leader`: fixed rest direction relative to it, length `ratio × leader length`.
    Follower { leader: usize, ratio: f32 },
}

/// A validated joint.
#[derive(Clone, Debug)]
pub struct JointDef {
    pub name: String,
    pub rest: Vec3,
    /// The bone ending at this joint (`None` for the root).
    pub parent_bone: Option<usize>,
}

/// A validated bone.
#[derive(Clone, Debug)]
pub struct BoneDef {
    pub name: String,
    /// Joint index of the first sphere.
    pub from: usize,
    /// Joint index of the second sphere.
    pub to: usize,
    /// The bone ending at `from` (`None` when `from` is the root).
    pub parent: Option<usize>,
    /// Bones starting at `to`.
    pub children: Vec<usize>,
    pub r1: f32,
    pub r2: f32,
    pub kind: BoneKind,
    /// Chain index and position in it.
    pub chain: Option<(usize, usize)>,
    pub swing_deg: f32,
    pub bend: Option<(Vec3, f32, f32)>,
}

/// A validated chain.
#[derive(Clone, Debug)]
pub struct ChainDef {
    pub name: String,
    pub bones: Vec<usize>,
    pub mirror: Option<usize>,
}

/// A validated template. Bones are stored parents-first (a topological order).
#[derive(Clone, Debug)]
pub struct Template {
    pub name: String,
    pub description: String,
    pub root: usize,
    pub joints: Vec<JointDef>,
    pub bones: Vec<BoneDef>,
    pub chains: Vec<ChainDef>,
    /// Height of the rest model along `+Y`, radii included.
    pub height: f32,
    /// The limb bones a portrait bust of this figure has lost, each with the bones it
    /// carries (the human's upper arms and thighs): the lost set of the bust hypothesis of
    /// [`crate::fakir::bust`]. Empty: the template has no bust hypothesis.
    pub bust: Vec<String>,
}

impl Template {
    /// One of the built-in templates by name (`human`, `centaur`, `quadruped`, `mermaid`).
    pub fn builtin(name: &str) -> Result<Template> {
        let src = builtin_source(name).ok_or_else(|| {
            Error::input(format!(
                "unknown template '{name}' (built-in templates: {})",
                BUILTIN_TEMPLATES.join(", ")
            ))
        })?;
        Template::from_toml(src, Path::new(&format!("config/templates/{name}.toml")))
    }

    /// A built-in template name, or a path to a template file.
    pub fn resolve(name_or_path: &str) -> Result<Template> {
        if builtin_source(name_or_path).is_some() {
            Template::builtin(name_or_path)
        } else {
            Template::load(name_or_path)
        }
    }

    /// Loads and validates a template file.
    pub fn load(path: impl AsRef<Path>) -> Result<Template> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|e| Error::Io {
            path: path.to_path_buf(),
            source: e,
        })?;
        Template::from_toml(&text, path)
    }

    /// Parses and validates template TOML; `path` is only used in error messages.
    pub fn from_toml(text: &str, path: &Path) -> Result<Template> {
        let file: TemplateFile = toml::from_str(text)
            .map_err(|e| Error::config(path, format!("invalid template: {e}")))?;
        Template::from_file(file, path)
    }

    /// Validates a parsed template file.
    pub fn from_file(file: TemplateFile, path: &Path) -> Result<Template> {
        let err = |msg: String| Error::config(PathBuf::from(path), msg);
        if file.name.trim().is_empty() {
            return Err(err("the template has no name".into()));
        }
        // Joints.
        let mut joint_index = HashMap::new();
        for (i, j) in file.joints.iter().enumerate() {
            if joint_index.insert(j.name.as_str(), i).is_some() {
                return Err(err(format!("joint '{}' is defined twice", j.name)));
            }
            if !j.at.iter().all(|v| v.is_finite()) {
                return Err(err(format!("joint '{}' has a non-finite position", j.name)));
            }
        }
        let root = *joint_index
            .get(file.root.as_str())
            .ok_or_else(|| err(format!("root joint '{}' is not defined", file.root)))?;
        // Bones.
        let mut bone_index = HashMap::new();
        let mut parent_of_joint: Vec<Option<usize>> = vec![None; file.joints.len()];
        for (i, b) in file.bones.iter().enumerate() {
            if bone_index.insert(b.name.as_str(), i).is_some() {
                return Err(err(format!("bone '{}' is defined twice", b.name)));
            }
            let from = *joint_index
                .get(b.from.as_str())
                .ok_or_else(|| err(format!("bone '{}': unknown joint '{}'", b.name, b.from)))?;
            let to = *joint_index
                .get(b.to.as_str())
                .ok_or_else(|| err(format!("bone '{}': unknown joint '{}'", b.name, b.to)))?;
            if to == root {
                return Err(err(format!(
                    "bone '{}' ends at the root joint '{}'",
                    b.name, b.to
                )));
            }
            if let Some(other) = parent_of_joint[to] {
                return Err(err(format!(
                    "joint '{}' ends two bones ('{}' and '{}'): joints must form a tree",
                    b.to, file.bones[other].name, b.name
                )));
            }
            parent_of_joint[to] = Some(i);
            let _ = from;
            if !(b.r1.is_finite() && b.r2.is_finite() && b.r1 > 0.0 && b.r2 > 0.0) {
                return Err(err(format!(
                    "bone '{}': radii must be positive (r1 = {}, r2 = {})",
                    b.name, b.r1, b.r2
                )));
            }
            let a = Vec3::from(file.joints[from].at);
            let c = Vec3::from(file.joints[to].at);
            let len = (c - a).length();
            if !(len > 1e-6) {
                return Err(err(format!("bone '{}' has zero length", b.name)));
            }
            if (b.r2 - b.r1).abs() >= len {
                return Err(err(format!(
                    "bone '{}': one sphere contains the other (|r2 − r1| = {} ≥ length {len})",
                    b.name,
                    (b.r2 - b.r1).abs()
                )));
            }
            if b.block && b.from != file.root {
                return Err(err(format!(
                    "block bone '{}' must start at the root '{}'",
                    b.name, file.root
                )));
            }
            if b.block && b.follows.is_some() {
                return Err(err(format!(
                    "bone '{}' cannot be both a block bone and a follower",
                    b.name
                )));
            }
            if !(b.swing.is_finite() && b.swing >= 0.0) {
                return Err(err(format!("bone '{}': swing must be ≥ 0 degrees", b.name)));
            }
            if b.bend.is_some() != b.bend_axis.is_some() {
                return Err(err(format!(
                    "bone '{}': 'bend' and 'bend_axis' go together",
                    b.name
                )));
            }
            if let Some(ax) = b.bend_axis
                && (!(Vec3::from(ax).length() > 1e-6) || !ax.iter().all(|v| v.is_finite()))
            {
                return Err(err(format!(
                    "bone '{}': bend_axis must be a non-zero vector",
                    b.name
                )));
            }
        }
        for (j, p) in parent_of_joint.iter().enumerate() {
            if j != root && p.is_none() {
                return Err(err(format!(
                    "joint '{}' is not the end of any bone",
                    file.joints[j].name
                )));
            }
        }
        // Depth of every joint below the root. Each joint ends exactly one bone (checked
        // above), so a joint the root never reaches is disconnected, or on a cycle.
        let mut joint_depth: Vec<Option<usize>> = vec![None; file.joints.len()];
        joint_depth[root] = Some(0);
        let mut frontier = vec![root];
        while let Some(j) = frontier.pop() {
            for b in file
                .bones
                .iter()
                .filter(|b| joint_index[b.from.as_str()] == j)
            {
                let t = joint_index[b.to.as_str()];
                joint_depth[t] = joint_depth[j].map(|d| d + 1);
                frontier.push(t);
            }
        }
        let lost: Vec<&str> = file
            .bones
            .iter()
            .filter(|b| joint_depth[joint_index[b.from.as_str()]].is_none())
            .map(|b| b.name.as_str())
            .collect();
        if !lost.is_empty() {
            return Err(err(format!(
                "bones not connected to the root: {}",
                lost.join(", ")
            )));
        }
        // Stable topological order: by depth, then file order.
        let mut order: Vec<usize> = (0..file.bones.len()).collect();
        order.sort_by_key(|&b| (joint_depth[joint_index[file.bones[b].from.as_str()]], b));
        let new_of_old: Vec<usize> = {
            let mut v = vec![0; order.len()];
            for (new, &old) in order.iter().enumerate() {
                v[old] = new;
            }
            v
        };
        let mut bones: Vec<BoneDef> = order
            .iter()
            .map(|&old| {
                let b = &file.bones[old];
                let from = joint_index[b.from.as_str()];
                let to = joint_index[b.to.as_str()];
                BoneDef {
                    name: b.name.clone(),
                    from,
                    to,
                    parent: parent_of_joint[from].map(|p| new_of_old[p]),
                    children: Vec::new(),
                    r1: b.r1,
                    r2: b.r2,
                    kind: if b.block {
                        BoneKind::Block
                    } else {
                        BoneKind::Free
                    },
                    chain: None,
                    swing_deg: b.swing,
                    bend: b
                        .bend_axis
                        .zip(b.bend)
                        .map(|(ax, r)| (Vec3::from(ax).normalize(), r[0], r[1])),
                }
            })
            .collect();
        for i in 0..bones.len() {
            if let Some(p) = bones[i].parent {
                bones[p].children.push(i);
            }
        }
        let bone_of = |name: &str| bone_index.get(name).map(|&old| new_of_old[old]);
        let joint_pos = |j: usize| Vec3::from(file.joints[j].at);
        // Followers.
        for b in &file.bones {
            if let Some(leader_name) = &b.follows {
                let me = bone_of(&b.name).unwrap();
                let leader = bone_of(leader_name).ok_or_else(|| {
                    err(format!(
                        "bone '{}' follows unknown bone '{leader_name}'",
                        b.name
                    ))
                })?;
                if bones[me].parent != Some(leader) {
                    return Err(err(format!(
                        "bone '{}' follows '{leader_name}' but does not start where it ends",
                        b.name
                    )));
                }
                let lead_len =
                    (joint_pos(bones[leader].to) - joint_pos(bones[leader].from)).length();
                let my_len = (joint_pos(bones[me].to) - joint_pos(bones[me].from)).length();
                bones[me].kind = BoneKind::Follower {
                    leader,
                    ratio: my_len / lead_len,
                };
            }
        }
        // Chains.
        let mut chains = Vec::new();
        let mut chain_index = HashMap::new();
        for (ci, c) in file.chains.iter().enumerate() {
            if chain_index.insert(c.name.as_str(), ci).is_some() {
                return Err(err(format!("chain '{}' is defined twice", c.name)));
            }
            if c.bones.is_empty() {
                return Err(err(format!("chain '{}' has no bones", c.name)));
            }
            let mut list = Vec::new();
            for (pos, name) in c.bones.iter().enumerate() {
                let b = bone_of(name)
                    .ok_or_else(|| err(format!("chain '{}': unknown bone '{name}'", c.name)))?;
                if bones[b].kind != BoneKind::Free {
                    return Err(err(format!(
                        "chain '{}': bone '{name}' is a block or follower bone and cannot be in a chain",
                        c.name
                    )));
                }
                if let Some((other, _)) = bones[b].chain {
                    return Err(err(format!(
                        "bone '{name}' is in two chains ('{}' and '{}')",
                        file.chains[other].name, c.name
                    )));
                }
                if let Some(&prev) = list.last() {
                    let prev: usize = prev;
                    // Consecutive: the bone starts where the previous ends, possibly through a
                    // follower bone in between.
                    let mut start = bones[b].parent;
                    if let Some(p) = start
                        && matches!(bones[p].kind, BoneKind::Follower { .. })
                    {
                        start = bones[p].parent;
                    }
                    if start != Some(prev) {
                        return Err(err(format!(
                            "chain '{}': bone '{name}' does not start where '{}' ends",
                            c.name, bones[prev].name
                        )));
                    }
                    if bones[b].parent == Some(prev) && (bones[prev].r2 - bones[b].r1).abs() > 1e-6
                    {
                        return Err(err(format!(
                            "chain '{}': '{}' and '{name}' must share their joint radius (r2 = {} vs r1 = {})",
                            c.name, bones[prev].name, bones[prev].r2, bones[b].r1
                        )));
                    }
                }
                bones[b].chain = Some((ci, pos));
                list.push(b);
            }
            chains.push(ChainDef {
                name: c.name.clone(),
                bones: list,
                mirror: None,
            });
        }
        for (ci, c) in file.chains.iter().enumerate() {
            if let Some(m) = &c.mirror {
                let mi = *chain_index.get(m.as_str()).ok_or_else(|| {
                    err(format!("chain '{}': unknown mirror chain '{m}'", c.name))
                })?;
                if chains[mi].bones.len() != chains[ci].bones.len() {
                    return Err(err(format!(
                        "chains '{}' and '{m}' mirror each other but differ in length",
                        c.name
                    )));
                }
                chains[ci].mirror = Some(mi);
            }
        }
        for b in &bones {
            if b.kind == BoneKind::Free && b.chain.is_none() {
                return Err(err(format!("bone '{}' is in no chain", b.name)));
            }
        }
        for name in &file.bust {
            if !bones.iter().any(|b| b.name == *name) {
                return Err(err(format!("bust: unknown bone '{name}'")));
            }
        }
        let joints: Vec<JointDef> = file
            .joints
            .iter()
            .enumerate()
            .map(|(j, spec)| JointDef {
                name: spec.name.clone(),
                rest: Vec3::from(spec.at),
                parent_bone: parent_of_joint[j].map(|p| new_of_old[p]),
            })
            .collect();
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        for b in &bones {
            for (j, r) in [(b.from, b.r1), (b.to, b.r2)] {
                lo = lo.min(joints[j].rest.y - r);
                hi = hi.max(joints[j].rest.y + r);
            }
        }
        Ok(Template {
            name: file.name,
            description: file.description,
            root,
            joints,
            bones,
            chains,
            height: hi - lo,
            bust: file.bust,
        })
    }

    /// Index of the bone called `name`.
    pub fn bone_index(&self, name: &str) -> Option<usize> {
        self.bones.iter().position(|b| b.name == name)
    }

    /// Index of the joint called `name`.
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// Index of the chain called `name`.
    pub fn chain_index(&self, name: &str) -> Option<usize> {
        self.chains.iter().position(|c| c.name == name)
    }

    /// The mirror bone of every bone: the bone at the same position in the mirror chain, and for
    /// a bone of the root block the block bone from the same joint whose rest vector is reflected
    /// across the template's `x = 0` plane (the pelvis' two sides); `None` for unpaired bones.
    pub fn mirror_bones(&self) -> Vec<Option<usize>> {
        let mut m = vec![None; self.bones.len()];
        for c in &self.chains {
            if let Some(mc) = c.mirror {
                for (a, b) in c.bones.iter().zip(&self.chains[mc].bones) {
                    m[*a] = Some(*b);
                }
            }
        }
        let rest_vec =
            |b: usize| self.joints[self.bones[b].to].rest - self.joints[self.bones[b].from].rest;
        for i in self.block_bones() {
            let v = rest_vec(i);
            let reflected = Vec3::new(-v.x, v.y, v.z);
            m[i] = self.block_bones().find(|&j| {
                j != i
                    && self.bones[j].from == self.bones[i].from
                    && (rest_vec(j) - reflected).length() <= 1e-4 * v.length().max(1e-6)
            });
        }
        m
    }

    /// Bones of the root block.
    pub fn block_bones(&self) -> impl Iterator<Item = usize> + '_ {
        self.bones
            .iter()
            .enumerate()
            .filter(|(_, b)| b.kind == BoneKind::Block)
            .map(|(i, _)| i)
    }

    /// `b` and every bone below it.
    pub fn subtree(&self, b: usize) -> Vec<usize> {
        let mut out = vec![b];
        let mut i = 0;
        while i < out.len() {
            out.extend(self.bones[out[i]].children.iter().copied());
            i += 1;
        }
        out
    }
}
