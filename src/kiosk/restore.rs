//! Part swapping: a broken statue shows its missing parts as **ghost bones**; tapping one opens
//! a **donor carousel** of the other statues' versions of that part, each already brought to
//! the statue's size; tapping a donor makes the part **fly in**, morphing from the donor's size
//! and pose to the statue's, and **merge**. Each restoration is kept as a **hypothesis**:
//! swipe between them, undo the last one. A restored statue is re-posed like any other. The
//! algorithms are the core's ([`crate::restore`]); this module schedules them off the main
//! thread and draws the result.
//!
//! ## Flow
//!
//! ```text
//! statue Ready ──(thread)── support, parts, completed skeleton ─► Restoration + GhostBone entities
//!                             └─ donors: other statues of the same template, loaded (cached
//!                                fit, or fitted in the background) ─(thread)─ per part × donor:
//!                                check + transfer (+ thumbnail) ─► carousel entry Ready
//! Tap on a ghost bone ─► carousel (part) ─► ZoneGesture tap on an entry ─► Flight:
//!    the part's points eased from donor space (donor size and pose, at the statue's joint)
//!    to the transferred positions, while (thread) Assembly::add merges (eq. 5.1) and the new
//!    cloud is bound ─► new Hypothesis shown: cloud, fit, binding and Provenance replaced
//! Undo (tap) ─► back to the hypothesis it was built on (the first one is the scan as found,
//!    kept as loaded: its points come back bit for bit) · swipe on the strip ─► another one
//! ```
//!
//! | stage | systems |
//! |---|---|
//! | [`KioskSet::Input`] (after [`GestureSystems`]) | taps on ghost bones ([`Tap`], picked with [`pick_bone`] on the statue's bones with the ghosts in place), taps and swipes on the carousel and the hypothesis strip ([`ZoneGesture`]) |
//! | [`KioskSet::Load`] | statue changes and resets, the analysis, donors, part preparation (all polled, never awaited) |
//! | [`KioskSet::Register`] | the flight and its landing, then the hypothesis shown written to the statue (before the frame's animation and skinning) |
//! | [`KioskSet::Skin`] | ghost bones placed from the frame's pose |
//! | [`KioskSet::Ui`] | touch zones, the notice's clock, and (with a window) the overlay |
//!
//! **Ghost bones.** Each bone of a missing part is a [`GhostBone`] entity, child of the statue,
//! placed from [`CurrentPose`] with the completed skeleton's size; its rotation relative to its
//! parent is the completed one (the mirror limb, [`crate::fakir::support`]) unless the
//! current pose turned that bone (a preset pose names it), then the pose's. The render plugin
//! draws them hatched and pale blue ([`super::render`]). A part that grows from a bone cut
//! part-way ([`crate::restore::stump`]) takes that bone too, but only its lost bones are
//! ghosts ([`Part::lost_bones`]): the stump is the statue's own, and a tap on it selects the
//! limb for posing as before.
//!
//! **Donors** are the other statues of the configuration with the same template. Each is loaded
//! once per run ([`Donors`]) with its cached fit and binding ([`super::statue`]); one without a
//! cache entry is fitted in a background thread when [`PartSwapSettings::fit_donors`] is on
//! (cancelled when the app ends) and shows as pending meanwhile. Preparing a part checks that
//! the donor has it ([`check_donor`]), then transfers it ([`transfer`], pose from
//! [`PartSwapSettings::pose`]); the carousel shows what is ready, pending or unavailable.
//!
//! **Flight.** The part's points start at the donor's own positions moved rigidly so that the
//! donor's joint sits on the statue's (root frames aligned), plus an offset away from the body
//! that vanishes, and end at the transferred positions; both are blended with
//! [`crate::anatomy::pose::ease`] over [`PartSwapSettings::fly_seconds`]. The points fly as a
//! child entity with its own [`SkinnedPoints`] (so the splat renderer draws them). Meanwhile the
//! merge and the new binding run off the main thread; the part lands when both are done. The
//! statue is brought back to its fitted pose during the flight (the part lands there).
//!
//! **Provenance.** [`Provenance`] on the statue gives, per point, `0` for the statue's own and
//! `1 + i` for a point from the `i`-th statue of the configuration, and the bone it came with.
//!
//! **Never a dead screen.** A failed analysis leaves the statue as it is (logged); a donor that
//! cannot give the part shows as unavailable, and tapping it, or a failed merge, shows a gentle
//! [`Notice`] (`texts.part_failed`) for a few seconds; the kiosk goes on.
//!
//! **Layout.** The carousel (left) and the hypothesis strip with the undo button (right) are
//! laid out by [`swap_layout`] in logical pixels and registered as [`TouchZones`], so the same
//! rectangles take injected touches headless and are drawn with bevy_ui (absolute nodes)
//! with a window. Texts come from `[texts]` ([`super::config::Texts`]).

use super::config::{KioskConfig, Texts};
use super::gestures::{
    GestureSystems, Tap, TouchZone, TouchZones, ZoneGesture, ZoneGestureKind, pick_bone,
};
use super::render::bone_transform;
use super::statue::{Pending, load, write_cache};
use super::ui::{self, Look, UiFont};
use super::{
    ActiveStatue, CurrentPose, FittedSkeleton, KioskSet, PoseAnimation, ResetRequested, Selection,
    Settings, SkinnedPoints, Statue, StatueBinding, StatueCloud, StatueState, screen_size,
};
use crate::anatomy::pose::ease;
use crate::anatomy::{Skeleton, Template};
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::fakir::register;
use crate::fakir::solver::{Cancelled, Pause, Solver};
use crate::fakir::support::{BoneSupport, complete_cut, support};
use crate::geometry::Bone;
use crate::restore::merge::MergeOptions;
use crate::restore::stump::start_at_stumps;
use crate::restore::transfer::{Part, PoseSource, TransferOptions, Transferred, parts_of};
use crate::restore::{Assembly, FROM_TARGET, check_donor, nearest_bones, transfer::transfer};
use crate::skinning::{Binding, Scratch};
use bevy::prelude::*;
use bevy::window::PrimaryWindow;
use std::collections::HashMap;
use std::sync::Arc;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, AtomicU8, Ordering};

/// Settings of part swapping (a resource; insert your own after adding the plugin to change
/// them).
#[derive(Resource, Clone, Debug)]
pub struct PartSwapSettings {
    /// Seconds the part takes to fly in.
    pub fly_seconds: f32,
    /// Where the part's pose comes from: [`PoseSource::Keep`] (default) lands it in the
    /// statue's completed pose (the mirror limb), [`PoseSource::Donor`] in the donor's.
    pub pose: PoseSource,
    /// Transfer options (the pose is [`PartSwapSettings::pose`]).
    pub transfer: TransferOptions,
    pub merge: MergeOptions,
    /// Fit donors without a cached fit in a background thread (else they stay pending).
    pub fit_donors: bool,
    /// Draw a picture of each donor's part on the carousel (software renderer; needs a window).
    pub thumbnails: bool,
    /// Thumbnail size, pixels.
    pub thumbnail_px: (u32, u32),
    /// Seconds a notice stays on screen.
    pub notice_seconds: f32,
    /// Smallest horizontal swipe (logical pixels) that changes the hypothesis or the page.
    pub swipe_px: f32,
}

impl Default for PartSwapSettings {
    fn default() -> Self {
        PartSwapSettings {
            fly_seconds: 1.0,
            pose: PoseSource::Keep,
            transfer: TransferOptions::default(),
            merge: MergeOptions::default(),
            fit_donors: true,
            thumbnails: false,
            thumbnail_px: (120, 84),
            notice_seconds: 4.0,
            swipe_px: 60.0,
        }
    }
}

/// Part swapping (see the module docs).
pub struct PartSwapPlugin {
    pub settings: PartSwapSettings,
    /// Without a window: no overlay drawn (the touch zones work all the same).
    pub headless: bool,
}

impl Plugin for PartSwapPlugin {
    fn build(&self, app: &mut App) {
        app.insert_resource(self.settings.clone())
            .init_resource::<PartSwap>()
            .init_resource::<Donors>()
            .init_resource::<TouchZones>()
            .init_resource::<Selection>()
            .add_message::<Tap>()
            .add_message::<ZoneGesture>()
            .add_message::<ResetRequested>()
            .add_systems(
                Update,
                (tap_ghosts, zone_gestures)
                    .chain()
                    .in_set(KioskSet::Input)
                    .after(GestureSystems),
            )
            .add_systems(
                Update,
                (follow_statue, analyse, poll_donors, prepare_parts)
                    .chain()
                    .in_set(KioskSet::Load),
            )
            .add_systems(
                Update,
                (fly, apply_hypothesis).chain().in_set(KioskSet::Register),
            )
            .add_systems(Update, place_ghosts.in_set(KioskSet::Skin))
            .add_systems(Update, (update_zones, tick_notice).in_set(KioskSet::Ui));
        if !self.headless {
            app.add_systems(Startup, spawn_overlay.after(ui::load_font))
                .add_systems(
                    Update,
                    draw_overlay.after(update_zones).in_set(KioskSet::Ui),
                );
        }
    }
}

