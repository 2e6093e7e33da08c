//! Kiosk gestures (headless: no window, no GPU): touch and mouse messages in, measured effects
//! out. Also the UI's button and operator-panel logic (which turns presses into messages).

use bevy::input::ButtonState;
use bevy::input::InputPlugin;
use bevy::input::keyboard::{Key, KeyboardInput};
use bevy::input::mouse::{MouseButtonInput, MouseScrollUnit, MouseWheel};
use bevy::input::touch::{TouchInput, TouchPhase};
use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use bevy::ui::Interaction as UiInteraction;
use bevy::window::CursorMoved;
use pygmalion::anatomy::{Skeleton, Template};
use pygmalion::fakir::Attempt;
use pygmalion::kiosk::animate::SkinMethod;
use pygmalion::kiosk::config::KioskConfig;
use pygmalion::kiosk::gestures::{
    FOV_Y, GestureConfig, GesturePlugin, GestureState, PickRay, View, chain_of_bone, pick_bone,
    screen_ray,
};
use pygmalion::kiosk::ik;
use pygmalion::kiosk::ui::{
    OperatorPanel, UiAction, UiPlugin, ascii_fallback, carousel_step, fitting_percent,
    friendly_pose_name, progress_fraction, status_text,
};
use pygmalion::kiosk::{
    ActiveStatue, CurrentPose, FittedSkeleton, Interaction, KioskSet, OrbitCamera, PoseAnimation,
    PoseRequested, ResetRequested, Selection, Settings, ShowBones, StatueSelected, StatueState,
};
use pygmalion::skinning::Method;
use std::sync::Arc;
use std::time::Duration;

const SIZE: Vec2 = Vec2::new(1280.0, 800.0);

/// Messages seen (collected in `PostUpdate`).
#[derive(Resource, Default)]
struct Seen {
    interactions: usize,
    poses: Vec<String>,
    statues: Vec<usize>,
    resets: usize,
}

fn collect(
    mut i: MessageReader<Interaction>,
    mut p: MessageReader<PoseRequested>,
    mut s: MessageReader<StatueSelected>,
    mut r: MessageReader<ResetRequested>,
    mut seen: ResMut<Seen>,
) {
    seen.interactions += i.read().count();
    seen.poses.extend(p.read().map(|m| m.0.clone()));
    seen.statues.extend(s.read().map(|m| m.0));
    seen.resets += r.read().count();
}

struct Rig {
    app: App,
    window: Entity,
}

impl Rig {
    fn new() -> Rig {
        let mut app = App::new();
        app.add_plugins((MinimalPlugins, InputPlugin, GesturePlugin::default()))
            .insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_millis(
                16,
            )))
            .add_message::<PoseRequested>()
            .add_message::<StatueSelected>()
            .add_message::<ResetRequested>()
            .init_resource::<Seen>()
            .add_systems(PostUpdate, collect)
            .configure_sets(
                Update,
                (KioskSet::Input, KioskSet::Idle, KioskSet::Ui).chain(),
            );
        let window = app.world_mut().spawn_empty().id();
        app.update();
        Rig { app, window }
    }
    fn touches(&mut self, list: &[(u64, TouchPhase, Vec2)]) {
        for &(id, phase, position) in list {
            self.app.world_mut().write_message(TouchInput {
                phase,
                position,
                window: self.window,
                force: None,
                id,
            });
        }
        self.app.update();
    }
    fn touch(&mut self, id: u64, phase: TouchPhase, p: Vec2) {
        self.touches(&[(id, phase, p)]);
    }
    /// One finger: press, `steps` moves along to `to`, release.
    fn drag(&mut self, from: Vec2, to: Vec2, steps: usize) {
        self.touch(0, TouchPhase::Started, from);
        for k in 1..=steps {
            let p = from.lerp(to, k as f32 / steps as f32);
            self.touch(0, TouchPhase::Moved, p);
        }
        self.touch(0, TouchPhase::Ended, to);
    }
    fn tap(&mut self, at: Vec2) {
        self.touch(0, TouchPhase::Started, at);
        self.touch(0, TouchPhase::Ended, at);
    }
    fn idle(&mut self, frames: usize) {
        for _ in 0..frames {
            self.app.update();
        }
    }
    fn orbit(&self) -> OrbitCamera {
        *self.app.world().resource::<OrbitCamera>()
    }
    fn set_orbit(&mut self, f: impl FnOnce(&mut OrbitCamera)) {
        f(&mut self.app.world_mut().resource_mut::<OrbitCamera>());
    }
    fn selection(&self) -> Option<usize> {
        self.app.world().resource::<Selection>().chain
    }
    fn seen(&self) -> &Seen {
        self.app.world().resource::<Seen>()
    }
    fn view(&self) -> View {
        View::from_orbit(&self.orbit(), SIZE, FOV_Y)
    }
    fn mouse_to(&mut self, p: Vec2) {
        let window = self.window;
        self.app.world_mut().write_message(CursorMoved {
            window,
            position: p,
            delta: None,
        });
    }
    fn mouse_button(&mut self, button: MouseButton, state: ButtonState) {
        let window = self.window;
        self.app.world_mut().write_message(MouseButtonInput {
            button,
            state,
            window,
        });
    }
}

