//! The visitor interface (bevy_ui): large touch targets, no text entry.
//!
//! ```text
//! ┌────────────────────────────────────────────────────────────────────┐
//! │ Pygmalion          [<]  Dancing Girl  [>]                  [Reset] │
//! │                         credit line                                │
//! ├──────────────────── SceneMargins::top ─────────────────────────────┤
//! │                      ┌ error card (failed) ┐      ┌ operator ┐     │
//! │                      └─────────────────────┘      │ panel    │     │
//! │                    (the statue, framed here)      └──────────┘     │
//! ├──────────────────── SceneMargins::bottom ──────────────────────────┤
//! │      status: loading / fitting · 42 % ▬▬▬▬▭▭▭  or, when ready,     │
//! │                 hint: touch the statue to turn it…                 │
//! │ [ 🯅  ] [ 🯅  ] [ 🯅  ]  …  one button per pose: pictogram,         │
//! │ Original Greeting Arms raised           label under it            │
//! └────────────────────────────────────────────────────────────────────┘
//!            "still there?" overlay with the countdown (over everything)
//! ```
//!
//! **Logic and drawing are separate.** Whatever the `headless` flag, the plugin runs the
//! systems that turn presses into messages (so tests drive them without a window): a pressed
//! bevy_ui [`UiInteraction`] on an entity carrying a [`UiAction`] writes
//! [`PoseRequested`] / [`StatueSelected`] / [`ResetRequested`], sets [`SkinMethod`] or
//! [`ShowBones`], or toggles the [`OperatorPanel`], and always writes an [`Interaction`]. The
//! operator panel also toggles on F2 and on a three-finger tap ([`ThreeFingerTap`]). With
//! `headless: false` the plugin also spawns the nodes ([`UiPart`] marks the ones it updates)
//! and keeps their texts and visibility up to date: title and credit of the active statue,
//! the status line, the error card (`texts.load_failed`; the carousel still works), the
//! "still there?" overlay with its countdown, the hint, and the operator panel (skinning
//! method, bones on/off, fps, last registration and skinning milliseconds, the fit's share
//! done and work units, configuration problems and the statue's failure message).
//!
//! **Status line and progress.** While the statue loads the line says `texts.loading`; while
//! FAKIR fits it, `texts.fitting` (`texts.fitting_again` while it fits the figure a second
//! time without limbs found lost, [`attempt_text`]) with the share done as a whole percentage
//! ([`fitting_percent`] of FAKIR's never-decreasing `Progress.activity.fraction`, rounded
//! down so that 100 % means finished; `{percent}` in the text places it, else it is
//! appended) over a thin bar filled to the same share; while the binding is built, 100 %.
//! The raw work-unit count, which says nothing to a visitor, is on the operator panel. The
//! line shares its place with the hint (shown once the statue is ready): the two never show
//! together, so the place above the pose strip is reserved once and the layout does not jump.
//!
//! **Pose pictograms.** Each pose button shows a small picture of the pose above its label:
//! the active statue's template in that pose, drawn from the pose data by the bevy-free
//! [`mod@crate::render::pictogram`] ([`POSE_ICON_PX`], three-quarter view, transparent
//! background) and turned into a Bevy `Image`. A pose file a museum adds to the strip gets its
//! pictogram with no further work; a pose that does not fit the template gets none (logged).
//! The pictograms are redrawn when the carousel brings a statue of another template.
//! "Original" (`identity`: back to the statue as scanned) has no pose to draw, and its fitted
//! skeleton is no help (on real scans FAKIR's fit is often crouched or twisted, and a visitor
//! would read that as a pose); it shows instead a small picture of the statue itself, its
//! cloud from the front by the point renderer ([`statue_picture`]), once loaded (the rest
//! figure until then), redrawn when the cloud changes (a part swap). Buttons stay at least
//! 150 × 118 logical pixels, the pictogram 64 × 76 above a 20-pixel label.
//!
//! **Where the statue goes.** The top bar and the bottom column (status/hint line and pose
//! strip) are measured after each layout and written to [`SceneMargins`]; the statue is framed
//! in the band between them ([`super::statue::frame_camera`]), so the hint and the strip never
//! cover its base (at 1280 × 800 the strip with its pictograms is about 220 px tall, the top
//! bar 128 px). Before the first layout (and headless) the margins are [`SCENE_TOP_PX`] and
//! [`SCENE_BOTTOM_PX`].
//!
//! **Font.** Bevy's built-in font covers ASCII only (no "…", "·", "–", accents), so at
//! start the plugin loads the first readable font of [`font_candidates`]
//! (`<assets_root>/fonts/ui.ttf`, then common system sans fonts such as DejaVu Sans) into the
//! font assets ([`UiFont`]); without one it keeps the built-in font and shows texts through
//! [`ascii_fallback`] (dashes, dots, ellipses and quotes become ASCII look-alikes).
//!
//! Pose names are shown in a friendly form ([`friendly_pose_name`]: `arms_raised` →
//! "Arms raised", `identity` → "Original", a file path → its stem).

