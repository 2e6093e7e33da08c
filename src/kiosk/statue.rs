//! Loading statues: the file is read, checked, given normals and subsampled off the main
//! thread; a cached fit and binding (keyed by the file's content and the template) make the
//! next start immediate; the carousel and the reset switch statues.
//!
//! **Cache.** `cache_dir/<key>.fit.json` (the fitted skeleton) and `cache_dir/<key>.binding`
//! ([`crate::skinning::Binding::save`]), where `key` is a 64-bit FNV-1a hash of the file's bytes,
//! the template's name and source text, the point budget and [`CACHE_VERSION`]. A changed file,
//! template or budget gives another key, so stale entries are never used; an unreadable or
//! damaged entry is ignored (and the statue fitted again).
//!
//! **Framing.** A loaded statue is framed in the band of the window the interface leaves free
//! ([`super::SceneMargins`], measured by the UI plugin), by moving the point looked at down the
//! statue's vertical axis and choosing the home distance ([`frame_camera`]); it is framed
//! again if the window or the margins change later ([`Framing`]).

use super::config::StatueEntry;
use super::{
    ActiveStatue, CurrentPose, FittedSkeleton, KioskSet, OrbitCamera, ResetRequested, SceneMargins,
    Settings, SkinnedPoints, Statue, StatueBinding, StatueCloud, StatueSelected, StatueState,
};
use crate::anatomy::{Skeleton, Template};
use crate::cloud::PointCloud;
use crate::cloud::normals::{NormalOptions, ensure_normals};
use crate::cloud::ply::{ReadOptions, read_ply_with};
use crate::error::{Error, Result};
use crate::fakir::{Attempt, Init, RegistrationOptions};
use crate::skinning::{Binding, Scratch};
use bevy::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// Bump when the cached formats or the fitting change meaning.
pub const CACHE_VERSION: u32 = 5;

/// The result of a background job, polled each frame.
#[derive(Component)]
pub struct Pending<T: Send + 'static>(pub Arc<Mutex<Option<T>>>);

impl<T: Send + 'static> Pending<T> {
    /// Runs `job` on its own thread.
    pub fn spawn(job: impl FnOnce() -> T + Send + 'static) -> Pending<T> {
        let slot = Arc::new(Mutex::new(None));
        let out = slot.clone();
        std::thread::spawn(move || {
            let r = job();
            if let Ok(mut s) = out.lock() {
                *s = Some(r);
            }
        });
        Pending(slot)
    }
    /// The result, once there (taken).
    pub fn take(&self) -> Option<T> {
        self.0.lock().ok().and_then(|mut s| s.take())
    }
}

/// What loading a statue gives.
pub struct Loaded {
    pub cloud: Arc<PointCloud>,
    pub template: Arc<Template>,
    /// How to register it: what the configuration knows (up, facing, lost limbs).
    pub fit_options: RegistrationOptions,
    pub cache_key: String,
    /// A cached fit and binding, when valid.
    pub cached: Option<(Skeleton, Binding)>,
}