fn human() -> Skeleton {
    Skeleton::rest(Arc::new(Template::builtin("human").unwrap()))
}

/// A rig with a fitted statue (the human rest skeleton, 1 unit tall) framed by the camera.
fn statue_rig() -> (Rig, Entity) {
    let mut rig = Rig::new();
    let s = human();
    let e = rig
        .app
        .world_mut()
        .spawn((CurrentPose(s.clone()), FittedSkeleton(s)))
        .id();
    rig.set_orbit(|o| o.target = Vec3::new(0.0, 0.5, 0.0));
    (rig, e)
}

fn pose_of(rig: &Rig, e: Entity) -> Skeleton {
    rig.app.world().get::<CurrentPose>(e).unwrap().0.clone()
}

fn bone_mid(s: &Skeleton, name: &str) -> Vec3 {
    let b = s.template.bone_index(name).unwrap();
    let posed = s.pose();
    (posed.bones[b].c1 + posed.bones[b].c2) * 0.5
}

#[test]
fn one_finger_drag_orbits_by_the_expected_amount() {
    let mut rig = Rig::new();
    let k = GestureConfig::default().orbit_rad_per_px;
    let before = rig.orbit();
    rig.drag(Vec2::new(640.0, 400.0), Vec2::new(740.0, 400.0), 10);
    let after = rig.orbit();
    // Dragging right turns the statue with the finger: the camera goes the other way.
    assert!(
        (after.yaw - (before.yaw - 100.0 * k)).abs() < 1e-5,
        "{after:?}"
    );
    assert!((after.pitch - before.pitch).abs() < 1e-6);
    assert_eq!(after.distance, before.distance);
    // Dragging down raises the camera.
    rig.drag(Vec2::new(640.0, 300.0), Vec2::new(640.0, 360.0), 6);
    assert!((rig.orbit().pitch - (before.pitch + 60.0 * k)).abs() < 1e-5);
    // Pitch is clamped.
    rig.drag(Vec2::new(640.0, 0.0), Vec2::new(640.0, 4000.0), 8);
    assert!((rig.orbit().pitch - 1.4).abs() < 1e-6);
    rig.drag(Vec2::new(640.0, 4000.0), Vec2::new(640.0, -4000.0), 8);
    assert!((rig.orbit().pitch + 1.4).abs() < 1e-6);
    // Every press wrote an Interaction.
    assert!(rig.seen().interactions >= 4);
}

#[test]
fn movement_under_the_tap_threshold_does_not_orbit() {
    let mut rig = Rig::new();
    let before = rig.orbit();
    rig.drag(Vec2::new(640.0, 400.0), Vec2::new(648.0, 404.0), 4);
    assert_eq!(rig.orbit(), before);
}

