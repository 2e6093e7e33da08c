//! Benchmarks of the kiosk's whole frame on the GPU: the kiosk's plugins with Bevy's real
//! renderer, no window, drawing into an off-screen image of 1920 × 1080 (a museum touchscreen),
//! a 1,000,000-point synthetic statue (all of it drawn: the point budget is lifted), fitted and
//! bound.
//!
//! - `render/kiosk_1m`: the statue animates towards the `greeting` pose the whole time (a pose
//!   change stretched over 10⁶ s), so every frame re-skins the million points, packs them and
//!   writes them to the splats' storage buffer: the frame a visitor sees while a statue moves.
//! - `render/kiosk_1m_still`: the same statue standing still: drawing alone.
//!
//! ## Method
//! The app is pumped by hand (no window, no winit: Bevy's `externally_driven_headless_renderer`
//! pattern). Before timing, frames are run until the splats are drawn, then 5 more (pipelines
//! compiled, buffers allocated). One timed body is one frame: `App::update` followed by a wait
//! until the GPU has finished everything submitted so far (`PollType::Wait`). Rendering is
//! pipelined as in the kiosk (frame `k` renders while frame `k + 1` updates), so the body's time
//! is the period at which frames come out — `1 / fps` — not one frame's latency. The median is
//! over `runs` frames.
//!
//! `extra`: `fps` (1 / median), `update_ms` (median of `App::update` alone: the main world's
//! systems plus any wait for the render world, still busy with the frame before, to come back
//! for extraction), `skin_ms` (the skinning system, last frame), `points` drawn, and
//! `statue_fraction`, the share of the scene band's pixels (the rows between the kiosk's top
//! bar and its pose strip) that are not background in a screenshot taken after the timed
//! frames — the check that the frames timed did draw the statue (an empty picture is an
//! error, not a figure). The adapter's name goes to standard error. With the environment
//! variable `PYGMALION_BENCH_PICTURES` naming a folder, that screenshot is saved there as
//! `render_kiosk_1m.png` (…), to look at.
//!
//! These benchmarks need a GPU (Mesa's software Vulkan runs them, at about 0.6 s a frame on a
//! 2-core machine): `pygmalion bench` leaves them out unless `--only` names them
//! (`--only render/`). Their harness, [`Offscreen`], also serves the rendering tests.

use super::{BenchResult, Entry};
use crate::anatomy::Skeleton;
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::kiosk::animate::SkinWork;
use crate::kiosk::config::{KioskConfig, StatueEntry};
use crate::kiosk::render::{KioskCamera, SplatPoints, capture_rgb};
use crate::kiosk::statue::frame_camera;
use crate::kiosk::{KioskPlugin, OrbitCamera, PoseRequested, SceneMargins};
use crate::skinning::Binding;
use bevy::asset::RenderAssetUsages;
use bevy::camera::RenderTarget;
use bevy::log::LogPlugin;
use bevy::prelude::*;
use bevy::render::RenderPlugin;
use bevy::render::render_resource::{
    Extent3d, PollType, TextureDimension, TextureFormat, TextureUsages,
};
use bevy::render::renderer::{RenderAdapterInfo, RenderDevice};
use bevy::render::view::screenshot::{Screenshot, ScreenshotCaptured};
use bevy::window::ExitCondition;
use bevy::winit::WinitPlugin;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// Points of the benchmark statue.
pub const POINTS: usize = 1_000_000;
/// The off-screen image, pixels.
pub const SIZE: (u32, u32) = (1920, 1080);
/// Most frames waited for the splats to appear or a screenshot to come back.
const PATIENCE: usize = 200;

pub(super) fn entries() -> Vec<Entry> {
    vec![
        Entry {
            name: "render/kiosk_1m",
            run: |runs| frames("render/kiosk_1m", POINTS, runs, true),
        },
        Entry {
            name: "render/kiosk_1m_still",
            run: |runs| frames("render/kiosk_1m_still", POINTS, runs, false),
        },
    ]
}

/// The kiosk's plugins with Bevy's renderer and no window, drawing into an off-screen image of
/// [`SIZE`], pumped by hand (Bevy's `externally_driven_headless_renderer` pattern); the
/// benchmarks' harness, and the tests'.
pub struct Offscreen {
    pub app: App,
    /// The image the kiosk's camera draws into.
    pub target: Handle<Image>,
}

