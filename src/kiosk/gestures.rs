//! Touch and mouse gestures: orbit, pan, pinch, double tap, taps on bones, limb drags.
//!
//! Every touch (`TouchInput`) and every left/right mouse press becomes a *pointer*; a
//! *gesture* lasts from the first pointer down to the last pointer up. The mouse emulates one
//! finger (left button) and a two-finger pan (right button); the wheel zooms.
//!
//! | gesture | effect |
//! |---|---|
//! | one finger (left button) drag | orbit: `yaw -= dx · k`, `pitch += dy · k` (`k` = [`GestureConfig::orbit_rad_per_px`]), pitch clamped to ±[`GestureConfig::pitch_limit`] — the statue turns with the finger |
//! | two fingers, or right-button drag | pan: the view follows the fingers' midpoint (exact at the focus depth) |
//! | pinch | zoom: `distance ×= old span / new span`, clamped to [`GestureConfig::zoom_range`] × the home distance |
//! | wheel | zoom: `distance ×= exp(−lines · wheel_zoom_per_line)` (pixels count 1/100 line) |
//! | tap | selects the limb (template chain) of the bone under the finger, or nothing; a [`Tap`] message carries its pick ray (other plugins pick their own targets: the ghost bones of [`super::restore`]) |
//! | tap or drag starting in a [`TouchZone`] | a [`ZoneGesture`] (tap, or swipe with its movement) for the zone's owner, nothing else |
//! | double tap | back to the home view ([`OrbitCamera::reset`]) |
//! | three-finger tap | [`ThreeFingerTap`] (the UI toggles the operator panel) |
//! | drag starting on the end bone of the selected limb | inverse kinematics: the limb follows the finger ([`super::ik`]) |
//!
//! **Taps.** A tap is a one-pointer gesture that never moved more than
//! [`GestureConfig::tap_max_move_px`] (12 px) from where it started and lasted at most
//! [`GestureConfig::tap_max_s`] (0.5 s); anything that moved is a drag and never a tap (and
//! a drag only starts once the threshold is crossed, with the whole movement since the press
//! applied then, so taps never nudge the view). Two taps form a double tap when the second
//! press comes within [`GestureConfig::double_tap_s`] (0.35 s) of the first release and
//! within [`GestureConfig::double_tap_px`] (30 px) of it; both taps also select.
//!
//! **Rays.** A screen point becomes a ray by [`screen_ray`], one pure function used in both
//! cases: with a camera (an active `Camera` with a perspective `Projection` and a
//! `GlobalTransform`) its eye, rotation, vertical field of view and logical viewport are used;
//! without one (headless tests) the view is built from [`OrbitCamera`] by [`View::from_orbit`]:
//! eye [`OrbitCamera::eye`], looking at [`OrbitCamera::focus`] with `+Y` up, a vertical field
//! of view of 45° ([`FOV_Y`], Bevy's default), and the window's logical size (the touch's
//! window, else the primary window, else the configured window size, else 1280 × 800).
//! Bevy's convention: the camera looks down its local `−Z`, `+Y` up; screen positions are
//! logical pixels from the top-left corner, `y` down.
//!
//! **Picking.** The ray is tested against the current pose's sphere-mesh bones
//! ([`pick_bone`], [`bone_hit`]): closest approach of the ray and the bone's axis, radius
//! interpolated between `r1` and `r2` there (entry refined by the end spheres). Among the
//! bones the ray passes through, those entered within one radius of the front-most entry
//! compete (bones overlapping at a joint; bones hidden behind do not), and the one whose axis
//! passes closest to the ray, relative to its radius, wins. Without such a bone, a bone
//! passing within [`GestureConfig::pick_slack_px`] pixels (fingers are wide) is taken. A
//! follower bone selects its leader's chain; the root block selects nothing.
//!
//! **Limb drags.** When a one-finger gesture starts on the end bone of the selected chain
//! (within the pick slack) of a fitted statue, the effector is the start of that end bone (the
//! wrist, ankle or head base; see [`super::ik`]). Its camera depth `d` and its offset from the
//! ray's point at depth `d` are recorded; each move then targets the new ray's point at depth
//! `d` plus that offset (the limb does not jump under the finger), the chain is solved by
//! FABRIK and written into the statue's [`CurrentPose`] (any running [`PoseAnimation`] is
//! stopped), which the skinning system re-skins.
//!
//! **Touch zones.** Screen rectangles claimed by overlays drawn without bevy_ui buttons (the
//! restoration's donor carousel and hypothesis strip, [`super::restore`]) are listed in the
//! [`TouchZones`] resource. A one-finger gesture that starts inside one is the zone's alone:
//! no orbit, no selection, no double tap; on release it becomes a [`ZoneGesture`], a
//! [`ZoneGestureKind::Tap`] under the tap thresholds, else a [`ZoneGestureKind::Swipe`] with
//! the finger's whole movement. The same rectangles work headless, so tests drive overlays
//! with injected touches.
//!
//! **Interaction.** Every touch or mouse press, every wheel step, and every frame with pointer
//! movement writes an [`Interaction`] message (the idle timers restart). A press that lands on
//! a pressed bevy_ui node (a button, a panel) starts a gesture that does nothing else.