#[test]
fn pinch_zooms_and_two_finger_drag_pans() {
    let mut rig = Rig::new();
    let before = rig.orbit();
    rig.touches(&[
        (1, TouchPhase::Started, Vec2::new(540.0, 400.0)),
        (2, TouchPhase::Started, Vec2::new(740.0, 400.0)),
    ]);
    rig.touch(1, TouchPhase::Moved, Vec2::new(490.0, 400.0));
    rig.touch(2, TouchPhase::Moved, Vec2::new(790.0, 400.0));
    rig.touches(&[
        (1, TouchPhase::Ended, Vec2::new(490.0, 400.0)),
        (2, TouchPhase::Ended, Vec2::new(790.0, 400.0)),
    ]);
    let after = rig.orbit();
    // Spread from 200 to 300 px: closer by 200/300.
    assert!(
        (after.distance - before.distance * 200.0 / 300.0).abs() < 1e-4,
        "{after:?}"
    );
    assert!(after.pan.length() < 1e-6, "the midpoint came back");
    assert_eq!(after.yaw, before.yaw, "no orbit while pinching");
    // A pinch is clamped to the zoom range.
    rig.touches(&[
        (1, TouchPhase::Started, Vec2::new(630.0, 400.0)),
        (2, TouchPhase::Started, Vec2::new(650.0, 400.0)),
    ]);
    rig.touches(&[
        (1, TouchPhase::Moved, Vec2::new(0.0, 400.0)),
        (2, TouchPhase::Moved, Vec2::new(1280.0, 400.0)),
    ]);
    rig.touches(&[
        (1, TouchPhase::Ended, Vec2::new(0.0, 400.0)),
        (2, TouchPhase::Ended, Vec2::new(1280.0, 400.0)),
    ]);
    let (lo, _) = GestureConfig::default().zoom_range;
    assert!((rig.orbit().distance - lo * before.home.2).abs() < 1e-5);
    // Two fingers moving together pan: the scene follows the midpoint.
    let d = rig.orbit().distance;
    rig.touches(&[
        (1, TouchPhase::Started, Vec2::new(500.0, 400.0)),
        (2, TouchPhase::Started, Vec2::new(700.0, 400.0)),
    ]);
    rig.touches(&[
        (1, TouchPhase::Moved, Vec2::new(550.0, 430.0)),
        (2, TouchPhase::Moved, Vec2::new(750.0, 430.0)),
    ]);
    rig.touches(&[
        (1, TouchPhase::Ended, Vec2::new(550.0, 430.0)),
        (2, TouchPhase::Ended, Vec2::new(750.0, 430.0)),
    ]);
    let px = rig.view().pixel_size();
    let o = rig.orbit();
    assert!((o.pan.x - (-50.0 * px)).abs() < 1e-5, "{o:?}");
    assert!((o.pan.y - 30.0 * px).abs() < 1e-5, "{o:?}");
    assert!((o.distance - d).abs() < 1e-5);
}

#[test]
fn double_tap_resets_the_view_and_slow_taps_do_not() {
    let mut rig = Rig::new();
    rig.set_orbit(|o| {
        o.yaw = 1.0;
        o.distance = 5.0;
    });
    rig.tap(Vec2::new(100.0, 100.0));
    assert_eq!(rig.orbit().yaw, 1.0, "one tap does nothing to the view");
    rig.tap(Vec2::new(110.0, 105.0));
    let o = rig.orbit();
    assert_eq!((o.yaw, o.pitch, o.distance), o.home);
    // Two taps 0.5 s apart: not a double tap.
    rig.set_orbit(|o| o.yaw = 1.0);
    rig.tap(Vec2::new(100.0, 100.0));
    rig.idle(32);
    rig.tap(Vec2::new(100.0, 100.0));
    assert_eq!(rig.orbit().yaw, 1.0);
    // Two taps far apart: not a double tap.
    rig.idle(32);
    rig.tap(Vec2::new(100.0, 100.0));
    rig.tap(Vec2::new(400.0, 100.0));
    assert_eq!(rig.orbit().yaw, 1.0);
    // A drag followed by a tap: not a double tap.
    rig.idle(32);
    rig.drag(Vec2::new(300.0, 300.0), Vec2::new(340.0, 300.0), 2);
    rig.set_orbit(|o| o.yaw = 1.0);
    rig.tap(Vec2::new(340.0, 300.0));
    assert_eq!(rig.orbit().yaw, 1.0);
}