// ---------------------------------------------------------------------------------------------
// State.

/// A bone of a missing part, drawn as a ghost (child entity of the statue).
#[derive(Component, Clone, Copy, Debug, PartialEq)]
pub struct GhostBone {
    /// Bone index in the template.
    pub bone: usize,
    /// Part index in [`Restoration::parts`].
    pub part: usize,
    /// Its geometry in the statue's frame (the entity's [`Transform`] puts `c1` at the origin,
    /// local `+Y` along the bone).
    pub shape: Bone,
}

/// Per point of the statue shown: where it comes from (see the module docs).
#[derive(Component, Clone, Debug)]
pub struct Provenance {
    /// [`FROM_TARGET`] (0) for the statue's own points, `1 + i` for the `i`-th statue's.
    pub source: Arc<Vec<u32>>,
    /// The bone each point came with.
    pub bone: Arc<Vec<u32>>,
}

/// One restoration of a statue (the first one: the statue as found).
#[derive(Clone)]
pub struct Hypothesis {
    pub cloud: Arc<PointCloud>,
    pub provenance: Provenance,
    pub fit: Skeleton,
    pub binding: Arc<Binding>,
    /// Parts restored, in order: (part index, donor statue index).
    pub restored: Vec<(usize, usize)>,
    /// The hypothesis it was built on (undo goes back there).
    pub parent: Option<usize>,
}

/// A part of a donor, prepared for the statue.
pub struct Prepared {
    /// The part brought to the statue (its frame, size and pose).
    pub transferred: Transferred,
    /// Where each point starts its flight: the donor's own point, moved rigidly so that the
    /// donor's joint sits on the statue's.
    pub start: Vec<Vec3>,
    /// A picture of the part (when [`PartSwapSettings::thumbnails`] is on).
    pub thumbnail: Option<crate::render::Image>,
}

/// Preparation of one part from one donor.
pub enum Preparation {
    Running(Pending<Result<Prepared>>),
    Ready(Arc<Prepared>),
    Failed(String),
}

/// What part swapping knows of a statue (on the statue entity, once analysed).
#[derive(Component)]
pub struct Restoration {
    /// Support of every bone (of the statue as found).
    pub support: Vec<BoneSupport>,
    /// Its missing parts (each its lost bones, with the bone it grows from when that one is
    /// cut part-way: [`Part::from`]).
    pub parts: Vec<Part>,
    /// Its skeleton with every missing bone completed.
    pub completed: Skeleton,
    /// Restorations kept side by side; `[0]` is the statue as found.
    pub hypotheses: Vec<Hypothesis>,
    /// The one shown.
    pub shown: usize,
    /// Parts prepared from donors: (part index, donor statue index).
    pub prepared: HashMap<(usize, usize), Preparation>,
    /// Bumped on every change of `hypotheses` or `shown`.
    pub generation: u64,
    applied: u64,
}

impl Restoration {
    /// The hypothesis shown.
    pub fn current(&self) -> &Hypothesis {
        &self.hypotheses[self.shown.min(self.hypotheses.len() - 1)]
    }
    /// Parts still missing on the hypothesis shown (but `except`).
    pub fn missing_parts(&self, except: Option<usize>) -> Vec<usize> {
        let done = &self.current().restored;
        (0..self.parts.len())
            .filter(|p| Some(*p) != except && !done.iter().any(|(q, _)| q == p))
            .collect()
    }
    /// Shows hypothesis `i`.
    pub fn show(&mut self, i: usize) {
        if i < self.hypotheses.len() && i != self.shown {
            self.shown = i;
            self.generation += 1;
        }
    }
    /// Undo: drops the hypothesis shown (never the first) and shows the one it was built on.
    /// False when there was nothing to undo.
    pub fn undo(&mut self) -> bool {
        let k = self.shown;
        if k == 0 || k >= self.hypotheses.len() {
            return false;
        }
        let removed = self.hypotheses.remove(k);
        let parent = removed.parent.unwrap_or(0);
        for h in &mut self.hypotheses {
            h.parent = h.parent.map(|p| match p {
                p if p == k => parent,
                p if p > k => p - 1,
                p => p,
            });
        }
        self.shown = if parent > k { parent - 1 } else { parent };
        self.generation += 1;
        true
    }
    /// Back to the statue as found, every restoration dropped.
    pub fn reset(&mut self) {
        if self.hypotheses.len() > 1 || self.shown != 0 {
            self.hypotheses.truncate(1);
            self.shown = 0;
            self.generation += 1;
        }
    }
}

/// A donor statue, ready to give parts.
pub struct DonorData {
    pub cloud: Arc<PointCloud>,
    pub fit: Skeleton,
    pub binding: Arc<Binding>,
    /// Its missing bones (its registration's verdict, kept by its binding): it cannot lend
    /// them.
    pub missing: Vec<bool>,
}

/// Where a donor is.
#[derive(Clone)]
pub enum DonorStatus {
    Loading,
    /// No cached fit: being fitted in the background.
    Fitting,
    Ready(Arc<DonorData>),
    Failed(String),
}

struct DonorSlot {
    status: DonorStatus,
    job: Option<Pending<Result<DonorData>>>,
    stage: Arc<AtomicU8>,
    cancel: Arc<AtomicBool>,
}

impl Drop for DonorSlot {
    fn drop(&mut self) {
        self.cancel.store(true, Ordering::Relaxed);
    }
}

const STAGE_LOADING: u8 = 0;
const STAGE_FITTING: u8 = 1;

/// Donor statues, by index in the configuration (loaded once per run).
#[derive(Resource, Default)]
pub struct Donors {
    slots: HashMap<usize, DonorSlot>,
}

impl Donors {
    /// The status of statue `i` as a donor, if it was asked for.
    pub fn status(&self, i: usize) -> Option<DonorStatus> {
        self.slots.get(&i).map(|s| s.status.clone())
    }
}

/// The open donor carousel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Carousel {
    /// Part index in [`Restoration::parts`].
    pub part: usize,
    /// Page shown (when there are more donors than fit).
    pub page: usize,
}

/// A part flying in.
pub struct Flight {
    pub statue: Entity,
    /// The entity drawing the flying points.
    pub entity: Entity,
    pub part: usize,
    /// Donor statue index.
    pub donor: usize,
    /// The hypothesis it builds on.
    pub base: usize,
    pub elapsed: f32,
    pub duration: f32,
    pub prepared: Arc<Prepared>,
    /// Extra displacement at the start, gone at the end.
    pub offset: Vec3,
    job: Pending<Result<Hypothesis>>,
    landed: Option<Hypothesis>,
}

/// A gentle message on screen.
#[derive(Clone, Debug, PartialEq)]
pub struct Notice {
    pub text: String,
    pub remaining_s: f32,
}

/// What a carousel entry shows.
#[derive(Clone, Debug, PartialEq)]
pub enum EntryState {
    /// The donor or its part is being prepared.
    Pending,
    /// The part is ready (its number of points).
    Ready(usize),
    /// The donor cannot give this part (why, for the log).
    Unavailable(String),
}

/// One carousel entry.
#[derive(Clone, Debug, PartialEq)]
pub struct Entry {
    /// Donor statue index.
    pub statue: usize,
    pub title: String,
    pub state: EntryState,
}

/// Part swapping's kiosk-wide state (one statue is shown at a time).
#[derive(Resource, Default)]
pub struct PartSwap {
    /// The statue it follows.
    pub statue: Option<Entity>,
    pub carousel: Option<Carousel>,
    pub flight: Option<Flight>,
    pub notice: Option<Notice>,
    /// Parts landed so far (for tests and the operator).
    pub landed: u64,
}

impl PartSwap {
    /// The part flying in, if any.
    pub fn flying_part(&self) -> Option<usize> {
        self.flight.as_ref().map(|f| f.part)
    }
}

// ---------------------------------------------------------------------------------------------
// Pure helpers.

