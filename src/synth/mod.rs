//! Synthetic statues with ground truth, for tests and benchmarks.
//!
//! [`generate`] poses a template (random but plausible pose, random proportions), samples
//! points area-uniformly with outward normals on the **outer envelope** of the union of its
//! bones, and returns the cloud with the ground-truth [`Skeleton`] and each point's bone.
//! [`chain4`] reproduces the papers' chain experiment (thesis §2.5.1: a 4-bone chain of total
//! length 140 sampled with 5k points).
//!
//! ## Method and choices
//! * **Envelope sampling.** A bone is drawn with probability proportional to its surface area,
//!   a point is drawn area-uniformly on it ([`crate::geometry::PreparedBone::sample_surface`]),
//!   and the sample is rejected when it lies inside another bone. Surface shared by two bones
//!   (within `1e-5 × height`) is kept only for the lower bone index, so it is not sampled
//!   twice. Rejection keeps the density uniform on the envelope; sampling repeats until
//!   exactly `points` samples are accepted (cuts are applied afterwards).
//! * **Random pose.** Each free bone gets, at the rest pose, a hinge bend uniform in the
//!   template's `bend` range about `bend_axis` and a swing of at most `swing` degrees about a
//!   random axis orthogonal to the bone (template fields, see [`crate::anatomy::template`]);
//!   the rotations are carried by the parents' motions.
//! * **Random proportions.** Each free bone's length is multiplied by a factor uniform in
//!   `1 ± proportion_jitter`; each joint radius (shared along chains) likewise; the root block
//!   gets one common factor; followers keep their length ratio. With `symmetric`, a left or
//!   right bone takes its mirror's factors (coherent, stylised proportions rather than a
//!   lopsided figure). Radii are clamped so that no sphere contains its neighbour.
//! * **Noise** is applied along the normal: Gaussian with standard deviation `noise_sigma`,
//!   and "Poisson noise" of parameter λ as a zero-mean displacement `K − λ` with
//!   `K ~ Poisson(λ)` (variance λ), both in output length units (the papers do not define
//!   their Poisson noise further).
//! * **Cuts** remove points: a plane removes the half-space its normal points to (output
//!   coordinates); a bone cut removes every point of the bone's descendants and the points of
//!   the bone beyond the plane orthogonal to it at fraction `at` of its length.
//! * **Rigid transform**: a uniformly random rotation and a translation of up to one height.
//! * **Plinth** (our addition, for [`crate::cloud::base`]): a box under the figure, as museum
//!   scans have. Its top touches the lowest point of the figure along the template's up
//!   (`+Y`, carried by the rigid transform); its footprint covers the figure's lowest tenth
//!   of the height plus `0.06 × height` on each side (half-widths at least `0.12 × height`);
//!   it is `0.08 × height` high. Its five outer faces and its bottom are sampled
//!   area-uniformly with `plinth_share × points` points, labelled [`PLINTH_LABEL`], after the
//!   noise and the cuts (a plinth is neither noisy nor broken here).
//!
//! Everything is deterministic for a seed (one sequential [`Rng`] stream).

use crate::anatomy::template::{BoneKind, ChainSpec, JointSpec, Template, TemplateFile};
use crate::anatomy::{Skeleton, skeleton::rest_frames};
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::geometry::{Bone, PreparedBone};
use crate::math::{Quat, Vec3};
use crate::rng::Rng;
use std::path::Path;
use std::sync::Arc;

/// A region removed from a synthetic statue (a broken statue).
#[derive(Clone, Debug, PartialEq)]
pub enum Cut {
    /// Removes the points `p` with `(p − point) · normal > 0` (output coordinates).
    Plane { point: Vec3, normal: Vec3 },
    /// Removes the limb below bone `bone`, cut orthogonally at fraction `at` of its length.
    Bone { bone: String, at: f32 },
}

