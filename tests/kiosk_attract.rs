//! Attract mode, the "still there?" countdown and the idle reset (headless, time driven by
//! `TimeUpdateStrategy::ManualDuration`); the UI's overlay, status line and error card.

use bevy::input::InputPlugin;
use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use pygmalion::anatomy::{Pose, Template};
use pygmalion::fakir::Attempt;
use pygmalion::kiosk::attract::{AttractConfig, AttractPlugin, IdleState, attract_cycle};
use pygmalion::kiosk::config::KioskConfig;
use pygmalion::kiosk::ui::{
    OperatorPanel, POSE_ICON_PX, PoseIcon, UiAction, UiPart, UiPlugin, ascii_fallback,
};
use pygmalion::kiosk::{
    ActiveStatue, Interaction, KioskPlugin, KioskSet, OrbitCamera, PoseRequested, ResetRequested,
    Selection, Settings, Statue, StatueCloud, StatueState,
};
use pygmalion::synth::{SynthOptions, generate};
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

const STEP: f32 = 0.1;

#[derive(Resource, Default)]
struct Log {
    /// (time, pose) of every PoseRequested.
    poses: Vec<(f32, String)>,
    /// Times of every ResetRequested.
    resets: Vec<f32>,
}

fn record(
    time: Res<Time>,
    mut poses: MessageReader<PoseRequested>,
    mut resets: MessageReader<ResetRequested>,
    mut log: ResMut<Log>,
) {
    let t = time.elapsed_secs();
    for p in poses.read() {
        log.poses.push((t, p.0.clone()));
    }
    for _ in resets.read() {
        log.resets.push(t);
    }
}

fn config(attract: f32, still: f32, countdown: f32) -> KioskConfig {
    let mut c = KioskConfig::default();
    c.idle.attract_after_s = attract;
    c.idle.still_there_after_s = still;
    c.idle.countdown_s = countdown;
    c.skinning.poses = ["identity", "greeting", "walking"]
        .map(String::from)
        .to_vec();
    c
}

fn app(config: KioskConfig) -> App {
    app_with(config, |_| {})
}

fn app_with(config: KioskConfig, extra: impl FnOnce(&mut App)) -> App {
    let mut app = App::new();
    app.add_plugins(MinimalPlugins)
        .insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_secs_f32(
            STEP,
        )))
        .insert_resource(Settings(config))
        .add_plugins(AttractPlugin)
        .init_resource::<Log>()
        .add_systems(PostUpdate, record)
        .configure_sets(Update, (KioskSet::Idle, KioskSet::Ui).chain());
    extra(&mut app);
    app.update();
    app
}

fn state(app: &App) -> IdleState {
    *app.world().resource::<IdleState>()
}

fn now(app: &App) -> f32 {
    app.world().resource::<Time>().elapsed_secs()
}

/// Updates until `pred` holds (or `max_s` of game time pass); returns the time it held.
fn run_until(app: &mut App, max_s: f32, pred: impl Fn(&App) -> bool) -> Option<f32> {
    let end = now(app) + max_s;
    while now(app) < end {
        app.update();
        if pred(app) {
            return Some(now(app));
        }
    }
    None
}

