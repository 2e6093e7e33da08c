//! The skeleton state of a template and its forward kinematics.
//!
//! A [`Skeleton`] holds, per bone, its rotation **relative to its parent bone's frame** (or to
//! the root frame for bones leaving the root), its intrinsic length and its two radii (thesis
//! §2.1: "each bone is fully defined by its intrinsic parameters (length and two radii) and
//! its extrinsic parameter (rotation with respect to its predecessor)"), plus the root's
//! position, orientation and the uniform scale of the root block.
//!
//! **Bone frames.** Each bone has an orthonormal frame whose X axis runs from `c1` to `c2`
//! (paper 001 appendix B). At rest the frame's Y axis is the template's forward (`+Z`)
//! made orthogonal to the bone (or `+Y` when the bone points forward), so twist is defined.
//! [`Skeleton::pose`] walks the bones parents-first: `F_b = F_parent · q_b`,
//! `c1 = end of the parent` (or the root position), `c2 = c1 + F_b · (l, 0, 0)`.
//!
//! Block bones keep their rest rotation and `length = rest length × block_scale`; follower
//! bones keep their rest rotation relative to their leader and `length = ratio × leader length`
//! ([`Skeleton::enforce_constraints`]).

use super::template::{BoneKind, Template};
use crate::error::{Error, Result};
use crate::geometry::Bone;
use crate::geometry::frames::frame_from_axis;
use crate::math::{Quat, Vec3};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

/// Per-bone state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoneState {
    /// Rotation relative to the parent bone's frame (or the root frame).
    pub rotation: Quat,
    /// Length `|c1c2|`.
    pub length: f32,
    /// Radius at `c1`.
    pub r1: f32,
    /// Radius at `c2`.
    pub r2: f32,
}

/// The state of a template's skeleton: root placement plus per-bone rotations and sizes.
#[derive(Clone, Debug)]
pub struct Skeleton {
    pub template: Arc<Template>,
    /// World position of the root joint.
    pub root_position: Vec3,
    /// World orientation of the root frame (template frame at rest).
    pub root_rotation: Quat,
    /// Uniform scale of the root block (1 at rest).
    pub block_scale: f32,
    /// Per-bone state, in the template's bone order.
    pub bones: Vec<BoneState>,
}

/// The world-space result of forward kinematics.
#[derive(Clone, Debug, PartialEq)]
pub struct Posed {
    /// World bones (sphere-mesh geometry), in template bone order.
    pub bones: Vec<Bone>,
    /// World frame of each bone (X along the bone).
    pub frames: Vec<Quat>,
    /// World position of each joint, in template joint order.
    pub joints: Vec<Vec3>,
}

/// Rest frames of every bone of a template (world = template frame).
pub fn rest_frames(t: &Template) -> Vec<Quat> {
    t.bones
        .iter()
        .map(|b| {
            let dir = t.joints[b.to].rest - t.joints[b.from].rest;
            frame_from_axis(dir, Vec3::Z, Vec3::Y)
        })
        .collect()
}

impl Skeleton {
    /// The template's rest pose, unscaled, at the template's own coordinates.
    pub fn rest(template: Arc<Template>) -> Skeleton {
        let frames = rest_frames(&template);
        let bones = template
            .bones
            .iter()
            .enumerate()
            .map(|(i, b)| {
                let parent_frame = b.parent.map(|p| frames[p]).unwrap_or(Quat::IDENTITY);
                BoneState {
                    rotation: (parent_frame.inverse() * frames[i]).normalize(),
                    length: (template.joints[b.to].rest - template.joints[b.from].rest).length(),
                    r1: b.r1,
                    r2: b.r2,
                }
            })
            .collect();
        Skeleton {
            root_position: template.joints[template.root].rest,
            root_rotation: Quat::IDENTITY,
            block_scale: 1.0,
            bones,
            template,
        }
    }

    /// The rest pose scaled by `scale` about the root and placed with the root at `position`
    /// and orientation `rotation`.
    pub fn rest_placed(
        template: Arc<Template>,
        position: Vec3,
        rotation: Quat,
        scale: f32,
    ) -> Skeleton {
        let mut s = Skeleton::rest(template);
        s.scale_sizes(scale);
        s.root_position = position;
        s.root_rotation = rotation;
        s
    }

    /// Multiplies every length and radius by `k` (the block scale too).
    pub fn scale_sizes(&mut self, k: f32) {
        for b in &mut self.bones {
            b.length *= k;
            b.r1 *= k;
            b.r2 *= k;
        }
        self.block_scale *= k;
    }

    /// Number of bones.
    pub fn len(&self) -> usize {
        self.bones.len()
    }

    /// True for a template without bones (never, for a validated template).
    pub fn is_empty(&self) -> bool {
        self.bones.is_empty()
    }