#[test]
fn mouse_emulates_touch_wheel_zooms_right_drag_pans() {
    let mut rig = Rig::new();
    let k = GestureConfig::default().orbit_rad_per_px;
    let before = rig.orbit();
    // Left drag orbits.
    rig.mouse_to(Vec2::new(600.0, 400.0));
    rig.mouse_button(MouseButton::Left, ButtonState::Pressed);
    rig.idle(1);
    for x in [620.0, 650.0, 680.0] {
        rig.mouse_to(Vec2::new(x, 400.0));
        rig.idle(1);
    }
    rig.mouse_button(MouseButton::Left, ButtonState::Released);
    rig.idle(1);
    assert!((rig.orbit().yaw - (before.yaw - 80.0 * k)).abs() < 1e-5);
    assert!(rig.seen().interactions >= 1);
    // Moving the mouse without a button does nothing.
    rig.mouse_to(Vec2::new(900.0, 100.0));
    rig.idle(1);
    assert!((rig.orbit().yaw - (before.yaw - 80.0 * k)).abs() < 1e-5);
    // Wheel: two lines up zoom in by exp(-0.2).
    let window = rig.window;
    rig.app.world_mut().write_message(MouseWheel {
        unit: MouseScrollUnit::Line,
        x: 0.0,
        y: 2.0,
        window,
        phase: TouchPhase::Moved,
    });
    rig.idle(1);
    assert!((rig.orbit().distance - before.distance * (-0.2f32).exp()).abs() < 1e-5);
    // Right drag pans.
    rig.mouse_to(Vec2::new(600.0, 400.0));
    rig.mouse_button(MouseButton::Right, ButtonState::Pressed);
    rig.idle(1);
    rig.mouse_to(Vec2::new(640.0, 380.0));
    rig.idle(1);
    rig.mouse_button(MouseButton::Right, ButtonState::Released);
    rig.idle(1);
    let px = rig.view().pixel_size();
    let o = rig.orbit();
    assert!((o.pan.x + 40.0 * px).abs() < 1e-5, "{o:?}");
    assert!((o.pan.y + 20.0 * px).abs() < 1e-5, "{o:?}");
    assert!(
        (o.yaw - (before.yaw - 80.0 * k)).abs() < 1e-5,
        "right drag does not orbit"
    );
}

#[test]
fn the_statue_is_framed_between_the_top_bar_and_the_status_line() {
    use pygmalion::cloud::PointCloud;
    use pygmalion::kiosk::SceneMargins;
    use pygmalion::kiosk::statue::{SCENE_FILL, frame_camera};
    // A statue-shaped box of points (1.6 tall on a plinth, 0.6 wide and deep), off the origin.
    let mut positions = Vec::new();
    for i in 0..=20 {
        for j in 0..=20 {
            for k in 0..=20 {
                let f = |n: i32| n as f32 / 20.0;
                positions.push(Vec3::new(
                    2.0 + 0.6 * f(i),
                    -0.3 + 1.6 * f(j),
                    5.0 + 0.6 * f(k),
                ));
            }
        }
    }
    let cloud = PointCloud {
        positions,
        ..Default::default()
    };
    for (screen, margins) in [
        (SIZE, SceneMargins::default()),
        (Vec2::new(1920.0, 1080.0), SceneMargins::default()),
        (
            SIZE,
            SceneMargins {
                top: 100.0,
                bottom: 300.0,
            },
        ),
    ] {
        let mut orbit = OrbitCamera::default();
        frame_camera(&mut orbit, &cloud, screen, margins);
        let view = View::from_orbit(&orbit, screen, FOV_Y);
        let ys: Vec<f32> = cloud
            .positions
            .iter()
            .map(|&p| view.project(p).unwrap().y)
            .collect();
        let (lo, hi) = ys
            .iter()
            .fold((f32::MAX, f32::MIN), |(l, h), &y| (l.min(y), h.max(y)));
        let band = (margins.top, screen.y - margins.bottom);
        println!(
            "{screen}: statue {lo:.0}..{hi:.0} px, free band {:.0}..{:.0}",
            band.0, band.1
        );
        // Inside the free band (the hint and the strip never cover it), filling most of it.
        assert!(lo >= band.0 && hi <= band.1, "{lo}..{hi} outside {band:?}");
        assert!(
            hi - lo > 0.85 * SCENE_FILL * (band.1 - band.0),
            "{lo}..{hi} in {band:?}"
        );
        // Still turned about the statue's own vertical axis, and home is where it started.
        assert!((orbit.target.x - 2.3).abs() < 1e-4 && (orbit.target.z - 5.3).abs() < 1e-4);
        let home = orbit;
        orbit.yaw += 1.0;
        orbit.reset();
        assert_eq!(orbit, home);
    }
}