/// The statues that can lend parts to statue `target`: the others with the same template.
pub fn donor_candidates(cfg: &KioskConfig, target: usize) -> Vec<usize> {
    let Some(t) = cfg.statues.get(target) else {
        return Vec::new();
    };
    (0..cfg.statues.len())
        .filter(|&i| i != target && cfg.statues[i].template == t.template)
        .collect()
}

/// A bone or chain name as visitors read it: `l_upper_arm` → "left upper arm".
pub fn friendly_name(name: &str) -> String {
    name.split('_')
        .filter(|w| !w.is_empty())
        .map(|w| match w {
            "l" => "left",
            "r" => "right",
            w => w,
        })
        .collect::<Vec<_>>()
        .join(" ")
}

/// A part's name: its chain's ("left arm") when it holds three bones or more of one chain,
/// else its bones' ("left forearm and hand").
pub fn part_name(t: &Template, part: &Part) -> String {
    let Some(&first) = part.bones.first() else {
        return String::new();
    };
    if part.bones.len() >= 3
        && let Some((c, _)) = t.bones[first].chain
    {
        return friendly_name(&t.chains[c].name);
    }
    let names: Vec<String> = part
        .bones
        .iter()
        .map(|&k| friendly_name(&t.bones[k].name))
        .collect();
    // "left forearm and left hand" → "left forearm and hand".
    let side = names[0].split(' ').next().unwrap_or("").to_string();
    let rest: Vec<String> = names[1..]
        .iter()
        .map(|n| match n.strip_prefix(&format!("{side} ")) {
            Some(r) if side == "left" || side == "right" => r.to_string(),
            _ => n.clone(),
        })
        .collect();
    std::iter::once(names[0].clone())
        .chain(rest)
        .collect::<Vec<_>>()
        .join(" and ")
}

/// `text` with each `{key}` replaced.
pub fn fill(text: &str, values: &[(&str, String)]) -> String {
    let mut s = text.to_string();
    for (k, v) in values {
        s = s.replace(&format!("{{{k}}}"), v);
    }
    s
}

/// The skeleton with the bones of `ghosts` as ghosts: each gets the completed skeleton's size,
/// and its rotation relative to its parent from `completed` unless `current` turned it away
/// from `fitted` (then `current`'s). Other bones are `current`'s.
pub fn ghost_skeleton(
    current: &Skeleton,
    fitted: &Skeleton,
    completed: &Skeleton,
    ghosts: &[usize],
) -> Skeleton {
    let mut s = current.clone();
    for &k in ghosts {
        let (Some(b), Some(c), Some(f)) = (
            s.bones.get_mut(k),
            completed.bones.get(k),
            fitted.bones.get(k),
        ) else {
            continue;
        };
        let rotation = if b.rotation == f.rotation {
            c.rotation
        } else {
            b.rotation
        };
        *b = *c;
        b.rotation = rotation;
    }
    s
}

/// Logical-pixel layout of the carousel, the hypothesis strip, the undo button and the notice.
#[derive(Clone, Debug, PartialEq)]
pub struct SwapLayout {
    /// The carousel's card (heading, entries, close button).
    pub panel: Rect,
    pub heading: Rect,
    /// The entries of the page shown.
    pub entries: Vec<Rect>,
    pub close: Rect,
    /// The hypothesis strip: swipe it, or tap its left or right third.
    pub strip: Rect,
    pub undo: Rect,
    pub notice: Rect,
    /// The hint while ghost bones are shown.
    pub hint: Rect,
}

const MARGIN: f32 = 16.0;
const TOP: f32 = 140.0;
const PANEL_W: f32 = 340.0;
const PAD: f32 = 12.0;
const HEAD_H: f32 = 60.0;
const ENTRY_H: f32 = 100.0;
const GAP: f32 = 10.0;
const CLOSE_H: f32 = 72.0;
/// Room kept free at the bottom (status/hint line and pose strip with its pictograms).
const BOTTOM: f32 = ui::SCENE_BOTTOM_PX;
const STRIP_W: f32 = 380.0;
const STRIP_H: f32 = 84.0;
const UNDO_W: f32 = 180.0;
const UNDO_H: f32 = 76.0;

fn rect(x: f32, y: f32, w: f32, h: f32) -> Rect {
    Rect::new(x, y, x + w, y + h)
}

/// Carousel entries that fit on one page of a `screen` (at least one).
pub fn entries_per_page(screen: Vec2) -> usize {
    let room = screen.y - TOP - BOTTOM - 2.0 * PAD - HEAD_H - CLOSE_H;
    ((room / (ENTRY_H + GAP)).floor().max(1.0)) as usize
}

/// The layout on a `screen` of logical size `screen` with `entries` carousel entries on the
/// page shown.
pub fn swap_layout(screen: Vec2, entries: usize) -> SwapLayout {
    let x = MARGIN;
    let inner = PANEL_W - 2.0 * PAD;
    let heading = rect(x + PAD, TOP + PAD, inner, HEAD_H);
    let list_top = TOP + PAD + HEAD_H;
    let entry_rects: Vec<Rect> = (0..entries)
        .map(|i| {
            rect(
                x + PAD,
                list_top + i as f32 * (ENTRY_H + GAP),
                inner,
                ENTRY_H,
            )
        })
        .collect();
    let close = rect(
        x + PAD,
        list_top + entries as f32 * (ENTRY_H + GAP),
        inner,
        CLOSE_H,
    );
    let panel = Rect::new(x, TOP, x + PANEL_W, close.max.y + PAD);
    let sx = screen.x - MARGIN - STRIP_W;
    let strip = rect(sx, TOP, STRIP_W, STRIP_H);
    let undo = rect(
        screen.x - MARGIN - UNDO_W,
        TOP + STRIP_H + GAP,
        UNDO_W,
        UNDO_H,
    );
    let nw = 640.0f32.min(screen.x - 2.0 * MARGIN);
    let notice = rect((screen.x - nw) * 0.5, screen.y - BOTTOM - 106.0, nw, 96.0);
    let hint = rect(x, TOP, PANEL_W, 90.0);
    SwapLayout {
        panel,
        heading,
        entries: entry_rects,
        close,
        strip,
        undo,
        notice,
        hint,
    }
}

/// Touch zone ids of part swapping.
pub mod zones {
    pub const PANEL: u32 = 0x5357_0000;
    pub const CLOSE: u32 = 0x5357_0001;
    pub const STRIP: u32 = 0x5357_0002;
    pub const UNDO: u32 = 0x5357_0003;
    /// Entry `i` of the page shown is `ENTRY + i`.
    pub const ENTRY: u32 = 0x5357_0100;
    /// Every id (for [`super::TouchZones::set`]).
    pub fn all() -> Vec<u32> {
        let mut v = vec![PANEL, CLOSE, STRIP, UNDO];
        v.extend((0..64).map(|i| ENTRY + i));
        v
    }
}

// ---------------------------------------------------------------------------------------------
// Background jobs (bevy-free).

/// Part swapping's thread pools, so that its parallel loops never queue behind the frame's
/// own (skinning uses the global pool): one for the short jobs (analysis, preparation,
/// merge; half the cores, at least one) and one thread for the long ones (fitting a donor),
/// which would otherwise hold the short ones back.
struct Pools {
    jobs: Option<rayon::ThreadPool>,
    fits: Option<rayon::ThreadPool>,
}

fn pools() -> &'static Pools {
    static POOLS: OnceLock<Pools> = OnceLock::new();
    POOLS.get_or_init(|| {
        let n = std::thread::available_parallelism().map_or(1, |n| (n.get() / 2).max(1));
        let build = |n: usize, name: &'static str| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .thread_name(move |i| format!("{name}-{i}"))
                .build()
                .ok()
        };
        Pools {
            jobs: build(n, "part-swap"),
            fits: build(1, "donor-fit"),
        }
    })
}

/// Runs `f` with its parallel work in `pool` (the global pool when it could not be built).
fn within<T: Send>(pool: &Option<rayon::ThreadPool>, f: impl FnOnce() -> T + Send) -> T {
    match pool {
        Some(p) => p.install(f),
        None => f(),
    }
}

/// Runs `job` on its own thread, its parallel work in the short jobs' pool.
fn background<T: Send + 'static>(job: impl FnOnce() -> T + Send + 'static) -> Pending<T> {
    Pending::spawn(move || within(&pools().jobs, job))
}

/// Stops a background fit when the flag is set (the app ended).
struct CancelFlag<'a>(&'a AtomicBool);

