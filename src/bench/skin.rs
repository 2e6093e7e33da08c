//! Benchmarks of point-set skinning on a 500k-point synthetic human (random pose, relief of
//! 0.4% of the height). The target pose bends every free joint by 0.4 rad, twists it by
//! 0.3 rad and lengthens every bone by 10%, so every code path of every method runs (the
//! worst case: in a real pose change most joints stay put). `skin/bind_500k` times
//! [`Binding::new`]; the other entries time one [`Binding::deform`] into reused buffers.

use super::{BenchResult, Entry, time_it};
use crate::anatomy::{BoneKind, Skeleton, Template};
use crate::cloud::PointCloud;
use crate::error::Result;
use crate::math::{Quat, Vec3};
use crate::skinning::{Binding, Method, Scratch};
use crate::synth::{SynthOptions, generate};
use std::sync::Arc;

const POINTS: usize = 500_000;

pub(super) fn entries() -> Vec<Entry> {
    vec![
        Entry {
            name: "skin/bind_500k",
            run: bind_500k,
        },
        Entry {
            name: "skin/baseline_500k",
            run: |r| deform_500k("skin/baseline_500k", Method::Baseline, r),
        },
        Entry {
            name: "skin/heightfield_500k",
            run: |r| deform_500k("skin/heightfield_500k", Method::Heightfield, r),
        },
        Entry {
            name: "skin/lbs_500k",
            run: |r| deform_500k("skin/lbs_500k", Method::Lbs, r),
        },
        Entry {
            name: "skin/dqs_500k",
            run: |r| deform_500k("skin/dqs_500k", Method::Dqs, r),
        },
    ]
}

/// The statue and its skeleton.
pub fn statue(points: usize) -> Result<(PointCloud, Skeleton)> {
    let t = Arc::new(Template::builtin("human")?);
    let s = generate(
        t,
        &SynthOptions {
            points,
            seed: 42,
            noise_sigma: 0.004,
            ..Default::default()
        },
    )?;
    Ok((s.cloud, s.truth))
}

/// The benchmark's target pose (see the module docs).
pub fn target(fitted: &Skeleton) -> Skeleton {
    let mut s = fitted.clone();
    for (b, def) in s.bones.iter_mut().zip(&fitted.template.bones) {
        if def.kind == BoneKind::Free && def.parent.is_some() {
            b.rotation = (b.rotation
                * Quat::from_axis_angle(Vec3::new(0.0, 0.6, 0.8), 0.4)
                * Quat::from_rotation_x(0.3))
            .normalize();
        }
        b.length *= 1.1;
    }
    s.enforce_constraints();
    s
}

fn bind_500k(runs: usize) -> Result<BenchResult> {
    let (cloud, skel) = statue(POINTS)?;
    let mut joint = 0;
    let mut r = time_it("skin/bind_500k", cloud.len() as u64, runs, || {
        let b = Binding::new(&cloud, &skel).expect("bind");
        joint = b.joint_points();
    });
    r.extra
        .insert("joint_fraction".into(), joint as f64 / cloud.len() as f64);
    Ok(r)
}

fn deform_500k(name: &str, method: Method, runs: usize) -> Result<BenchResult> {
    let (cloud, skel) = statue(POINTS)?;
    let binding = Binding::new(&cloud, &skel)?;
    let target = target(&skel);
    let mut scratch = Scratch::default();
    let mut pos = vec![Vec3::ZERO; binding.len()];
    let mut nrm = vec![Vec3::ZERO; binding.len()];
    let mut r = time_it(name, binding.len() as u64, runs, || {
        binding
            .deform(&target, method, &mut scratch, &mut pos, &mut nrm)
            .expect("deform");
    });
    r.extra.insert(
        "points_per_s".into(),
        binding.len() as f64 / r.median_s.max(1e-12),
    );
    Ok(r)
}