use super::animate::{SkinMethod, SkinWork};
use super::attract::IdleState;
use super::config::Texts;
use super::fitting::FitWork;
use super::gestures::ThreeFingerTap;
use super::{
    ActiveStatue, Interaction, KioskSet, PoseRequested, ResetRequested, SceneMargins, Settings,
    ShowBones, Statue, StatueCloud, StatueSelected, StatueState,
};
use crate::anatomy::{Pose, Template};
use crate::cloud::PointCloud;
use crate::fakir::Attempt;
use crate::render::pictogram::{PictogramOptions, named_pose_pictogram};
use crate::skinning::Method;
use bevy::prelude::*;
use bevy::ui::{ComputedNode, Interaction as UiInteraction, UiGlobalTransform};
use bevy::window::PrimaryWindow;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Size of a pose pictogram on its button, logical pixels (width, height).
pub const POSE_ICON_PX: (u32, u32) = (64, 76);
/// Smallest pose button, logical pixels (width, height): pictogram and label.
pub const POSE_BUTTON_PX: (f32, f32) = (150.0, 118.0);
/// Height kept for the status line (with its bar) or the hint, logical pixels.
pub const STATUS_SLOT_PX: f32 = 52.0;
/// Padding around the whole interface, logical pixels.
const EDGE_PX: f32 = 16.0;
/// Padding inside cards, logical pixels.
const CARD_PAD_PX: f32 = 12.0;
/// Gap between the status/hint line and the pose strip, logical pixels.
const BOTTOM_GAP_PX: f32 = 12.0;
/// [`SceneMargins::top`] before the layout is measured: the top bar (its 88-pixel buttons in
/// a card).
pub const SCENE_TOP_PX: f32 = EDGE_PX + 2.0 * CARD_PAD_PX + 88.0;
/// [`SceneMargins::bottom`] before the layout is measured: status/hint line, gap, one row of
/// pose buttons in a card.
pub const SCENE_BOTTOM_PX: f32 =
    EDGE_PX + 2.0 * CARD_PAD_PX + POSE_BUTTON_PX.1 + BOTTOM_GAP_PX + STATUS_SLOT_PX;

/// The visitor interface.
pub struct UiPlugin {
    pub headless: bool,
}

/// What pressing a button does.
#[derive(Component, Clone, Debug, PartialEq)]
pub enum UiAction {
    /// Animate to the named pose.
    Pose(String),
    /// Carousel: the previous statue.
    PreviousStatue,
    /// Carousel: the next statue.
    NextStatue,
    /// Back to the home state.
    Reset,
    /// Operator: the skinning method.
    Method(Method),
    /// Operator: bones on/off.
    ToggleBones,
    /// Operator panel open/closed.
    ToggleOperatorPanel,
}

/// Whether the operator panel is open.
#[derive(Resource, Clone, Copy, Debug, Default, PartialEq)]
pub struct OperatorPanel {
    pub open: bool,
}

/// Frames per second, smoothed (operator panel).
#[derive(Resource, Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameRate {
    pub fps: f32,
}

/// The font of the interface, when one was found (see [`font_candidates`]); without one,
/// Bevy's built-in font (ASCII only) is used and texts go through [`ascii_fallback`].
#[derive(Resource, Clone, Debug, Default)]
pub struct UiFont {
    pub handle: Option<Handle<Font>>,
    pub path: Option<PathBuf>,
}

/// The nodes the UI updates.
#[derive(Component, Clone, Copy, Debug, PartialEq, Eq)]
pub enum UiPart {
    Title,
    /// The top row (title, carousel card, reset): its bottom is [`SceneMargins::top`].
    TopBar,
    StatueTitle,
    Credit,
    /// The bottom column (status/hint line and pose strip): its top is
    /// [`SceneMargins::bottom`] from the window's bottom edge.
    BottomBar,
    /// The status card (text and progress bar).
    Status,
    StatusText,
    /// The progress bar's track and its fill (width: the percentage).
    ProgressTrack,
    ProgressFill,
    Hint,
    PoseStrip,
    ErrorCard,
    ErrorText,
    StillThere,
    StillThereText,
    Countdown,
    ContinueText,
    OperatorPanel,
    BonesLabel,
    Fps,
    Work,
    Problems,
}

/// The pictogram of a pose button ([`UiAction::Pose`] of its button): the pose name.
#[derive(Component, Clone, Debug, PartialEq)]
pub struct PoseIcon(pub String);