    /// Re-applies the block and follower constraints: block bones get their rest rotation and
    /// `rest length × block_scale`; followers their rest relative rotation and
    /// `ratio × leader length`.
    pub fn enforce_constraints(&mut self) {
        let rest = Skeleton::rest(self.template.clone());
        for (i, def) in self.template.bones.iter().enumerate() {
            match def.kind {
                BoneKind::Free => {}
                BoneKind::Block => {
                    self.bones[i].rotation = rest.bones[i].rotation;
                    self.bones[i].length = rest.bones[i].length * self.block_scale;
                }
                BoneKind::Follower { leader, ratio } => {
                    self.bones[i].rotation = rest.bones[i].rotation;
                    self.bones[i].length = ratio * self.bones[leader].length;
                }
            }
        }
    }

    /// Forward kinematics: world bones, frames and joints.
    pub fn pose(&self) -> Posed {
        let mut posed = Posed {
            bones: Vec::new(),
            frames: Vec::new(),
            joints: Vec::new(),
        };
        self.pose_into(&mut posed);
        posed
    }

    /// [`Skeleton::pose`] into existing buffers (no allocation once they have grown).
    pub fn pose_into(&self, out: &mut Posed) {
        let t = &self.template;
        out.frames.clear();
        out.frames.resize(t.bones.len(), Quat::IDENTITY);
        out.bones.clear();
        out.bones
            .resize(t.bones.len(), Bone::new(Vec3::ZERO, 0.0, Vec3::ZERO, 0.0));
        out.joints.clear();
        out.joints.resize(t.joints.len(), Vec3::ZERO);
        let Posed {
            bones,
            frames,
            joints,
        } = out;
        joints[t.root] = self.root_position;
        // Bones are stored parents-first.
        for (i, def) in t.bones.iter().enumerate() {
            let (parent_frame, c1) = match def.parent {
                Some(p) => (frames[p], bones[p].c2),
                None => (self.root_rotation, self.root_position),
            };
            let f = (parent_frame * self.bones[i].rotation).normalize();
            let c2 = c1 + f * Vec3::new(self.bones[i].length, 0.0, 0.0);
            frames[i] = f;
            bones[i] = Bone::new(c1, self.bones[i].r1, c2, self.bones[i].r2);
            joints[def.to] = c2;
        }
    }

    /// The statue's up as the skeleton carries it: the template's `+Y` in the root's frame
    /// (the up of a figure standing like the rest pose).
    pub fn up(&self) -> Vec3 {
        self.root_rotation * Vec3::Y
    }

    /// A world-space rigid motion of the whole skeleton: `x ↦ rotation · x + translation`.
    pub fn transform_rigid(&mut self, rotation: Quat, translation: Vec3) {
        self.root_position = rotation * self.root_position + translation;
        self.root_rotation = (rotation * self.root_rotation).normalize();
    }

    /// Serialisable form (see [`SkeletonJson`]).
    pub fn to_json(&self) -> SkeletonJson {
        let posed = self.pose();
        let t = &self.template;
        SkeletonJson {
            template: t.name.clone(),
            joints: t
                .joints
                .iter()
                .zip(&posed.joints)
                .map(|(j, p)| (j.name.clone(), p.to_array()))
                .collect(),
            bones: t
                .bones
                .iter()
                .zip(posed.bones.iter().zip(&posed.frames))
                .map(|(def, (b, f))| BoneJson {
                    name: def.name.clone(),
                    c1: b.c1.to_array(),
                    c2: b.c2.to_array(),
                    r1: b.r1,
                    r2: b.r2,
                    frame: Some(f.to_array()),
                })
                .collect(),
            root_rotation: Some(self.root_rotation.to_array()),
            block_scale: Some(self.block_scale),
        }
    }

