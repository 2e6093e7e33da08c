//! Pose changes and skinning: a requested pose (pose strip, attract mode, reset) becomes a
//! [`PoseAnimation`] from the current pose to the target, eased over the configured time; every
//! frame the current pose is re-skinned into the statue's [`SkinnedPoints`] buffers (no
//! allocation per frame: the binding writes in place). At exactly the fitted pose the buffers
//! get the statue's own points ([`StatueCloud`]) instead: the scan as it is, bit for bit (a
//! swapped-in restoration and its undo show their point sets exactly).

use super::{
    CurrentPose, FittedSkeleton, KioskSet, PoseAnimation, PoseRequested, ResetRequested, Settings,
    SkinnedPoints, StatueBinding, StatueCloud,
};
use crate::anatomy::Skeleton;
use crate::anatomy::pose::{Pose, ease, interpolate_into};
use crate::skinning::Method;
use bevy::prelude::*;
use std::time::Instant;

/// Pose animation and skinning.
pub struct AnimatePlugin;

/// The skinning method in use (operator panel).
#[derive(Resource, Clone, Copy, Debug, PartialEq, Eq)]
pub struct SkinMethod(pub Method);

/// Skinning work per frame (operator panel, performance test).
#[derive(Resource, Clone, Copy, Debug, Default)]
pub struct SkinWork {
    /// Milliseconds of the last deform.
    pub last_ms: f32,
    /// Largest deform so far, milliseconds.
    pub max_ms: f32,
    /// Deforms done.
    pub count: u64,
}

impl Plugin for AnimatePlugin {
    fn build(&self, app: &mut App) {
        app.init_resource::<SkinWork>()
            .add_systems(Startup, init_method)
            .add_systems(
                Update,
                (request_poses, advance_animations)
                    .chain()
                    .in_set(KioskSet::Animate),
            )
            .add_systems(Update, skin.in_set(KioskSet::Skin));
    }
}

fn init_method(mut commands: Commands, settings: Res<Settings>) {
    commands.insert_resource(SkinMethod(settings.0.skinning.method));
}

fn request_poses(
    mut commands: Commands,
    mut poses: MessageReader<PoseRequested>,
    mut reset: MessageReader<ResetRequested>,
    q: Query<(Entity, &FittedSkeleton, &CurrentPose), With<StatueBinding>>,
    settings: Res<Settings>,
) {
    let mut wanted: Option<String> = poses.read().last().map(|p| p.0.clone());
    if reset.read().count() > 0 {
        wanted = Some("identity".into());
    }
    let Some(name) = wanted else { return };
    let pose = match Pose::resolve(&name) {
        Ok(p) => p,
        Err(e) => {
            warn!("pose '{name}': {e}");
            return;
        }
    };
    for (e, fitted, current) in &q {
        match pose.apply(&fitted.0, &Pose::source_path(&name)) {
            Ok(to) => {
                commands.entity(e).insert(PoseAnimation {
                    from: current.0.clone(),
                    to,
                    elapsed: 0.0,
                    duration: settings.0.skinning.pose_seconds,
                });
            }
            Err(err) => warn!("pose '{name}' does not fit this statue: {err}"),
        }
    }
}

fn advance_animations(
    mut commands: Commands,
    mut q: Query<(Entity, &mut PoseAnimation, &mut CurrentPose)>,
    time: Res<Time>,
) {
    for (e, mut anim, mut current) in &mut q {
        anim.elapsed += time.delta_secs();
        let t = if anim.duration > 0.0 {
            anim.elapsed / anim.duration
        } else {
            1.0
        };
        interpolate_into(&anim.from, &anim.to, ease(t), &mut current.0);
        if t >= 1.0 {
            commands.entity(e).remove::<PoseAnimation>();
        }
    }
}

/// True when two skeletons are the same state, bit for bit.
pub fn same_skeleton(a: &Skeleton, b: &Skeleton) -> bool {
    a.root_position == b.root_position
        && a.root_rotation == b.root_rotation
        && a.block_scale == b.block_scale
        && a.bones == b.bones
}

#[allow(clippy::type_complexity)]
fn skin(
    mut q: Query<
        (
            &StatueBinding,
            &CurrentPose,
            &mut SkinnedPoints,
            Option<&StatueCloud>,
        ),
        Changed<CurrentPose>,
    >,
    method: Option<Res<SkinMethod>>,
    mut work: ResMut<SkinWork>,
) {
    let method = method.map(|m| m.0).unwrap_or_default();
    for (binding, pose, mut points, cloud) in &mut q {
        let start = Instant::now();
        let p = &mut *points;
        // At the fitted pose: the statue's own points.
        if let Some(cloud) = cloud.map(|c| &c.0)
            && cloud.len() == p.positions.len()
            && p.normals.len() == p.positions.len()
            && same_skeleton(&pose.0, binding.0.fitted())
        {
            p.positions.copy_from_slice(&cloud.positions);
            match &cloud.normals {
                Some(n) if n.len() == cloud.len() => p.normals.copy_from_slice(n),
                _ => p.normals.fill(Vec3::Y),
            }
            p.version += 1;
            continue;
        }
        match binding.0.deform(
            &pose.0,
            method,
            &mut p.scratch,
            &mut p.positions,
            &mut p.normals,
        ) {
            Ok(()) => p.version += 1,
            Err(e) => warn!("skinning failed: {e}"),
        }
        let ms = start.elapsed().as_secs_f32() * 1000.0;
        work.last_ms = ms;
        work.max_ms = work.max_ms.max(ms);
        work.count += 1;
    }
}