impl Plugin for UiPlugin {
    fn build(&self, app: &mut App) {
        app.init_resource::<OperatorPanel>()
            .init_resource::<SceneMargins>()
            .init_resource::<UiFont>()
            .init_resource::<FrameRate>()
            .init_resource::<ShowBones>()
            .add_message::<PoseRequested>()
            .add_message::<StatueSelected>()
            .add_message::<ResetRequested>()
            .add_message::<Interaction>()
            .add_message::<ThreeFingerTap>()
            .add_systems(
                Update,
                (press_buttons, toggle_operator_panel, measure_fps)
                    .chain()
                    .in_set(KioskSet::Ui),
            );
        if !self.headless {
            app.add_systems(Startup, (load_font, spawn_ui).chain())
                .add_systems(
                    Update,
                    (
                        update_texts,
                        update_buttons,
                        update_pose_icons,
                        measure_scene_margins,
                    )
                        .after(measure_fps)
                        .in_set(KioskSet::Ui),
                );
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Pure helpers.

/// A pose name as visitors read it: `arms_raised` → "Arms raised", `identity` → "Original",
/// a file path → its stem, made friendly the same way.
pub fn friendly_pose_name(name: &str) -> String {
    let stem = std::path::Path::new(name)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| name.to_string());
    if stem == "identity" {
        return "Original".into();
    }
    let words = stem.replace(['_', '-'], " ");
    let words = words.split_whitespace().collect::<Vec<_>>().join(" ");
    let mut c = words.chars();
    match c.next() {
        Some(first) => first.to_uppercase().chain(c).collect(),
        None => name.to_string(),
    }
}

/// The statue index `step` places from `current` on a carousel of `count` statues (wrapping).
pub fn carousel_step(current: usize, count: usize, step: isize) -> usize {
    if count == 0 {
        return 0;
    }
    (current as isize + step).rem_euclid(count as isize) as usize
}

/// The share of the fit done as a whole percentage, rounded down (100 only when finished; a
/// non-finite fraction counts as 0).
pub fn fitting_percent(fraction: f32) -> u32 {
    if fraction.is_finite() {
        (fraction.clamp(0.0, 1.0) * 100.0).floor() as u32
    } else {
        0
    }
}

/// The share of the fit a state shows on the progress bar, in `[0, 1]`: FAKIR's fraction
/// while fitting, 1 while binding, `None` when there is no bar (loading, ready, failed).
pub fn progress_fraction(state: &StatueState) -> Option<f32> {
    match state {
        StatueState::Fitting { fraction, .. } => Some(fitting_percent(*fraction) as f32 / 100.0),
        StatueState::Binding => Some(1.0),
        _ => None,
    }
}

/// `texts.fitting` with a percentage: in place of `{percent}` when the text has it (a
/// translation can write "… {percent} %"), else appended as "… 42%".
pub fn fitting_text(texts: &Texts, percent: u32) -> String {
    with_percent(&texts.fitting, percent)
}

/// The text of a fitting attempt ([`Attempt`]: `texts.fitting` for the whole figure,
/// `texts.fitting_again` for a second registration without limbs found lost) with its
/// percentage, placed as in [`fitting_text`].
pub fn attempt_text(texts: &Texts, attempt: Attempt, percent: u32) -> String {
    match attempt {
        Attempt::Whole => fitting_text(texts, percent),
        Attempt::Bust
        | Attempt::Pair
        | Attempt::PairBelow
        | Attempt::Broken
        | Attempt::BrokenAgain => with_percent(&texts.fitting_again, percent),
    }
}

fn with_percent(text: &str, percent: u32) -> String {
    if text.contains("{percent}") {
        text.replace("{percent}", &percent.to_string())
    } else {
        format!("{text} {percent}%")
    }
}

/// The status line for a statue state (empty when there is nothing to say): loading, or the
/// fit's share done as a percentage (100 % while the binding is built).
pub fn status_text(state: &StatueState, texts: &Texts) -> String {
    match state {
        StatueState::Loading => texts.loading.clone(),
        StatueState::Fitting {
            fraction, attempt, ..
        } => attempt_text(texts, *attempt, fitting_percent(*fraction)),
        StatueState::Binding => fitting_text(texts, 100),
        StatueState::Ready | StatueState::Failed { .. } => String::new(),
    }
}

/// How the kiosk draws its pose pictograms: [`PictogramOptions`]' defaults at
/// [`POSE_ICON_PX`].
pub fn pose_icon_options() -> PictogramOptions {
    PictogramOptions {
        width: POSE_ICON_PX.0,
        height: POSE_ICON_PX.1,
        ..PictogramOptions::default()
    }
}

/// RGBA pixels (sRGB, straight alpha, `width × height`, top row first) as a Bevy image.
pub fn rgba_image(width: u32, height: u32, rgba: Vec<u8>) -> Image {
    use bevy::asset::RenderAssetUsages;
    use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat};
    Image::new(
        Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        rgba,
        TextureFormat::Rgba8UnormSrgb,
        RenderAssetUsages::default(),
    )
}

/// Where the interface looks for its font, in order: `<assets_root>/fonts/ui.ttf` (or
/// `.otf`; a museum can ship a font covering its language there), then common system sans
/// fonts (DejaVu Sans, Noto Sans, Liberation Sans).
pub fn font_candidates(assets_root: &Path) -> Vec<PathBuf> {
    let mut v = vec![
        assets_root.join("fonts/ui.ttf"),
        assets_root.join("fonts/ui.otf"),
    ];
    v.extend(
        [
            "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
            "/usr/share/fonts/TTF/DejaVuSans.ttf",
            "/usr/share/fonts/dejavu/DejaVuSans.ttf",
            "/usr/share/fonts/truetype/noto/NotoSans-Regular.ttf",
            "/usr/share/fonts/noto/NotoSans-Regular.ttf",
            "/usr/share/fonts/truetype/liberation/LiberationSans-Regular.ttf",
            "C:/Windows/Fonts/segoeui.ttf",
            "C:/Windows/Fonts/arial.ttf",
        ]
        .map(PathBuf::from),
    );
    v
}

/// Typographic characters Bevy's built-in font lacks, replaced by ASCII look-alikes (dashes,
/// middle dots, ellipses, curly quotes, non-breaking spaces).
pub fn ascii_fallback(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '\u{2010}'..='\u{2015}' | '\u{2212}' => out.push('-'),
            '\u{00b7}' | '\u{2022}' | '\u{2027}' => out.push('|'),
            '\u{2026}' => out.push_str("..."),
            '\u{2018}' | '\u{2019}' | '\u{201a}' | '\u{2032}' => out.push('\''),
            '\u{201c}' | '\u{201d}' | '\u{201e}' | '\u{00ab}' | '\u{00bb}' => out.push('"'),
            '\u{00a0}' | '\u{202f}' | '\u{2009}' => out.push(' '),
            '\u{00d7}' => out.push('x'),
            c => out.push(c),
        }
    }
    out
}

/// The countdown as shown (whole seconds, rounded up).
pub fn countdown_text(remaining_s: f32) -> String {
    format!("{}", remaining_s.max(0.0).ceil() as u32)
}

// ---------------------------------------------------------------------------------------------
// Logic (runs headless too).