use super::ik::{self, IkOptions};
use super::{
    ActiveStatue, CurrentPose, FittedSkeleton, Interaction, KioskSet, OrbitCamera, PoseAnimation,
    Selection, Settings,
};
use crate::anatomy::{BoneKind, Template};
use crate::geometry::Bone;
use crate::math::{Mat3, Quat, Vec2, Vec3};
use bevy::ecs::system::SystemParam;
use bevy::input::ButtonState;
use bevy::input::mouse::{MouseButtonInput, MouseScrollUnit, MouseWheel};
use bevy::input::touch::{TouchInput, TouchPhase};
use bevy::prelude::*;
use bevy::ui::Interaction as UiInteraction;
use bevy::window::{CursorMoved, PrimaryWindow};

/// The vertical field of view assumed when there is no camera (Bevy's default, 45°).
pub const FOV_Y: f32 = std::f32::consts::FRAC_PI_4;

/// Thresholds and speeds of the gestures (a resource; see the module docs).
#[derive(Resource, Clone, Debug, PartialEq)]
pub struct GestureConfig {
    /// Largest movement of a tap, logical pixels.
    pub tap_max_move_px: f32,
    /// Longest tap, seconds.
    pub tap_max_s: f32,
    /// Longest gap between the first tap's release and the second press of a double tap.
    pub double_tap_s: f32,
    /// Largest distance between the two taps of a double tap, logical pixels.
    pub double_tap_px: f32,
    /// Orbit speed, radians per logical pixel.
    pub orbit_rad_per_px: f32,
    /// Pitch limit, radians (both ways).
    pub pitch_limit: f32,
    /// Zoom limits as multiples of the home distance.
    pub zoom_range: (f32, f32),
    /// Zoom per wheel line: `distance ×= exp(−lines · this)`.
    pub wheel_zoom_per_line: f32,
    /// How far from a bone (logical pixels) a tap still picks it.
    pub pick_slack_px: f32,
    /// Vertical field of view without a camera, radians.
    pub fov_y: f32,
    /// Viewport size when no window is known, logical pixels.
    pub fallback_viewport: Vec2,
    /// Inverse kinematics of limb drags.
    pub ik: IkOptions,
}

impl Default for GestureConfig {
    fn default() -> Self {
        GestureConfig {
            tap_max_move_px: 12.0,
            tap_max_s: 0.5,
            double_tap_s: 0.35,
            double_tap_px: 30.0,
            orbit_rad_per_px: 0.005,
            pitch_limit: 1.4,
            zoom_range: (0.25, 4.0),
            wheel_zoom_per_line: 0.1,
            pick_slack_px: 16.0,
            fov_y: FOV_Y,
            fallback_viewport: Vec2::new(1280.0, 800.0),
            ik: IkOptions::default(),
        }
    }
}

/// Gestures: orbit, pan, pinch, double tap, taps on bones, limb drags.
#[derive(Default)]
pub struct GesturePlugin {
    /// Thresholds and speeds (inserted as the [`GestureConfig`] resource).
    pub config: GestureConfig,
}

/// A tap with three fingers (the UI toggles the operator panel).
#[derive(Message, Clone, Copy, Debug, Default)]
pub struct ThreeFingerTap;

/// A one-finger tap outside the UI and the touch zones, with its pick ray (written after the
/// gesture plugin's own selection; see the module docs).
#[derive(Message, Clone, Copy, Debug)]
pub struct Tap {
    pub window: Entity,
    /// Logical pixels from the window's top-left corner.
    pub position: Vec2,
    /// The ray through `position` (see [`View::ray`]).
    pub ray: PickRay,
    /// How far a bone may be from the ray and still be picked, per unit of depth
    /// ([`GestureConfig::pick_slack_px`] at this view).
    pub slack_per_depth: f32,
}

/// A screen rectangle claimed by an overlay (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TouchZone {
    /// The owner's name for it.
    pub id: u32,
    /// Logical pixels, `y` down.
    pub rect: Rect,
}

/// The touch zones of this frame (owners rewrite their own each frame).
#[derive(Resource, Clone, Debug, Default)]
pub struct TouchZones {
    pub zones: Vec<TouchZone>,
}

impl TouchZones {
    /// The zone under `position` (the last listed wins, as the one drawn on top).
    pub fn at(&self, position: Vec2) -> Option<u32> {
        self.zones
            .iter()
            .rev()
            .find(|z| z.rect.contains(position))
            .map(|z| z.id)
    }
    /// Replaces the zones whose ids are in `ids` by `zones`.
    pub fn set(&mut self, ids: &[u32], zones: impl IntoIterator<Item = TouchZone>) {
        self.zones.retain(|z| !ids.contains(&z.id));
        self.zones.extend(zones);
    }
}

/// What a gesture in a touch zone was.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ZoneGestureKind {
    Tap,
    /// The finger's movement from press to release, logical pixels.
    Swipe {
        delta: Vec2,
    },
}

