//! Comparing a fitted skeleton with a ground truth of **another topology** (a rigged mesh's
//! skeleton: other joints, other bones, no names in common).
//!
//! A synthetic statue's truth has the template's own bones, and its fit is graded joint by
//! joint ([`crate::anatomy::Skeleton::mean_joint_distance`]). A skeleton drawn by an artist
//! for a rig (the `skel_*_joints.json` files of the shared data: a TGF edge list with joints
//! `j01`…) has other joints (no clavicles, a chest root, a three-bone tail) and no names to
//! match. So the two skeletons are compared as **curves**: each is the union of its bones'
//! segments, and
//!
//! * `truth_to_fit` is the mean distance from the truth's curve to the fit's (a truth bone the
//!   fit misses — an ear taken for a leg, a tail left out — counts here);
//! * `fit_to_truth` is the mean distance from the fit's curve to the truth's (a fitted bone
//!   laid where the truth has none counts here);
//! * `joints` is the mean distance from each truth joint to the nearest end of a fitted bone
//!   (ends and bends: a curve can lie on the truth's while its knee sits elsewhere along it).
//!
//! **Choices.** Each curve is sampled every 1/200 of the truth's extent (the largest side of
//! the bounding box of its joints and bone ends), both ends of every segment included, and a mean is over
//! those samples (so a long bone weighs more than a short one). The figures are also given
//! as a share of that extent. A fit's lost bones (FIT.json's `missing`) are left out: they
//! were not fitted to anything. Both skeletons must be in the same coordinates (FIT.json's
//! joints are in the input cloud's, like the shared data's joint files).

use crate::cloud::Aabb;
use crate::error::{Error, Result};
use crate::math::Vec3;
use std::path::Path;

/// A skeleton as named joints and the segments between them (any topology).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct JointGraph {
    /// Joint names (may be empty strings for unnamed joints).
    pub names: Vec<String>,
    /// Joint positions.
    pub joints: Vec<Vec3>,
    /// Segments as pairs of endpoints (a fit's bones, a rig's edges).
    pub segments: Vec<(Vec3, Vec3)>,
}

/// How far apart two skeletons lie (see the module docs), in the skeletons' units and as a
/// share of the truth's extent.
#[derive(Clone, Debug, PartialEq)]
pub struct SkeletonDistance {
    /// Largest side of the bounding box of the truth's joints and bone ends.
    pub extent: f32,
    /// Mean distance from the truth's curve to the fit's.
    pub truth_to_fit: f32,
    /// Mean distance from the fit's curve to the truth's.
    pub fit_to_truth: f32,
    /// Mean distance from each truth joint to the nearest end of a fitted bone.
    pub joints: f32,
    /// The truth joint farthest from every fitted bone end, and that distance.
    pub worst_joint: (String, f32),
}

impl SkeletonDistance {
    /// `value` as a percentage of the truth's extent.
    pub fn percent(&self, value: f32) -> f32 {
        100.0 * value / self.extent.max(f32::MIN_POSITIVE)
    }
}