#[allow(clippy::too_many_arguments)]
fn press_buttons(
    buttons: Query<(&UiInteraction, &UiAction), Changed<UiInteraction>>,
    settings: Option<Res<Settings>>,
    active: Option<Res<ActiveStatue>>,
    mut panel: ResMut<OperatorPanel>,
    mut show_bones: ResMut<ShowBones>,
    mut commands: Commands,
    mut poses: MessageWriter<PoseRequested>,
    mut statues: MessageWriter<StatueSelected>,
    mut reset: MessageWriter<ResetRequested>,
    mut interactions: MessageWriter<Interaction>,
) {
    let count = settings.as_ref().map_or(0, |s| s.0.statues.len());
    let current = active.as_ref().map_or(0, |a| a.index);
    for (state, action) in &buttons {
        if *state != UiInteraction::Pressed {
            continue;
        }
        interactions.write(Interaction);
        match action {
            UiAction::Pose(name) => {
                poses.write(PoseRequested(name.clone()));
            }
            UiAction::PreviousStatue | UiAction::NextStatue if count > 0 => {
                let step = if *action == UiAction::NextStatue {
                    1
                } else {
                    -1
                };
                statues.write(StatueSelected(carousel_step(current, count, step)));
            }
            UiAction::PreviousStatue | UiAction::NextStatue => {}
            UiAction::Reset => {
                reset.write(ResetRequested);
            }
            UiAction::Method(m) => commands.insert_resource(SkinMethod(*m)),
            UiAction::ToggleBones => show_bones.0 = !show_bones.0,
            UiAction::ToggleOperatorPanel => panel.open = !panel.open,
        }
    }
}

fn toggle_operator_panel(
    keys: Option<Res<ButtonInput<KeyCode>>>,
    mut taps: MessageReader<ThreeFingerTap>,
    mut panel: ResMut<OperatorPanel>,
) {
    let mut toggles = taps.read().count();
    if keys.is_some_and(|k| k.just_pressed(KeyCode::F2)) {
        toggles += 1;
    }
    if toggles % 2 == 1 {
        panel.open = !panel.open;
    }
}

fn measure_fps(time: Res<Time<Real>>, mut rate: ResMut<FrameRate>) {
    let dt = time.delta_secs();
    if dt > 0.0 {
        let now = 1.0 / dt;
        rate.fps = if rate.fps > 0.0 {
            rate.fps * 0.9 + now * 0.1
        } else {
            now
        };
    }
}

// ---------------------------------------------------------------------------------------------
// Drawing.

pub(crate) const FG: Color = Color::srgb(0.95, 0.94, 0.90);
pub(crate) const FG_DIM: Color = Color::srgb(0.74, 0.73, 0.69);
pub(crate) const CARD: Color = Color::srgba(0.07, 0.08, 0.11, 0.72);
pub(crate) const BUTTON: Color = Color::srgba(0.20, 0.22, 0.28, 0.92);
const BUTTON_HOVER: Color = Color::srgba(0.28, 0.31, 0.38, 0.95);
const BUTTON_PRESSED: Color = Color::srgba(0.42, 0.47, 0.56, 1.0);
const BUTTON_ON: Color = Color::srgba(0.18, 0.44, 0.52, 0.95);
const ERROR_CARD: Color = Color::srgba(0.30, 0.14, 0.12, 0.88);
const OVERLAY: Color = Color::srgba(0.0, 0.0, 0.0, 0.62);
const PROGRESS_TRACK: Color = Color::srgba(1.0, 1.0, 1.0, 0.16);
const PROGRESS_FILL: Color = Color::srgb(0.93, 0.62, 0.33);

fn button_node(min_width: f32, min_height: f32) -> Node {
    Node {
        min_width: Val::Px(min_width),
        min_height: Val::Px(min_height),
        padding: UiRect::axes(Val::Px(22.0), Val::Px(12.0)),
        justify_content: JustifyContent::Center,
        align_items: AlignItems::Center,
        border_radius: BorderRadius::all(Val::Px(14.0)),
        ..default()
    }
}

/// How texts are drawn: the UI font, and whether it is Bevy's built-in ASCII-only font
/// (then texts go through [`ascii_fallback`]).
pub(crate) struct Look {
    font: FontSource,
    ascii: bool,
}

impl Look {
    /// The look of the interface font (Bevy's built-in one, ASCII only, without it).
    pub(crate) fn new(font: &UiFont) -> Look {
        Look {
            font: font
                .handle
                .clone()
                .map_or_else(FontSource::default, FontSource::Handle),
            ascii: font.handle.is_none(),
        }
    }

    pub(crate) fn text(
        &self,
        s: impl Into<String>,
        size: f32,
        color: Color,
    ) -> (Text, TextFont, TextColor) {
        let s: String = s.into();
        (
            Text::new(if self.ascii { ascii_fallback(&s) } else { s }),
            TextFont {
                font: self.font.clone(),
                font_size: FontSize::Px(size),
                ..default()
            },
            TextColor(color),
        )
    }

    fn button(
        &self,
        action: UiAction,
        label: String,
        size: f32,
        min_w: f32,
        min_h: f32,
    ) -> impl Bundle {
        (
            Button,
            action,
            button_node(min_w, min_h),
            BackgroundColor(BUTTON),
            children![self.text(label, size, FG)],
        )
    }