/// A one-finger gesture that started in a [`TouchZone`].
#[derive(Message, Clone, Copy, Debug, PartialEq)]
pub struct ZoneGesture {
    pub zone: u32,
    /// Where the finger was pressed, logical pixels.
    pub start: Vec2,
    pub kind: ZoneGestureKind,
}

/// The gesture system (other plugins order their tap handling after it).
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct GestureSystems;

impl Plugin for GesturePlugin {
    fn build(&self, app: &mut App) {
        // `add_message` does nothing for messages already registered (InputPlugin,
        // WindowPlugin); headless tests run without the window plugin.
        app.insert_resource(self.config.clone())
            .init_resource::<GestureState>()
            .init_resource::<TouchZones>()
            .init_resource::<Selection>()
            .init_resource::<OrbitCamera>()
            .add_message::<TouchInput>()
            .add_message::<CursorMoved>()
            .add_message::<MouseButtonInput>()
            .add_message::<MouseWheel>()
            .add_message::<Interaction>()
            .add_message::<ThreeFingerTap>()
            .add_message::<Tap>()
            .add_message::<ZoneGesture>()
            .add_systems(
                Update,
                gestures.in_set(KioskSet::Input).in_set(GestureSystems),
            );
    }
}

// ---------------------------------------------------------------------------------------------
// Pure geometry: views, rays, picking.

/// A ray (unit direction).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PickRay {
    pub origin: Vec3,
    pub direction: Vec3,
}

impl PickRay {
    /// The point at parameter `t`.
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.direction * t
    }
    /// The point of the ray at camera depth `depth` (distance along the view direction
    /// `forward`, a unit vector).
    pub fn at_depth(&self, forward: Vec3, depth: f32) -> Vec3 {
        let c = self.direction.dot(forward);
        if c.abs() < 1e-6 {
            return self.origin + forward * depth;
        }
        self.at(depth / c)
    }
}

/// The ray from a perspective camera through a screen point. `eye` and `rotation` place the
/// camera (Bevy convention: it looks down its local `−Z`, `+Y` up), `fov_y` is the vertical
/// field of view in radians, `viewport` the viewport's logical size and `position` the point
/// in logical pixels from the viewport's top-left corner, `y` down.
pub fn screen_ray(
    eye: Vec3,
    rotation: Quat,
    fov_y: f32,
    viewport: Vec2,
    position: Vec2,
) -> PickRay {
    let size = viewport.max(Vec2::ONE);
    let half = (fov_y * 0.5).tan();
    let aspect = size.x / size.y;
    let ndc = Vec2::new(
        2.0 * position.x / size.x - 1.0,
        1.0 - 2.0 * position.y / size.y,
    );
    let local = Vec3::new(ndc.x * half * aspect, ndc.y * half, -1.0);
    PickRay {
        origin: eye,
        direction: (rotation * local).normalize(),
    }
}

/// The rotation of a camera looking along `direction` with `+Y` up (as Bevy's
/// `Transform::looking_to(direction, Vec3::Y)`).
pub fn look_rotation(direction: Vec3) -> Quat {
    let back = (-direction).normalize_or(Vec3::Z);
    let mut right = Vec3::Y.cross(back);
    if right.length_squared() < 1e-12 {
        right = Vec3::X;
    }
    let right = right.normalize();
    let up = back.cross(right);
    Quat::from_mat3(&Mat3::from_cols(right, up, back)).normalize()
}

/// A perspective view: what [`screen_ray`] needs, plus the viewport's place in the window.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    pub eye: Vec3,
    pub rotation: Quat,
    /// Vertical field of view, radians.
    pub fov_y: f32,
    /// Top-left corner of the viewport in the window, logical pixels.
    pub origin: Vec2,
    /// Viewport size, logical pixels.
    pub size: Vec2,
}

impl View {
    /// The view of an [`OrbitCamera`] (no camera entity: headless), filling a window of
    /// logical size `size`.
    pub fn from_orbit(orbit: &OrbitCamera, size: Vec2, fov_y: f32) -> View {
        let eye = orbit.eye();
        View {
            eye,
            rotation: look_rotation(orbit.focus() - eye),
            fov_y,
            origin: Vec2::ZERO,
            size,
        }
    }
    /// The unit view direction.
    pub fn forward(&self) -> Vec3 {
        self.rotation * Vec3::NEG_Z
    }
    /// The ray through a window position (logical pixels).
    pub fn ray(&self, position: Vec2) -> PickRay {
        screen_ray(
            self.eye,
            self.rotation,
            self.fov_y,
            self.size,
            position - self.origin,
        )
    }
    /// The window position (logical pixels) of a world point in front of the camera.
    pub fn project(&self, point: Vec3) -> Option<Vec2> {
        let local = self.rotation.inverse() * (point - self.eye);
        if local.z > -1e-6 {
            return None;
        }
        let size = self.size.max(Vec2::ONE);
        let half = (self.fov_y * 0.5).tan();
        let aspect = size.x / size.y;
        let ndc = Vec2::new(
            local.x / (-local.z * half * aspect),
            local.y / (-local.z * half),
        );
        Some(self.origin + Vec2::new((ndc.x + 1.0) * 0.5 * size.x, (1.0 - ndc.y) * 0.5 * size.y))
    }
    /// World size of one logical pixel at depth 1 (`2 tan(fov/2) / height`).
    pub fn pixel_size(&self) -> f32 {
        2.0 * (self.fov_y * 0.5).tan() / self.size.y.max(1.0)
    }
}

