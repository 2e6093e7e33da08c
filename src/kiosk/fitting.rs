//! Incremental FAKIR in the frame loop: each frame the statue's [`Registration`] runs for at
//! most the configured budget (it stops at the first work-unit boundary after it), and the
//! statue's [`CurrentPose`] shows the skeleton as it is — visitors watch the bones move,
//! stretch and settle onto the statue. The statue's [`StatueState::Fitting`] carries the work
//! units done (for the operator) and FAKIR's estimate of the share done
//! (`Progress.activity.fraction`, held never decreasing), which the status line shows as a
//! percentage. When FAKIR registers the figure a second time without limbs it found lost
//! (`Progress.attempt`: a bust, an armless figure), the state says so and the share starts
//! again from 0: the status line then reads `texts.fitting_again`, and visitors watch the
//! skeleton settle in once more, without those limbs. When the fit is done the binding is
//! built off the main thread and both are cached ([`super::statue::write_cache`]).

use super::statue::{CacheKey, Pending, StatueTemplate, write_cache};
use super::{
    CurrentPose, FittedSkeleton, KioskSet, Settings, StatueBinding, StatueCloud, StatueState,
};
use crate::error::Result;
use crate::fakir::Registration;
use crate::skinning::Binding;
use bevy::prelude::*;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Incremental registration, `budget_ms` of work per frame.
pub struct FittingPlugin {
    pub budget_ms: f32,
}

/// A statue's running registration.
#[derive(Component)]
pub struct Fitter(pub Mutex<Registration>);

/// Registration work per frame (what the budget test and the operator panel read).
#[derive(Resource, Clone, Copy, Debug, Default)]
pub struct FitWork {
    /// The budget, milliseconds.
    pub budget_ms: f32,
    /// Work of the last frame that fitted, milliseconds.
    pub last_ms: f32,
    /// Largest work of one frame so far, milliseconds.
    pub max_ms: f32,
    /// Frames that did registration work.
    pub frames: u64,
    /// Work units of all frames so far.
    pub units: u64,
    /// Most work units one frame ran.
    pub max_units: u64,
}

impl Plugin for FittingPlugin {
    fn build(&self, app: &mut App) {
        app.insert_resource(FitWork {
            budget_ms: self.budget_ms,
            ..Default::default()
        })
        .add_systems(
            Update,
            (start_fitting, step_fitting, finish_binding)
                .chain()
                .in_set(KioskSet::Register),
        );
    }
}

#[allow(clippy::type_complexity)]
fn start_fitting(
    mut commands: Commands,
    mut q: Query<
        (Entity, &mut StatueState, &StatueCloud, &StatueTemplate),
        (Without<Fitter>, Without<FittedSkeleton>),
    >,
) {
    for (e, mut state, cloud, t) in &mut q {
        if !matches!(*state, StatueState::Fitting { .. }) {
            continue;
        }
        match Registration::new(cloud.0.clone(), t.template.clone(), t.fit_options.clone()) {
            Ok(reg) => {
                commands.entity(e).insert(Fitter(Mutex::new(reg)));
            }
            Err(err) => {
                warn!("the statue cannot be fitted: {err}");
                *state = StatueState::Failed {
                    message: err.to_string(),
                };
            }
        }
    }
}

#[allow(clippy::type_complexity)]
fn step_fitting(
    mut commands: Commands,
    mut q: Query<(
        Entity,
        &mut StatueState,
        &Fitter,
        Option<&mut CurrentPose>,
        &StatueCloud,
        &CacheKey,
    )>,
    mut work: ResMut<FitWork>,
    settings: Res<Settings>,
) {
    let budget = Duration::from_secs_f32(work.budget_ms.max(0.1) / 1000.0);
    for (e, mut state, fitter, pose, cloud, key) in &mut q {
        let Ok(mut reg) = fitter.0.lock() else {
            continue;
        };
        let start = Instant::now();
        let units_before = reg.progress().units;
        let progress = reg.step(budget);
        let ms = start.elapsed().as_secs_f32() * 1000.0;
        work.last_ms = ms;
        work.max_ms = work.max_ms.max(ms);
        work.frames += 1;
        let units = progress.units.saturating_sub(units_before);
        work.units += units;
        work.max_units = work.max_units.max(units);
        if let Some(s) = progress.skeleton {
            match pose {
                Some(mut p) => p.0 = s,
                None => {
                    commands.entity(e).insert(CurrentPose(s));
                }
            }
        }
        // FAKIR's fraction never decreases within an attempt; the kiosk holds to that whatever
        // happens, and starts again from 0 only when a second attempt begins.
        let shown = match *state {
            StatueState::Fitting {
                fraction, attempt, ..
            } if attempt == progress.attempt => fraction,
            _ => 0.0,
        };
        *state = StatueState::Fitting {
            units: progress.units,
            fraction: progress.activity.fraction.clamp(0.0, 1.0).max(shown),
            attempt: progress.attempt,
        };
        if !reg.is_done() {
            continue;
        }
        let result = reg.take_result();
        drop(reg);
        let mut ec = commands.entity(e);
        ec.remove::<Fitter>();
        match result {
            Some(Ok(fit)) => {
                info!(
                    "fitted in {} work units, mean distance {:.4}",
                    fit.units, fit.mean_distance
                );
                let skel = fit.skeleton.clone();
                ec.insert((CurrentPose(skel.clone()), FittedSkeleton(skel.clone())));
                let cloud = cloud.0.clone();
                let dir = settings.0.cache_dir.clone();
                let key = key.0.clone();
                // The base (plinth), when registration found one, stays put when posing.
                let base = fit.base.map(|b| b.points).unwrap_or_default();
                // Lost limbs (completed by the registration) bind no point.
                let lost = fit.missing;
                ec.insert(Pending::spawn(move || -> Result<Binding> {
                    let b = Binding::new_without(&cloud, &skel, &lost)?.with_base(&base)?;
                    write_cache(&dir, &key, &skel, &b);
                    Ok(b)
                }));
                *state = StatueState::Binding;
            }
            Some(Err(err)) => {
                warn!("the statue could not be fitted: {err}");
                *state = StatueState::Failed {
                    message: err.to_string(),
                };
            }
            None => {}
        }
    }
}

fn finish_binding(
    mut commands: Commands,
    mut q: Query<(Entity, &mut StatueState, &Pending<Result<Binding>>)>,
) {
    for (e, mut state, pending) in &mut q {
        let Some(r) = pending.take() else { continue };
        let mut ec = commands.entity(e);
        ec.remove::<Pending<Result<Binding>>>();
        match r {
            Ok(b) => {
                ec.insert(StatueBinding(Arc::new(b)));
                *state = StatueState::Ready;
            }
            Err(err) => {
                warn!("the statue could not be bound: {err}");
                *state = StatueState::Failed {
                    message: err.to_string(),
                };
            }
        }
    }
}