    /// A pose button: the pose's pictogram ([`PoseIcon`], drawn by [`update_pose_icons`])
    /// over its friendly name.
    fn pose_button(&self, pose: &str) -> impl Bundle {
        (
            Button,
            UiAction::Pose(pose.to_string()),
            Node {
                flex_direction: FlexDirection::Column,
                row_gap: Val::Px(2.0),
                padding: UiRect::axes(Val::Px(18.0), Val::Px(8.0)),
                ..button_node(POSE_BUTTON_PX.0, POSE_BUTTON_PX.1)
            },
            BackgroundColor(BUTTON),
            children![
                (
                    ImageNode::default(),
                    Node {
                        width: Val::Px(POSE_ICON_PX.0 as f32),
                        height: Val::Px(POSE_ICON_PX.1 as f32),
                        ..default()
                    },
                    PoseIcon(pose.to_string()),
                ),
                self.text(friendly_pose_name(pose), 20.0, FG),
            ],
        )
    }
}

fn card(node: Node) -> (Node, BackgroundColor) {
    (
        Node {
            border_radius: BorderRadius::all(Val::Px(18.0)),
            padding: UiRect::all(Val::Px(CARD_PAD_PX)),
            ..node
        },
        BackgroundColor(CARD),
    )
}

fn spawn_ui(mut commands: Commands, settings: Res<Settings>, font: Res<UiFont>) {
    let look = Look::new(&font);
    let cfg = &settings.0;
    let t = &cfg.texts;
    let first = cfg.statues.first();
    // The whole screen: top bar, middle, bottom strip.
    commands
        .spawn(Node {
            width: Val::Percent(100.0),
            height: Val::Percent(100.0),
            position_type: PositionType::Absolute,
            flex_direction: FlexDirection::Column,
            justify_content: JustifyContent::SpaceBetween,
            padding: UiRect::all(Val::Px(EDGE_PX)),
            ..default()
        })
        .with_children(|root| {
            // Top bar: title, carousel, reset.
            root.spawn((
                Node {
                    flex_direction: FlexDirection::Row,
                    justify_content: JustifyContent::SpaceBetween,
                    align_items: AlignItems::FlexStart,
                    ..default()
                },
                UiPart::TopBar,
            ))
            .with_children(|top| {
                top.spawn((look.text(t.title.clone(), 30.0, FG_DIM), UiPart::Title));
                top.spawn((
                    card(Node {
                        flex_direction: FlexDirection::Row,
                        align_items: AlignItems::Center,
                        column_gap: Val::Px(16.0),
                        ..default()
                    }),
                    // Presses on the card do not turn the statue.
                    UiInteraction::default(),
                ))
                .with_children(|c| {
                    c.spawn(look.button(UiAction::PreviousStatue, "<".into(), 40.0, 88.0, 88.0));
                    c.spawn(Node {
                        flex_direction: FlexDirection::Column,
                        align_items: AlignItems::Center,
                        min_width: Val::Px(320.0),
                        ..default()
                    })
                    .with_children(|col| {
                        col.spawn((
                            look.text(first.map_or("", |s| s.title.as_str()), 34.0, FG),
                            UiPart::StatueTitle,
                        ));
                        col.spawn((
                            look.text(first.map_or("", |s| s.credit.as_str()), 18.0, FG_DIM),
                            UiPart::Credit,
                        ));
                    });
                    c.spawn(look.button(UiAction::NextStatue, ">".into(), 40.0, 88.0, 88.0));
                });
                top.spawn(look.button(UiAction::Reset, t.reset.clone(), 28.0, 140.0, 88.0));
            });
            // Middle: the error card (over the scene; the statue is framed here).
            root.spawn(Node {
                flex_grow: 1.0,
                flex_direction: FlexDirection::Column,
                align_items: AlignItems::Center,
                justify_content: JustifyContent::Center,
                ..default()
            })
            .with_children(|mid| {
                mid.spawn((
                    Node {
                        max_width: Val::Px(640.0),
                        padding: UiRect::all(Val::Px(28.0)),
                        border_radius: BorderRadius::all(Val::Px(22.0)),
                        justify_content: JustifyContent::Center,
                        ..default()
                    },
                    BackgroundColor(ERROR_CARD),
                    Visibility::Hidden,
                    UiPart::ErrorCard,
                ))
                .with_children(|e| {
                    e.spawn((
                        look.text(t.load_failed.clone(), 30.0, FG),
                        UiPart::ErrorText,
                    ));
                });
            });
            // Bottom: the status line or the hint (one place, never both), and the pose strip.
            root.spawn((
                Node {
                    flex_direction: FlexDirection::Column,
                    align_items: AlignItems::Center,
                    row_gap: Val::Px(BOTTOM_GAP_PX),
                    ..default()
                },
                UiPart::BottomBar,
            ))
            .with_children(|bottom| {
                // One grid cell holding both, so the place is the same whichever shows.
                let cell = || Node {
                    grid_row: GridPlacement::start(1),
                    grid_column: GridPlacement::start(1),
                    justify_self: JustifySelf::Center,
                    align_self: AlignSelf::Center,
                    ..default()
                };
                bottom
                    .spawn(Node {
                        display: Display::Grid,
                        grid_template_columns: vec![GridTrack::auto()],
                        grid_template_rows: vec![GridTrack::auto()],
                        min_height: Val::Px(STATUS_SLOT_PX),
                        align_items: AlignItems::Center,
                        justify_items: JustifyItems::Center,
                        ..default()
                    })
                    .with_children(|slot| {
                        slot.spawn((
                            look.text(t.hint.clone(), 22.0, FG_DIM),
                            cell(),
                            UiPart::Hint,
                        ));
                        slot.spawn((
                            Node {
                                flex_direction: FlexDirection::Column,
                                align_items: AlignItems::Stretch,
                                row_gap: Val::Px(6.0),
                                min_width: Val::Px(360.0),
                                padding: UiRect::axes(Val::Px(18.0), Val::Px(7.0)),
                                border_radius: BorderRadius::all(Val::Px(16.0)),
                                ..cell()
                            },
                            BackgroundColor(CARD),
                            UiPart::Status,
                        ))
                        .with_children(|st| {
                            st.spawn((
                                look.text(t.loading.clone(), 22.0, FG),
                                TextLayout::justify(Justify::Center),
                                UiPart::StatusText,
                            ));
                            st.spawn((
                                Node {
                                    height: Val::Px(5.0),
                                    border_radius: BorderRadius::all(Val::Px(2.5)),
                                    overflow: Overflow::clip(),
                                    ..default()
                                },
                                BackgroundColor(PROGRESS_TRACK),
                                Visibility::Hidden,
                                UiPart::ProgressTrack,
                            ))
                            .with_children(|track| {
                                track.spawn((
                                    Node {
                                        width: Val::Percent(0.0),
                                        height: Val::Percent(100.0),
                                        ..default()
                                    },
                                    BackgroundColor(PROGRESS_FILL),
                                    UiPart::ProgressFill,
                                ));
                            });
                        });
                    });
                bottom
                    .spawn((
                        card(Node {
                            flex_direction: FlexDirection::Row,
                            flex_wrap: FlexWrap::Wrap,
                            justify_content: JustifyContent::Center,
                            column_gap: Val::Px(12.0),
                            row_gap: Val::Px(12.0),
                            ..default()
                        }),
                        UiInteraction::default(),
                        UiPart::PoseStrip,
                    ))
                    .with_children(|strip| {
                        for pose in &cfg.skinning.poses {
                            strip.spawn(look.pose_button(pose));
                        }
                    });
            });
        });

    // "Still there?" overlay: lets touches through (the gestures' Interaction wakes the
    // kiosk up).
    commands
        .spawn((
            Node {
                width: Val::Percent(100.0),
                height: Val::Percent(100.0),
                position_type: PositionType::Absolute,
                flex_direction: FlexDirection::Column,
                justify_content: JustifyContent::Center,
                align_items: AlignItems::Center,
                row_gap: Val::Px(24.0),
                ..default()
            },
            BackgroundColor(OVERLAY),
            GlobalZIndex(10),
            Visibility::Hidden,
            UiPart::StillThere,
        ))
        .with_children(|o| {
            o.spawn((
                look.text(t.still_there.clone(), 64.0, FG),
                UiPart::StillThereText,
            ));
            o.spawn((look.text("", 120.0, FG), UiPart::Countdown));
            o.spawn((
                look.text(t.touch_to_continue.clone(), 32.0, FG_DIM),
                UiPart::ContinueText,
            ));
        });

    // Operator panel.
    commands
        .spawn((
            Node {
                position_type: PositionType::Absolute,
                right: Val::Px(16.0),
                top: Val::Px(130.0),
                width: Val::Px(480.0),
                flex_direction: FlexDirection::Column,
                row_gap: Val::Px(12.0),
                padding: UiRect::all(Val::Px(18.0)),
                border_radius: BorderRadius::all(Val::Px(18.0)),
                ..default()
            },
            BackgroundColor(Color::srgba(0.05, 0.05, 0.07, 0.92)),
            UiInteraction::default(),
            GlobalZIndex(20),
            Visibility::Hidden,
            UiPart::OperatorPanel,
        ))
        .with_children(|p| {
            p.spawn(Node {
                flex_direction: FlexDirection::Row,
                justify_content: JustifyContent::SpaceBetween,
                align_items: AlignItems::Center,
                ..default()
            })
            .with_children(|h| {
                h.spawn(look.text("Operator", 26.0, FG));
                h.spawn(look.button(
                    UiAction::ToggleOperatorPanel,
                    "Close".into(),
                    20.0,
                    96.0,
                    56.0,
                ));
            });
            p.spawn(look.text("Skinning", 18.0, FG_DIM));
            p.spawn(Node {
                flex_direction: FlexDirection::Row,
                flex_wrap: FlexWrap::Wrap,
                column_gap: Val::Px(8.0),
                row_gap: Val::Px(8.0),
                ..default()
            })
            .with_children(|row| {
                for m in Method::ALL {
                    row.spawn(look.button(UiAction::Method(m), m.name().into(), 20.0, 90.0, 56.0));
                }
            });
            p.spawn((
                Button,
                UiAction::ToggleBones,
                button_node(160.0, 56.0),
                BackgroundColor(BUTTON),
            ))
            .with_children(|b| {
                b.spawn((look.text("Bones: off", 20.0, FG), UiPart::BonesLabel));
            });
            p.spawn((look.text("", 18.0, FG), UiPart::Fps));
            p.spawn((look.text("", 18.0, FG), UiPart::Work));
            p.spawn((look.text("", 16.0, FG_DIM), UiPart::Problems));
        });
}