/// 64-bit FNV-1a.
pub fn fnv1a(chunks: &[&[u8]]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for c in chunks {
        for &b in *c {
            h ^= b as u64;
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    h
}

/// Keeps at most `budget` points: every `k`-th one, deterministic and spread over the file
/// (scans are stored in scan order, so a stride samples every region).
pub fn subsample(cloud: &mut PointCloud, budget: usize) {
    let n = cloud.len();
    if n <= budget || budget == 0 {
        return;
    }
    let keep: Vec<usize> = (0..budget).map(|i| i * n / budget).collect();
    *cloud = cloud.select(&keep);
}

/// Checks that `file` (under `root`) really lies inside `root` once links are resolved.
pub fn resolve_inside(root: &Path, file: &Path) -> Result<PathBuf> {
    let full = root.join(file);
    let canon_root = root.canonicalize().map_err(|e| Error::Io {
        path: root.to_path_buf(),
        source: e,
    })?;
    let canon = full.canonicalize().map_err(|e| Error::Io {
        path: full.clone(),
        source: e,
    })?;
    if !canon.starts_with(&canon_root) {
        return Err(Error::config(
            &full,
            format!("outside the assets root {}", root.display()),
        ));
    }
    Ok(canon)
}

/// Loads one statue (runs off the main thread).
pub fn load(
    root: &Path,
    cache_dir: &Path,
    entry: &StatueEntry,
    point_budget: usize,
) -> Result<Loaded> {
    let path = resolve_inside(root, &entry.file)?;
    let bytes = std::fs::read(&path).map_err(|e| Error::Io {
        path: path.clone(),
        source: e,
    })?;
    let template = Arc::new(Template::resolve(&entry.template)?);
    let axis = |a: &Option<String>, what: &str| {
        a.as_deref()
            .map(crate::cli::register::parse_axis)
            .transpose()
            .map_err(|e| Error::config(&path, format!("{what}: {e}")))
    };
    let up = axis(&entry.up, "up axis")?;
    let front = axis(&entry.front, "facing")?;
    crate::fakir::support::lost_from_names(&template, &entry.missing)
        .map_err(|e| Error::config(&path, e.to_string()))?;
    let fit_options = RegistrationOptions {
        init: up.map(Init::Up).unwrap_or_default(),
        front,
        lost: entry.missing.clone(),
        ..Default::default()
    };
    let template_text = format!("{:?}", template);
    let key = format!(
        "{:016x}",
        fnv1a(&[
            &bytes,
            template.name.as_bytes(),
            template_text.as_bytes(),
            &(point_budget as u64).to_le_bytes(),
            &CACHE_VERSION.to_le_bytes(),
            format!("{up:?}").as_bytes(),
            format!("{front:?} {:?}", entry.missing).as_bytes(),
        ])
    );
    let mut cloud = read_ply_with(&path, &ReadOptions::default())?;
    subsample(&mut cloud, point_budget);
    ensure_normals(&mut cloud, &NormalOptions::default())
        .map_err(|e| Error::input(format!("{}: {e}", path.display())))?;
    let cached = read_cache(cache_dir, &key, &template, cloud.len());
    Ok(Loaded {
        cloud: Arc::new(cloud),
        template,
        fit_options,
        cache_key: key,
        cached,
    })
}

fn read_cache(
    dir: &Path,
    key: &str,
    template: &Arc<Template>,
    points: usize,
) -> Option<(Skeleton, Binding)> {
    let fit =
        Skeleton::load_json(dir.join(format!("{key}.fit.json")), Some(template.clone())).ok()?;
    let binding = Binding::load(dir.join(format!("{key}.binding")), template.clone()).ok()?;
    (binding.len() == points).then_some((fit, binding))
}

/// Writes a fit and its binding to the cache (best effort: a failure is logged, not fatal).
pub fn write_cache(dir: &Path, key: &str, fit: &Skeleton, binding: &Binding) {
    let r = std::fs::create_dir_all(dir)
        .map_err(|e| Error::Io {
            path: dir.to_path_buf(),
            source: e,
        })
        .and_then(|_| fit.save_json(dir.join(format!("{key}.fit.json"))))
        .and_then(|_| binding.save(dir.join(format!("{key}.binding"))));
    if let Err(e) = r {
        warn!("could not cache the fit: {e}");
    }
}

/// Loading, caching and switching statues.
pub struct StatuePlugin;

impl Plugin for StatuePlugin {
    fn build(&self, app: &mut App) {
        app.init_resource::<Framing>()
            .init_resource::<SceneMargins>()
            .add_systems(
                Update,
                (
                    switch_statue,
                    spawn_active_statue,
                    finish_loading,
                    reframe_camera,
                )
                    .chain()
                    .in_set(KioskSet::Load),
            );
    }
}

/// The window size and scene margins the camera was last framed for ([`frame_camera`]).
#[derive(Resource, Clone, Copy, Debug, Default, PartialEq)]
pub struct Framing(pub Option<(Vec2, SceneMargins)>);

/// The statue's cache key (for writing the fit when it is done).
#[derive(Component, Clone, Debug)]
pub struct CacheKey(pub String);

/// The statue's template and up hint (for the registration).
#[derive(Component, Clone, Debug)]
pub struct StatueTemplate {
    pub template: Arc<Template>,
    /// How to register it ([`Loaded::fit_options`]).
    pub fit_options: RegistrationOptions,
}

fn switch_statue(
    mut commands: Commands,
    mut selected: MessageReader<StatueSelected>,
    mut reset: MessageReader<ResetRequested>,
    mut active: ResMut<ActiveStatue>,
    settings: Res<Settings>,
) {
    let mut next = None;
    for s in selected.read() {
        next = Some(s.0);
    }
    if reset.read().count() > 0 {
        next = Some(0);
    }
    let Some(i) = next else { return };
    let n = settings.0.statues.len();
    if n == 0 {
        return;
    }
    let i = i.min(n - 1);
    if i == active.index && active.entity.is_some() && next.is_some() {
        // Same statue: a reset keeps it loaded (the animation system brings its pose home).
        return;
    }
    if let Some(e) = active.entity.take() {
        commands.entity(e).despawn();
    }
    active.index = i;
}

fn spawn_active_statue(
    mut commands: Commands,
    mut active: ResMut<ActiveStatue>,
    settings: Res<Settings>,
) {
    if active.entity.is_some() {
        return;
    }
    let cfg = &settings.0;
    let Some(entry) = cfg.statues.get(active.index).cloned() else {
        return;
    };
    let root = cfg.assets_root.clone();
    let cache = cfg.cache_dir.clone();
    let budget = cfg.budget.point_budget;
    let job = {
        let entry = entry.clone();
        move || load(&root, &cache, &entry, budget)
    };
    let e = commands
        .spawn((
            Statue {
                index: active.index,
                title: entry.title.clone(),
            },
            StatueState::Loading,
            Pending::spawn(job),
            Transform::default(),
            Visibility::default(),
        ))
        .id();
    active.entity = Some(e);
}

#[allow(clippy::type_complexity)]
fn finish_loading(
    mut commands: Commands,
    mut q: Query<(Entity, &mut StatueState, &Pending<Result<Loaded>>)>,
    mut camera: ResMut<OrbitCamera>,
    margins: Res<SceneMargins>,
    settings: Res<Settings>,
    windows: Query<&Window, With<bevy::window::PrimaryWindow>>,
    mut framing: ResMut<Framing>,
) {
    for (e, mut state, pending) in &mut q {
        let Some(r) = pending.take() else { continue };
        let mut ec = commands.entity(e);
        ec.remove::<Pending<Result<Loaded>>>();
        match r {
            Err(err) => {
                warn!("statue failed to load: {err}");
                *state = StatueState::Failed {
                    message: err.to_string(),
                };
            }
            Ok(loaded) => {
                let screen = super::screen_size(windows.iter().next(), &settings.0);
                frame_camera(&mut camera, &loaded.cloud, screen, *margins);
                framing.0 = Some((screen, *margins));
                let cloud = loaded.cloud.clone();
                ec.insert((
                    StatueCloud(cloud.clone()),
                    SkinnedPoints {
                        positions: cloud.positions.clone(),
                        normals: cloud
                            .normals
                            .clone()
                            .unwrap_or_else(|| vec![Vec3::Y; cloud.len()]),
                        colors: cloud.colors.clone(),
                        version: 1,
                        scratch: Scratch::default(),
                    },
                    CacheKey(loaded.cache_key.clone()),
                    StatueTemplate {
                        template: loaded.template.clone(),
                        fit_options: loaded.fit_options.clone(),
                    },
                ));
                match loaded.cached {
                    Some((_, binding)) => {
                        info!("statue ready from the cache");
                        // The binding's own skeleton: bit-identical to the fit it was built
                        // on (the JSON's is rounded), so the fitted pose shows the scan as is.
                        let fit = binding.fitted().clone();
                        ec.insert((
                            CurrentPose(fit.clone()),
                            FittedSkeleton(fit),
                            StatueBinding(Arc::new(binding)),
                        ));
                        *state = StatueState::Ready;
                    }
                    None => {
                        *state = StatueState::Fitting {
                            units: 0,
                            fraction: 0.0,
                            attempt: Attempt::Whole,
                        };
                    }
                }
            }
        }
    }
}

/// Frames the camera again (home view) when the window or the interface's margins change by
/// more than 2 logical pixels after the statue was framed (a window going fullscreen, a
/// pose strip wrapping onto a second row).
fn reframe_camera(
    active: Res<ActiveStatue>,
    clouds: Query<&StatueCloud>,
    margins: Res<SceneMargins>,
    settings: Res<Settings>,
    windows: Query<&Window, With<bevy::window::PrimaryWindow>>,
    mut framing: ResMut<Framing>,
    mut camera: ResMut<OrbitCamera>,
) {
    let (Some((screen, m)), Some(cloud)) =
        (framing.0, active.entity.and_then(|e| clouds.get(e).ok()))
    else {
        return;
    };
    let now = super::screen_size(windows.iter().next(), &settings.0);
    let moved = (now - screen).abs().max_element() > 2.0
        || (m.top - margins.top).abs() > 2.0
        || (m.bottom - margins.bottom).abs() > 2.0;
    if moved {
        frame_camera(&mut camera, &cloud.0, now, *margins);
        framing.0 = Some((now, *margins));
    }
}

/// Share of the free scene band's height the statue's box fills in the home view.
pub const SCENE_FILL: f32 = 0.94;

/// Frames the orbit camera on a cloud: the home view looks from the front, a little above
/// (pitch 0.1 rad), and the cloud's bounding box fills [`SCENE_FILL`] of the height of the
/// band the interface leaves free on a window of logical size `screen` (`margins`), centred
/// in it. The band is rarely centred on the screen (the pose strip is taller than the top
/// bar), so the point looked at is moved down the vertical axis through the statue's centre
/// rather than panned: the statue shows higher, orbiting still turns it about its own axis,
/// and a reset or a double tap keeps the framing. Distance and shift are found by projecting
/// the box's corners with the kiosk's own view ([`super::gestures::View`]) a few times (the
/// perspective makes the near corners larger). A band under 40% of the screen's height is
/// widened to that, about its centre.
pub fn frame_camera(
    camera: &mut OrbitCamera,
    cloud: &PointCloud,
    screen: Vec2,
    margins: SceneMargins,
) {
    use super::gestures::{FOV_Y, View};
    let Some(b) = cloud.bounding_box() else {
        return;
    };
    let size = b.size().max_element().max(1e-6);
    let screen = screen.max(Vec2::ONE);
    let (mut top, mut bottom) = (margins.top, screen.y - margins.bottom);
    let min_band = 0.4 * screen.y;
    if bottom - top < min_band {
        let mid = ((top + bottom) * 0.5).clamp(min_band * 0.5, screen.y - min_band * 0.5);
        (top, bottom) = (mid - min_band * 0.5, mid + min_band * 0.5);
    }
    let want = (bottom - top) * SCENE_FILL;
    let band_mid = (top + bottom) * 0.5;
    let corners: Vec<Vec3> = (0..8)
        .map(|i| {
            Vec3::new(
                if i & 1 == 0 { b.min.x } else { b.max.x },
                if i & 2 == 0 { b.min.y } else { b.max.y },
                if i & 4 == 0 { b.min.z } else { b.max.z },
            )
        })
        .collect();
    let pitch = 0.1;
    let mut distance = 1.9 * size;
    camera.target = b.center();
    for _ in 0..8 {
        camera.home = (0.0, pitch, distance);
        camera.reset();
        let view = View::from_orbit(camera, screen, FOV_Y);
        let ys: Vec<f32> = corners
            .iter()
            .filter_map(|&c| view.project(c).map(|p| p.y))
            .collect();
        if ys.len() < corners.len() {
            // A corner behind the eye: step back.
            distance *= 1.5;
            continue;
        }
        let (lo, hi) = ys
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), &y| {
                (l.min(y), h.max(y))
            });
        // Too low on screen (larger y): look lower, by the world size of that many pixels at
        // the target's depth.
        let pixel = view.pixel_size() * distance;
        camera.target.y -= ((lo + hi) * 0.5 - band_mid) * pixel;
        distance *= ((hi - lo) / want).clamp(0.25, 4.0);
    }
    camera.home = (0.0, pitch, distance);
    camera.reset();
}