/// Closest approach of a ray and the segment `a b`: `(t, s, distance)` with `t ≥ 0` the ray
/// parameter and `s ∈ [0, 1]` the segment parameter.
pub fn ray_segment(ray: &PickRay, a: Vec3, b: Vec3) -> (f32, f32, f32) {
    let d = ray.direction;
    let u = b - a;
    let w = ray.origin - a;
    let (aa, bb, cc) = (d.dot(d), d.dot(u), u.dot(u));
    let (dd, ee) = (d.dot(w), u.dot(w));
    let denom = aa * cc - bb * bb;
    let mut s = if cc < 1e-12 {
        0.0
    } else if denom > 1e-12 * aa * cc {
        ((aa * ee - bb * dd) / denom).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let t = ((s * bb - dd) / aa).max(0.0);
    if cc >= 1e-12 {
        s = ((ee + t * bb) / cc).clamp(0.0, 1.0);
    }
    let dist = (w + d * t - u * s).length();
    (t, s, dist)
}

/// How a ray meets a bone (see [`bone_hit`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoneHit {
    /// The ray passes through the bone (not only within the slack).
    pub inside: bool,
    /// Ray parameter where it enters the bone (approximate), or of the closest approach for
    /// a slack hit.
    pub entry: f32,
    /// Distance of the ray from the bone's axis over the radius there (inside hits), or miss
    /// distance over the slack (slack hits): smaller is a more central hit.
    pub closeness: f32,
    /// The bone's radius at the closest approach.
    pub radius: f32,
}

fn sphere_entry(ray: &PickRay, c: Vec3, r: f32) -> Option<f32> {
    let oc = ray.origin - c;
    let b = oc.dot(ray.direction);
    let disc = b * b - (oc.length_squared() - r * r);
    if disc < 0.0 {
        return None;
    }
    let t = -b - disc.sqrt();
    (-b + disc.sqrt() >= 0.0).then_some(t.max(0.0))
}

/// How a ray meets a sphere-mesh bone: closest approach of the ray and the bone's axis,
/// radius interpolated between `r1` and `r2` there; inside when the ray passes within that
/// radius (the entry refined by the two end spheres), a slack hit when it passes within
/// `slack_per_depth × t` more, `None` otherwise.
pub fn bone_hit(ray: &PickRay, bone: &Bone, slack_per_depth: f32) -> Option<BoneHit> {
    let (t, s, dist) = ray_segment(ray, bone.c1, bone.c2);
    let r = bone.r1 + (bone.r2 - bone.r1) * s;
    if dist <= r {
        let mut entry = t - (r * r - dist * dist).max(0.0).sqrt();
        for (c, rr) in [(bone.c1, bone.r1), (bone.c2, bone.r2)] {
            if let Some(e) = sphere_entry(ray, c, rr) {
                entry = entry.min(e);
            }
        }
        return Some(BoneHit {
            inside: true,
            entry: entry.max(0.0),
            closeness: if r > 0.0 { dist / r } else { 0.0 },
            radius: r,
        });
    }
    let slack = slack_per_depth * t;
    if slack > 0.0 && dist <= r + slack {
        return Some(BoneHit {
            inside: false,
            entry: t,
            closeness: (dist - r) / slack,
            radius: r,
        });
    }
    None
}

/// The bone a ray picks among `bones`, if any. Bones the ray passes through come first: of
/// those whose entry lies within one radius of the front-most entry (bones that overlap at a
/// joint, not bones hidden behind), the one whose axis passes closest to the ray relative to
/// its radius. Without such a bone, the slack hit closest to the ray.
pub fn pick_bone(ray: &PickRay, bones: &[Bone], slack_per_depth: f32) -> Option<usize> {
    let hits: Vec<(usize, BoneHit)> = bones
        .iter()
        .enumerate()
        .filter_map(|(i, b)| bone_hit(ray, b, slack_per_depth).map(|h| (i, h)))
        .collect();
    let by = |a: f32, b: f32| a.total_cmp(&b);
    let front = hits
        .iter()
        .filter(|(_, h)| h.inside)
        .min_by(|a, b| by(a.1.entry, b.1.entry));
    if let Some((_, f)) = front {
        let band = f.entry + f.radius;
        return hits
            .iter()
            .filter(|(_, h)| h.inside && h.entry <= band)
            .min_by(|a, b| by(a.1.closeness, b.1.closeness))
            .map(|(i, _)| *i);
    }
    hits.iter()
        .min_by(|a, b| by(a.1.closeness, b.1.closeness))
        .map(|(i, _)| *i)
}