impl Cut {
    /// Parses `bone:NAME[@FRACTION]` or `plane:px,py,pz,nx,ny,nz`.
    pub fn parse(s: &str) -> Result<Cut> {
        let bad = || {
            Error::input(format!(
                "invalid cut '{s}': expected 'bone:NAME' , 'bone:NAME@0.5' or 'plane:px,py,pz,nx,ny,nz'"
            ))
        };
        if let Some(rest) = s.strip_prefix("bone:") {
            let (name, at) = match rest.split_once('@') {
                Some((n, a)) => (n, a.trim().parse::<f32>().map_err(|_| bad())?),
                None => (rest, 0.0),
            };
            if name.is_empty() || !(0.0..=1.0).contains(&at) {
                return Err(bad());
            }
            Ok(Cut::Bone {
                bone: name.to_string(),
                at,
            })
        } else if let Some(rest) = s.strip_prefix("plane:") {
            let v: Vec<f32> = rest
                .split(',')
                .map(|x| x.trim().parse::<f32>())
                .collect::<Result<_, _>>()
                .map_err(|_| bad())?;
            if v.len() != 6 || !v.iter().all(|x| x.is_finite()) {
                return Err(bad());
            }
            let normal = Vec3::new(v[3], v[4], v[5]);
            if normal.length() < 1e-9 {
                return Err(bad());
            }
            Ok(Cut::Plane {
                point: Vec3::new(v[0], v[1], v[2]),
                normal,
            })
        } else {
            Err(bad())
        }
    }
}

/// Options of the generator.
#[derive(Clone, Debug)]
pub struct SynthOptions {
    /// Number of points sampled on the envelope (before cuts).
    pub points: usize,
    /// Seed of the random stream.
    pub seed: u64,
    /// Draw a random plausible pose (otherwise the rest pose).
    pub random_pose: bool,
    /// Per-bone length and per-joint radius factor uniform in `1 ± proportion_jitter`.
    pub proportion_jitter: f32,
    /// Left and right get the same factors (a figure with coherent, stylised proportions):
    /// each bone takes its mirror's factors (see [`Template::mirror_bones`]).
    pub symmetric: bool,
    /// Height of the statue (the template's height is scaled to it).
    pub height: f32,
    /// Gaussian noise along the normal (standard deviation, output units).
    pub noise_sigma: f32,
    /// Poisson noise parameter λ (output units).
    pub poisson_lambda: f32,
    /// Regions to remove.
    pub cuts: Vec<Cut>,
    /// Apply a random rigid transform to the statue and its skeleton.
    pub rigid: bool,
    /// Points of a plinth under the figure, as a share of `points` (0: no plinth; see the
    /// module docs).
    pub plinth_share: f32,
}

/// Label of the plinth's points in [`SynthStatue::labels`].
pub const PLINTH_LABEL: u32 = u32::MAX;

impl Default for SynthOptions {
    fn default() -> Self {
        SynthOptions {
            points: 30_000,
            seed: 0,
            random_pose: true,
            proportion_jitter: 0.3,
            symmetric: false,
            height: 1.0,
            noise_sigma: 0.0,
            poisson_lambda: 0.0,
            cuts: Vec::new(),
            rigid: false,
            plinth_share: 0.0,
        }
    }
}

/// A synthetic statue and its ground truth.
#[derive(Clone, Debug)]
pub struct SynthStatue {
    /// The sampled points with their outward normals.
    pub cloud: PointCloud,
    /// The skeleton the points were sampled from.
    pub truth: Skeleton,
    /// For each point, the index of the bone it was sampled on ([`PLINTH_LABEL`] on the
    /// plinth).
    pub labels: Vec<u32>,
    /// The rigid transform applied (identity when `rigid` was off).
    pub rigid: (Quat, Vec3),
}