#[test]
fn screen_ray_and_projection_agree() {
    let mut orbit = OrbitCamera {
        yaw: 0.7,
        pitch: 0.3,
        distance: 2.5,
        target: Vec3::new(0.1, 0.5, -0.2),
        ..Default::default()
    };
    orbit.pan = Vec2::new(0.05, -0.02);
    let view = View::from_orbit(&orbit, SIZE, FOV_Y);
    // The centre of the screen looks at the focus.
    let centre = view.ray(SIZE * 0.5);
    assert!((centre.direction - (orbit.focus() - orbit.eye()).normalize()).length() < 1e-5);
    assert!((view.project(orbit.focus()).unwrap() - SIZE * 0.5).length() < 1e-3);
    // A point projects where its ray comes from.
    let p = Vec3::new(0.3, 0.8, 0.1);
    let s = view.project(p).unwrap();
    let ray: PickRay = screen_ray(view.eye, view.rotation, FOV_Y, SIZE, s);
    let to_p = (p - ray.origin).normalize();
    assert!((ray.direction - to_p).length() < 1e-4);
    // The top edge of the screen is half the vertical field of view above the centre.
    let top = view.ray(Vec2::new(640.0, 0.0));
    let angle = top.direction.angle_between(centre.direction);
    assert!((angle - FOV_Y / 2.0).abs() < 1e-4);
    // At yaw 0 the camera looks down -Z from +Z and screen right is +X.
    let front = View::from_orbit(&OrbitCamera::default(), SIZE, FOV_Y);
    assert!(front.forward().z < -0.9);
    let right = front.project(Vec3::new(0.5, 0.0, 0.0)).unwrap();
    assert!(right.x > 640.0);
}

#[test]
fn picking_finds_the_bone_under_the_ray() {
    let s = human();
    let posed = s.pose();
    let orbit = OrbitCamera {
        target: Vec3::new(0.0, 0.5, 0.0),
        ..Default::default()
    };
    let view = View::from_orbit(&orbit, SIZE, FOV_Y);
    let slack = 16.0 * view.pixel_size();
    for name in ["l_forearm", "r_shin", "head", "l_hand", "spine_lower"] {
        let at = view.project(bone_mid(&s, name)).unwrap();
        let b = pick_bone(&view.ray(at), &posed.bones, slack).expect("a bone");
        assert_eq!(s.template.bones[b].name, name);
    }
    // Far from the body: nothing.
    assert_eq!(
        pick_bone(&view.ray(Vec2::new(20.0, 20.0)), &posed.bones, slack),
        None
    );
    // Followers select their leader's chain, the root block selects nothing.
    let t = &s.template;
    let link = t.bone_index("neck_link").unwrap();
    assert_eq!(chain_of_bone(t, link), t.chain_index("spine"));
    let pelvis = t.block_bones().next().unwrap();
    assert_eq!(chain_of_bone(t, pelvis), None);
}

#[test]
fn tap_on_a_bone_selects_its_chain_and_a_drag_does_not() {
    let (mut rig, _) = statue_rig();
    let s = human();
    let l_arm = s.template.chain_index("l_arm").unwrap();
    let r_leg = s.template.chain_index("r_leg").unwrap();
    let forearm = rig.view().project(bone_mid(&s, "l_forearm")).unwrap();
    // The same path as a drag: no selection (and the view turns).
    rig.drag(forearm, forearm + Vec2::new(0.0, 40.0), 4);
    assert_eq!(rig.selection(), None);
    rig.set_orbit(|o| o.reset());
    rig.idle(30);
    // A tap: the left arm.
    let forearm = rig.view().project(bone_mid(&s, "l_forearm")).unwrap();
    rig.tap(forearm);
    assert_eq!(rig.selection(), Some(l_arm));
    // A long press is not a tap.
    rig.idle(30);
    let shin = rig.view().project(bone_mid(&s, "r_shin")).unwrap();
    rig.touch(0, TouchPhase::Started, shin);
    rig.idle(40);
    rig.touch(0, TouchPhase::Ended, shin);
    assert_eq!(rig.selection(), Some(l_arm));
    // Another bone: its chain.
    rig.tap(shin);
    assert_eq!(rig.selection(), Some(r_leg));
    // Nothing under the tap: nothing selected.
    rig.idle(30);
    rig.tap(Vec2::new(40.0, 700.0));
    assert_eq!(rig.selection(), None);
}