/// The chain a tap on `bone` selects: its own chain, its leader's for a follower bone, none
/// for a block bone.
pub fn chain_of_bone(template: &Template, bone: usize) -> Option<usize> {
    let def = template.bones.get(bone)?;
    match def.kind {
        BoneKind::Follower { leader, .. } if leader != bone => chain_of_bone(template, leader),
        _ => def.chain.map(|(c, _)| c),
    }
}

/// `yaw`/`pitch` after a one-finger drag of `delta` logical pixels.
pub fn orbit_by(orbit: &mut OrbitCamera, delta: Vec2, config: &GestureConfig) {
    orbit.yaw -= delta.x * config.orbit_rad_per_px;
    orbit.pitch = (orbit.pitch + delta.y * config.orbit_rad_per_px)
        .clamp(-config.pitch_limit, config.pitch_limit);
}

/// Pan after the fingers' midpoint moved by `delta` logical pixels, in a view whose pixel
/// size at depth 1 is `pixel_size` (the scene follows the fingers at the focus depth).
pub fn pan_by(orbit: &mut OrbitCamera, delta: Vec2, pixel_size: f32) {
    orbit.pan.x -= delta.x * pixel_size;
    orbit.pan.y += delta.y * pixel_size;
}

/// Multiplies the distance by `factor`, clamped to the zoom range around the home distance.
pub fn zoom_by(orbit: &mut OrbitCamera, factor: f32, config: &GestureConfig) {
    if !(factor.is_finite() && factor > 0.0) {
        return;
    }
    let home = if orbit.home.2 > 0.0 {
        orbit.home.2
    } else {
        orbit.distance
    };
    let (lo, hi) = config.zoom_range;
    orbit.distance = (orbit.distance * factor).clamp(home * lo, home * hi);
}

// ---------------------------------------------------------------------------------------------
// Gesture state.

/// Which device a pointer comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PointerId {
    Touch(u64),
    /// Left mouse button (one finger).
    Mouse,
    /// Right mouse button (pan).
    MousePan,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    Start,
    Move,
    End,
    Cancel,
}

#[derive(Clone, Copy, Debug)]
struct PointerEvent {
    id: PointerId,
    phase: Phase,
    position: Vec2,
    window: Entity,
}

#[derive(Clone, Copy, Debug)]
struct Pointer {
    id: PointerId,
    window: Entity,
    start: Vec2,
    position: Vec2,
}

#[derive(Clone, Debug)]
struct LimbDrag {
    bones: Vec<usize>,
    depth: f32,
    offset: Vec3,
    started: bool,
}

#[derive(Clone, Debug)]
enum Mode {
    /// Over the UI, or nothing to do.
    Inert,
    Orbit,
    Pan,
    Multi {
        span: f32,
        mid: Vec2,
    },
    Limb(LimbDrag),
    /// In a touch zone (the zone's id).
    Zone(u32),
}

#[derive(Clone, Debug)]
struct Gesture {
    started_at: f64,
    max_pointers: usize,
    moved: bool,
    canceled: bool,
    on_ui: bool,
    mode: Mode,
}

/// The gesture recogniser's state (pointers down, the gesture in progress, the last tap).
#[derive(Resource, Default, Debug)]
pub struct GestureState {
    pointers: Vec<Pointer>,
    gesture: Option<Gesture>,
    /// Release time and position of the last tap (for double taps).
    last_tap: Option<(f64, Vec2)>,
    /// Last known mouse cursor (window, position).
    cursor: Option<(Entity, Vec2)>,
}

impl GestureState {
    /// Pointers currently down.
    pub fn pointer_count(&self) -> usize {
        self.pointers.len()
    }
    /// True while a limb is being dragged (after the tap threshold).
    pub fn dragging_limb(&self) -> bool {
        matches!(&self.gesture, Some(Gesture { mode: Mode::Limb(d), .. }) if d.started)
    }
}

/// What one frame of gesture handling works on.
struct Frame<'a> {
    cfg: &'a GestureConfig,
    now: f64,
    orbit: OrbitCamera,
    chain: Option<usize>,
    camera: Option<View>,
    sizes: &'a [(Entity, Vec2)],
    default_size: Vec2,
    zones: &'a TouchZones,
    /// One-finger taps of this frame (window, position).
    taps: Vec<(Entity, Vec2)>,
    zone_gestures: Vec<ZoneGesture>,
    pose: Option<Mut<'a, CurrentPose>>,
    fitted: bool,
    stop_animation: bool,
    interactions: usize,
    three_finger_taps: usize,
    moved: bool,
}

