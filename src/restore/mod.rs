//! Virtual restoration by part combination (thesis ch. 5, paper 001 §5): a broken statue
//! (the *target*) is completed with parts of other statues (*donors*), each brought first to
//! the target's proportions and pose, then merged without a seam.
//!
//! ```text
//! target cloud + fit ─► missing bones (the registration's verdict) ─► completed skeleton
//! donor cloud + fit ─► transfer (scale + skin the donor's part onto the completed skeleton)
//!                   ─► merge (eq. 5.1 in the overlap) ─► restored cloud + provenance
//! ```
//!
//! | stage | module |
//! |---|---|
//! | which bones are there: support, missing and partial bones, completion (measured by the registration) | [`crate::fakir::support`] |
//! | a part growing from a bone cut part-way (the stump's end) | [`mod@stump`] |
//! | a donor's part re-proportioned and re-posed onto the target | [`mod@transfer`] |
//! | the overlap merged to a single layer (eq. 5.1) | [`mod@merge`] |
//! | the whole restoration, with provenance | [`restore`] (this module) |
//! | one part at a time (the kiosk's part swapping): donor check, assembly with provenance | [`check_donor`], [`Assembly`] |

pub mod merge;
pub mod stump;
pub mod transfer;

use crate::anatomy::Skeleton;
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::fakir::support::{BoneSupport, complete_cut, support};
use crate::math::Vec3;
use merge::{MergeOptions, MergeStats, merge};
use serde::Serialize;
use stump::start_at_stumps;
use transfer::{Part, PoseSource, TransferOptions, parts_of, transfer};

/// Where a restored point comes from.
pub const FROM_TARGET: u32 = 0;

/// One donor statue.
#[derive(Clone)]
pub struct Donor<'a> {
    pub name: String,
    pub cloud: &'a PointCloud,
    pub fit: &'a Skeleton,
    /// The bones its registration found lost ([`crate::fakir::Fit::missing`]; `None`: not
    /// known, judged by their support).
    pub missing: Option<&'a [bool]>,
}

/// Which bones of `fit` are missing: the registration's verdict when there is one
/// ([`crate::fakir::Fit::missing`], also in `FIT.json`: the lost limbs it found or was told
/// of, already completed in `fit`), otherwise the support of its bones in `cloud`
/// ([`crate::fakir::support`], for a skeleton that comes without one). One rule for the
/// restoration, the kiosk's ghost limbs and `FIT.json`.
pub fn missing_bones(
    cloud: &PointCloud,
    fit: &Skeleton,
    verdict: Option<&[bool]>,
) -> Result<Vec<bool>> {
    let n = fit.template.bones.len();
    match verdict {
        Some(v) if v.len() == n => Ok(v.to_vec()),
        Some(v) => Err(Error::input(format!(
            "{} missing-bone flags for the {n} bones of template '{}'",
            v.len(),
            fit.template.name
        ))),
        None => Ok(support(cloud, fit)?.iter().map(|s| s.missing).collect()),
    }
}

/// Options of a restoration.
#[derive(Clone, Debug)]
pub struct RestoreOptions {
    /// Bones to restore (names); empty: every missing bone ([`missing_bones`]).
    pub parts: Vec<String>,
    /// The target registration's verdict on its missing bones ([`missing_bones`]).
    pub target_missing: Option<Vec<bool>>,
    pub pose: PoseSource,
    pub transfer: TransferOptions,
    pub merge: MergeOptions,
}

impl Default for RestoreOptions {
    fn default() -> Self {
        RestoreOptions {
            parts: Vec::new(),
            target_missing: None,
            pose: PoseSource::Donor,
            transfer: TransferOptions::default(),
            merge: MergeOptions::default(),
        }
    }
}

/// What replaced what (the JSON report).
#[derive(Clone, Debug, Serialize)]
pub struct PartReport {
    pub bones: Vec<String>,
    pub attach: Option<String>,
    /// Where the part starts on its first bone ([`Part::from`]: 0 from the joint, else the
    /// end of the statue's stump of that bone, a fraction of its length).
    pub from: f32,
    pub donor: String,
    /// Source index in [`Restored::source`] (donor `i` is `i + 1`).
    pub source: u32,
    pub points: usize,
    pub merge: MergeStats,
}

/// The restoration's report.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    pub support: Vec<BoneSupport>,
    pub parts: Vec<PartReport>,
    pub pose: PoseSource,
    pub method: String,
    pub three_delta_over_rho: f32,
    pub margin: f32,
    /// The completed target skeleton (JSON form).
    pub skeleton: crate::anatomy::SkeletonJson,
}

/// A restored statue.
pub struct Restored {
    pub cloud: PointCloud,
    /// Per point: [`FROM_TARGET`] or `1 + donor index`.
    pub source: Vec<u32>,
    /// Per point: the bone it came with (target: nearest bone of the completed skeleton;
    /// donor: the donor bone).
    pub bone: Vec<u32>,
    /// The completed target skeleton.
    pub skeleton: Skeleton,
    pub report: Report,
}

