//! `pygmalion kiosk`: the museum kiosk in a window (the default command).
//!
//! ```text
//! pygmalion kiosk [--config config/kiosk.toml] [--screenshot OUT.png [--frames N]] [--pose NAME]
//! ```
//!
//! * The configuration never stops the kiosk from starting: a missing or wrong file falls back to
//!   the defaults, and the problems are logged ([`KioskConfig::load`]).
//! * `--pose NAME`: once the statue is ready ([`StatueState::Ready`]), the pose is requested
//!   once, as if a visitor had picked it on the pose strip.
//! * `--screenshot OUT.png`: after `N` frames (`--frames`, default 30), at the first frame where
//!   the statue's points have been on screen for a few frames (and, with `--pose`, the pose has
//!   been requested and its animation has finished, or the statue failed), the primary window is
//!   captured and written to `OUT.png` with the crate's PNG encoder
//!   ([`crate::render::Image::save_png`]); the kiosk then exits. In this mode the window is
//!   windowed at the configured size, pipelines compile synchronously (the first frames are
//!   not blank), attract mode and the idle reset are off (they would turn the camera and undo
//!   the pose), and the run stops with an error if no picture was written after `N + 600`
//!   frames, not counting the frames while a statue is still loading, fitting or binding (a
//!   live fit under a software renderer takes thousands). The mean frame time is printed at
//!   the end.

use crate::error::{Error, Result};
use crate::kiosk::config::KioskConfig;
use crate::kiosk::render::{SplatPoints, capture_rgb};
use crate::kiosk::{KioskPlugin, KioskSet, PoseAnimation, PoseRequested, StatueState};
use bevy::prelude::*;
use bevy::render::RenderPlugin;
use bevy::render::view::screenshot::{Screenshot, ScreenshotCaptured};
use bevy::window::{MonitorSelection, WindowMode, WindowResolution};
use bevy::winit::{UpdateMode, WinitSettings};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// Frames after `--frames` before a screenshot run gives up.
pub const SAFETY_FRAMES: u32 = 600;

/// Frames the statue must have been drawn before the screenshot.
const SETTLE_FRAMES: u32 = 3;

/// The kiosk command's arguments.
#[derive(Clone, Debug)]
pub struct KioskArgs<'a> {
    pub config: &'a Path,
    pub screenshot: Option<&'a Path>,
    pub frames: u32,
    pub pose: Option<&'a str>,
}

/// A pose to request once the statue is ready.
#[derive(Resource, Debug)]
struct PosePlan {
    name: String,
    sent: bool,
}

/// The screenshot run's state.
#[derive(Resource, Debug)]
struct ScreenshotPlan {
    path: PathBuf,
    frames: u32,
    frame: u32,
    settled: u32,
    /// Frames during which a statue was loading, fitting or binding (not counted towards
    /// giving up).
    busy: u32,
    requested: bool,
    result: Arc<Mutex<Option<std::result::Result<(), String>>>>,
    /// Sum and count of frame times (seconds) after the first frames.
    frame_time: (f64, u32),
}

/// Runs the kiosk until its window is closed (or, with a screenshot, until it is written).
pub fn run(args: &KioskArgs) -> Result<()> {
    // Without a graphical session winit cannot open a window: say so instead of panicking.
    #[cfg(target_os = "linux")]
    if ["DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"]
        .iter()
        .all(|v| std::env::var_os(v).is_none_or(|x| x.is_empty()))
    {
        return Err(Error::input(
            "the kiosk needs a display, and none is set (DISPLAY / WAYLAND_DISPLAY). On a machine \
             without a screen run it in a virtual one: `Xvfb :99 & DISPLAY=:99 pygmalion kiosk` \
             (tests/run.sh installs Xvfb and Mesa's software Vulkan). Every other command \
             (picture, film, repose, register, restore, …) works without a display.",
        ));
    }
    let mut config = KioskConfig::load(args.config);
    let screenshot = args.screenshot.map(Path::to_path_buf);
    if screenshot.is_some() {
        // A picture shows the state asked for: attract mode would turn the camera and change
        // the pose, and the reset would undo `--pose`, while a slow machine is still fitting.
        config.idle.attract_after_s = f32::INFINITY;
        config.idle.still_there_after_s = f32::INFINITY;
    }
    if let Some(path) = &screenshot
        && let Some(dir) = path.parent()
        && !dir.as_os_str().is_empty()
        && !dir.is_dir()
    {
        return Err(Error::input(format!(
            "{}: the folder for the screenshot does not exist",
            path.display()
        )));
    }
    let w = &config.window;
    let fullscreen = w.fullscreen && screenshot.is_none();
    let window = Window {
        title: config.texts.title.clone(),
        resolution: WindowResolution::new(w.width.max(1), w.height.max(1)),
        mode: if fullscreen {
            WindowMode::BorderlessFullscreen(MonitorSelection::Primary)
        } else {
            WindowMode::Windowed
        },
        ..default()
    };
    // A machine without a usable GPU driver makes Bevy's renderer panic while starting: turn
    // that into an error that says what to install.
    let run = std::panic::catch_unwind(std::panic::AssertUnwindSafe(move || {
        let mut app = App::new();
        app.add_plugins(
            DefaultPlugins
                .set(WindowPlugin {
                    primary_window: Some(window),
                    ..default()
                })
                .set(RenderPlugin {
                    synchronous_pipeline_compilation: screenshot.is_some(),
                    ..default()
                }),
        )
        .insert_resource(WinitSettings {
            focused_mode: UpdateMode::Continuous,
            unfocused_mode: UpdateMode::Continuous,
        })
        .add_plugins(KioskPlugin {
            config,
            headless: false,
        });
        if let Some(name) = args.pose {
            app.insert_resource(PosePlan {
                name: name.to_string(),
                sent: false,
            })
            .add_systems(Update, request_pose.before(KioskSet::Animate));
        }
        if let Some(path) = screenshot {
            app.insert_resource(ScreenshotPlan {
                path,
                frames: args.frames,
                frame: 0,
                settled: 0,
                busy: 0,
                requested: false,
                result: Arc::new(Mutex::new(None)),
                frame_time: (0.0, 0),
            })
            .add_systems(Update, drive_screenshot.after(KioskSet::Ui));
        }
        app.run()
    }));
    match run {
        Ok(AppExit::Success) => Ok(()),
        Ok(AppExit::Error(code)) => Err(Error::input(format!(
            "the kiosk stopped with an error (code {code})"
        ))),
        Err(panic) => {
            let msg = panic
                .downcast_ref::<String>()
                .map(String::as_str)
                .or_else(|| panic.downcast_ref::<&str>().copied())
                .unwrap_or("unknown failure");
            Err(Error::input(format!(
                "the kiosk could not start its window or graphics ({msg}); a GPU driver or \
                 Mesa's software Vulkan (`apt install mesa-vulkan-drivers`) is needed"
            )))
        }
    }
}

