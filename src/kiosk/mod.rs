//! The kiosk: a Bevy app where visitors watch a statue's anatomy appear and re-pose it by
//! touch. It is a set of plugins over the bevy-free core (`cloud`, `fakir`, `skinning`,
//! `anatomy`), in the manner of `bevy_picking`: one module per stage, plugin structs that
//! carry their settings, and ordered system sets.
//!
//! ## Pipeline (one frame)
//!
//! ```text
//! KioskSet::Input     gestures: touch/mouse → orbit camera, taps on bones, limb drags (IK);
//!                     then taps on ghost bones, the donor carousel, the hypothesis strip
//! KioskSet::Idle      attract mode, "still there?" countdown, reset
//! KioskSet::Load      statue files read and prepared off the main thread; cache look-ups;
//!                     part swapping's jobs polled (support, donors, parts brought to size)
//! KioskSet::Register  incremental FAKIR within a per-frame budget (the skeleton settles in);
//!                     a part flying in, and the restoration shown written to the statue
//! KioskSet::Animate   pose animations (eased), limb drags → the statue's current pose
//! KioskSet::Skin      the binding deforms the points into the statue's point buffer (at the
//!                     fitted pose: the scan's own points); ghost bones follow the pose
//! KioskSet::Render    point buffer → GPU splats, bones and ghost bones, camera
//! KioskSet::Ui        pose strip, carousel, progress, error cards, operator panel; part
//!                     swapping's touch zones and overlay
//! ```
//!
//! | plugin | module |
//! |---|---|
//! | loading, cache, statue carousel | [`statue`] |
//! | incremental FAKIR | [`fitting`] |
//! | pose animation, skinning | [`animate`] |
//! | touch and mouse gestures, picking, touch zones | [`gestures`] (limb drags: [`ik`]) |
//! | attract mode, idle reset | [`attract`] |
//! | visitor interface, operator panel | [`ui`] |
//! | part swapping on broken statues (ghost bones, donor carousel, hypotheses, undo) | [`restore`] |
//! | GPU splats, bones, camera (not headless) | [`render`] |
//!
//! ## Entities
//! * a **statue** ([`Statue`], [`StatueState`], and once ready [`FittedSkeleton`],
//!   [`StatueBinding`], [`CurrentPose`], [`SkinnedPoints`]);
//! * its **bones**: child entities ([`BoneMarker`]) placed from the current pose, drawn as
//!   translucent sphere-mesh bones while fitting, while posing, or when toggled;
//! * its **points**: the rendered cloud (a child entity owned by the render plugin);
//! * on a broken statue, once analysed: [`restore::Restoration`] (missing parts, completed
//!   skeleton, the restorations kept side by side) and [`restore::Provenance`] on the statue,
//!   its **ghost bones** ([`restore::GhostBone`] children, one per bone of a missing part), and
//!   while a part flies in a child entity with its own [`SkinnedPoints`]. Swapping a part
//!   replaces the statue's [`StatueCloud`], [`FittedSkeleton`], [`StatueBinding`] and
//!   [`CurrentPose`]; undo puts the originals back (the very same point cloud).
//!
//! Only one statue is shown at a time ([`ActiveStatue`]); the carousel switches statues by
//! despawning the current one and spawning the next ([`StatueSelected`]).

pub mod animate;
pub mod attract;
pub mod config;
pub mod fitting;
pub mod gestures;
pub mod ik;
pub mod render;
pub mod restore;
pub mod statue;
pub mod ui;

use crate::anatomy::Skeleton;
use crate::cloud::PointCloud;
use crate::fakir::Attempt;
use crate::math::{Vec2, Vec3};
use crate::skinning::{Binding, Scratch};
use bevy::prelude::*;
use config::KioskConfig;
use std::sync::Arc;

/// The ordered stages of a kiosk frame (see the module docs).
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum KioskSet {
    Input,
    Idle,
    Load,
    Register,
    Animate,
    Skin,
    Render,
    Ui,
}

/// The configuration, as a resource (read by every plugin).
#[derive(Resource, Clone, Debug)]
pub struct Settings(pub KioskConfig);