#[test]
fn idle_goes_attract_then_still_there_then_resets() {
    let mut app = app(config(2.0, 5.0, 3.0));
    let t0 = now(&app);
    assert_eq!(state(&app), IdleState::Active);
    app.world_mut().resource_mut::<Selection>().chain = Some(3);
    let t_attract = run_until(&mut app, 10.0, |a| state(a) == IdleState::Attract).unwrap();
    assert!(
        ((t_attract - t0) - 2.0).abs() <= STEP + 1e-3,
        "attract at {t_attract}"
    );
    let yaw_at_attract = app.world().resource::<OrbitCamera>().yaw;
    let t_still = run_until(&mut app, 10.0, |a| {
        matches!(state(a), IdleState::StillThere { .. })
    })
    .unwrap();
    assert!(
        ((t_still - t0) - 5.0).abs() <= STEP + 1e-3,
        "still there at {t_still}"
    );
    // The camera orbits slowly in attract mode.
    let yaw = app.world().resource::<OrbitCamera>().yaw;
    let speed = AttractConfig::default().orbit_rad_per_s;
    assert!(
        ((yaw - yaw_at_attract) - speed * (t_still - t_attract)).abs() < 2.0 * STEP * speed,
        "yaw {yaw_at_attract} → {yaw}"
    );
    // The countdown counts down.
    let IdleState::StillThere { remaining_s: r0 } = state(&app) else {
        unreachable!()
    };
    assert!((r0 - 3.0).abs() <= STEP + 1e-3);
    app.update();
    let IdleState::StillThere { remaining_s: r1 } = state(&app) else {
        panic!("still counting")
    };
    assert!((r0 - r1 - STEP).abs() < 1e-3, "{r0} → {r1}");
    assert!(app.world().resource::<Log>().resets.is_empty());
    // At zero: a reset, home view, nothing selected, back to Active.
    let t_reset = run_until(&mut app, 10.0, |a| state(a) == IdleState::Active).unwrap();
    assert!(
        ((t_reset - t0) - 8.0).abs() <= STEP + 1e-3,
        "reset at {t_reset}"
    );
    assert_eq!(app.world().resource::<Log>().resets, [t_reset]);
    let o = *app.world().resource::<OrbitCamera>();
    assert_eq!((o.yaw, o.pitch, o.distance), o.home);
    assert_eq!(app.world().resource::<Selection>().chain, None);
    // And the cycle starts over.
    let again = run_until(&mut app, 10.0, |a| state(a) == IdleState::Attract).unwrap();
    assert!(((again - t_reset) - 2.0).abs() <= STEP + 1e-3);
}

#[test]
fn attract_mode_cycles_through_the_poses() {
    let mut app = app(config(1.0, 40.0, 5.0));
    run_until(&mut app, 30.0, |a| now(a) >= 28.0);
    let log = app.world().resource::<Log>();
    let names: Vec<&str> = log.poses.iter().map(|(_, n)| n.as_str()).collect();
    // On entering (t ≈ 1), then every 8 s; identity is left out of the cycle.
    assert_eq!(names, ["greeting", "walking", "greeting", "walking"]);
    for w in log.poses.windows(2) {
        assert!(
            ((w[1].0 - w[0].0) - 8.0).abs() <= STEP + 1e-3,
            "{:?}",
            log.poses
        );
    }
    assert!((log.poses[0].0 - 1.0).abs() <= 2.0 * STEP);
    let only = ["identity".to_string()];
    let cycle = attract_cycle(&only);
    assert_eq!(cycle, ["identity"], "identity alone still cycles");
}

#[test]
fn any_interaction_returns_to_active_without_a_reset() {
    let mut app = app(config(1.0, 3.0, 4.0));
    // From attract mode.
    run_until(&mut app, 5.0, |a| state(a) == IdleState::Attract).unwrap();
    run_until(&mut app, 0.5, |_| false);
    let yaw = app.world().resource::<OrbitCamera>().yaw;
    assert!(yaw > 0.0, "orbiting");
    app.world_mut().write_message(Interaction);
    app.update();
    assert_eq!(state(&app), IdleState::Active);
    // Leaving attract just stops it: the view stays where it was.
    let yaw_after = app.world().resource::<OrbitCamera>().yaw;
    assert!((yaw_after - yaw).abs() < 1e-6);
    app.update();
    assert_eq!(app.world().resource::<OrbitCamera>().yaw, yaw_after);
    // From the countdown.
    run_until(&mut app, 5.0, |a| {
        matches!(state(a), IdleState::StillThere { .. })
    })
    .unwrap();
    run_until(&mut app, 2.0, |_| false);
    app.world_mut().write_message(Interaction);
    app.update();
    assert_eq!(state(&app), IdleState::Active);
    // While active, interactions keep it active.
    for _ in 0..30 {
        app.world_mut().write_message(Interaction);
        run_until(&mut app, 0.5, |_| false);
        assert_eq!(state(&app), IdleState::Active);
    }
    assert!(app.world().resource::<Log>().resets.is_empty());
}

/// The width of the progress bar's fill.
fn fill_width(app: &mut App) -> Val {
    let mut q = app.world_mut().query::<(&UiPart, &Node)>();
    let w: Vec<Val> = q
        .iter(app.world())
        .filter(|(p, _)| **p == UiPart::ProgressFill)
        .map(|(_, n)| n.width)
        .collect();
    assert_eq!(w.len(), 1);
    w[0]
}