/// Generates a synthetic statue of `template` (see the module docs).
pub fn generate(template: Arc<Template>, opts: &SynthOptions) -> Result<SynthStatue> {
    if opts.points == 0 {
        return Err(Error::input("a synthetic statue needs at least one point"));
    }
    if !(opts.height.is_finite() && opts.height > 0.0) {
        return Err(Error::input(format!(
            "invalid statue height {}",
            opts.height
        )));
    }
    if !(0.0..0.9).contains(&opts.proportion_jitter) {
        return Err(Error::input("proportion jitter must be in [0, 0.9)"));
    }
    if !(opts.noise_sigma >= 0.0 && opts.poisson_lambda >= 0.0) {
        return Err(Error::input("noise levels must be ≥ 0"));
    }
    if !(0.0..=4.0).contains(&opts.plinth_share) {
        return Err(Error::input(
            "the plinth's share of points must be in [0, 4]",
        ));
    }
    let mut rng = Rng::new(opts.seed);
    let mut skel = Skeleton::rest(template.clone());
    jitter_proportions(&mut skel, opts.proportion_jitter, opts.symmetric, &mut rng);
    if opts.random_pose {
        random_pose(&mut skel, &mut rng);
    }
    // Scale to the requested height about the root.
    let k = opts.height / template.height;
    skel.scale_sizes(k);
    skel.root_position *= k;
    let rigid = if opts.rigid {
        let q = random_rotation(&mut rng);
        let t = Vec3::new(
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        ) * opts.height;
        (q, t)
    } else {
        (Quat::IDENTITY, Vec3::ZERO)
    };
    skel.transform_rigid(rigid.0, rigid.1);
    let posed = skel.pose();
    let (mut positions, mut normals, mut labels) =
        sample_envelope(&posed.bones, opts.points, opts.height, &mut rng);
    displace_along_normals(
        &mut positions,
        &normals,
        opts.noise_sigma,
        opts.poisson_lambda,
        &mut rng,
    );
    apply_cuts(
        &template,
        &posed.bones,
        &opts.cuts,
        &mut positions,
        &mut normals,
        &mut labels,
    )?;
    let plinth = (opts.plinth_share * opts.points as f32).round() as usize;
    if plinth > 0 && !positions.is_empty() {
        let up = rigid.0 * Vec3::Y;
        let frame = (rigid.0 * Vec3::X, up, rigid.0 * Vec3::Z);
        add_plinth(
            frame,
            opts.height,
            plinth,
            &mut rng,
            (&mut positions, &mut normals, &mut labels),
        );
    }
    Ok(SynthStatue {
        cloud: PointCloud::with_normals(positions, normals),
        truth: skel,
        labels,
        rigid,
    })
}

/// Moves every point along its normal by Gaussian noise `σ` and zero-mean Poisson noise
/// `K − λ` (see the module docs); draws nothing when both are zero.
fn displace_along_normals(
    positions: &mut [Vec3],
    normals: &[Vec3],
    sigma: f32,
    lambda: f32,
    rng: &mut Rng,
) {
    if sigma <= 0.0 && lambda <= 0.0 {
        return;
    }
    for (p, n) in positions.iter_mut().zip(normals) {
        let mut d = 0.0;
        if sigma > 0.0 {
            d += sigma * rng.normal();
        }
        if lambda > 0.0 {
            d += rng.poisson(lambda) as f32 - lambda;
        }
        *p += d * *n;
    }
}

/// Adds a plinth of `count` points under the figure (see the module docs); `frame` holds the
/// statue's x, up and z axes.
fn add_plinth(
    frame: (Vec3, Vec3, Vec3),
    height: f32,
    count: usize,
    rng: &mut Rng,
    (positions, normals, labels): (&mut Vec<Vec3>, &mut Vec<Vec3>, &mut Vec<u32>),
) {
    let (ex, up, ez) = frame;
    let low = positions
        .iter()
        .map(|p| p.dot(up))
        .fold(f32::INFINITY, f32::min);
    let (mut x0, mut x1, mut z0, mut z1) = (
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::INFINITY,
        f32::NEG_INFINITY,
    );
    for p in positions.iter().filter(|p| p.dot(up) < low + 0.1 * height) {
        x0 = x0.min(p.dot(ex));
        x1 = x1.max(p.dot(ex));
        z0 = z0.min(p.dot(ez));
        z1 = z1.max(p.dot(ez));
    }
    let (cx, cz) = (0.5 * (x0 + x1), 0.5 * (z0 + z1));
    let hx = (0.5 * (x1 - x0) + 0.06 * height).max(0.12 * height);
    let hz = (0.5 * (z1 - z0) + 0.06 * height).max(0.12 * height);
    let hy = 0.04 * height;
    let centre = ex * cx + ez * cz + up * (low - hy);
    // Faces: (normal, first edge half-vector, second edge half-vector).
    let faces = [
        (up, ex * hx, ez * hz),
        (-up, ex * hx, ez * hz),
        (ex, up * hy, ez * hz),
        (-ex, up * hy, ez * hz),
        (ez, ex * hx, up * hy),
        (-ez, ex * hx, up * hy),
    ];
    let offsets = [hy, hy, hx, hx, hz, hz];
    let areas: Vec<f32> = faces
        .iter()
        .map(|(_, a, b)| 4.0 * a.length() * b.length())
        .collect();
    let total: f32 = areas.iter().sum();
    for _ in 0..count {
        let mut r = rng.f32() * total;
        let mut f = faces.len() - 1;
        for (k, a) in areas.iter().enumerate() {
            if r < *a {
                f = k;
                break;
            }
            r -= a;
        }
        let (n, a, b) = faces[f];
        let p = centre + n * offsets[f] + a * rng.range(-1.0, 1.0) + b * rng.range(-1.0, 1.0);
        positions.push(p);
        normals.push(n);
        labels.push(PLINTH_LABEL);
    }
}