/// Which statue of the carousel is shown.
#[derive(Resource, Clone, Copy, Debug, Default)]
pub struct ActiveStatue {
    /// Index in the configuration's statue list.
    pub index: usize,
    /// The statue entity, once spawned.
    pub entity: Option<Entity>,
}

/// A statue entity.
#[derive(Component, Clone, Debug)]
pub struct Statue {
    /// Index in the configuration's statue list.
    pub index: usize,
    /// Title shown to visitors.
    pub title: String,
}

/// Where a statue is in its life.
#[derive(Component, Debug)]
pub enum StatueState {
    /// The file is being read (and normals estimated) off the main thread.
    Loading,
    /// FAKIR is running, a budget per frame; `units` counts the work units done so far and
    /// `attempt` says which registration of the figure runs (FAKIR's `Progress.attempt`: the
    /// whole figure, or again without limbs found lost), and
    /// `fraction` estimates the share of that attempt done (FAKIR's `Progress.activity.fraction`,
    /// in `[0, 1]`, never decreasing): visitors see it as a percentage and a bar.
    Fitting {
        units: u64,
        fraction: f32,
        attempt: Attempt,
    },
    /// The fit is done; the binding is being built off the main thread.
    Binding,
    /// Ready to pose.
    Ready,
    /// Something went wrong; the message is for the operator, the card for the visitor.
    Failed { message: String },
}

/// The statue's point cloud (subsampled to the point budget).
#[derive(Component, Clone, Debug)]
pub struct StatueCloud(pub Arc<PointCloud>);

/// The statue's fitted skeleton.
#[derive(Component, Clone, Debug)]
pub struct FittedSkeleton(pub Skeleton);

/// The statue's binding.
#[derive(Component, Clone)]
pub struct StatueBinding(pub Arc<Binding>);

/// The pose the statue shows now (the fitted skeleton re-posed). While fitting it is the
/// registration's current skeleton.
#[derive(Component, Clone, Debug)]
pub struct CurrentPose(pub Skeleton);

/// A running pose change: from `from` to `to` over `duration` seconds, eased.
#[derive(Component, Clone, Debug)]
pub struct PoseAnimation {
    pub from: Skeleton,
    pub to: Skeleton,
    pub elapsed: f32,
    pub duration: f32,
}

/// The statue's skinned points: rewritten in place by the skinning system (no allocation per
/// frame), read by the renderer when `version` changes.
#[derive(Component)]
pub struct SkinnedPoints {
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    pub colors: Option<Vec<[u8; 3]>>,
    pub version: u64,
    pub scratch: Scratch,
}

/// A bone of the statue (child entity), placed from [`CurrentPose`].
#[derive(Component, Clone, Copy, Debug)]
pub struct BoneMarker {
    /// Bone index in the template.
    pub index: usize,
}

/// The selected limb (a chain of the template), if any.
#[derive(Resource, Clone, Debug, Default)]
pub struct Selection {
    /// Selected chain index.
    pub chain: Option<usize>,
}

/// Whether bones are drawn (operator toggle); they are also drawn while fitting and posing.
#[derive(Resource, Clone, Copy, Debug, Default)]
pub struct ShowBones(pub bool);

/// The orbiting camera's state, driven by gestures and attract mode and applied to the camera
/// by the render plugin.
#[derive(Resource, Clone, Copy, Debug, PartialEq)]
pub struct OrbitCamera {
    /// Point looked at.
    pub target: Vec3,
    /// Turn about the up axis (radians).
    pub yaw: f32,
    /// Elevation (radians, clamped to ±1.4).
    pub pitch: f32,
    /// Distance from the target.
    pub distance: f32,
    /// Pan offset in the view plane (fractions of the distance).
    pub pan: Vec2,
    /// The home view (double tap and reset go back to it).
    pub home: (f32, f32, f32),
}

impl Default for OrbitCamera {
    fn default() -> Self {
        OrbitCamera {
            target: Vec3::ZERO,
            yaw: 0.0,
            pitch: 0.1,
            distance: 3.0,
            pan: Vec2::ZERO,
            home: (0.0, 0.1, 3.0),
        }
    }
}