/// Each pose button's pictogram: pose name → ((width, height), RGBA bytes).
fn pose_pictures(app: &mut App) -> HashMap<String, ((u32, u32), Vec<u8>)> {
    let mut q = app.world_mut().query::<(&PoseIcon, &ImageNode)>();
    let handles: Vec<(String, Handle<Image>)> = q
        .iter(app.world())
        .map(|(p, n)| (p.0.clone(), n.image.clone()))
        .collect();
    let images = app.world().resource::<Assets<Image>>();
    handles
        .into_iter()
        .map(|(pose, h)| {
            let img = images
                .get(&h)
                .unwrap_or_else(|| panic!("{pose}: no picture"));
            let size = (img.width(), img.height());
            (pose, (size, img.data.clone().expect("pixels on the CPU")))
        })
        .collect()
}

/// The rest figure as the kiosk draws it.
fn rest_figure() -> Vec<u8> {
    let human = Arc::new(Template::builtin("human").unwrap());
    pygmalion::render::pose_pictogram(
        &Pose::builtin("rest").unwrap(),
        human,
        &pygmalion::kiosk::ui::pose_icon_options(),
    )
    .unwrap()
    .rgba
}

fn texts_of(app: &mut App, part: UiPart) -> Vec<String> {
    let mut q = app.world_mut().query::<(&UiPart, &Text)>();
    q.iter(app.world())
        .filter(|(p, _)| **p == part)
        .map(|(_, t)| t.0.clone())
        .collect()
}

fn visible(app: &mut App, part: UiPart) -> bool {
    let mut q = app.world_mut().query::<(&UiPart, &Visibility)>();
    let v: Vec<Visibility> = q
        .iter(app.world())
        .filter(|(p, _)| **p == part)
        .map(|(_, v)| *v)
        .collect();
    assert_eq!(v.len(), 1, "{part:?}");
    v[0] != Visibility::Hidden
}