#[test]
fn dragging_the_hand_of_the_selected_arm_poses_it_by_ik() {
    let (mut rig, e) = statue_rig();
    let s = human();
    let t = s.template.clone();
    let l_arm = t.chain_index("l_arm").unwrap();
    let bones = ik::limb_bones(&t, l_arm);
    let wrist_j = t.joint_index("l_wrist").unwrap();
    let chain_joints = [
        "spine_top",
        "l_shoulder",
        "l_elbow",
        "l_wrist",
        "l_hand_tip",
    ];
    // A running pose animation is stopped by the drag.
    rig.app.world_mut().entity_mut(e).insert(PoseAnimation {
        from: s.clone(),
        to: s.clone(),
        elapsed: 0.0,
        duration: 100.0,
    });
    rig.app.world_mut().resource_mut::<Selection>().chain = Some(l_arm);
    let view = rig.view();
    let start = view.project(bone_mid(&s, "l_hand")).unwrap();
    let end = start + Vec2::new(-30.0, -90.0);
    // The expected target: the wrist moved with the finger at the wrist's depth.
    let wrist0 = s.pose().joints[wrist_j];
    let depth = (wrist0 - view.eye).dot(view.forward());
    let target = wrist0 + view.ray(end).at_depth(view.forward(), depth)
        - view.ray(start).at_depth(view.forward(), depth);
    rig.drag(start, end, 6);
    let posed = pose_of(&rig, e).pose();
    let wrist = posed.joints[wrist_j];
    assert!(
        (wrist - target).length() < 0.1 * (wrist0 - target).length(),
        "wrist {wrist:?} did not reach {target:?} (from {wrist0:?})"
    );
    let root = ik::chain_points(&s.pose(), &bones)[0];
    let reach: f32 = bones.iter().map(|&b| s.bones[b].length).sum();
    if (target - root).length() < 0.99 * reach {
        assert!((wrist - target).length() < 1e-3, "reachable target reached");
    }
    // Bone lengths kept (joint to joint along the arm).
    let rest = s.pose();
    for w in chain_joints.windows(2) {
        let (a, b) = (t.joint_index(w[0]).unwrap(), t.joint_index(w[1]).unwrap());
        let l0 = (rest.joints[b] - rest.joints[a]).length();
        let l1 = (posed.joints[b] - posed.joints[a]).length();
        assert!(
            ((l1 - l0) / l0).abs() < 1e-4,
            "{}–{}: {l0} → {l1}",
            w[0],
            w[1]
        );
    }
    // The view did not turn, the selection stays, the animation is gone.
    let o = rig.orbit();
    assert_eq!((o.yaw, o.pitch), (0.0, 0.1));
    assert_eq!(rig.selection(), Some(l_arm));
    assert!(rig.app.world().get::<PoseAnimation>(e).is_none());
    assert!(!rig.app.world().resource::<GestureState>().dragging_limb());
}

#[test]
fn dragging_elsewhere_with_a_selection_orbits_and_keeps_the_pose() {
    let (mut rig, e) = statue_rig();
    let s = human();
    let l_arm = s.template.chain_index("l_arm").unwrap();
    rig.app.world_mut().resource_mut::<Selection>().chain = Some(l_arm);
    // The right hand is not the selected limb's end bone.
    let start = rig.view().project(bone_mid(&s, "r_hand")).unwrap();
    rig.drag(start, start + Vec2::new(60.0, 0.0), 3);
    assert!(rig.orbit().yaw < -0.2);
    let after = pose_of(&rig, e);
    for (a, b) in after.bones.iter().zip(&s.bones) {
        assert_eq!(a.rotation, b.rotation);
    }
}

// --- UI logic (headless) -------------------------------------------------------------------

