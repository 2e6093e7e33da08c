//! Benchmark of the kiosk's per-frame CPU work while a statue animates: a headless app
//! (`MinimalPlugins` + the kiosk's plugins without rendering) holds a 500k-point synthetic
//! statue, ready (fitted and bound), and animates it to the `greeting` pose; each timed body is
//! one `app.update()` — every kiosk system of the frame, skinning included (baseline).
//! `extra.skin_ms` is the skinning system's share (last frame). `kiosk/splat_pack_500k` times
//! what the renderer adds on the CPU when the points move: packing them for the GPU.

use super::{BenchResult, Entry, time_it};
use crate::anatomy::Skeleton;
use crate::cloud::PointCloud;
use crate::error::Result;
use crate::kiosk::animate::SkinWork;
use crate::kiosk::config::KioskConfig;
use crate::kiosk::render::{SPLAT_POINT_BYTES, pack_points};
use crate::kiosk::{
    ActiveStatue, CurrentPose, FittedSkeleton, KioskPlugin, PoseRequested, SkinnedPoints, Statue,
    StatueBinding, StatueCloud, StatueState,
};
use crate::skinning::{Binding, Scratch};
use bevy::prelude::*;
use std::sync::Arc;

pub(super) fn entries() -> Vec<Entry> {
    vec![
        Entry {
            name: "kiosk/animate_500k",
            run: animate_500k,
        },
        Entry {
            name: "kiosk/splat_pack_500k",
            run: splat_pack_500k,
        },
    ]
}

/// The renderer's CPU share of a moving frame: packing 500k skinned points (centre and normal)
/// into the splats' staging bytes ([`pack_points`]), which are then handed to the GPU queue.
fn splat_pack_500k(runs: usize) -> Result<BenchResult> {
    let (cloud, _) = super::skin::statue(500_000)?;
    let points = SkinnedPoints {
        normals: cloud.normals.clone().unwrap_or_default(),
        positions: cloud.positions,
        colors: None,
        version: 1,
        scratch: Scratch::default(),
    };
    let mut staging = vec![0u8; SPLAT_POINT_BYTES * points.positions.len()];
    let mut ok = true;
    let r = time_it(
        "kiosk/splat_pack_500k",
        points.positions.len() as u64,
        runs,
        || {
            ok &= pack_points(&mut staging, &points, None);
        },
    );
    if !ok {
        return Err(crate::Error::input(
            "kiosk/splat_pack_500k: the points were not packed",
        ));
    }
    Ok(r)
}

/// Spawns `cloud` as the kiosk's active statue, ready: fitted to `skel`, bound, at rest.
pub(super) fn ready_statue(
    app: &mut App,
    cloud: &Arc<PointCloud>,
    skel: &Skeleton,
    binding: Arc<Binding>,
) -> Entity {
    let e = app
        .world_mut()
        .spawn((
            Statue {
                index: 0,
                title: "bench".into(),
            },
            StatueState::Ready,
            StatueCloud(cloud.clone()),
            FittedSkeleton(skel.clone()),
            CurrentPose(skel.clone()),
            StatueBinding(binding),
            SkinnedPoints {
                positions: cloud.positions.clone(),
                normals: cloud.normals.clone().unwrap_or_default(),
                colors: None,
                version: 1,
                scratch: Scratch::default(),
            },
            Transform::default(),
            Visibility::default(),
        ))
        .id();
    app.world_mut().resource_mut::<ActiveStatue>().entity = Some(e);
    e
}

fn animate_500k(runs: usize) -> Result<BenchResult> {
    let (cloud, skel) = super::skin::statue(500_000)?;
    let binding = Arc::new(Binding::new(&cloud, &skel)?);
    let mut config = KioskConfig::default();
    // A long pose change, so every timed frame animates and re-skins.
    config.skinning.pose_seconds = 1.0e6;
    let mut app = App::new();
    app.add_plugins((
        MinimalPlugins,
        bevy::input::InputPlugin,
        KioskPlugin {
            config,
            headless: true,
        },
    ));
    let cloud = Arc::new(cloud);
    ready_statue(&mut app, &cloud, &skel, binding);
    app.update();
    app.world_mut()
        .write_message(PoseRequested("greeting".into()));
    app.update();
    let mut r = time_it("kiosk/animate_500k", cloud.len() as u64, runs, || {
        app.update();
    });
    r.extra.insert(
        "skin_ms".into(),
        app.world().resource::<SkinWork>().last_ms as f64,
    );
    Ok(r)
}