/// Removes the points that `cuts` take away (see [`Cut`]), keeping the three arrays aligned.
fn apply_cuts(
    template: &Template,
    bones: &[Bone],
    cuts: &[Cut],
    positions: &mut Vec<Vec3>,
    normals: &mut Vec<Vec3>,
    labels: &mut Vec<u32>,
) -> Result<()> {
    if cuts.is_empty() {
        return Ok(());
    }
    let mut keep = vec![true; positions.len()];
    for cut in cuts {
        match cut {
            Cut::Plane { point, normal } => {
                let n = normal.normalize();
                for (k, p) in keep.iter_mut().zip(positions.iter()) {
                    if (*p - *point).dot(n) > 0.0 {
                        *k = false;
                    }
                }
            }
            Cut::Bone { bone, at } => {
                let b = template.bone_index(bone).ok_or_else(|| {
                    Error::input(format!(
                        "cut: unknown bone '{bone}' in template '{}'",
                        template.name
                    ))
                })?;
                let below = template.subtree(b);
                let geo = bones[b];
                let axis = (geo.c2 - geo.c1).normalize();
                let q = geo.c1 + *at * (geo.c2 - geo.c1);
                for i in 0..positions.len() {
                    let l = labels[i] as usize;
                    if (l == b && (positions[i] - q).dot(axis) > 0.0)
                        || (l != b && below.contains(&l))
                    {
                        keep[i] = false;
                    }
                }
            }
        }
    }
    let mut j = 0;
    for i in 0..positions.len() {
        if keep[i] {
            positions[j] = positions[i];
            normals[j] = normals[i];
            labels[j] = labels[i];
            j += 1;
        }
    }
    positions.truncate(j);
    normals.truncate(j);
    labels.truncate(j);
    Ok(())
}

/// Samples `n` points area-uniformly on the outer envelope of `bones` (see the module docs).
/// Returns positions, outward normals and bone labels.
pub fn sample_envelope(
    bones: &[Bone],
    n: usize,
    scale: f32,
    rng: &mut Rng,
) -> (Vec<Vec3>, Vec<Vec3>, Vec<u32>) {
    let prepared: Vec<PreparedBone> = bones.iter().map(|b| b.prepare()).collect();
    let areas: Vec<f32> = prepared
        .iter()
        .map(|b| b.part_areas().iter().sum())
        .collect();
    let mut cumulative = Vec::with_capacity(areas.len());
    let mut acc = 0.0f64;
    for a in &areas {
        acc += *a as f64;
        cumulative.push(acc);
    }
    let total = acc;
    let tol = 1e-5 * scale;
    let mut positions = Vec::with_capacity(n);
    let mut normals = Vec::with_capacity(n);
    let mut labels = Vec::with_capacity(n);
    let mut attempts = 0usize;
    while positions.len() < n {
        attempts += 1;
        if attempts > 200 * n + 1000 {
            break; // Degenerate model (everything inside something else): give what we have.
        }
        let pick = rng.f64() * total;
        let i = cumulative
            .partition_point(|&c| c <= pick)
            .min(prepared.len() - 1);
        let (p, nrm) = prepared[i].sample_surface(rng);
        let hidden = prepared.iter().enumerate().any(|(j, other)| {
            if j == i {
                return false;
            }
            let d = other.sdf_fast(p);
            d < -tol || (d <= tol && j < i)
        });
        if !hidden {
            positions.push(p);
            normals.push(nrm);
            labels.push(i as u32);
        }
    }
    (positions, normals, labels)
}