/// Loads the first font of [`font_candidates`] that reads and parses into the font assets.
pub(crate) fn load_font(
    settings: Res<Settings>,
    fonts: Option<ResMut<Assets<Font>>>,
    mut ui_font: ResMut<UiFont>,
) {
    let Some(mut fonts) = fonts else { return };
    for path in font_candidates(&settings.0.assets_root) {
        let Ok(bytes) = std::fs::read(&path) else {
            continue;
        };
        if bytes.len() < 12 {
            continue;
        }
        info!("interface font: {}", path.display());
        ui_font.handle = Some(fonts.add(Font::from_bytes(bytes)));
        ui_font.path = Some(path);
        return;
    }
    warn!(
        "no interface font found (put one at {}); using Bevy's built-in font, ASCII only",
        settings.0.assets_root.join("fonts/ui.ttf").display()
    );
}

pub(crate) fn set_text(ascii: bool, text: &mut Mut<Text>, s: &str) {
    let s = if ascii {
        ascii_fallback(s)
    } else {
        s.to_string()
    };
    if text.0 != s {
        text.0 = s;
    }
}

pub(crate) fn set_visible(v: &mut Mut<Visibility>, visible: bool) {
    let want = if visible {
        Visibility::Inherited
    } else {
        Visibility::Hidden
    };
    if **v != want {
        **v = want;
    }
}