#[test]
fn ui_shows_the_countdown_status_and_error_card() {
    let config = config(1.0, 3.0, 4.0);
    let poses = config.skinning.poses.clone();
    let texts = config.texts.clone();
    let titles: Vec<String> = config.statues.iter().map(|s| s.title.clone()).collect();
    let mut app = app_with(config, |app| {
        app.insert_resource(ActiveStatue {
            index: 1,
            entity: None,
        })
        // Image assets (no asset plugin here) for the pose pictograms.
        .init_resource::<Assets<Image>>()
        .add_plugins(UiPlugin { headless: false });
    });
    let statue = app
        .world_mut()
        .spawn((
            Statue {
                index: 1,
                title: titles[1].clone(),
            },
            StatueState::Fitting {
                units: 17,
                fraction: 0.4271,
                attempt: Attempt::Whole,
            },
        ))
        .id();
    app.world_mut().resource_mut::<ActiveStatue>().entity = Some(statue);
    app.update();
    // One big button per pose, with friendly names.
    let mut q = app.world_mut().query::<&UiAction>();
    let pose_buttons: Vec<UiAction> = q
        .iter(app.world())
        .filter(|a| matches!(a, UiAction::Pose(_)))
        .cloned()
        .collect();
    assert_eq!(pose_buttons.len(), poses.len());
    assert_eq!(texts_of(&mut app, UiPart::StatueTitle), [titles[1].clone()]);
    let status = texts_of(&mut app, UiPart::StatusText);
    // No font assets headless: the built-in font, with its ASCII fallback. The share done as
    // a percentage (rounded down), not the work units, and the bar filled as much.
    assert_eq!(status, [ascii_fallback(&format!("{} 42%", texts.fitting))]);
    assert!(visible(&mut app, UiPart::Status));
    assert!(visible(&mut app, UiPart::ProgressTrack));
    assert_eq!(fill_width(&mut app), Val::Percent(42.0));
    // Every pose button has its pictogram: an image of the pictogram's size with the figure
    // on a transparent background, a different one per pose.
    let pictures = pose_pictures(&mut app);
    assert_eq!(pictures.len(), poses.len());
    for (pose, (size, rgba)) in &pictures {
        assert_eq!(*size, POSE_ICON_PX, "{pose}");
        let ink = rgba.chunks_exact(4).filter(|p| p[3] > 128).count();
        let clear = rgba.chunks_exact(4).filter(|p| p[3] == 0).count();
        let n = rgba.len() / 4;
        assert!(
            ink * 20 > n && clear * 2 > n,
            "{pose}: ink {ink}, clear {clear} of {n}"
        );
    }
    for (a, pa) in &pictures {
        for (b, pb) in &pictures {
            assert!(a == b || pa.1 != pb.1, "{a} and {b} look the same");
        }
    }
    // "Original" shows the rest figure until the statue is loaded, then the statue itself
    // (its cloud from the front).
    assert_eq!(pictures["identity"].1, rest_figure());
    let human = Arc::new(Template::builtin("human").unwrap());
    let synth = generate(
        human,
        &SynthOptions {
            points: 4000,
            seed: 3,
            ..Default::default()
        },
    )
    .unwrap();
    app.world_mut()
        .entity_mut(statue)
        .insert(StatueCloud(Arc::new(synth.cloud)));
    app.update();
    let original = pose_pictures(&mut app)["identity"].1.clone();
    let ink = original.chunks_exact(4).filter(|p| p[3] > 0).count();
    assert!(
        ink * 20 > original.len() / 4,
        "the statue's picture is empty"
    );
    assert_ne!(original, pictures["identity"].1);
    // The other buttons keep their pictograms.
    assert_eq!(pose_pictures(&mut app)["walking"], pictures["walking"]);

    assert!(!visible(&mut app, UiPart::ErrorCard));
    assert!(!visible(&mut app, UiPart::StillThere));
    assert!(!visible(&mut app, UiPart::OperatorPanel));
    // The countdown overlay.
    run_until(&mut app, 5.0, |a| {
        matches!(state(a), IdleState::StillThere { .. })
    })
    .unwrap();
    run_until(&mut app, 0.55, |_| false);
    assert!(visible(&mut app, UiPart::StillThere));
    let IdleState::StillThere { remaining_s } = state(&app) else {
        unreachable!()
    };
    let shown = texts_of(&mut app, UiPart::Countdown);
    assert_eq!(shown, [format!("{}", remaining_s.ceil() as u32)]);
    assert_eq!(
        texts_of(&mut app, UiPart::StillThereText),
        std::slice::from_ref(&texts.still_there)
    );
    app.world_mut().write_message(Interaction);
    app.update();
    assert!(!visible(&mut app, UiPart::StillThere));
    // A failed statue: the gentle card, no status line; the operator sees the message.
    *app.world_mut().get_mut::<StatueState>(statue).unwrap() = StatueState::Failed {
        message: "cannot read x.ply".into(),
    };
    app.world_mut().resource_mut::<OperatorPanel>().open = true;
    app.update();
    assert!(visible(&mut app, UiPart::ErrorCard));
    assert!(!visible(&mut app, UiPart::Status));
    assert!(visible(&mut app, UiPart::OperatorPanel));
    assert_eq!(
        texts_of(&mut app, UiPart::ErrorText),
        std::slice::from_ref(&texts.load_failed)
    );
    let problems = texts_of(&mut app, UiPart::Problems).join("");
    assert!(problems.contains("cannot read x.ply"), "{problems}");
}

#[test]
fn whole_kiosk_runs_headless_with_a_missing_statue() {
    let mut config = config(1.0, 2.0, 1.0);
    config.assets_root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests");
    config.statues.truncate(1);
    config.statues[0].file = PathBuf::from("no_such_statue.ply");
    config.cache_dir =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/test-scratch/kiosk_attract");
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, InputPlugin))
        .insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_secs_f32(
            STEP,
        )))
        .add_plugins(KioskPlugin {
            config,
            headless: true,
        })
        .init_resource::<Log>()
        .add_systems(PostUpdate, record);
    let failed = |a: &mut App| {
        let mut q = a.world_mut().query::<&StatueState>();
        q.iter(a.world())
            .any(|s| matches!(s, StatueState::Failed { .. }))
    };
    let mut ok = false;
    for _ in 0..200 {
        app.update();
        if failed(&mut app) {
            ok = true;
            break;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    assert!(ok, "the missing statue fails gently");
    // The idle cycle runs in the full kiosk too: a reset after 3 s without interaction.
    run_until(&mut app, 5.0, |a| {
        !a.world().resource::<Log>().resets.is_empty()
    });
    assert!(!app.world().resource::<Log>().resets.is_empty());
}