impl Offscreen {
    /// A kiosk configured by `config` (its window size is replaced by [`SIZE`], its statues by
    /// this one, its idle timeouts by never: attract mode would turn the camera) showing
    /// `cloud`,
    /// fitted to `skel` and bound, framed as the kiosk frames a statue; one frame has run.
    /// Errors (labelled `name`): no GPU adapter, no camera.
    pub fn new(
        name: &str,
        mut config: KioskConfig,
        cloud: &Arc<PointCloud>,
        skel: &Skeleton,
        binding: Arc<Binding>,
    ) -> Result<Offscreen> {
        config.window.width = SIZE.0;
        config.window.height = SIZE.1;
        config.idle.attract_after_s = f32::INFINITY;
        config.idle.still_there_after_s = f32::INFINITY;
        // The carousel lists the statue shown (no other statue is loaded or lends parts).
        config.statues = vec![StatueEntry {
            file: "synthetic.ply".into(),
            template: skel.template.name.clone(),
            title: "Synthetic statue".into(),
            credit: format!("{} points", cloud.len()),
            up: None,
            front: None,
            missing: Vec::new(),
        }];
        // Bevy's log plugin sets a global logger: only the first app of the process may add it.
        static LOGGING: AtomicBool = AtomicBool::new(false);
        let mut plugins = DefaultPlugins.build();
        if LOGGING.swap(true, Ordering::SeqCst) {
            plugins = plugins.disable::<LogPlugin>();
        }
        let mut app = App::new();
        app.add_plugins(
            plugins
                .set(WindowPlugin {
                    primary_window: None,
                    exit_condition: ExitCondition::DontExit,
                    ..default()
                })
                .set(RenderPlugin {
                    synchronous_pipeline_compilation: true,
                    ..default()
                })
                .disable::<WinitPlugin>(),
        )
        .add_plugins(KioskPlugin {
            config,
            headless: false,
        });
        // Pumped by hand: `App::run` would have finished the plugins.
        app.finish();
        app.cleanup();
        if !app.world().contains_resource::<RenderDevice>() {
            return Err(Error::input(format!(
                "{name}: no GPU adapter (a Vulkan driver or Mesa's software Vulkan is needed)"
            )));
        }
        if let Some(info) = app.world().get_resource::<RenderAdapterInfo>() {
            eprintln!(
                "{name}: adapter {} ({:?}, {:?}), {}×{} off-screen",
                info.name, info.device_type, info.backend, SIZE.0, SIZE.1
            );
        }
        let target = {
            let mut image = Image::new_uninit(
                Extent3d {
                    width: SIZE.0,
                    height: SIZE.1,
                    depth_or_array_layers: 1,
                },
                TextureDimension::D2,
                TextureFormat::Rgba8UnormSrgb,
                RenderAssetUsages::RENDER_WORLD,
            );
            image.texture_descriptor.usage |= TextureUsages::RENDER_ATTACHMENT
                | TextureUsages::COPY_SRC
                | TextureUsages::TEXTURE_BINDING;
            app.world_mut().resource_mut::<Assets<Image>>().add(image)
        };
        super::kiosk::ready_statue(&mut app, cloud, skel, binding);
        {
            let margins = *app.world().resource::<SceneMargins>();
            let mut orbit = app.world_mut().resource_mut::<OrbitCamera>();
            frame_camera(
                &mut orbit,
                cloud,
                Vec2::new(SIZE.0 as f32, SIZE.1 as f32),
                margins,
            );
        }
        // The first frame spawns the camera (Startup); it then draws into the image.
        app.update();
        let cameras: Vec<Entity> = app
            .world_mut()
            .query_filtered::<Entity, With<KioskCamera>>()
            .iter(app.world())
            .collect();
        if cameras.is_empty() {
            return Err(Error::input(format!("{name}: the kiosk spawned no camera")));
        }
        for c in cameras {
            app.world_mut()
                .entity_mut(c)
                .insert(RenderTarget::Image(target.clone().into()));
        }
        Ok(Offscreen { app, target })
    }

    /// [`Offscreen::new`] on the benchmarks' synthetic statue of `points` points (seed 42,
    /// fitted to its ground truth and bound).
    pub fn synthetic(name: &str, points: usize, config: KioskConfig) -> Result<Offscreen> {
        let (cloud, skel) = super::skin::statue(points)?;
        let binding = Arc::new(Binding::new(&cloud, &skel)?);
        Offscreen::new(name, config, &Arc::new(cloud), &skel, binding)
    }

    /// Waits until the GPU has finished everything submitted so far.
    pub fn wait(&self) {
        let _ = self
            .app
            .world()
            .resource::<RenderDevice>()
            .wgpu_device()
            .poll(PollType::Wait {
                submission_index: None,
                timeout: None,
            });
    }

    /// One frame, up to the GPU having finished it.
    pub fn frame(&mut self) {
        self.app.update();
        self.wait();
    }

    /// Frames until the statue's splats exist and show in a screenshot; the number of points
    /// drawn. Errors (labelled `name`) when they never appear. The splats can exist some
    /// frames before they show: the renderer compiles their pipeline in the background, and
    /// on a loaded machine under software Vulkan a first screenshot once showed only the
    /// background (`statue_fraction` 0).
    pub fn until_drawn(&mut self, name: &str) -> Result<usize> {
        for _ in 0..PATIENCE {
            self.frame();
            if let Ok(p) = self
                .app
                .world_mut()
                .query::<&SplatPoints>()
                .single(self.app.world())
            {
                let count = p.count;
                for _ in 0..PATIENCE {
                    if statue_fraction(self, name)? > 0.0 {
                        return Ok(count);
                    }
                }
                return Err(Error::input(format!(
                    "{name}: the statue's splats never showed on the screen"
                )));
            }
        }
        Err(Error::input(format!(
            "{name}: the statue's splats never appeared"
        )))
    }
}