/// Restores `target` (fitted as `target_fit`) from `donors`: each part (a connected set of
/// missing bones, or the bones named in `opts.parts`, with the bone it hangs on when that one
/// is cut part-way: [`stump`]) is taken from the first donor that has it.
pub fn restore(
    target: &PointCloud,
    target_fit: &Skeleton,
    donors: &[Donor],
    opts: &RestoreOptions,
) -> Result<Restored> {
    if donors.is_empty() {
        return Err(Error::input("restore: no donor statue given"));
    }
    let t = &target_fit.template;
    let sup = support(target, target_fit)?;
    let missing: Vec<bool> = if opts.parts.is_empty() {
        missing_bones(target, target_fit, opts.target_missing.as_deref())?
    } else {
        let mut m = vec![false; t.bones.len()];
        for p in &opts.parts {
            let k = t.bone_index(p).ok_or_else(|| {
                Error::input(format!(
                    "restore: unknown bone '{p}' in template '{}'",
                    t.name
                ))
            })?;
            m[k] = true;
        }
        m
    };
    let mut parts: Vec<Part> = parts_of(t, &missing);
    let listed: Vec<String> = sup
        .iter()
        .filter(|s| s.missing || s.partial)
        .map(|s| {
            format!(
                "{} ({}, coverage {:.2})",
                s.bone,
                if s.missing { "missing" } else { "partial" },
                s.coverage
            )
        })
        .collect();
    if parts.is_empty() {
        return Err(Error::input(
            "restore: no missing part found on the target (name the bones with --parts)",
        ));
    }
    // Missing bones get their expected size and pose, as the registration completes the lost
    // limbs it finds (the same again for those); a bone cut part-way that FAKIR shrank onto
    // its stump gets its length back (`complete_cut`).
    let healthy: Vec<bool> = missing.iter().map(|m| !m).collect();
    let completed = complete_cut(target_fit, &missing, Some(&healthy));
    // Start from the target's points.
    let mut assembly = Assembly::from_target(target, &completed);
    // A part whose bone it hangs on was cut part-way grows from that bone's stump.
    start_at_stumps(&mut parts, &target.positions, &completed);
    let mut reports = Vec::new();
    let topts = TransferOptions {
        pose: opts.pose,
        ..opts.transfer
    };
    // What each donor has (a donor missing a bone of the part cannot give it).
    let donor_missing: Vec<Vec<bool>> = donors
        .iter()
        .map(|d| missing_bones(d.cloud, d.fit, d.missing))
        .collect::<Result<_>>()?;
    // Each donor is bound once, when it first gives a part.
    let mut bindings: Vec<Option<crate::skinning::Binding>> = donors.iter().map(|_| None).collect();
    for part in &parts {
        let mut last_err = None;
        let mut done = false;
        for (di, d) in donors.iter().enumerate() {
            if let Err(e) = check_donor(t, &d.name, &donor_missing[di], part) {
                last_err = Some(e);
                continue;
            }
            if bindings[di].is_none() {
                bindings[di] = Some(crate::skinning::Binding::new_on_base(d.cloud, d.fit)?);
            }
            let binding = bindings[di].as_ref().expect("bound just above");
            match transfer(&completed, d.cloud, binding, part, &topts) {
                Ok(tr) => {
                    let source = di as u32 + 1;
                    let stats =
                        assembly.add(&completed, part, &tr, source, topts.margin, &opts.merge);
                    reports.push(PartReport {
                        bones: part
                            .bones
                            .iter()
                            .map(|&k| t.bones[k].name.clone())
                            .collect(),
                        attach: part.attach.map(|a| t.bones[a].name.clone()),
                        from: part.from,
                        donor: d.name.clone(),
                        source,
                        points: tr.cloud.len(),
                        merge: stats,
                    });
                    done = true;
                    break;
                }
                Err(e) => last_err = Some(e),
            }
        }
        if !done {
            let names: Vec<&str> = part
                .bones
                .iter()
                .map(|&k| t.bones[k].name.as_str())
                .collect();
            return Err(Error::input(format!(
                "no donor can give {}: {} (target support: {})",
                names.join(", "),
                last_err.map_or("no donor".to_string(), |e| e.to_string()),
                listed.join(", ")
            )));
        }
    }
    let (cloud, source, bone) = assembly.finish();
    Ok(Restored {
        report: Report {
            support: sup,
            parts: reports,
            pose: opts.pose,
            method: topts.method.name().to_string(),
            three_delta_over_rho: opts.merge.three_delta_over_rho,
            margin: topts.margin,
            skeleton: completed.to_json(),
        },
        cloud,
        source,
        bone,
        skeleton: completed,
    })
}