impl OrbitCamera {
    /// Back to the home view.
    pub fn reset(&mut self) {
        (self.yaw, self.pitch, self.distance) = self.home;
        self.pan = Vec2::ZERO;
    }
    /// The eye position.
    pub fn eye(&self) -> Vec3 {
        let dir = Vec3::new(
            self.pitch.cos() * self.yaw.sin(),
            self.pitch.sin(),
            self.pitch.cos() * self.yaw.cos(),
        );
        self.target + dir * self.distance + self.pan_offset()
    }
    /// The pan offset in world space.
    pub fn pan_offset(&self) -> Vec3 {
        let right = Vec3::new(self.yaw.cos(), 0.0, -self.yaw.sin());
        (right * self.pan.x + Vec3::Y * self.pan.y) * self.distance
    }
    /// The point looked at, panned.
    pub fn focus(&self) -> Vec3 {
        self.target + self.pan_offset()
    }
}

/// Logical pixels the interface covers at the top and at the bottom of the window: the scene
/// between them is where the statue is framed ([`statue::frame_camera`]). The defaults are
/// those of the visitor interface at its usual size; with a window the UI plugin measures its
/// own layout every frame and keeps this up to date ([`ui`]).
#[derive(Resource, Clone, Copy, Debug, PartialEq)]
pub struct SceneMargins {
    /// From the window's top edge to the bottom of the top bar.
    pub top: f32,
    /// From the top of the status/hint line (above the pose strip) to the window's bottom
    /// edge.
    pub bottom: f32,
}

impl Default for SceneMargins {
    fn default() -> Self {
        SceneMargins {
            top: ui::SCENE_TOP_PX,
            bottom: ui::SCENE_BOTTOM_PX,
        }
    }
}

/// The logical size of the screen: the primary window's, else the configured window size.
pub fn screen_size(window: Option<&bevy::window::Window>, cfg: &KioskConfig) -> Vec2 {
    match window {
        Some(w) => Vec2::new(w.width(), w.height()),
        None => Vec2::new(cfg.window.width as f32, cfg.window.height as f32),
    }
}

/// A visitor asked for a pose (by name, from the pose strip or attract mode).
#[derive(Message, Clone, Debug)]
pub struct PoseRequested(pub String);

/// A visitor picked another statue on the carousel.
#[derive(Message, Clone, Copy, Debug)]
pub struct StatueSelected(pub usize);

/// Back to the home state (reset button, end of the idle countdown).
#[derive(Message, Clone, Copy, Debug, Default)]
pub struct ResetRequested;

/// Any visitor interaction (resets the idle timers).
#[derive(Message, Clone, Copy, Debug, Default)]
pub struct Interaction;

/// The kiosk: every plugin, configured from `settings`.
pub struct KioskPlugin {
    pub config: KioskConfig,
    /// Without a window and GPU (tests): no render plugin.
    pub headless: bool,
}

impl Plugin for KioskPlugin {
    fn build(&self, app: &mut App) {
        for p in &self.config.problems {
            warn!("{p}");
        }
        app.insert_resource(Settings(self.config.clone()))
            .init_resource::<ActiveStatue>()
            .init_resource::<Selection>()
            .init_resource::<ShowBones>()
            .init_resource::<OrbitCamera>()
            .init_resource::<SceneMargins>()
            .add_message::<PoseRequested>()
            .add_message::<StatueSelected>()
            .add_message::<ResetRequested>()
            .add_message::<Interaction>()
            .configure_sets(
                Update,
                (
                    KioskSet::Input,
                    KioskSet::Idle,
                    KioskSet::Load,
                    KioskSet::Register,
                    KioskSet::Animate,
                    KioskSet::Skin,
                    KioskSet::Render,
                    KioskSet::Ui,
                )
                    .chain(),
            )
            .add_plugins((
                statue::StatuePlugin,
                fitting::FittingPlugin {
                    budget_ms: self.config.budget.fakir_ms_per_frame,
                },
                animate::AnimatePlugin,
                gestures::GesturePlugin::default(),
                attract::AttractPlugin,
                ui::UiPlugin {
                    headless: self.headless,
                },
                restore::PartSwapPlugin {
                    settings: restore::PartSwapSettings {
                        thumbnails: !self.headless,
                        ..Default::default()
                    },
                    headless: self.headless,
                },
            ));
        if !self.headless {
            app.add_plugins(render::SplatRenderPlugin);
        }
    }
}