/// Times `runs` frames of the kiosk drawing a synthetic statue of `points` points off-screen,
/// animating it when `animate` (see the module docs); `name` labels the result and the errors.
pub fn frames(name: &str, points: usize, runs: usize, animate: bool) -> Result<BenchResult> {
    let mut config = KioskConfig::default();
    config.budget.point_budget = points;
    config.skinning.pose_seconds = 1.0e6;
    let mut view = Offscreen::synthetic(name, points, config)?;
    if animate {
        view.app
            .world_mut()
            .write_message(PoseRequested("greeting".into()));
    }
    let drawn = view.until_drawn(name)?;
    for _ in 0..5 {
        view.frame();
    }

    let runs = runs.max(1);
    let skinned_before = view.app.world().resource::<SkinWork>().count;
    let mut period = Vec::with_capacity(runs);
    let mut cpu = Vec::with_capacity(runs);
    for _ in 0..runs {
        let t = Instant::now();
        view.app.update();
        cpu.push(t.elapsed().as_secs_f64());
        view.wait();
        period.push(t.elapsed().as_secs_f64());
    }
    let skin_ms = view.app.world().resource::<SkinWork>().last_ms as f64;
    let moved = view.app.world().resource::<SkinWork>().count - skinned_before;

    let fraction = statue_fraction(&mut view, name)?;
    if fraction <= 0.0 {
        return Err(Error::input(format!(
            "{name}: the frames timed drew nothing (the screenshot is background only)"
        )));
    }
    if animate && moved < runs as u64 {
        return Err(Error::input(format!(
            "{name}: the statue was re-skinned {moved} times in {runs} timed frames"
        )));
    }

    let mut r = super::summarise(name, drawn as u64, &mut period);
    cpu.sort_by(f64::total_cmp);
    r.extra.insert("fps".into(), 1.0 / r.median_s.max(1e-9));
    r.extra.insert("update_ms".into(), 1e3 * cpu[cpu.len() / 2]);
    r.extra.insert("skin_ms".into(), skin_ms);
    r.extra.insert("points".into(), drawn as f64);
    r.extra.insert("statue_fraction".into(), fraction);
    Ok(r)
}

/// The share of the scene band's pixels that differ from the background, from a screenshot
/// (saved to `PYGMALION_BENCH_PICTURES` when set). Errors (labelled `name`): the screenshot
/// never came back.
pub fn statue_fraction(view: &mut Offscreen, name: &str) -> Result<f64> {
    let (app, target) = (&mut view.app, &view.target);
    let got: Arc<Mutex<Option<Image>>> = Arc::default();
    let slot = got.clone();
    app.world_mut()
        .spawn(Screenshot::image(target.clone()))
        .observe(move |captured: On<ScreenshotCaptured>| {
            *slot.lock().unwrap_or_else(|p| p.into_inner()) = Some(captured.image.clone());
        });
    let bg = app
        .world()
        .resource::<crate::kiosk::Settings>()
        .0
        .render
        .background;
    for _ in 0..PATIENCE {
        app.update();
        let image = got.lock().unwrap_or_else(|p| p.into_inner()).take();
        if let Some(image) = image {
            let (width, height, rgb) =
                capture_rgb(&image).map_err(|e| Error::input(format!("{name}: {e}")))?;
            if let Some(dir) = std::env::var_os("PYGMALION_BENCH_PICTURES") {
                let path =
                    std::path::Path::new(&dir).join(format!("{}.png", name.replace('/', "_")));
                let picture = crate::render::Image {
                    width,
                    height,
                    rgb: rgb.clone(),
                };
                picture
                    .save_png(&path)
                    .map_err(|e| Error::input(format!("{}: {e}", path.display())))?;
            }
            // Rows of the scene band (between the top bar and the pose strip).
            let margins = *app.world().resource::<SceneMargins>();
            let row = 3 * width as usize;
            let top = (margins.top.max(0.0) as usize).min(height as usize);
            let bottom = (height as usize)
                .saturating_sub(margins.bottom.max(0.0) as usize)
                .max(top);
            let band = &rgb[top * row..bottom * row];
            let n = band.len() / 3;
            let lit = band
                .chunks_exact(3)
                .filter(|p| (0..3).any(|i| (p[i] as i32 - bg[i] as i32).abs() > 8))
                .count();
            return Ok(lit as f64 / n.max(1) as f64);
        }
    }
    Err(Error::input(format!(
        "{name}: the screenshot never came back from the GPU"
    )))
}