impl Frame<'_> {
    fn view(&self, window: Entity) -> View {
        if let Some(v) = self.camera {
            return v;
        }
        let size = self
            .sizes
            .iter()
            .find(|(e, _)| *e == window)
            .map(|(_, s)| *s)
            .unwrap_or(self.default_size);
        View::from_orbit(&self.orbit, size, self.cfg.fov_y)
    }

    /// The limb drag a press at `position` starts, if it lands on the selected end bone.
    fn limb_drag_at(&self, window: Entity, position: Vec2) -> Option<LimbDrag> {
        let chain = self.chain?;
        if !self.fitted {
            return None;
        }
        let skeleton = &self.pose.as_ref()?.0;
        let template = skeleton.template.clone();
        let end = ik::end_bone(&template, chain)?;
        let posed = skeleton.pose();
        let view = self.view(window);
        let ray = view.ray(position);
        bone_hit(
            &ray,
            &posed.bones[end],
            self.cfg.pick_slack_px * view.pixel_size(),
        )?;
        let bones = ik::limb_bones(&template, chain);
        let effector = *ik::chain_points(&posed, &bones).last()?;
        let depth = (effector - view.eye).dot(view.forward());
        if !(depth > 0.0) {
            return None;
        }
        Some(LimbDrag {
            bones,
            depth,
            offset: effector - ray.at_depth(view.forward(), depth),
            started: false,
        })
    }

    /// Selects the chain under a tap.
    fn select_at(&mut self, window: Entity, position: Vec2) {
        let view = self.view(window);
        let ray = view.ray(position);
        self.chain = self.pose.as_ref().and_then(|pose| {
            let posed = pose.0.pose();
            let slack = self.cfg.pick_slack_px * view.pixel_size();
            pick_bone(&ray, &posed.bones, slack).and_then(|b| chain_of_bone(&pose.0.template, b))
        });
    }
}

fn touch_count(pointers: &[Pointer]) -> usize {
    pointers
        .iter()
        .filter(|p| matches!(p.id, PointerId::Touch(_)))
        .count()
}

/// Span and midpoint of the first two touches.
fn two_touches(pointers: &[Pointer]) -> Option<(f32, Vec2)> {
    let mut it = pointers
        .iter()
        .filter(|p| matches!(p.id, PointerId::Touch(_)));
    let a = it.next()?.position;
    let b = it.next()?.position;
    Some(((b - a).length(), (a + b) * 0.5))
}

impl GestureState {
    fn handle(&mut self, ev: PointerEvent, ui_pressed: bool, f: &mut Frame) {
        match ev.phase {
            Phase::Start => self.start(ev, ui_pressed, f),
            Phase::Move => self.moved(ev, f),
            Phase::End | Phase::Cancel => self.end(ev, f),
        }
    }

    fn start(&mut self, ev: PointerEvent, ui_pressed: bool, f: &mut Frame) {
        f.interactions += 1;
        if self.pointers.iter().any(|p| p.id == ev.id) {
            return;
        }
        // A mouse press while fingers are down (a platform's emulated pointer) is ignored.
        let is_mouse = !matches!(ev.id, PointerId::Touch(_));
        if is_mouse && touch_count(&self.pointers) > 0 {
            return;
        }
        self.pointers.push(Pointer {
            id: ev.id,
            window: ev.window,
            start: ev.position,
            position: ev.position,
        });
        match &mut self.gesture {
            None => {
                let mode = if ui_pressed {
                    Mode::Inert
                } else if let Some(zone) = f.zones.at(ev.position) {
                    Mode::Zone(zone)
                } else if ev.id == PointerId::MousePan {
                    Mode::Pan
                } else if let Some(drag) = f.limb_drag_at(ev.window, ev.position) {
                    Mode::Limb(drag)
                } else {
                    Mode::Orbit
                };
                self.gesture = Some(Gesture {
                    started_at: f.now,
                    max_pointers: 1,
                    moved: false,
                    canceled: false,
                    on_ui: ui_pressed,
                    mode,
                });
            }
            Some(g) => {
                g.max_pointers = g.max_pointers.max(self.pointers.len());
                if !g.on_ui
                    && !matches!(g.mode, Mode::Zone(_))
                    && touch_count(&self.pointers) >= 2
                    && let Some((span, mid)) = two_touches(&self.pointers)
                {
                    g.mode = Mode::Multi { span, mid };
                }
            }
        }
    }

    fn moved(&mut self, ev: PointerEvent, f: &mut Frame) {
        let Some(i) = self.pointers.iter().position(|p| p.id == ev.id) else {
            return;
        };
        let old = self.pointers[i].position;
        let start = self.pointers[i].start;
        let window = self.pointers[i].window;
        self.pointers[i].position = ev.position;
        if ev.position == old {
            return;
        }
        f.moved = true;
        let Some(g) = &mut self.gesture else { return };
        let mut crossing = false;
        if !g.moved && (ev.position - start).length() > f.cfg.tap_max_move_px {
            g.moved = true;
            crossing = true;
        }
        if !g.moved {
            return;
        }
        let delta = if crossing {
            ev.position - start
        } else {
            ev.position - old
        };
        match &mut g.mode {
            Mode::Inert | Mode::Zone(_) => {}
            Mode::Orbit => orbit_by(&mut f.orbit, delta, f.cfg),
            Mode::Pan => {
                let px = f.view(window).pixel_size();
                pan_by(&mut f.orbit, delta, px);
            }
            Mode::Multi { span, mid } => {
                if let Some((s, m)) = two_touches(&self.pointers) {
                    if *span > 1.0 && s > 1.0 {
                        zoom_by(&mut f.orbit, *span / s, f.cfg);
                    }
                    let px = f.view(window).pixel_size();
                    pan_by(&mut f.orbit, m - *mid, px);
                    *span = s;
                    *mid = m;
                }
            }
            Mode::Limb(drag) => {
                let view = f.view(window);
                let ray = view.ray(ev.position);
                let target = ray.at_depth(view.forward(), drag.depth) + drag.offset;
                if let Some(pose) = f.pose.as_mut() {
                    if !drag.started {
                        drag.started = true;
                        f.stop_animation = true;
                    }
                    ik::drag_chain(&mut pose.0, &drag.bones, target, &f.cfg.ik);
                }
            }
        }
    }