fn ui_rig() -> Rig {
    let mut rig = Rig::new();
    let config = KioskConfig::default();
    rig.app
        .insert_resource(Settings(config))
        .insert_resource(ActiveStatue {
            index: 2,
            entity: None,
        })
        .insert_resource(SkinMethod(Method::Baseline))
        .add_plugins(UiPlugin { headless: true });
    rig.app.update();
    rig
}

fn press(rig: &mut Rig, action: UiAction) {
    rig.app.world_mut().spawn((action, UiInteraction::Pressed));
    rig.app.update();
}

#[test]
fn buttons_write_their_messages() {
    let mut rig = ui_rig();
    let i0 = rig.seen().interactions;
    press(&mut rig, UiAction::Pose("greeting".into()));
    assert_eq!(rig.seen().poses, ["greeting"]);
    press(&mut rig, UiAction::NextStatue);
    press(&mut rig, UiAction::PreviousStatue);
    assert_eq!(
        rig.seen().statues,
        [0, 1],
        "the carousel wraps from the last statue"
    );
    press(&mut rig, UiAction::Reset);
    assert_eq!(rig.seen().resets, 1);
    press(&mut rig, UiAction::Method(Method::Dqs));
    assert_eq!(rig.app.world().resource::<SkinMethod>().0, Method::Dqs);
    press(&mut rig, UiAction::ToggleBones);
    assert!(rig.app.world().resource::<ShowBones>().0);
    assert_eq!(
        rig.seen().interactions - i0,
        6,
        "every press is an interaction"
    );
    // A button that is only hovered does nothing.
    rig.app
        .world_mut()
        .spawn((UiAction::Reset, UiInteraction::Hovered));
    rig.app.update();
    assert_eq!(rig.seen().resets, 1);
}

#[test]
fn operator_panel_toggles_on_f2_and_three_finger_tap() {
    let mut rig = ui_rig();
    let open = |rig: &Rig| rig.app.world().resource::<OperatorPanel>().open;
    assert!(!open(&rig));
    let window = rig.window;
    rig.app.world_mut().write_message(KeyboardInput {
        key_code: KeyCode::F2,
        logical_key: Key::F2,
        state: ButtonState::Pressed,
        text: None,
        repeat: false,
        window,
    });
    rig.app.update();
    assert!(open(&rig));
    // Three fingers down and up without moving.
    let p = |x: f32| Vec2::new(x, 400.0);
    rig.touches(&[
        (1, TouchPhase::Started, p(500.0)),
        (2, TouchPhase::Started, p(600.0)),
        (3, TouchPhase::Started, p(700.0)),
    ]);
    rig.touches(&[
        (1, TouchPhase::Ended, p(500.0)),
        (2, TouchPhase::Ended, p(600.0)),
        (3, TouchPhase::Ended, p(700.0)),
    ]);
    assert!(!open(&rig));
    // Three fingers that move: a pinch, not a tap.
    let before = rig.orbit();
    rig.touches(&[
        (1, TouchPhase::Started, p(500.0)),
        (2, TouchPhase::Started, p(600.0)),
        (3, TouchPhase::Started, p(700.0)),
    ]);
    rig.touches(&[(1, TouchPhase::Moved, p(400.0))]);
    rig.touches(&[
        (1, TouchPhase::Ended, p(400.0)),
        (2, TouchPhase::Ended, p(600.0)),
        (3, TouchPhase::Ended, p(700.0)),
    ]);
    assert!(!open(&rig));
    assert!(rig.orbit().distance < before.distance);
    press(&mut rig, UiAction::ToggleOperatorPanel);
    assert!(open(&rig));
}