#[allow(clippy::too_many_arguments)]
fn update_texts(
    settings: Res<Settings>,
    active: Option<Res<ActiveStatue>>,
    statues: Query<(Entity, &Statue, &StatueState)>,
    idle: Option<Res<IdleState>>,
    panel: Res<OperatorPanel>,
    rate: Res<FrameRate>,
    fit: Option<Res<FitWork>>,
    skin: Option<Res<SkinWork>>,
    show_bones: Res<ShowBones>,
    font: Res<UiFont>,
    mut texts: Query<(&UiPart, &mut Text)>,
    mut visibility: Query<(&UiPart, &mut Visibility)>,
    mut nodes: Query<(&UiPart, &mut Node)>,
) {
    let cfg = &settings.0;
    let ascii = font.handle.is_none();
    let index = active.as_ref().map_or(0, |a| a.index);
    let entry = cfg.statues.get(index);
    let state = statues
        .iter()
        .find(|(e, _, _)| active.as_ref().and_then(|a| a.entity) == Some(*e))
        .or_else(|| statues.iter().next())
        .map(|(_, _, s)| s);
    let status = state.map_or_else(|| cfg.texts.loading.clone(), |s| status_text(s, &cfg.texts));
    let failed = match state {
        Some(StatueState::Failed { message }) => Some(message.as_str()),
        _ => None,
    };
    let ready = matches!(state, Some(StatueState::Ready));
    let progress = state.and_then(progress_fraction);
    let fitting = match state {
        Some(StatueState::Fitting {
            units,
            fraction,
            attempt,
        }) => {
            format!(
                "\nfit ({}) {}% done, {units} work units",
                attempt.name(),
                fitting_percent(*fraction)
            )
        }
        _ => String::new(),
    };
    let still = match idle.as_deref() {
        Some(IdleState::StillThere { remaining_s }) => Some(*remaining_s),
        _ => None,
    };
    let work = format!(
        "registration {:.1} ms (max {:.1}, budget {:.1}){fitting}\nskinning {:.1} ms (max {:.1}, {} deforms)",
        fit.as_ref().map_or(0.0, |f| f.last_ms),
        fit.as_ref().map_or(0.0, |f| f.max_ms),
        fit.as_ref().map_or(0.0, |f| f.budget_ms),
        skin.as_ref().map_or(0.0, |s| s.last_ms),
        skin.as_ref().map_or(0.0, |s| s.max_ms),
        skin.as_ref().map_or(0, |s| s.count),
    );
    let mut problems: Vec<String> = cfg.problems.clone();
    if let Some(m) = failed {
        problems.push(format!("statue: {m}"));
    }
    let problems = if problems.is_empty() {
        "No configuration problems.".to_string()
    } else {
        format!("Problems:\n{}", problems.join("\n"))
    };
    for (part, mut text) in &mut texts {
        match part {
            UiPart::StatueTitle => {
                set_text(ascii, &mut text, entry.map_or("", |e| e.title.as_str()))
            }
            UiPart::Credit => set_text(ascii, &mut text, entry.map_or("", |e| e.credit.as_str())),
            UiPart::StatusText => set_text(ascii, &mut text, &status),
            UiPart::Countdown => set_text(ascii, &mut text, &countdown_text(still.unwrap_or(0.0))),
            UiPart::BonesLabel => set_text(
                ascii,
                &mut text,
                if show_bones.0 {
                    "Bones: on"
                } else {
                    "Bones: off"
                },
            ),
            UiPart::Fps => set_text(ascii, &mut text, &format!("{:.0} fps", rate.fps)),
            UiPart::Work => set_text(ascii, &mut text, &work),
            UiPart::Problems => set_text(ascii, &mut text, &problems),
            _ => {}
        }
    }
    for (part, mut v) in &mut visibility {
        match part {
            UiPart::Status => set_visible(&mut v, !status.is_empty()),
            UiPart::ProgressTrack => set_visible(&mut v, progress.is_some()),
            UiPart::ErrorCard => set_visible(&mut v, failed.is_some()),
            UiPart::Hint => set_visible(&mut v, ready),
            UiPart::StillThere => set_visible(&mut v, still.is_some()),
            UiPart::OperatorPanel => set_visible(&mut v, panel.open),
            _ => {}
        }
    }
    let fill = Val::Percent(100.0 * progress.unwrap_or(0.0));
    for (part, mut node) in &mut nodes {
        if *part == UiPart::ProgressFill && node.width != fill {
            node.width = fill;
        }
    }
}

/// What the pose pictograms were last drawn for (see [`update_pose_icons`]).
#[derive(Default)]
pub(crate) struct IconsDrawn {
    /// The template of the pose pictograms.
    template: Option<String>,
    /// The statue and the change tick of the cloud the "Original" picture shows (`None`: the
    /// rest figure).
    original: Option<(Entity, bevy::ecs::change_detection::Tick)>,
}