fn request_pose(
    mut plan: ResMut<PosePlan>,
    statues: Query<&StatueState>,
    mut poses: MessageWriter<PoseRequested>,
) {
    if plan.sent {
        return;
    }
    if statues.iter().any(|s| matches!(s, StatueState::Ready)) {
        info!("requesting the pose '{}'", plan.name);
        poses.write(PoseRequested(plan.name.clone()));
        plan.sent = true;
    }
}

#[allow(clippy::too_many_arguments)]
fn drive_screenshot(
    mut commands: Commands,
    mut plan: ResMut<ScreenshotPlan>,
    pose: Option<Res<PosePlan>>,
    drawn: Query<(), With<SplatPoints>>,
    states: Query<&StatueState>,
    animating: Query<(), With<PoseAnimation>>,
    time: Res<Time<Real>>,
    mut exit: MessageWriter<AppExit>,
) {
    plan.frame += 1;
    if plan.frame > 5 {
        plan.frame_time.0 += time.delta_secs_f64();
        plan.frame_time.1 += 1;
    }
    let failed = states
        .iter()
        .any(|s| matches!(s, StatueState::Failed { .. }));
    if states.iter().any(|s| {
        matches!(
            s,
            StatueState::Loading | StatueState::Fitting { .. } | StatueState::Binding
        )
    }) {
        plan.busy += 1;
    }
    let pose_done = match &pose {
        None => true,
        Some(p) => p.sent && animating.is_empty(),
    };
    if failed || (!drawn.is_empty() && pose_done) {
        plan.settled += 1;
    }
    let result = plan.result.lock().ok().and_then(|mut r| r.take());
    match result {
        Some(Ok(())) if plan.path.exists() => {
            let (sum, n) = plan.frame_time;
            if n > 0 {
                println!(
                    "kiosk: {} frames, mean frame time {:.1} ms; screenshot → {}",
                    plan.frame,
                    1000.0 * sum / n as f64,
                    plan.path.display()
                );
            }
            exit.write(AppExit::Success);
            return;
        }
        Some(Ok(())) => {
            error!("the screenshot {} vanished", plan.path.display());
            exit.write(AppExit::error());
            return;
        }
        Some(Err(e)) => {
            error!("the screenshot failed: {e}");
            exit.write(AppExit::error());
            return;
        }
        None => {}
    }
    if !plan.requested && plan.frame >= plan.frames && plan.settled >= SETTLE_FRAMES {
        plan.requested = true;
        let path = plan.path.clone();
        let slot = plan.result.clone();
        commands.spawn(Screenshot::primary_window()).observe(
            move |captured: On<ScreenshotCaptured>| {
                let r = save_capture(&captured.image, &path);
                if let Ok(mut s) = slot.lock() {
                    *s = Some(r);
                }
            },
        );
    }
    if plan.frame
        > plan
            .frames
            .saturating_add(SAFETY_FRAMES)
            .saturating_add(plan.busy)
    {
        error!(
            "no screenshot after {} frames (the statue was {}drawn); giving up",
            plan.frame,
            if drawn.is_empty() { "never " } else { "" }
        );
        exit.write(AppExit::error());
    }
}

fn save_capture(image: &Image, path: &Path) -> std::result::Result<(), String> {
    let (width, height, rgb) = capture_rgb(image)?;
    let picture = crate::render::Image { width, height, rgb };
    picture.save_png(path).map_err(|e| e.to_string())?;
    info!("screenshot saved to {}", path.display());
    Ok(())
}