    fn end(&mut self, ev: PointerEvent, f: &mut Frame) {
        let Some(i) = self.pointers.iter().position(|p| p.id == ev.id) else {
            return;
        };
        let p = self.pointers.remove(i);
        let position = if ev.phase == Phase::End {
            ev.position
        } else {
            p.position
        };
        let Some(g) = &mut self.gesture else { return };
        if ev.phase == Phase::Cancel {
            g.canceled = true;
        }
        if !self.pointers.is_empty() {
            // Fewer fingers: re-anchor a pinch, or go on orbiting with the one left.
            if let Mode::Multi { .. } = g.mode {
                g.mode = match two_touches(&self.pointers) {
                    Some((span, mid)) => Mode::Multi { span, mid },
                    None => Mode::Orbit,
                };
            }
            return;
        }
        let g = self.gesture.take().expect("gesture");
        let quick = f.now - g.started_at <= f.cfg.tap_max_s as f64;
        if let Mode::Zone(zone) = g.mode {
            self.last_tap = None;
            if g.canceled || g.on_ui || g.max_pointers != 1 {
                return;
            }
            let kind = if g.moved {
                ZoneGestureKind::Swipe {
                    delta: position - p.start,
                }
            } else if quick {
                ZoneGestureKind::Tap
            } else {
                return;
            };
            f.zone_gestures.push(ZoneGesture {
                zone,
                start: p.start,
                kind,
            });
            return;
        }
        if g.canceled || g.moved || g.on_ui || !quick {
            return;
        }
        match g.max_pointers {
            1 => {
                f.select_at(p.window, position);
                f.taps.push((p.window, position));
                let double = self.last_tap.is_some_and(|(t, at)| {
                    g.started_at - t <= f.cfg.double_tap_s as f64
                        && (position - at).length() <= f.cfg.double_tap_px
                });
                if double {
                    f.orbit.reset();
                    self.last_tap = None;
                } else {
                    self.last_tap = Some((f.now, position));
                }
            }
            3 => f.three_finger_taps += 1,
            _ => {}
        }
    }
}

#[derive(SystemParam)]
struct Inputs<'w, 's> {
    touches: MessageReader<'w, 's, TouchInput>,
    cursor: MessageReader<'w, 's, CursorMoved>,
    buttons: MessageReader<'w, 's, MouseButtonInput>,
    wheel: MessageReader<'w, 's, MouseWheel>,
}

#[derive(SystemParam)]
struct Viewports<'w, 's> {
    cameras: Query<
        'w,
        's,
        (
            &'static Camera,
            &'static GlobalTransform,
            Option<&'static Projection>,
        ),
    >,
    windows: Query<'w, 's, (Entity, &'static Window)>,
    primary: Query<'w, 's, &'static Window, With<PrimaryWindow>>,
    settings: Option<Res<'w, Settings>>,
}

impl Viewports<'_, '_> {
    /// The view of the first active perspective camera with a known viewport.
    fn camera_view(&self) -> Option<View> {
        self.cameras
            .iter()
            .find_map(|(camera, transform, projection)| {
                if !camera.is_active {
                    return None;
                }
                let Some(Projection::Perspective(p)) = projection else {
                    return None;
                };
                let rect = camera.logical_viewport_rect()?;
                Some(View {
                    eye: transform.translation(),
                    rotation: transform.rotation(),
                    fov_y: p.fov,
                    origin: rect.min,
                    size: rect.size(),
                })
            })
    }

    fn default_size(&self, fallback: Vec2) -> Vec2 {
        if let Some(w) = self.primary.iter().next() {
            return Vec2::new(w.width(), w.height());
        }
        if let Some(s) = &self.settings {
            return Vec2::new(s.0.window.width as f32, s.0.window.height as f32);
        }
        fallback
    }
}

#[derive(SystemParam)]
struct Outputs<'w> {
    interactions: MessageWriter<'w, Interaction>,
    three_finger: MessageWriter<'w, ThreeFingerTap>,
    taps: MessageWriter<'w, Tap>,
    zone_gestures: MessageWriter<'w, ZoneGesture>,
}