/// Fails when the donor (its missing bones `donor_missing`, [`missing_bones`]) lacks a bone
/// of `part` too: a donor missing a bone of the part cannot give it.
pub fn check_donor(
    t: &crate::anatomy::Template,
    donor: &str,
    donor_missing: &[bool],
    part: &Part,
) -> Result<()> {
    let lacking: Vec<&str> = part
        .bones
        .iter()
        .filter(|&&k| donor_missing.get(k).copied().unwrap_or(false))
        .map(|&k| t.bones[k].name.as_str())
        .collect();
    if lacking.is_empty() {
        Ok(())
    } else {
        Err(Error::input(format!(
            "donor {donor} lacks {} too",
            lacking.join(", ")
        )))
    }
}

/// A restoration being assembled: the target's points first, then each transferred part's,
/// with per-point provenance ([`Restored::source`], [`Restored::bone`]). [`restore`] builds
/// one; the kiosk adds parts one at a time (each step a new hypothesis).
#[derive(Clone, Debug)]
pub struct Assembly {
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    pub colors: Option<Vec<[u8; 3]>>,
    /// Per point: [`FROM_TARGET`] or the source given to [`Assembly::add`].
    pub source: Vec<u32>,
    /// Per point: the bone it came with.
    pub bone: Vec<u32>,
}

impl Assembly {
    /// The target's points, each labelled [`FROM_TARGET`] and with its nearest bone of
    /// `skeleton` (the completed target skeleton).
    pub fn from_target(target: &PointCloud, skeleton: &Skeleton) -> Assembly {
        let positions = target.positions.clone();
        let bone = nearest_bones(&positions, skeleton);
        Assembly {
            normals: target
                .normals
                .clone()
                .unwrap_or_else(|| vec![Vec3::Y; target.len()]),
            colors: target.colors.clone(),
            source: vec![FROM_TARGET; target.len()],
            bone,
            positions,
        }
    }

    /// An assembly resumed from a restored cloud and its provenance (one entry per point).
    pub fn resume(cloud: &PointCloud, source: Vec<u32>, bone: Vec<u32>) -> Result<Assembly> {
        if source.len() != cloud.len() || bone.len() != cloud.len() {
            return Err(Error::input(format!(
                "restore: {} points with {} sources and {} bones",
                cloud.len(),
                source.len(),
                bone.len()
            )));
        }
        Ok(Assembly {
            positions: cloud.positions.clone(),
            normals: cloud
                .normals
                .clone()
                .unwrap_or_else(|| vec![Vec3::Y; cloud.len()]),
            colors: cloud.colors.clone(),
            source,
            bone,
        })
    }

    /// Number of points so far.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// True when there is no point.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Appends a transferred part (its points labelled `source`, with their donor bones) and
    /// merges the overlap around the part's joint on `skeleton` (eq. 5.1, [`mod@merge`]).
    pub fn add(
        &mut self,
        skeleton: &Skeleton,
        part: &Part,
        tr: &transfer::Transferred,
        source: u32,
        margin: f32,
        opts: &MergeOptions,
    ) -> MergeStats {
        let n = tr.cloud.len();
        self.positions.extend_from_slice(&tr.cloud.positions);
        self.normals
            .extend(tr.cloud.normals.clone().unwrap_or_else(|| vec![Vec3::Y; n]));
        match (&mut self.colors, &tr.cloud.colors) {
            (Some(c), Some(tc)) => c.extend_from_slice(tc),
            (Some(c), None) => c.extend(std::iter::repeat_n([200, 200, 200], n)),
            _ => {}
        }
        self.source.extend(std::iter::repeat_n(source, n));
        self.bone.extend_from_slice(&tr.bones);
        let (_, stats) = merge(skeleton, part, margin, &mut self.positions, opts);
        stats
    }

    /// The restored cloud and its provenance (`source`, `bone`); colours are dropped when
    /// some points lack them.
    pub fn finish(self) -> (PointCloud, Vec<u32>, Vec<u32>) {
        let mut colors = self.colors;
        if colors
            .as_ref()
            .is_some_and(|c| c.len() != self.positions.len())
        {
            colors = None;
        }
        let mut cloud = PointCloud::with_normals(self.positions, self.normals);
        cloud.colors = colors;
        (cloud, self.source, self.bone)
    }
}

/// The nearest bone (by signed distance) of every point.
pub fn nearest_bones(positions: &[Vec3], skel: &Skeleton) -> Vec<u32> {
    use rayon::prelude::*;
    let prepared: Vec<_> = skel
        .pose()
        .bones
        .iter()
        .map(crate::geometry::Bone::prepare)
        .collect();
    positions
        .par_iter()
        .map(|&p| crate::geometry::bone::nearest_bone(&prepared, p).0 as u32)
        .collect()
}