impl Pause for CancelFlag<'_> {
    fn unit(&mut self, _: Option<&Solver<'_>>) -> std::result::Result<(), Cancelled> {
        if self.0.load(Ordering::Relaxed) {
            Err(Cancelled)
        } else {
            Ok(())
        }
    }
}

struct Analysis {
    support: Vec<BoneSupport>,
    parts: Vec<Part>,
    completed: Skeleton,
    bone: Vec<u32>,
}

/// The statue's missing parts are the bones its registration found or was told lost (its
/// binding leaves them out: [`Binding::lost`]), as for `restore` and `FIT.json`
/// ([`crate::restore::missing_bones`]); the support of every bone is measured too, for the
/// operator.
fn analyse_statue(cloud: &PointCloud, fit: &Skeleton, missing: Vec<bool>) -> Result<Analysis> {
    let sup = support(cloud, fit)?;
    let mut parts = parts_of(&fit.template, &missing);
    let healthy: Vec<bool> = missing.iter().map(|m| !m).collect();
    let completed = complete_cut(fit, &missing, Some(&healthy));
    let bone = if parts.is_empty() {
        vec![0; cloud.len()]
    } else {
        nearest_bones(&cloud.positions, &completed)
    };
    // As `restore` does: a part hanging on a bone cut part-way grows from its stump.
    start_at_stumps(&mut parts, &cloud.positions, &completed);
    Ok(Analysis {
        support: sup,
        parts,
        completed,
        bone,
    })
}

fn load_donor(
    cfg: &KioskConfig,
    index: usize,
    fit_donors: bool,
    stage: &AtomicU8,
    cancel: &AtomicBool,
) -> Result<DonorData> {
    let entry = cfg
        .statues
        .get(index)
        .ok_or_else(|| Error::input(format!("no statue {index}")))?;
    let loaded = within(&pools().jobs, || {
        load(
            &cfg.assets_root,
            &cfg.cache_dir,
            entry,
            cfg.budget.point_budget,
        )
    })?;
    let (fit, binding) = match loaded.cached {
        Some(c) => c,
        None if fit_donors => {
            stage.store(STAGE_FITTING, Ordering::Relaxed);
            let opts = loaded.fit_options.clone();
            let (fit, binding) = within(&pools().fits, || -> Result<_> {
                let fit = register(
                    &loaded.cloud,
                    loaded.template.clone(),
                    &opts,
                    &mut CancelFlag(cancel),
                )?;
                let base = fit.base.map(|b| b.points).unwrap_or_default();
                let binding = Binding::new_without(&loaded.cloud, &fit.skeleton, &fit.missing)?
                    .with_base(&base)?;
                let fit = fit.skeleton;
                Ok((fit, binding))
            })?;
            write_cache(&cfg.cache_dir, &loaded.cache_key, &fit, &binding);
            (fit, binding)
        }
        None => {
            return Err(Error::input(format!(
                "{} is not fitted yet",
                entry.file.display()
            )));
        }
    };
    let missing = binding.lost_bones();
    Ok(DonorData {
        cloud: loaded.cloud,
        fit,
        binding: Arc::new(binding),
        missing,
    })
}

/// Brings `part` of `donor` to the statue whose completed skeleton is `completed`.
fn prepare_part(
    completed: &Skeleton,
    part: &Part,
    donor_name: &str,
    donor: &DonorData,
    opts: &TransferOptions,
    thumbnail: Option<(u32, u32, [u8; 3])>,
) -> Result<Prepared> {
    check_donor(&completed.template, donor_name, &donor.missing, part)?;
    let tr = transfer(completed, &donor.cloud, &donor.binding, part, opts)?;
    let root = part.bones[0];
    let jt = completed.pose().bones[root].c1;
    let jd = donor.fit.pose().bones[root].c1;
    let r = (completed.root_rotation * donor.fit.root_rotation.inverse()).normalize();
    let start = tr
        .indices
        .iter()
        .map(|&i| jt + r * (donor.cloud.positions[i as usize] - jd))
        .collect();
    let thumbnail = thumbnail.map(|t| part_picture(completed, part, &tr, opts.margin, t));
    Ok(Prepared {
        transferred: tr,
        start,
        thumbnail,
    })
}

/// A front view of a transferred part, framed on the statue's completed part and the margin
/// on the bone it hangs on (so every donor's version is drawn at the same scale: the statue's).
fn part_picture(
    completed: &Skeleton,
    part: &Part,
    tr: &Transferred,
    margin: f32,
    (w, h, background): (u32, u32, [u8; 3]),
) -> crate::render::Image {
    let posed = completed.pose();
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    let mut spheres: Vec<(Vec3, f32)> = Vec::new();
    // The sphere of bone `k` at fraction `f` of its length.
    let at = |k: usize, f: f32| {
        let b = posed.bones[k];
        let f = f.clamp(0.0, 1.0);
        (b.c1.lerp(b.c2, f), b.r1 + (b.r2 - b.r1) * f)
    };
    for (i, &k) in part.bones.iter().enumerate() {
        // A part growing from a stump starts inside its first bone, its margin before that.
        let start = if i == 0 { part.from - margin } else { 0.0 };
        spheres.extend([at(k, start), at(k, 1.0)]);
    }
    if let Some(a) = part.attach.filter(|_| part.from <= 0.0) {
        spheres.push(at(a, 1.0 - margin));
    }
    for (c, r) in spheres {
        lo = lo.min(c - Vec3::splat(r));
        hi = hi.max(c + Vec3::splat(r));
    }
    let camera =
        crate::render::Camera::frame_aspect(lo, hi, -Vec3::Z, Vec3::Y, w as f32 / h.max(1) as f32);
    let opts = crate::render::RenderOptions {
        width: w,
        height: h,
        background,
        ..Default::default()
    };
    crate::render::render(
        &tr.cloud.positions,
        tr.cloud.normals.as_deref(),
        tr.cloud.colors.as_deref(),
        &camera,
        &opts,
    )
}

/// A landing part: what its merge needs (moved into the job's thread).
struct Landing {
    /// The hypothesis it builds on, and its index.
    base: Hypothesis,
    base_index: usize,
    completed: Skeleton,
    part_index: usize,
    part: Part,
    /// Donor statue index.
    donor: usize,
    prepared: Arc<Prepared>,
    settings: PartSwapSettings,
}

/// The merge and the new binding of a landing part (runs off the main thread).
fn land(job: &Landing) -> Result<Hypothesis> {
    let Landing {
        base,
        base_index,
        completed,
        part_index,
        part,
        donor,
        prepared,
        settings,
    } = job;
    let (base_index, part_index, donor) = (*base_index, *part_index, *donor);
    let tr = &prepared.transferred;
    let mut assembly = Assembly::resume(
        &base.cloud,
        base.provenance.source.to_vec(),
        base.provenance.bone.to_vec(),
    )?;
    assembly.add(
        completed,
        part,
        tr,
        donor as u32 + 1,
        settings.transfer.margin,
        &settings.merge,
    );
    let (cloud, source, bone) = assembly.finish();
    let mut fit = base.fit.clone();
    for &k in &part.bones {
        fit.bones[k] = tr.skeleton.bones[k];
    }
    let binding = Binding::new_on_base(&cloud, &fit)?;
    let mut restored = base.restored.clone();
    restored.push((part_index, donor));
    Ok(Hypothesis {
        cloud: Arc::new(cloud),
        provenance: Provenance {
            source: Arc::new(source),
            bone: Arc::new(bone),
        },
        fit,
        binding: Arc::new(binding),
        restored,
        parent: Some(base_index),
    })
}

// ---------------------------------------------------------------------------------------------
// Systems.

/// The entries of the open carousel for statue `target` (what each donor can give now).
pub fn carousel_entries(
    cfg: &KioskConfig,
    target: usize,
    part: usize,
    restoration: &Restoration,
    donors: &Donors,
) -> Vec<Entry> {
    donor_candidates(cfg, target)
        .into_iter()
        .map(|d| {
            let state = match restoration.prepared.get(&(part, d)) {
                Some(Preparation::Ready(p)) => EntryState::Ready(p.transferred.cloud.len()),
                Some(Preparation::Failed(m)) => EntryState::Unavailable(m.clone()),
                Some(Preparation::Running(_)) => EntryState::Pending,
                None => match donors.status(d) {
                    Some(DonorStatus::Failed(m)) => EntryState::Unavailable(m),
                    _ => EntryState::Pending,
                },
            };
            Entry {
                statue: d,
                title: cfg.statues[d].title.clone(),
                state,
            }
        })
        .collect()
}