    /// Rebuilds a skeleton of `template` from its JSON form. Bone frames default to the
    /// minimal rotation of the rest frame onto the saved direction when absent.
    pub fn from_json(
        template: Arc<Template>,
        json: &SkeletonJson,
        path: &Path,
    ) -> Result<Skeleton> {
        let err = |m: String| Error::config(path, m);
        if json.template != template.name {
            return Err(err(format!(
                "the skeleton was fitted with template '{}', not '{}'",
                json.template, template.name
            )));
        }
        let mut by_name = BTreeMap::new();
        for b in &json.bones {
            let finite = b.c1.iter().chain(&b.c2).all(|v| v.is_finite())
                && b.r1.is_finite()
                && b.r2.is_finite();
            if !finite || b.r1 < 0.0 || b.r2 < 0.0 {
                return Err(err(format!(
                    "bone '{}' has non-finite coordinates or negative radii",
                    b.name
                )));
            }
            by_name.insert(b.name.as_str(), b);
        }
        let rest_f = rest_frames(&template);
        let mut world_frames = Vec::with_capacity(template.bones.len());
        let mut states = Vec::with_capacity(template.bones.len());
        for (i, def) in template.bones.iter().enumerate() {
            let b = by_name
                .get(def.name.as_str())
                .ok_or_else(|| err(format!("bone '{}' is missing", def.name)))?;
            let c1 = Vec3::from(b.c1);
            let c2 = Vec3::from(b.c2);
            let frame = match b.frame {
                Some(q) => Quat::from_array(q).normalize(),
                None => {
                    let rest_axis = rest_f[i] * Vec3::X;
                    crate::geometry::frames::rotation_arc(
                        rest_axis,
                        (c2 - c1).normalize_or(rest_axis),
                    ) * rest_f[i]
                }
            };
            world_frames.push(frame);
            states.push(BoneState {
                rotation: Quat::IDENTITY,
                length: (c2 - c1).length(),
                r1: b.r1,
                r2: b.r2,
            });
        }
        let root_rotation = match json.root_rotation {
            Some(q) => Quat::from_array(q).normalize(),
            None => {
                // From the first root bone: F = R_root · q_rest.
                let rest = Skeleton::rest(template.clone());
                match template.bones.iter().position(|b| b.parent.is_none()) {
                    Some(i) => (world_frames[i] * rest.bones[i].rotation.inverse()).normalize(),
                    None => Quat::IDENTITY,
                }
            }
        };
        for (i, def) in template.bones.iter().enumerate() {
            let parent = def.parent.map(|p| world_frames[p]).unwrap_or(root_rotation);
            states[i].rotation = (parent.inverse() * world_frames[i]).normalize();
        }
        let root_name = &template.joints[template.root].name;
        let root_position = match json.joints.get(root_name) {
            Some(p) => Vec3::from(*p),
            None => template
                .bones
                .iter()
                .position(|b| b.parent.is_none())
                .map(|i| Vec3::from(by_name[template.bones[i].name.as_str()].c1))
                .unwrap_or(Vec3::ZERO),
        };
        let block_scale = json.block_scale.unwrap_or_else(|| {
            let rest = Skeleton::rest(template.clone());
            template
                .block_bones()
                .next()
                .map(|i| states[i].length / rest.bones[i].length)
                .unwrap_or(1.0)
        });
        if !(root_position.is_finite() && block_scale.is_finite() && block_scale > 0.0) {
            return Err(err("invalid root position or block scale".into()));
        }
        Ok(Skeleton {
            template,
            root_position,
            root_rotation,
            block_scale,
            bones: states,
        })
    }

    /// Writes the skeleton as pretty JSON.
    pub fn save_json(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        let text = serde_json::to_string_pretty(&self.to_json()).expect("skeleton JSON serialises");
        std::fs::write(path, text).map_err(|e| Error::Io {
            path: path.to_path_buf(),
            source: e,
        })
    }

    /// Reads a skeleton JSON written by [`Skeleton::save_json`] (or any JSON with `template`,
    /// `joints` and `bones`), resolving its template by name (built-in) unless one is given.
    pub fn load_json(path: impl AsRef<Path>, template: Option<Arc<Template>>) -> Result<Skeleton> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|e| Error::Io {
            path: path.to_path_buf(),
            source: e,
        })?;
        let json: SkeletonJson = serde_json::from_str(&text)
            .map_err(|e| Error::config(path, format!("invalid skeleton JSON: {e}")))?;
        let template = match template {
            Some(t) => t,
            None => Arc::new(
                Template::builtin(&json.template)
                    .map_err(|e| Error::config(path, e.to_string()))?,
            ),
        };
        Skeleton::from_json(template, &json, path)
    }

    /// Mean distance between corresponding joints of two skeletons of the same template (the
    /// joint error used to grade a fit against a ground truth).
    pub fn mean_joint_distance(&self, other: &Skeleton) -> f32 {
        let (a, b) = (self.pose().joints, other.pose().joints);
        a.iter()
            .zip(&b)
            .map(|(x, y)| (*x - *y).length())
            .sum::<f32>()
            / a.len().max(1) as f32
    }

    /// World position of the joint called `name`.
    pub fn joint(&self, name: &str) -> Option<Vec3> {
        let j = self.template.joint_index(name)?;
        Some(self.pose().joints[j])
    }
}

/// The JSON form of a skeleton: `joints` (name → `[x, y, z]`) and `bones` (name, `c1`, `c2`,
/// `r1`, `r2`, and the bone's world frame as a quaternion `[x, y, z, w]`), in the statue's
/// coordinates.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct SkeletonJson {
    pub template: String,
    pub joints: BTreeMap<String, [f32; 3]>,
    pub bones: Vec<BoneJson>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub root_rotation: Option<[f32; 4]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub block_scale: Option<f32>,
}

/// One bone of [`SkeletonJson`].
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct BoneJson {
    pub name: String,
    pub c1: [f32; 3],
    pub c2: [f32; 3],
    pub r1: f32,
    pub r2: f32,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame: Option<[f32; 4]>,
}