#[allow(clippy::too_many_arguments)]
fn gestures(
    mut inputs: Inputs,
    viewports: Viewports,
    mut out: Outputs,
    zones: Res<TouchZones>,
    mut state: ResMut<GestureState>,
    cfg: Res<GestureConfig>,
    time: Res<Time>,
    mut orbit: ResMut<OrbitCamera>,
    mut selection: ResMut<Selection>,
    active: Option<Res<ActiveStatue>>,
    mut statues: Query<(Entity, &mut CurrentPose, Has<FittedSkeleton>)>,
    ui_nodes: Query<&UiInteraction>,
    mut commands: Commands,
    mut events: Local<Vec<PointerEvent>>,
    mut sizes: Local<Vec<(Entity, Vec2)>>,
) {
    // Collect this frame's pointer events: touches in order, then the mouse.
    events.clear();
    for t in inputs.touches.read() {
        let phase = match t.phase {
            TouchPhase::Started => Phase::Start,
            TouchPhase::Moved => Phase::Move,
            TouchPhase::Ended => Phase::End,
            TouchPhase::Canceled => Phase::Cancel,
        };
        events.push(PointerEvent {
            id: PointerId::Touch(t.id),
            phase,
            position: t.position,
            window: t.window,
        });
    }
    for c in inputs.cursor.read() {
        state.cursor = Some((c.window, c.position));
        for id in [PointerId::Mouse, PointerId::MousePan] {
            events.push(PointerEvent {
                id,
                phase: Phase::Move,
                position: c.position,
                window: c.window,
            });
        }
    }
    for b in inputs.buttons.read() {
        let id = match b.button {
            MouseButton::Left => PointerId::Mouse,
            MouseButton::Right => PointerId::MousePan,
            _ => continue,
        };
        let position = match state.cursor {
            Some((w, p)) if w == b.window => p,
            _ => viewports
                .windows
                .get(b.window)
                .ok()
                .and_then(|(_, w)| w.cursor_position())
                .unwrap_or_default(),
        };
        events.push(PointerEvent {
            id,
            phase: match b.state {
                ButtonState::Pressed => Phase::Start,
                ButtonState::Released => Phase::End,
            },
            position,
            window: b.window,
        });
    }
    let mut wheel_lines = 0.0;
    let mut wheel_events = 0;
    for w in inputs.wheel.read() {
        wheel_events += 1;
        wheel_lines += match w.unit {
            MouseScrollUnit::Line => w.y,
            MouseScrollUnit::Pixel => w.y / MouseScrollUnit::SCROLL_UNIT_CONVERSION_FACTOR,
        };
    }
    if events.is_empty() && wheel_events == 0 {
        return;
    }

    sizes.clear();
    sizes.extend(
        viewports
            .windows
            .iter()
            .map(|(e, w)| (e, Vec2::new(w.width(), w.height()))),
    );
    let statue = active
        .as_ref()
        .and_then(|a| a.entity)
        .filter(|e| statues.contains(*e))
        .or_else(|| statues.iter().next().map(|(e, ..)| e));
    let (pose, fitted) = match statue.and_then(|e| statues.get_mut(e).ok()) {
        Some((_, pose, fitted)) => (Some(pose), fitted),
        None => (None, false),
    };
    let mut frame = Frame {
        cfg: &cfg,
        now: time.elapsed_secs_f64(),
        orbit: *orbit,
        chain: selection.chain,
        camera: viewports.camera_view(),
        sizes: &sizes,
        default_size: viewports.default_size(cfg.fallback_viewport),
        zones: &zones,
        taps: Vec::new(),
        zone_gestures: Vec::new(),
        pose,
        fitted,
        stop_animation: false,
        interactions: 0,
        three_finger_taps: 0,
        moved: false,
    };
    let ui_pressed = ui_nodes.iter().any(|i| *i == UiInteraction::Pressed);
    for ev in events.iter().copied() {
        state.handle(ev, ui_pressed, &mut frame);
    }
    if wheel_events > 0 {
        frame.interactions += 1;
        zoom_by(
            &mut frame.orbit,
            (-wheel_lines * cfg.wheel_zoom_per_line).exp(),
            &cfg,
        );
    }

    if frame.moved {
        frame.interactions += 1;
    }
    for _ in 0..frame.interactions {
        out.interactions.write(Interaction);
    }
    for _ in 0..frame.three_finger_taps {
        out.three_finger.write(ThreeFingerTap);
    }
    for &(window, position) in &frame.taps {
        let view = frame.view(window);
        out.taps.write(Tap {
            window,
            position,
            ray: view.ray(position),
            slack_per_depth: cfg.pick_slack_px * view.pixel_size(),
        });
    }
    for g in frame.zone_gestures.drain(..) {
        out.zone_gestures.write(g);
    }
    if frame.stop_animation
        && let Some(e) = statue
    {
        commands.entity(e).remove::<PoseAnimation>();
    }
    if frame.orbit != *orbit {
        *orbit = frame.orbit;
    }
    if frame.chain != selection.chain {
        selection.chain = frame.chain;
    }
}
