//! Attract mode and the idle reset.
//!
//! [`IdleState`] is driven by the time since the last [`Interaction`] message (from the
//! gestures and the UI), measured with Bevy's [`Time`] (so tests drive it with
//! `TimeUpdateStrategy::ManualDuration`):
//!
//! | idle time `t` | state | what happens |
//! |---|---|---|
//! | `t < idle.attract_after_s` | [`IdleState::Active`] | nothing |
//! | `attract_after_s ≤ t < still_there_after_s` | [`IdleState::Attract`] | the camera orbits slowly ([`AttractConfig::orbit_rad_per_s`]); a [`PoseRequested`] on entering and then every [`AttractConfig::pose_every_s`] (8 s), cycling through `skinning.poses` (without `identity`, unless it is the only one) |
//! | `still_there_after_s ≤ t < still_there_after_s + countdown_s` | [`IdleState::StillThere`] | the "still there?" overlay counts `remaining_s` down; the camera keeps orbiting, no new poses |
//! | `t` reaches the end of the countdown | back to [`IdleState::Active`] | a [`ResetRequested`] is written (home state), the idle clock restarts |
//!
//! **Any interaction** returns to [`IdleState::Active`] at once and restarts the clock.
//! Leaving attract mode (or the countdown) by an interaction **just stops it**: no reset is
//! written, the camera and the pose stay where attract mode left them, so the visitor goes on
//! from what they see. Only the end of the countdown resets.
//!
//! **Reset.** On every [`ResetRequested`] (the end of the countdown, the reset button) this
//! plugin also brings the camera home ([`OrbitCamera::reset`]) and clears the limb
//! [`Selection`]; the statue plugin switches back to the first statue and the animation plugin
//! brings the pose home.

use super::{
    Interaction, KioskSet, OrbitCamera, PoseRequested, ResetRequested, Selection, Settings,
};
use bevy::prelude::*;

/// Idle behaviour.
pub struct AttractPlugin;

/// Where the kiosk is in its idle cycle (see the module docs).
#[derive(Resource, Clone, Copy, Debug, Default, PartialEq)]
pub enum IdleState {
    /// Someone is (or was recently) using the kiosk.
    #[default]
    Active,
    /// Nobody for a while: slow orbit and pose changes.
    Attract,
    /// The "still there?" overlay, `remaining_s` seconds before the reset.
    StillThere { remaining_s: f32 },
}

/// Attract-mode motion (a resource; insert your own before adding the plugin to change it).
#[derive(Resource, Clone, Copy, Debug, PartialEq)]
pub struct AttractConfig {
    /// Orbit speed of the camera in attract mode, radians per second (positive: yaw grows).
    pub orbit_rad_per_s: f32,
    /// Seconds between pose changes in attract mode.
    pub pose_every_s: f32,
}

impl Default for AttractConfig {
    fn default() -> Self {
        AttractConfig {
            orbit_rad_per_s: 0.15,
            pose_every_s: 8.0,
        }
    }
}

/// The idle clock.
#[derive(Resource, Clone, Copy, Debug, Default, PartialEq)]
pub struct IdleClock {
    /// Seconds since the last interaction (or the last reset).
    pub idle_s: f32,
    /// Seconds since attract mode last requested a pose.
    pub since_pose_s: f32,
    /// Next pose of the attract cycle (index into the pose cycle).
    pub next_pose: usize,
}

impl Plugin for AttractPlugin {
    fn build(&self, app: &mut App) {
        app.init_resource::<IdleState>()
            .init_resource::<IdleClock>()
            .init_resource::<AttractConfig>()
            .init_resource::<OrbitCamera>()
            .init_resource::<Selection>()
            .add_message::<Interaction>()
            .add_message::<PoseRequested>()
            .add_message::<ResetRequested>()
            .add_systems(
                Update,
                (track_idle, home_on_reset).chain().in_set(KioskSet::Idle),
            );
    }
}

/// The poses attract mode cycles through: `poses` without `identity` (all of them if that
/// leaves none).
pub fn attract_cycle(poses: &[String]) -> Vec<&str> {
    let shown: Vec<&str> = poses
        .iter()
        .map(String::as_str)
        .filter(|p| *p != "identity")
        .collect();
    if shown.is_empty() {
        poses.iter().map(String::as_str).collect()
    } else {
        shown
    }
}

/// The state for `idle_s` seconds without interaction (before the reset at the end of the
/// countdown).
pub fn idle_state_at(idle_s: f32, idle: &super::config::IdleConfig) -> IdleState {
    if idle_s >= idle.still_there_after_s {
        IdleState::StillThere {
            remaining_s: (idle.still_there_after_s + idle.countdown_s - idle_s).max(0.0),
        }
    } else if idle_s >= idle.attract_after_s {
        IdleState::Attract
    } else {
        IdleState::Active
    }
}

#[allow(clippy::too_many_arguments)]
fn track_idle(
    time: Res<Time>,
    settings: Res<Settings>,
    cfg: Res<AttractConfig>,
    mut interactions: MessageReader<Interaction>,
    mut state: ResMut<IdleState>,
    mut clock: ResMut<IdleClock>,
    mut orbit: ResMut<OrbitCamera>,
    mut poses: MessageWriter<PoseRequested>,
    mut reset: MessageWriter<ResetRequested>,
) {
    let idle = &settings.0.idle;
    if interactions.read().count() > 0 {
        clock.idle_s = 0.0;
        state.set_if_neq(IdleState::Active);
        return;
    }
    let dt = time.delta_secs();
    clock.idle_s += dt;
    if clock.idle_s >= idle.still_there_after_s + idle.countdown_s {
        reset.write(ResetRequested);
        clock.idle_s = 0.0;
        state.set_if_neq(IdleState::Active);
        return;
    }
    let next = idle_state_at(clock.idle_s, idle);
    let entering_attract = next == IdleState::Attract && *state != IdleState::Attract;
    *state = next;
    if matches!(next, IdleState::Active) {
        return;
    }
    // Attract or StillThere: the slow orbit.
    let yaw = orbit.yaw + cfg.orbit_rad_per_s * dt;
    orbit.yaw = if yaw > std::f32::consts::PI {
        yaw - std::f32::consts::TAU
    } else {
        yaw
    };
    if next != IdleState::Attract {
        return;
    }
    clock.since_pose_s += dt;
    if entering_attract || clock.since_pose_s >= cfg.pose_every_s {
        clock.since_pose_s = 0.0;
        let cycle = attract_cycle(&settings.0.skinning.poses);
        if !cycle.is_empty() {
            let name = cycle[clock.next_pose % cycle.len()];
            clock.next_pose = (clock.next_pose + 1) % cycle.len();
            poses.write(PoseRequested(name.to_string()));
        }
    }
}

fn home_on_reset(
    mut reset: MessageReader<ResetRequested>,
    mut orbit: ResMut<OrbitCamera>,
    mut selection: ResMut<Selection>,
) {
    if reset.read().count() == 0 {
        return;
    }
    orbit.reset();
    selection.chain = None;
}