fn jitter_proportions(skel: &mut Skeleton, j: f32, symmetric: bool, rng: &mut Rng) {
    if j <= 0.0 {
        return;
    }
    let t = skel.template.clone();
    let block = 1.0 + rng.range(-j, j) * 0.5;
    skel.block_scale *= block;
    // Every factor is drawn (the same draws with or without `symmetric`); a symmetric figure
    // then gives each bone of a right/left pair the factors of the pair's first bone.
    let mut length_factor: Vec<f32> = t
        .bones
        .iter()
        .map(|def| match def.kind {
            BoneKind::Free => 1.0 + rng.range(-j, j),
            _ => 1.0,
        })
        .collect();
    // Joint radii: one factor per joint, shared by the bones meeting there.
    let mut joint_factor: Vec<f32> = (0..t.joints.len())
        .map(|_| 1.0 + rng.range(-j, j))
        .collect();
    if symmetric {
        for (i, m) in t.mirror_bones().into_iter().enumerate() {
            if let Some(m) = m.filter(|&m| m < i) {
                length_factor[i] = length_factor[m];
                joint_factor[t.bones[i].to] = joint_factor[t.bones[m].to];
                joint_factor[t.bones[i].from] = joint_factor[t.bones[m].from];
            }
        }
    }
    // Bones other than free ones have the factor 1.
    for (bone, f) in skel.bones.iter_mut().zip(&length_factor) {
        bone.length *= f;
    }
    for (i, def) in t.bones.iter().enumerate() {
        let s = if def.kind == BoneKind::Block {
            block
        } else {
            1.0
        };
        skel.bones[i].r1 *= joint_factor[def.from] * s;
        skel.bones[i].r2 *= joint_factor[def.to] * s;
    }
    skel.enforce_constraints();
    for (i, def) in t.bones.iter().enumerate() {
        if def.kind == BoneKind::Block {
            // Rest radii times the block factor (the block is rigid and uniformly scaled).
            skel.bones[i].r1 = def.r1 * skel.block_scale;
            skel.bones[i].r2 = def.r2 * skel.block_scale;
        }
    }
    // Keep every bone a proper cone: |r2 − r1| < 0.9 l.
    for b in &mut skel.bones {
        let max_dr = 0.9 * b.length;
        if (b.r2 - b.r1).abs() > max_dr {
            let mid = 0.5 * (b.r1 + b.r2);
            let half = 0.5 * max_dr * (b.r2 - b.r1).signum();
            b.r1 = mid - half;
            b.r2 = mid + half;
        }
    }
}

/// Applies a random plausible pose (template `bend` / `swing` ranges) to a skeleton.
pub fn random_pose(skel: &mut Skeleton, rng: &mut Rng) {
    let t = skel.template.clone();
    let frames = rest_frames(&t);
    for (i, def) in t.bones.iter().enumerate() {
        if def.kind != BoneKind::Free {
            continue;
        }
        let axis = frames[i] * Vec3::X;
        let mut world = Quat::IDENTITY;
        if let Some((bend_axis, lo, hi)) = def.bend {
            let angle = rng.range(lo, hi).to_radians();
            world = Quat::from_axis_angle(bend_axis, angle) * world;
        }
        if def.swing_deg > 0.0 {
            let perp = {
                let r = rng.unit_vector();
                let v = r - r.dot(axis) * axis;
                v.normalize_or(axis.any_orthonormal_vector())
            };
            let angle = rng.range(0.0, def.swing_deg).to_radians();
            world = Quat::from_axis_angle(perp, angle) * world;
        }
        // Rotation `world` applied at rest, expressed in the bone's own rest frame.
        let local = frames[i].inverse() * world * frames[i];
        skel.bones[i].rotation = (skel.bones[i].rotation * local).normalize();
    }
}