/// Ends a flight (its points disappear).
fn cancel_flight(swap: &mut PartSwap, commands: &mut Commands) {
    if let Some(f) = swap.flight.take()
        && let Ok(mut e) = commands.get_entity(f.entity)
    {
        e.try_despawn();
    }
}

fn notify(swap: &mut PartSwap, text: &str, settings: &PartSwapSettings) {
    swap.notice = Some(Notice {
        text: text.to_string(),
        remaining_s: settings.notice_seconds,
    });
}

#[allow(clippy::too_many_arguments)]
fn tap_ghosts(
    mut taps: MessageReader<Tap>,
    active: Res<ActiveStatue>,
    mut swap: ResMut<PartSwap>,
    mut selection: ResMut<Selection>,
    statues: Query<(&Restoration, &CurrentPose, &FittedSkeleton)>,
) {
    for tap in taps.read() {
        let Some(e) = active.entity else {
            continue;
        };
        let Ok((r, pose, fitted)) = statues.get(e) else {
            continue;
        };
        if swap.flight.is_some() {
            continue;
        }
        let missing = r.missing_parts(None);
        // A part growing from a stump: the statue's own bone is no ghost (a tap on it selects
        // the limb, as on any other), the lost bones are.
        let ghosts: Vec<usize> = missing
            .iter()
            .flat_map(|&p| r.parts[p].lost_bones().iter().copied())
            .collect();
        if ghosts.is_empty() {
            continue;
        }
        let skel = ghost_skeleton(&pose.0, &fitted.0, &r.completed, &ghosts);
        let posed = skel.pose();
        let picked = pick_bone(&tap.ray, &posed.bones, tap.slack_per_depth);
        let part = picked.and_then(|b| {
            missing
                .iter()
                .copied()
                .find(|&p| r.parts[p].lost_bones().contains(&b))
        });
        match part {
            Some(p) => {
                // A missing limb cannot be dragged: the tap opens its carousel instead.
                selection.chain = None;
                swap.carousel = Some(Carousel { part: p, page: 0 });
            }
            None => swap.carousel = None,
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn zone_gestures(
    mut commands: Commands,
    mut gestures: MessageReader<ZoneGesture>,
    active: Res<ActiveStatue>,
    settings: Res<Settings>,
    swap_settings: Res<PartSwapSettings>,
    mut swap: ResMut<PartSwap>,
    donors: Res<Donors>,
    mut statues: Query<(&Statue, &mut Restoration, &CurrentPose)>,
    windows: Query<&Window, With<PrimaryWindow>>,
) {
    let cfg = &settings.0;
    let screen = screen_size(windows.iter().next(), cfg);
    for g in gestures.read() {
        let Some(e) = active.entity else {
            continue;
        };
        let Ok((statue, mut r, pose)) = statues.get_mut(e) else {
            continue;
        };
        match (g.zone, g.kind) {
            (zones::UNDO, ZoneGestureKind::Tap) => {
                if swap.flight.is_some() {
                    cancel_flight(&mut swap, &mut commands);
                } else if r.undo() {
                    swap.carousel = None;
                }
            }
            (zones::STRIP, kind) => {
                if swap.flight.is_some() {
                    continue;
                }
                let n = r.hypotheses.len();
                let step: isize = match kind {
                    ZoneGestureKind::Swipe { delta } if delta.x <= -swap_settings.swipe_px => 1,
                    ZoneGestureKind::Swipe { delta } if delta.x >= swap_settings.swipe_px => -1,
                    ZoneGestureKind::Tap => {
                        let l = swap_layout(screen, 0).strip;
                        let third = l.width() / 3.0;
                        if g.start.x < l.min.x + third {
                            -1
                        } else if g.start.x > l.max.x - third {
                            1
                        } else {
                            0
                        }
                    }
                    _ => 0,
                };
                let next = (r.shown as isize + step).clamp(0, n as isize - 1) as usize;
                if next != r.shown {
                    r.show(next);
                    swap.carousel = None;
                }
            }
            (zones::CLOSE, ZoneGestureKind::Tap) => swap.carousel = None,
            (z, ZoneGestureKind::Swipe { delta })
                if z == zones::PANEL || z == zones::CLOSE || z >= zones::ENTRY =>
            {
                // Page through the donors.
                let Some(c) = swap.carousel.as_mut() else {
                    continue;
                };
                let count = donor_candidates(cfg, statue.index).len();
                let pages = count.div_ceil(entries_per_page(screen)).max(1);
                let d = if delta.x.abs() >= delta.y.abs() {
                    delta.x
                } else {
                    delta.y
                };
                if d <= -swap_settings.swipe_px {
                    c.page = (c.page + 1).min(pages - 1);
                } else if d >= swap_settings.swipe_px {
                    c.page = c.page.saturating_sub(1);
                }
            }
            (z, ZoneGestureKind::Tap) if (zones::ENTRY..zones::ENTRY + 64).contains(&z) => {
                let Some(c) = swap.carousel else { continue };
                if swap.flight.is_some() {
                    continue;
                }
                let per = entries_per_page(screen);
                let i = c.page * per + (z - zones::ENTRY) as usize;
                let entries = carousel_entries(cfg, statue.index, c.part, &r, &donors);
                let Some(entry) = entries.get(i) else {
                    continue;
                };
                match r.prepared.get(&(c.part, entry.statue)) {
                    Some(Preparation::Ready(p)) => {
                        let p = p.clone();
                        start_flight(
                            &mut commands,
                            &mut swap,
                            &swap_settings,
                            e,
                            &r,
                            pose,
                            c.part,
                            entry.statue,
                            p,
                        );
                    }
                    Some(Preparation::Failed(m)) => {
                        info!("{} cannot lend the part: {m}", entry.title);
                        notify(&mut swap, &cfg.texts.part_failed, &swap_settings);
                    }
                    _ => {
                        if let EntryState::Unavailable(m) = &entry.state {
                            info!("{} cannot lend the part: {m}", entry.title);
                            notify(&mut swap, &cfg.texts.part_failed, &swap_settings);
                        }
                    }
                }
            }
            _ => {}
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn start_flight(
    commands: &mut Commands,
    swap: &mut PartSwap,
    settings: &PartSwapSettings,
    statue: Entity,
    r: &Restoration,
    pose: &CurrentPose,
    part_index: usize,
    donor: usize,
    prepared: Arc<Prepared>,
) {
    let part = r.parts[part_index].clone();
    let base_index = r.shown;
    let base = r.current().clone();
    let completed = r.completed.clone();
    let tr = &prepared.transferred;
    // Away from the body: from the root through the joint, a part's length.
    let posed = completed.pose();
    let joint = posed.bones[part.bones[0]].c1;
    let length: f32 = part.bones.iter().map(|&k| completed.bones[k].length).sum();
    let offset = (joint - completed.root_position).normalize_or(Vec3::Y) * length * 0.8;
    let n = tr.cloud.len();
    let positions: Vec<Vec3> = prepared.start.iter().map(|&p| p + offset).collect();
    let entity = commands
        .spawn((
            Name::new("part flying in"),
            SkinnedPoints {
                positions,
                normals: tr.cloud.normals.clone().unwrap_or_else(|| vec![Vec3::Y; n]),
                colors: tr.cloud.colors.clone(),
                version: 1,
                scratch: Scratch::default(),
            },
            Transform::default(),
            Visibility::default(),
            ChildOf(statue),
        ))
        .id();
    // The part lands in the fitted pose: bring the statue there during the flight.
    if !super::animate::same_skeleton(&pose.0, &base.fit) {
        commands.entity(statue).insert(PoseAnimation {
            from: pose.0.clone(),
            to: base.fit.clone(),
            elapsed: 0.0,
            duration: settings.fly_seconds,
        });
    }
    let landing = Landing {
        base,
        base_index,
        completed,
        part_index,
        part,
        donor,
        prepared: prepared.clone(),
        settings: settings.clone(),
    };
    let job = background(move || land(&landing));
    swap.carousel = None;
    swap.flight = Some(Flight {
        statue,
        entity,
        part: part_index,
        donor,
        base: base_index,
        elapsed: 0.0,
        duration: settings.fly_seconds.max(0.0),
        prepared,
        offset,
        job,
        landed: None,
    });
}

/// Follows the active statue: a new statue or a reset closes everything; a reset also goes back
/// to the statue as found.
fn follow_statue(
    mut commands: Commands,
    active: Res<ActiveStatue>,
    mut swap: ResMut<PartSwap>,
    mut reset: MessageReader<ResetRequested>,
    mut statues: Query<&mut Restoration>,
) {
    let resets = reset.read().count() > 0;
    if swap.statue != active.entity || resets {
        swap.carousel = None;
        swap.notice = None;
        cancel_flight(&mut swap, &mut commands);
        swap.statue = active.entity;
    }
    if resets
        && let Some(e) = active.entity
        && let Ok(mut r) = statues.get_mut(e)
    {
        r.reset();
    }
}

#[allow(clippy::type_complexity)]
fn analyse(
    mut commands: Commands,
    settings: Res<Settings>,
    swap_settings: Res<PartSwapSettings>,
    mut donors: ResMut<Donors>,
    start: Query<
        (
            Entity,
            &StatueState,
            &StatueCloud,
            &FittedSkeleton,
            &StatueBinding,
        ),
        (Without<Restoration>, Without<Pending<Result<Analysis>>>),
    >,
    done: Query<(
        Entity,
        &Statue,
        &StatueCloud,
        &FittedSkeleton,
        &StatueBinding,
        &Pending<Result<Analysis>>,
    )>,
) {
    for (e, state, cloud, fit, binding) in &start {
        if !matches!(state, StatueState::Ready) {
            continue;
        }
        let cloud = cloud.0.clone();
        let fit = fit.0.clone();
        let missing = binding.0.lost_bones();
        commands
            .entity(e)
            .insert(background(move || analyse_statue(&cloud, &fit, missing)));
    }
    for (e, statue, cloud, fit, binding, pending) in &done {
        let Some(result) = pending.take() else {
            continue;
        };
        let mut ec = commands.entity(e);
        ec.remove::<Pending<Result<Analysis>>>();
        let a = match result {
            Ok(a) => a,
            Err(err) => {
                warn!("part swapping: the statue could not be analysed: {err}");
                Analysis {
                    support: Vec::new(),
                    parts: Vec::new(),
                    completed: fit.0.clone(),
                    bone: vec![0; cloud.0.len()],
                }
            }
        };
        if !a.parts.is_empty() {
            let t = &a.completed.template;
            let names: Vec<String> = a.parts.iter().map(|p| part_name(t, p)).collect();
            info!("missing parts: {}", names.join(", "));
            // Donors load now, so the carousel is ready when a visitor asks.
            for d in donor_candidates(&settings.0, statue.index) {
                request_donor(&mut donors, &settings.0, d, swap_settings.fit_donors);
            }
        }
        let provenance = Provenance {
            source: Arc::new(vec![FROM_TARGET; cloud.0.len()]),
            bone: Arc::new(a.bone),
        };
        let first = Hypothesis {
            cloud: cloud.0.clone(),
            provenance: provenance.clone(),
            fit: fit.0.clone(),
            binding: binding.0.clone(),
            restored: Vec::new(),
            parent: None,
        };
        ec.insert((
            Restoration {
                support: a.support,
                parts: a.parts,
                completed: a.completed,
                hypotheses: vec![first],
                shown: 0,
                prepared: HashMap::new(),
                generation: 0,
                applied: 0,
            },
            provenance,
        ));
    }
}

fn request_donor(donors: &mut Donors, cfg: &KioskConfig, index: usize, fit: bool) {
    if donors.slots.contains_key(&index) {
        return;
    }
    let stage = Arc::new(AtomicU8::new(STAGE_LOADING));
    let cancel = Arc::new(AtomicBool::new(false));
    let job = {
        let cfg = cfg.clone();
        let (stage, cancel) = (stage.clone(), cancel.clone());
        Pending::spawn(move || load_donor(&cfg, index, fit, &stage, &cancel))
    };
    donors.slots.insert(
        index,
        DonorSlot {
            status: DonorStatus::Loading,
            job: Some(job),
            stage,
            cancel,
        },
    );
}

fn poll_donors(mut donors: ResMut<Donors>, settings: Res<Settings>) {
    for (&i, slot) in donors.slots.iter_mut() {
        let Some(job) = &slot.job else { continue };
        match job.take() {
            Some(Ok(d)) => {
                info!("donor ready: {}", settings.0.statues[i].title);
                slot.status = DonorStatus::Ready(Arc::new(d));
                slot.job = None;
            }
            Some(Err(e)) => {
                warn!("donor {} unavailable: {e}", settings.0.statues[i].title);
                slot.status = DonorStatus::Failed(e.to_string());
                slot.job = None;
            }
            None => {
                if slot.stage.load(Ordering::Relaxed) == STAGE_FITTING {
                    slot.status = DonorStatus::Fitting;
                }
            }
        }
    }
}

/// Prepares every missing part from every ready donor (one thread each), and polls them.
fn prepare_parts(
    settings: Res<Settings>,
    swap_settings: Res<PartSwapSettings>,
    active: Res<ActiveStatue>,
    donors: Res<Donors>,
    mut statues: Query<(&Statue, &mut Restoration)>,
) {
    let Some(e) = active.entity else { return };
    let Ok((statue, mut r)) = statues.get_mut(e) else {
        return;
    };
    let cfg = &settings.0;
    let r = &mut *r;
    for p in 0..r.parts.len() {
        for d in donor_candidates(cfg, statue.index) {
            match r.prepared.get(&(p, d)) {
                None => {
                    let Some(DonorStatus::Ready(data)) = donors.status(d) else {
                        continue;
                    };
                    let completed = r.completed.clone();
                    let part = r.parts[p].clone();
                    let name = cfg.statues[d].title.clone();
                    let opts = TransferOptions {
                        pose: swap_settings.pose,
                        ..swap_settings.transfer
                    };
                    let thumb = swap_settings.thumbnails.then(|| {
                        let (w, h) = swap_settings.thumbnail_px;
                        (w, h, [30, 32, 40])
                    });
                    let job = background(move || {
                        prepare_part(&completed, &part, &name, &data, &opts, thumb)
                    });
                    r.prepared.insert((p, d), Preparation::Running(job));
                }
                Some(Preparation::Running(job)) => match job.take() {
                    Some(Ok(prep)) => {
                        r.prepared
                            .insert((p, d), Preparation::Ready(Arc::new(prep)));
                    }
                    Some(Err(err)) => {
                        info!("{} cannot lend part {p}: {err}", cfg.statues[d].title);
                        r.prepared
                            .insert((p, d), Preparation::Failed(err.to_string()));
                    }
                    None => {}
                },
                Some(_) => {}
            }
        }
    }
}

/// Writes the hypothesis shown into the statue (cloud, fit, binding, pose, points, provenance).
#[allow(clippy::type_complexity)]
fn apply_hypothesis(
    mut commands: Commands,
    active: Res<ActiveStatue>,
    mut selection: ResMut<Selection>,
    mut statues: Query<(
        &mut Restoration,
        &mut StatueCloud,
        &mut FittedSkeleton,
        &mut StatueBinding,
        &mut CurrentPose,
        &mut SkinnedPoints,
    )>,
) {
    let Some(e) = active.entity else { return };
    let Ok((mut r, mut cloud, mut fitted, mut binding, mut pose, mut points)) = statues.get_mut(e)
    else {
        return;
    };
    if r.applied == r.generation {
        return;
    }
    r.applied = r.generation;
    let h = r.current().clone();
    if Arc::ptr_eq(&cloud.0, &h.cloud) && Arc::ptr_eq(&binding.0, &h.binding) {
        return;
    }
    cloud.0 = h.cloud.clone();
    fitted.0 = h.fit.clone();
    binding.0 = h.binding.clone();
    pose.0 = h.fit.clone();
    let p = &mut *points;
    p.positions.clone_from(&h.cloud.positions);
    p.normals = h
        .cloud
        .normals
        .clone()
        .unwrap_or_else(|| vec![Vec3::Y; h.cloud.len()]);
    p.colors.clone_from(&h.cloud.colors);
    p.version += 1;
    selection.chain = None;
    commands
        .entity(e)
        .remove::<PoseAnimation>()
        .insert(h.provenance.clone());
}

fn fly(
    mut commands: Commands,
    time: Res<Time>,
    mut swap: ResMut<PartSwap>,
    texts: Res<Settings>,
    swap_settings: Res<PartSwapSettings>,
    mut points: Query<&mut SkinnedPoints>,
    mut statues: Query<&mut Restoration>,
) {
    let Some(f) = swap.flight.as_mut() else {
        return;
    };
    if f.landed.is_none() {
        match f.job.take() {
            Some(Ok(h)) => f.landed = Some(h),
            Some(Err(err)) => {
                warn!("part swapping: the part could not be merged: {err}");
                cancel_flight(&mut swap, &mut commands);
                notify(&mut swap, &texts.0.texts.part_failed, &swap_settings);
                return;
            }
            None => {}
        }
    }
    let before = f.elapsed;
    f.elapsed += time.delta_secs();
    let t = if f.duration > 0.0 {
        (f.elapsed / f.duration).min(1.0)
    } else {
        1.0
    };
    let moving = before < f.duration || before == 0.0;
    if moving && let Ok(mut p) = points.get_mut(f.entity) {
        let e = ease(t);
        let end = &f.prepared.transferred.cloud.positions;
        let offset = f.offset * (1.0 - e);
        for ((out, s), d) in p.positions.iter_mut().zip(&f.prepared.start).zip(end) {
            *out = s.lerp(*d, e) + offset;
        }
        p.version += 1;
    }
    if t < 1.0 || f.landed.is_none() {
        return;
    }
    let f = swap.flight.take().expect("flight");
    commands.entity(f.entity).try_despawn();
    let Ok(mut r) = statues.get_mut(f.statue) else {
        return;
    };
    if f.base >= r.hypotheses.len() {
        return;
    }
    let h = f.landed.expect("landed");
    r.hypotheses.push(h);
    let last = r.hypotheses.len() - 1;
    r.show(last);
    swap.landed += 1;
}

/// Places the ghost bones of the statue shown from its pose (spawns, moves, removes them).
#[allow(clippy::type_complexity)]
fn place_ghosts(
    mut commands: Commands,
    active: Res<ActiveStatue>,
    swap: Res<PartSwap>,
    statues: Query<(Entity, &Restoration, &CurrentPose, &FittedSkeleton)>,
    mut ghosts: Query<(Entity, &mut GhostBone, &mut Transform, &ChildOf)>,
) {
    let shown = active.entity.and_then(|e| statues.get(e).ok());
    let mut wanted: Vec<GhostBone> = Vec::new();
    if let Some((_, r, pose, fitted)) = shown {
        let flying = swap.flight.as_ref().map(|f| f.part);
        let parts = r.missing_parts(flying);
        let bones: Vec<usize> = parts
            .iter()
            .flat_map(|&p| r.parts[p].lost_bones().iter().copied())
            .collect();
        if !bones.is_empty() {
            let skel = ghost_skeleton(&pose.0, &fitted.0, &r.completed, &bones);
            let posed = skel.pose();
            for &p in &parts {
                for &k in r.parts[p].lost_bones() {
                    wanted.push(GhostBone {
                        bone: k,
                        part: p,
                        shape: posed.bones[k],
                    });
                }
            }
        }
    }
    let statue = shown.map(|s| s.0);
    let mut have: Vec<usize> = Vec::new();
    for (e, mut g, mut t, parent) in &mut ghosts {
        let keep = (Some(parent.parent()) == statue)
            .then(|| wanted.iter().find(|w| w.bone == g.bone))
            .flatten();
        match keep {
            Some(w) => {
                if *g != *w {
                    *g = *w;
                    *t = bone_transform(w.shape.c1, w.shape.c2);
                }
                have.push(w.bone);
            }
            None => commands.entity(e).despawn(),
        }
    }
    let Some(statue) = statue else { return };
    for w in wanted.iter().filter(|w| !have.contains(&w.bone)) {
        commands.spawn((
            Name::new(format!("ghost bone {}", w.bone)),
            *w,
            bone_transform(w.shape.c1, w.shape.c2),
            Visibility::default(),
            ChildOf(statue),
        ));
    }
}

/// What the overlay shows this frame (computed once for the zones and the drawing).
struct OverlayState {
    layout: SwapLayout,
    carousel: Option<(String, Vec<Entry>, usize, usize)>,
    strip: Option<String>,
    undo: bool,
    hint: bool,
}

fn overlay_state(
    cfg: &KioskConfig,
    screen: Vec2,
    swap: &PartSwap,
    statue: Option<(&Statue, &Restoration)>,
    donors: &Donors,
) -> OverlayState {
    let texts: &Texts = &cfg.texts;
    let per = entries_per_page(screen);
    let mut carousel = None;
    let mut strip = None;
    let mut hint = false;
    let mut undo = false;
    let mut on_page = 0;
    if let Some((statue, r)) = statue {
        if let Some(c) = swap.carousel.filter(|c| c.part < r.parts.len()) {
            let entries = carousel_entries(cfg, statue.index, c.part, r, donors);
            let pages = entries.len().div_ceil(per).max(1);
            let page = c.page.min(pages - 1);
            let shown: Vec<Entry> = entries.into_iter().skip(page * per).take(per).collect();
            on_page = shown.len();
            let name = part_name(&r.completed.template, &r.parts[c.part]);
            carousel = Some((
                fill(&texts.part_choose, &[("part", name)]),
                shown,
                page,
                pages,
            ));
        }
        let n = r.hypotheses.len();
        if n > 1 || swap.flight.is_some() {
            strip = Some(if r.shown == 0 {
                texts.original.clone()
            } else {
                fill(
                    &texts.restoration,
                    &[("i", r.shown.to_string()), ("n", (n - 1).to_string())],
                )
            });
            undo = r.shown > 0 || swap.flight.is_some();
        }
        hint = carousel.is_none()
            && swap.flight.is_none()
            && swap.notice.is_none()
            && !r.missing_parts(None).is_empty();
    }
    OverlayState {
        layout: swap_layout(screen, on_page),
        carousel,
        strip,
        undo,
        hint,
    }
}

fn update_zones(
    settings: Res<Settings>,
    active: Res<ActiveStatue>,
    swap: Res<PartSwap>,
    donors: Res<Donors>,
    statues: Query<(&Statue, &Restoration)>,
    windows: Query<&Window, With<PrimaryWindow>>,
    mut touch: ResMut<TouchZones>,
) {
    let cfg = &settings.0;
    let screen = screen_size(windows.iter().next(), cfg);
    let statue = active.entity.and_then(|e| statues.get(e).ok());
    let o = overlay_state(cfg, screen, &swap, statue, &donors);
    let mut list = Vec::new();
    if o.carousel.is_some() {
        list.push(TouchZone {
            id: zones::PANEL,
            rect: o.layout.panel,
        });
        for (i, r) in o.layout.entries.iter().enumerate() {
            list.push(TouchZone {
                id: zones::ENTRY + i as u32,
                rect: *r,
            });
        }
        list.push(TouchZone {
            id: zones::CLOSE,
            rect: o.layout.close,
        });
    }
    if o.strip.is_some() {
        list.push(TouchZone {
            id: zones::STRIP,
            rect: o.layout.strip,
        });
    }
    if o.undo {
        list.push(TouchZone {
            id: zones::UNDO,
            rect: o.layout.undo,
        });
    }
    let mine: Vec<&TouchZone> = touch
        .zones
        .iter()
        .filter(|z| zones::all().contains(&z.id))
        .collect();
    if mine.len() != list.len() || mine.iter().zip(&list).any(|(a, b)| **a != *b) {
        touch.set(&zones::all(), list);
    }
}

fn tick_notice(time: Res<Time>, mut swap: ResMut<PartSwap>) {
    let Some(n) = swap.notice.as_mut() else {
        return;
    };
    n.remaining_s -= time.delta_secs();
    if n.remaining_s <= 0.0 {
        swap.notice = None;
    }
}

// ---------------------------------------------------------------------------------------------
// Drawing (with a window).

/// The overlay's nodes.
#[derive(Component, Clone, Copy, Debug, PartialEq, Eq)]
pub enum SwapNode {
    Panel,
    Heading,
    Entry(usize),
    EntryTitle(usize),
    EntryStatus(usize),
    EntryPicture(usize),
    Close,
    CloseText,
    Strip,
    StripText,
    Undo,
    UndoText,
    Notice,
    NoticeText,
    Hint,
}

/// Entry nodes spawned (pages beyond show through swipes).
const SLOTS: usize = 8;

const GHOST_ACCENT: Color = Color::srgba(0.47, 0.78, 1.0, 0.95);

fn absolute(r: Rect) -> Node {
    Node {
        position_type: PositionType::Absolute,
        left: Val::Px(r.min.x),
        top: Val::Px(r.min.y),
        width: Val::Px(r.width()),
        height: Val::Px(r.height()),
        ..default()
    }
}

fn spawn_overlay(mut commands: Commands, settings: Res<Settings>, font: Res<UiFont>) {
    let look = Look::new(&font);
    let t = &settings.0.texts;
    let hidden = Visibility::Hidden;
    let rounded = |node: Node, r: f32| Node {
        border_radius: BorderRadius::all(Val::Px(r)),
        ..node
    };
    let l = swap_layout(Vec2::new(1280.0, 800.0), SLOTS);
    commands.spawn((
        rounded(absolute(l.panel), 18.0),
        BackgroundColor(ui::CARD),
        GlobalZIndex(5),
        hidden,
        SwapNode::Panel,
    ));
    commands.spawn((
        absolute(l.heading),
        look.text("", 22.0, ui::FG),
        GlobalZIndex(6),
        hidden,
        SwapNode::Heading,
    ));
    for (i, r) in l.entries.iter().enumerate() {
        commands
            .spawn((
                Node {
                    flex_direction: FlexDirection::Row,
                    align_items: AlignItems::Center,
                    column_gap: Val::Px(12.0),
                    padding: UiRect::all(Val::Px(8.0)),
                    ..rounded(absolute(*r), 14.0)
                },
                BackgroundColor(ui::BUTTON),
                GlobalZIndex(6),
                hidden,
                SwapNode::Entry(i),
            ))
            .with_children(|e| {
                e.spawn((
                    Node {
                        width: Val::Px(120.0),
                        height: Val::Px(84.0),
                        ..default()
                    },
                    ImageNode::default(),
                    SwapNode::EntryPicture(i),
                ));
                e.spawn(Node {
                    flex_direction: FlexDirection::Column,
                    row_gap: Val::Px(4.0),
                    ..default()
                })
                .with_children(|c| {
                    c.spawn((look.text("", 22.0, ui::FG), SwapNode::EntryTitle(i)));
                    c.spawn((look.text("", 16.0, ui::FG_DIM), SwapNode::EntryStatus(i)));
                });
            });
    }
    commands
        .spawn((
            Node {
                justify_content: JustifyContent::Center,
                align_items: AlignItems::Center,
                ..rounded(absolute(l.close), 14.0)
            },
            BackgroundColor(ui::BUTTON),
            GlobalZIndex(6),
            hidden,
            SwapNode::Close,
        ))
        .with_child((
            look.text(t.close.clone(), 24.0, ui::FG),
            SwapNode::CloseText,
        ));
    commands
        .spawn((
            Node {
                justify_content: JustifyContent::Center,
                align_items: AlignItems::Center,
                ..rounded(absolute(l.strip), 18.0)
            },
            BackgroundColor(ui::CARD),
            GlobalZIndex(5),
            hidden,
            SwapNode::Strip,
        ))
        .with_child((look.text("", 24.0, ui::FG), SwapNode::StripText));
    commands
        .spawn((
            Node {
                justify_content: JustifyContent::Center,
                align_items: AlignItems::Center,
                ..rounded(absolute(l.undo), 14.0)
            },
            BackgroundColor(ui::BUTTON),
            GlobalZIndex(5),
            hidden,
            SwapNode::Undo,
        ))
        .with_child((look.text(t.undo.clone(), 26.0, ui::FG), SwapNode::UndoText));
    commands
        .spawn((
            Node {
                justify_content: JustifyContent::Center,
                align_items: AlignItems::Center,
                padding: UiRect::all(Val::Px(16.0)),
                ..rounded(absolute(l.notice), 20.0)
            },
            BackgroundColor(ui::CARD),
            GlobalZIndex(8),
            hidden,
            SwapNode::Notice,
        ))
        .with_child((look.text("", 26.0, ui::FG), SwapNode::NoticeText));
    commands.spawn((
        absolute(l.hint),
        look.text(t.ghost_hint.clone(), 22.0, GHOST_ACCENT),
        GlobalZIndex(4),
        hidden,
        SwapNode::Hint,
    ));
}

fn place(node: &mut Node, r: Rect) {
    let want = (
        Val::Px(r.min.x),
        Val::Px(r.min.y),
        Val::Px(r.width()),
        Val::Px(r.height()),
    );
    if (node.left, node.top, node.width, node.height) != want {
        (node.left, node.top, node.width, node.height) = want;
    }
}

#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn draw_overlay(
    settings: Res<Settings>,
    active: Res<ActiveStatue>,
    swap: Res<PartSwap>,
    donors: Res<Donors>,
    font: Res<UiFont>,
    statues: Query<(&Statue, &Restoration)>,
    windows: Query<&Window, With<PrimaryWindow>>,
    mut nodes: Query<(&SwapNode, &mut Visibility, Option<&mut Node>)>,
    mut texts: Query<(&SwapNode, &mut Text)>,
    mut pictures: Query<(&SwapNode, &mut ImageNode)>,
    mut images: Option<ResMut<Assets<Image>>>,
    mut thumbs: Local<HashMap<(Entity, usize, usize), Handle<Image>>>,
) {
    let cfg = &settings.0;
    let ascii = font.handle.is_none();
    let screen = screen_size(windows.iter().next(), cfg);
    let statue = active.entity.and_then(|e| statues.get(e).ok());
    let o = overlay_state(cfg, screen, &swap, statue, &donors);
    let t = &cfg.texts;
    let entries: &[Entry] = o.carousel.as_ref().map_or(&[], |c| c.1.as_slice());
    for (part, mut vis, node) in &mut nodes {
        let (visible, r) = match *part {
            SwapNode::Panel => (o.carousel.is_some(), Some(o.layout.panel)),
            SwapNode::Heading => (o.carousel.is_some(), Some(o.layout.heading)),
            SwapNode::Entry(i) => (
                o.carousel.is_some() && i < entries.len(),
                o.layout.entries.get(i).copied(),
            ),
            SwapNode::Close => (o.carousel.is_some(), Some(o.layout.close)),
            SwapNode::Strip => (o.strip.is_some(), Some(o.layout.strip)),
            SwapNode::Undo => (o.undo, Some(o.layout.undo)),
            SwapNode::Notice => (swap.notice.is_some(), Some(o.layout.notice)),
            SwapNode::Hint => (o.hint, Some(o.layout.hint)),
            _ => continue,
        };
        ui::set_visible(&mut vis, visible);
        if let (Some(mut node), Some(r)) = (node, r) {
            place(&mut node, r);
        }
    }
    for (part, mut text) in &mut texts {
        let s = match *part {
            SwapNode::Heading => match &o.carousel {
                Some((h, _, page, pages)) if *pages > 1 => {
                    format!("{h}  {}/{}", page + 1, pages)
                }
                Some((h, ..)) => h.clone(),
                None => continue,
            },
            SwapNode::EntryTitle(i) => match entries.get(i) {
                Some(e) => e.title.clone(),
                None => continue,
            },
            SwapNode::EntryStatus(i) => match entries.get(i).map(|e| &e.state) {
                Some(EntryState::Pending) => t.part_pending.clone(),
                Some(EntryState::Ready(_)) => t.part_ready.clone(),
                Some(EntryState::Unavailable(_)) => t.part_unavailable.clone(),
                None => continue,
            },
            SwapNode::StripText => match &o.strip {
                Some(s) => format!("‹   {s}   ›"),
                None => continue,
            },
            SwapNode::NoticeText => match &swap.notice {
                Some(n) => n.text.clone(),
                None => continue,
            },
            _ => continue,
        };
        ui::set_text(ascii, &mut text, &s);
    }
    // Pictures of the parts.
    let (Some(images), Some((_, r)), Some(c)) = (images.as_mut(), statue, swap.carousel) else {
        return;
    };
    let Some(e) = active.entity else { return };
    for (part, mut node) in &mut pictures {
        let SwapNode::EntryPicture(i) = *part else {
            continue;
        };
        let Some(entry) = entries.get(i) else {
            continue;
        };
        let key = (e, c.part, entry.statue);
        let handle = match (thumbs.get(&key), r.prepared.get(&(c.part, entry.statue))) {
            (Some(h), _) => Some(h.clone()),
            (None, Some(Preparation::Ready(p))) => p.thumbnail.as_ref().map(|img| {
                let h = images.add(to_bevy_image(img));
                thumbs.insert(key, h.clone());
                h
            }),
            _ => None,
        };
        let want = handle.unwrap_or_default();
        if node.image != want {
            node.image = want;
        }
    }
}

fn to_bevy_image(img: &crate::render::Image) -> Image {
    use bevy::asset::RenderAssetUsages;
    use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat};
    let rgba: Vec<u8> = img
        .rgb
        .chunks_exact(3)
        .flat_map(|p| [p[0], p[1], p[2], 255])
        .collect();
    Image::new(
        Extent3d {
            width: img.width,
            height: img.height,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        rgba,
        TextureFormat::Rgba8UnormSrgb,
        RenderAssetUsages::default(),
    )
}