/// Draws the pose buttons' pictograms (see the module docs): all of them when the active
/// statue's template changes (the first frame included); "Original" again when the active
/// statue's cloud appears or changes.
pub(crate) fn update_pose_icons(
    settings: Res<Settings>,
    active: Option<Res<ActiveStatue>>,
    clouds: Query<Ref<StatueCloud>>,
    images: Option<ResMut<Assets<Image>>>,
    mut icons: Query<(&PoseIcon, &mut ImageNode)>,
    mut drawn: Local<IconsDrawn>,
    mut template: Local<Option<Arc<Template>>>,
) {
    let Some(mut images) = images else { return };
    let cfg = &settings.0;
    let index = active.as_ref().map_or(0, |a| a.index);
    // Borrowed, not cloned: this runs every frame and usually finds nothing to redraw.
    let name: &str = cfg
        .statues
        .get(index)
        .map_or("human", |e| e.template.as_str());
    let options = pose_icon_options();
    let mut set = |node: &mut Mut<ImageNode>, p: Option<(u32, u32, Vec<u8>)>| {
        node.image = p.map_or_else(Handle::default, |(w, h, rgba)| {
            images.add(rgba_image(w, h, rgba))
        });
    };
    if drawn.template.as_deref() != Some(name) {
        drawn.template = Some(name.to_string());
        drawn.original = None;
        *template = match Template::resolve(name) {
            Ok(t) => Some(Arc::new(t)),
            Err(e) => {
                warn!("no pose pictograms: {e}");
                None
            }
        };
        for (icon, mut node) in &mut icons {
            let p = template.as_ref().and_then(|t| {
                named_pose_pictogram(&icon.0, t.clone(), &options)
                    .map_err(|e| warn!("no pictogram for the pose '{}': {e}", icon.0))
                    .ok()
            });
            set(&mut node, p.map(|p| (p.width, p.height, p.rgba)));
        }
    }
    // "Original": the statue itself once loaded (the rest figure until then).
    let cloud = active
        .as_ref()
        .and_then(|a| a.entity)
        .and_then(|e| clouds.get(e).ok().map(|c| (e, c)));
    let key = cloud.as_ref().map(|(e, c)| (*e, c.last_changed()));
    if key == drawn.original {
        return;
    }
    let had_picture = drawn.original.is_some();
    drawn.original = key;
    if cloud.is_none() && !had_picture {
        return;
    }
    let identity = Pose::identity().name;
    for (icon, mut node) in &mut icons {
        if icon.0 != identity {
            continue;
        }
        let p = match (&cloud, template.as_ref()) {
            (Some((_, c)), _) => Some(statue_picture(&c.0, POSE_ICON_PX)),
            (None, Some(t)) => named_pose_pictogram(&identity, t.clone(), &options)
                .ok()
                .map(|p| (p.width, p.height, p.rgba)),
            (None, None) => None,
        };
        set(&mut node, p);
    }
}

/// Background of [`statue_picture`]'s rendering, keyed out to transparency afterwards (a
/// colour no lit stone takes).
const KEY: [u8; 3] = [255, 0, 255];

/// A small picture of a statue's cloud as scanned, seen from the front (the home view's side)
/// by the point renderer, on a transparent background: `(width, height, RGBA)`.
pub fn statue_picture(cloud: &PointCloud, (w, h): (u32, u32)) -> (u32, u32, Vec<u8>) {
    use crate::render::{Camera, RenderOptions, render};
    let Some(b) = cloud.bounding_box() else {
        return (w, h, vec![0; w as usize * h as usize * 4]);
    };
    let camera = Camera::front(b.min, b.max, w as f32 / h.max(1) as f32);
    let img = render(
        &cloud.positions,
        cloud.normals.as_deref(),
        cloud.colors.as_deref(),
        &camera,
        &RenderOptions {
            width: w,
            height: h,
            background: KEY,
            ..RenderOptions::default()
        },
    );
    let rgba = img
        .rgb
        .chunks_exact(3)
        .flat_map(|c| {
            if c == KEY {
                [0, 0, 0, 0]
            } else {
                [c[0], c[1], c[2], 255]
            }
        })
        .collect();
    (w, h, rgba)
}

/// Measures the top bar and the bottom column after the last layout into [`SceneMargins`]
/// (logical pixels; a change under half a pixel is ignored).
fn measure_scene_margins(
    parts: Query<(&UiPart, &ComputedNode, &UiGlobalTransform)>,
    windows: Query<&Window, With<PrimaryWindow>>,
    mut margins: ResMut<SceneMargins>,
) {
    let Some(window) = windows.iter().next() else {
        return;
    };
    let mut m = *margins;
    for (part, node, at) in &parts {
        if node.size.y <= 0.0 {
            continue;
        }
        let k = node.inverse_scale_factor;
        let (centre, half) = (at.translation.y * k, node.size.y * 0.5 * k);
        match part {
            UiPart::TopBar => m.top = centre + half,
            UiPart::BottomBar => m.bottom = window.height() - (centre - half),
            _ => {}
        }
    }
    if (m.top - margins.top).abs() > 0.5 || (m.bottom - margins.bottom).abs() > 0.5 {
        *margins = m;
    }
}

fn update_buttons(
    method: Option<Res<SkinMethod>>,
    show_bones: Res<ShowBones>,
    mut buttons: Query<(&UiInteraction, &UiAction, &mut BackgroundColor), With<Button>>,
) {
    for (state, action, mut bg) in &mut buttons {
        let on = match action {
            UiAction::Method(m) => method.as_ref().is_some_and(|s| s.0 == *m),
            UiAction::ToggleBones => show_bones.0,
            _ => false,
        };
        let color = match state {
            UiInteraction::Pressed => BUTTON_PRESSED,
            UiInteraction::Hovered => BUTTON_HOVER,
            UiInteraction::None if on => BUTTON_ON,
            UiInteraction::None => BUTTON,
        };
        if bg.0 != color {
            bg.0 = color;
        }
    }
}