#[test]
fn friendly_names_and_status_lines() {
    assert_eq!(friendly_pose_name("arms_raised"), "Arms raised");
    assert_eq!(friendly_pose_name("identity"), "Original");
    assert_eq!(friendly_pose_name("thinker"), "Thinker");
    assert_eq!(friendly_pose_name("config/poses/my-pose.ron"), "My pose");
    assert_eq!(carousel_step(0, 3, -1), 2);
    assert_eq!(carousel_step(2, 3, 1), 0);
    assert_eq!(carousel_step(0, 0, 1), 0);
    let texts = KioskConfig::default().texts;
    assert_eq!(status_text(&StatueState::Loading, &texts), texts.loading);
    // Fitting: the share done as a whole percentage, rounded down (100 only when finished),
    // whatever the work-unit count; binding shows 100%.
    let fitting = |units, fraction| {
        status_text(
            &StatueState::Fitting {
                units,
                fraction,
                attempt: Attempt::Whole,
            },
            &texts,
        )
    };
    assert_eq!(fitting(42, 0.5), format!("{} 50%", texts.fitting));
    assert_eq!(fitting(7, 0.5), fitting(9000, 0.5));
    assert_eq!(fitting(1, 0.0), format!("{} 0%", texts.fitting));
    assert_eq!(fitting(1, 0.999), format!("{} 99%", texts.fitting));
    assert_eq!(fitting(1, 1.0), format!("{} 100%", texts.fitting));
    assert_eq!(
        status_text(&StatueState::Binding, &texts),
        format!("{} 100%", texts.fitting)
    );
    // A second registration without limbs found lost (a bust, an armless figure) says so,
    // with its own share done.
    for attempt in [Attempt::Bust, Attempt::Pair, Attempt::PairBelow] {
        let again = StatueState::Fitting {
            units: 9000,
            fraction: 0.25,
            attempt,
        };
        assert_eq!(
            status_text(&again, &texts),
            format!("{} 25%", texts.fitting_again)
        );
        assert_ne!(texts.fitting_again, texts.fitting);
    }
    assert_eq!(fitting_percent(f32::NAN), 0);
    assert_eq!(fitting_percent(-0.5), 0);
    assert_eq!(fitting_percent(1.5), 100);
    assert_eq!(fitting_percent(0.4271), 42);
    // The progress bar: FAKIR's share while fitting (as shown), full while binding, none
    // otherwise.
    let bar = |s: StatueState| progress_fraction(&s);
    assert_eq!(
        bar(StatueState::Fitting {
            units: 3,
            fraction: 0.4271,
            attempt: Attempt::Whole,
        }),
        Some(0.42)
    );
    assert_eq!(bar(StatueState::Binding), Some(1.0));
    assert_eq!(bar(StatueState::Loading), None);
    assert_eq!(bar(StatueState::Ready), None);
    // A translation places the number itself.
    let mut french = texts.clone();
    french.fitting = "Révélation de l’anatomie… {percent} %".into();
    assert_eq!(
        status_text(
            &StatueState::Fitting {
                units: 3,
                fraction: 0.25,
                attempt: Attempt::Whole,
            },
            &french
        ),
        "Révélation de l’anatomie… 25 %"
    );
    assert_eq!(status_text(&StatueState::Ready, &texts), "");
    assert_eq!(
        ascii_fallback("1817–22 · scan “x” … ok"),
        "1817-22 | scan \"x\" ... ok"
    );
}

#[test]
fn an_emulated_mouse_press_during_a_touch_is_ignored() {
    let mut rig = Rig::new();
    let k = GestureConfig::default().orbit_rad_per_px;
    let before = rig.orbit();
    // Some platforms echo a touch as a mouse press at the same place.
    rig.mouse_to(Vec2::new(600.0, 400.0));
    rig.mouse_button(MouseButton::Left, ButtonState::Pressed);
    rig.touch(0, TouchPhase::Started, Vec2::new(600.0, 400.0));
    for x in [630.0, 660.0] {
        rig.mouse_to(Vec2::new(x, 400.0));
        rig.touch(0, TouchPhase::Moved, Vec2::new(x, 400.0));
    }
    rig.mouse_button(MouseButton::Left, ButtonState::Released);
    rig.touch(0, TouchPhase::Ended, Vec2::new(660.0, 400.0));
    assert!((rig.orbit().yaw - (before.yaw - 60.0 * k)).abs() < 1e-5);
    // And a tap echoed by the mouse is still a tap (double tap works).
    rig.set_orbit(|o| o.yaw = 1.0);
    for _ in 0..2 {
        rig.mouse_button(MouseButton::Left, ButtonState::Pressed);
        rig.touch(0, TouchPhase::Started, Vec2::new(660.0, 400.0));
        rig.mouse_button(MouseButton::Left, ButtonState::Released);
        rig.touch(0, TouchPhase::Ended, Vec2::new(660.0, 400.0));
    }
    assert_eq!(rig.orbit().yaw, rig.orbit().home.0);
}