impl JointGraph {
    /// Reads a skeleton JSON: an object with `joints` (name → `[x, y, z]`) and `bones`, either
    /// as `[parent, child]` joint-name pairs (a rig's edge list, the shared data's
    /// `skel_*_joints.json`) or as objects with `c1` and `c2` (a `FIT.json`, a synthetic
    /// statue's `--truth`); bones named in a `missing` list are left out.
    pub fn load(path: &Path) -> Result<JointGraph> {
        let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })?;
        JointGraph::parse(&text).map_err(|problem| Error::config(path, problem))
    }

    /// [`JointGraph::load`] from the JSON text.
    pub fn parse(text: &str) -> std::result::Result<JointGraph, String> {
        let v: serde_json::Value =
            serde_json::from_str(text).map_err(|e| format!("not a skeleton JSON file: {e}"))?;
        let joints = v
            .get("joints")
            .and_then(|j| j.as_object())
            .ok_or("no `joints` object (joint name → [x, y, z])")?;
        let mut g = JointGraph::default();
        for (name, p) in joints {
            let p = point(p).ok_or_else(|| format!("joint `{name}` is not a finite [x, y, z]"))?;
            g.names.push(name.clone());
            g.joints.push(p);
        }
        let missing: Vec<&str> = v
            .get("missing")
            .and_then(|m| m.as_array())
            .map(|m| m.iter().filter_map(|x| x.as_str()).collect())
            .unwrap_or_default();
        let bones = v
            .get("bones")
            .and_then(|b| b.as_array())
            .ok_or("no `bones` list")?;
        for (i, b) in bones.iter().enumerate() {
            if let Some(pair) = b.as_array() {
                let names: Vec<&str> = pair.iter().filter_map(|n| n.as_str()).collect();
                if names.len() != 2 || pair.len() != 2 {
                    return Err(format!(
                        "bone {i} is not a [parent, child] pair of joint names"
                    ));
                }
                let end = |k: usize| {
                    let name = names[k];
                    g.names
                        .iter()
                        .position(|n| n == name)
                        .map(|j| g.joints[j])
                        .ok_or_else(|| format!("bone {i} names an unknown joint `{name}`"))
                };
                g.segments.push((end(0)?, end(1)?));
            } else {
                let name = b.get("name").and_then(|n| n.as_str()).unwrap_or("");
                if missing.contains(&name) {
                    continue;
                }
                let end = |key: &str| {
                    b.get(key)
                        .and_then(point)
                        .ok_or_else(|| format!("bone {i} ({name}) has no finite `{key}` [x, y, z]"))
                };
                g.segments.push((end("c1")?, end("c2")?));
            }
        }
        if g.segments.is_empty() {
            return Err("the skeleton has no bones".into());
        }
        Ok(g)
    }

    /// Largest side of the bounding box of the joints and segment ends (0 when there are none).
    pub fn extent(&self) -> f32 {
        let ends = self.segments.iter().flat_map(|&(a, b)| [a, b]);
        let points: Vec<Vec3> = self.joints.iter().copied().chain(ends).collect();
        Aabb::of(&points).map_or(0.0, |b| b.size().max_element())
    }

    /// Points along every segment, at most `step` apart, both ends included.
    fn samples(&self, step: f32) -> Vec<Vec3> {
        let mut out = Vec::new();
        for &(a, b) in &self.segments {
            let n = ((b - a).length() / step).ceil().max(1.0) as usize;
            out.extend((0..=n).map(|i| a.lerp(b, i as f32 / n as f32)));
        }
        out
    }

    /// Distance from `p` to the nearest segment.
    fn distance(&self, p: Vec3) -> f32 {
        self.segments
            .iter()
            .map(|&(a, b)| point_segment_distance(p, a, b))
            .fold(f32::INFINITY, f32::min)
    }
}

/// A finite `[x, y, z]`.
fn point(v: &serde_json::Value) -> Option<Vec3> {
    let a = v.as_array()?;
    if a.len() != 3 {
        return None;
    }
    let c: Vec<f32> = a
        .iter()
        .filter_map(|x| x.as_f64())
        .map(|x| x as f32)
        .collect();
    (c.len() == 3 && c.iter().all(|x| x.is_finite())).then(|| Vec3::new(c[0], c[1], c[2]))
}

/// Distance from `p` to the segment `[a, b]` (a point when `a == b`).
pub fn point_segment_distance(p: Vec3, a: Vec3, b: Vec3) -> f32 {
    let ab = b - a;
    let len2 = ab.length_squared();
    let t = if len2 > 0.0 {
        ((p - a).dot(ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p - (a + ab * t)).length()
}

/// Compares a fitted skeleton with a truth (see the module docs). `None` when either has no
/// segment or the truth has no extent.
pub fn skeleton_distance(fit: &JointGraph, truth: &JointGraph) -> Option<SkeletonDistance> {
    let extent = truth.extent();
    if fit.segments.is_empty() || truth.segments.is_empty() || !(extent > 0.0) {
        return None;
    }
    let step = extent / 200.0;
    let mean = |from: &JointGraph, to: &JointGraph| {
        let s = from.samples(step);
        s.iter().map(|&p| to.distance(p) as f64).sum::<f64>() / s.len() as f64
    };
    // The fit's joints are its kept bones' ends (a lost bone's joints were not fitted).
    let fit_joints: Vec<Vec3> = fit.segments.iter().flat_map(|&(a, b)| [a, b]).collect();
    let mut worst = (String::new(), 0.0f32);
    let mut sum = 0.0f64;
    for (k, &j) in truth.joints.iter().enumerate() {
        let d = fit_joints
            .iter()
            .map(|&f| (f - j).length())
            .fold(f32::INFINITY, f32::min);
        sum += d as f64;
        if d > worst.1 {
            worst = (truth.names.get(k).cloned().unwrap_or_default(), d);
        }
    }
    Some(SkeletonDistance {
        extent,
        truth_to_fit: mean(truth, fit) as f32,
        fit_to_truth: mean(fit, truth) as f32,
        joints: (sum / truth.joints.len().max(1) as f64) as f32,
        worst_joint: worst,
    })
}