/// A uniformly distributed random rotation.
pub fn random_rotation(rng: &mut Rng) -> Quat {
    // Shoemake's method.
    let u1 = rng.f32();
    let u2 = rng.range(0.0, std::f32::consts::TAU);
    let u3 = rng.range(0.0, std::f32::consts::TAU);
    let a = (1.0 - u1).sqrt();
    let b = u1.sqrt();
    Quat::from_xyzw(a * u2.sin(), a * u2.cos(), b * u3.sin(), b * u3.cos()).normalize()
}

/// A template made of a single chain of bones with the given lengths and joint radii
/// (`radii.len() == lengths.len() + 1`), lying along `+X` from the root at the origin.
pub fn chain_template(name: &str, lengths: &[f32], radii: &[f32]) -> Result<Template> {
    if lengths.is_empty() || radii.len() != lengths.len() + 1 {
        return Err(Error::input("a chain needs n lengths and n + 1 radii"));
    }
    let mut joints = Vec::new();
    let mut x = 0.0;
    for k in 0..=lengths.len() {
        joints.push(JointSpec {
            name: format!("j{k}"),
            at: [x, 0.0, 0.0],
            doc: String::new(),
        });
        if k < lengths.len() {
            x += lengths[k];
        }
    }
    let bones = (0..lengths.len())
        .map(|k| crate::anatomy::template::BoneSpec {
            name: format!("b{}", k + 1),
            from: format!("j{k}"),
            to: format!("j{}", k + 1),
            r1: radii[k],
            r2: radii[k + 1],
            block: false,
            follows: None,
            swing: 0.0,
            bend_axis: None,
            bend: None,
        })
        .collect();
    let file = TemplateFile {
        name: name.to_string(),
        description: "a single chain of bones".into(),
        root: "j0".into(),
        joints,
        bones,
        chains: vec![ChainSpec {
            name: "chain".into(),
            bones: (1..=lengths.len()).map(|k| format!("b{k}")).collect(),
            mirror: None,
        }],
        bust: Vec::new(),
    };
    Template::from_file(file, Path::new(name))
}

/// The papers' chain experiment (thesis §2.5.1, fig. 2.8–2.12): a 4-bone chain of total
/// length 140 (bones 40, 35, 35, 30; joint radii 9, 8, 7, 6, 5) in a bent, non-planar pose,
/// sampled with `points` points; the anchor (root) is the first extremity at the origin.
pub fn chain4(
    points: usize,
    seed: u64,
    noise_sigma: f32,
    poisson_lambda: f32,
    cuts: Vec<Cut>,
) -> Result<SynthStatue> {
    let t = Arc::new(chain_template(
        "chain4",
        &[40.0, 35.0, 35.0, 30.0],
        &[9.0, 8.0, 7.0, 6.0, 5.0],
    )?);
    let mut skel = Skeleton::rest(t.clone());
    let bends = [
        Quat::from_rotation_z(0.35),
        Quat::from_rotation_z(-0.6) * Quat::from_rotation_y(0.3),
        Quat::from_rotation_z(0.7),
        Quat::from_rotation_y(-0.5),
    ];
    for (b, q) in skel.bones.iter_mut().zip(bends) {
        b.rotation = (b.rotation * q).normalize();
    }
    let posed = skel.pose();
    let mut rng = Rng::new(seed);
    let (mut positions, mut normals, mut labels) =
        sample_envelope(&posed.bones, points, 140.0, &mut rng);
    displace_along_normals(
        &mut positions,
        &normals,
        noise_sigma,
        poisson_lambda,
        &mut rng,
    );
    apply_cuts(
        &t,
        &posed.bones,
        &cuts,
        &mut positions,
        &mut normals,
        &mut labels,
    )?;
    let cloud = PointCloud::with_normals(positions, normals);
    Ok(SynthStatue {
        cloud,
        truth: skel,
        labels,
        rigid: (Quat::IDENTITY, Vec3::ZERO),
    })
}
