//! Part swapping in the kiosk (`src/kiosk/restore.rs`), headless and driven by injected touches:
//! a synthetic statue with a cut arm shows ghost bones for it; a tap on one opens the donor
//! carousel; a tap on a donor flies the part in and merges it; the restored statue re-poses;
//! undo gives back the original points bit for bit; swipes switch between restorations; a donor
//! that cannot lend the part gets a gentle message and the kiosk goes on.
//!
//! The statues' fits are their ground-truth skeletons, written to the kiosk's cache beforehand
//! (the kiosk uses cached fits), so no registration runs and the tests stay fast.

use bevy::input::InputPlugin;
use bevy::input::touch::{TouchInput, TouchPhase};
use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use pygmalion::anatomy::Template;
use pygmalion::cloud::PointCloud;
use pygmalion::cloud::ply::{WriteOptions, write_ply};
use pygmalion::kiosk::config::{KioskConfig, StatueEntry};
use pygmalion::kiosk::gestures::{FOV_Y, View};
use pygmalion::kiosk::restore::{
    DonorStatus, Donors, EntryState, GhostBone, PartSwap, Provenance, Restoration,
    carousel_entries, entries_per_page, swap_layout,
};
use pygmalion::kiosk::statue::{load, write_cache};
use pygmalion::kiosk::{
    ActiveStatue, CurrentPose, KioskPlugin, OrbitCamera, PoseRequested, Selection, SkinnedPoints,
    StatueBinding, StatueCloud, StatueState,
};
use pygmalion::skinning::Binding;
use pygmalion::synth::{Cut, SynthOptions, SynthStatue, generate};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

const SCREEN: Vec2 = Vec2::new(1280.0, 800.0);
const POINTS: usize = 12_000;

fn synth(seed: u64, cuts: &[&str]) -> SynthStatue {
    let t = Arc::new(Template::builtin("human").unwrap());
    generate(
        t,
        &SynthOptions {
            points: POINTS,
            seed,
            cuts: cuts.iter().map(|c| Cut::parse(c).unwrap()).collect(),
            ..Default::default()
        },
    )
    .unwrap()
}

/// Writes the statues (file name, statue, cached or not) under `dir` and returns the kiosk's
/// configuration; cached statues get their ground truth as fit, and their cut limbs as the
/// lost bones the registration would have reported.
fn setup(dir: &Path, statues: &[(&str, &SynthStatue, bool)]) -> KioskConfig {
    let mut c = KioskConfig {
        assets_root: dir.to_path_buf(),
        cache_dir: dir.join("cache"),
        statues: statues
            .iter()
            .map(|(name, _, _)| StatueEntry {
                file: PathBuf::from(format!("{name}.ply")),
                template: "human".into(),
                title: name.to_string(),
                credit: String::new(),
                up: None,
                ..Default::default()
            })
            .collect(),
        ..Default::default()
    };
    c.budget.point_budget = 20_000;
    c.skinning.pose_seconds = 0.3;
    // No attract mode or idle reset while a test waits.
    c.idle.attract_after_s = 86_400.0;
    c.idle.still_there_after_s = 86_400.0;
    for ((name, s, cached), entry) in statues.iter().zip(&c.statues) {
        write_ply(
            dir.join(format!("{name}.ply")),
            &s.cloud,
            &WriteOptions::default(),
        )
        .unwrap();
        if *cached {
            let l = load(&c.assets_root, &c.cache_dir, entry, c.budget.point_budget).unwrap();
            // The registration's verdict on its lost limbs, as the generator knows them.
            let lost = crate::common::cut_bones(s);
            let b = Binding::new_without(&l.cloud, &s.truth, &lost).unwrap();
            write_cache(&c.cache_dir, &l.cache_key, &s.truth, &b);
        }
    }
    c
}

struct Kiosk {
    app: App,
    window: Entity,
    /// Longest frame seen so far (after the first).
    max_frame: Duration,
    frames: usize,
}

impl Kiosk {
    fn new(c: KioskConfig) -> Kiosk {
        let mut app = App::new();
        app.add_plugins((
            MinimalPlugins,
            InputPlugin,
            KioskPlugin {
                config: c,
                headless: true,
            },
        ))
        .insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_millis(
            16,
        )));
        let window = app.world_mut().spawn_empty().id();
        app.update();
        Kiosk {
            app,
            window,
            max_frame: Duration::ZERO,
            frames: 0,
        }
    }
    fn update(&mut self) {
        let t = Instant::now();
        self.app.update();
        self.max_frame = self.max_frame.max(t.elapsed());
        self.frames += 1;
    }
    /// Updates until `done` (wall-clock limit 120 s); returns the frames run.
    fn until(&mut self, what: &str, mut done: impl FnMut(&mut World) -> bool) -> usize {
        let start = Instant::now();
        let mut n = 0;
        while start.elapsed() < Duration::from_secs(120) {
            self.update();
            n += 1;
            if done(self.app.world_mut()) {
                return n;
            }
        }
        panic!("{what}: not done after {n} frames");
    }
    fn touch(&mut self, phase: TouchPhase, position: Vec2) {
        let window = self.window;
        self.app.world_mut().write_message(TouchInput {
            phase,
            position,
            window,
            force: None,
            id: 7,
        });
        self.update();
    }
    fn tap(&mut self, at: Vec2) {
        self.touch(TouchPhase::Started, at);
        self.touch(TouchPhase::Ended, at);
    }
    fn swipe(&mut self, from: Vec2, to: Vec2) {
        self.touch(TouchPhase::Started, from);
        for k in 1..=6 {
            self.touch(TouchPhase::Moved, from.lerp(to, k as f32 / 6.0));
        }
        self.touch(TouchPhase::Ended, to);
    }
    fn statue(&self) -> Entity {
        self.app.world().resource::<ActiveStatue>().entity.unwrap()
    }
    fn restoration(&self) -> &Restoration {
        self.app
            .world()
            .get::<Restoration>(self.statue())
            .expect("analysed")
    }
    fn swap(&self) -> &PartSwap {
        self.app.world().resource::<PartSwap>()
    }
    fn cloud(&self) -> Arc<PointCloud> {
        self.app
            .world()
            .get::<StatueCloud>(self.statue())
            .unwrap()
            .0
            .clone()
    }
    fn ghosts(&mut self) -> Vec<GhostBone> {
        let w = self.app.world_mut();
        let mut q = w.query::<&GhostBone>();
        let mut v: Vec<GhostBone> = q.iter(w).copied().collect();
        v.sort_by_key(|g| g.bone);
        v
    }
    fn view(&self) -> View {
        View::from_orbit(self.app.world().resource::<OrbitCamera>(), SCREEN, FOV_Y)
    }
    fn entries(&self) -> Vec<pygmalion::kiosk::restore::Entry> {
        let w = self.app.world();
        let c = w.resource::<PartSwap>().carousel.expect("carousel open");
        let cfg = &w.resource::<pygmalion::kiosk::Settings>().0;
        let index = w.resource::<ActiveStatue>().index;
        carousel_entries(
            cfg,
            index,
            c.part,
            self.restoration(),
            w.resource::<Donors>(),
        )
    }
    /// Waits for the statue to be analysed with ghost bones shown.
    fn wait_for_ghosts(&mut self) -> usize {
        self.until("ghost bones", |w| {
            let mut q = w.query::<&GhostBone>();
            q.iter(w).count() > 0
        })
    }
    /// Taps the ghost bones' midpoints until one opens the carousel; returns the tapped bone.
    fn tap_a_ghost(&mut self) -> usize {
        for g in self.ghosts() {
            let mid = (g.shape.c1 + g.shape.c2) * 0.5;
            let Some(at) = self.view().project(mid) else {
                continue;
            };
            self.tap(at);
            if self.swap().carousel.is_some() {
                return g.bone;
            }
        }
        panic!("no ghost bone opened the carousel");
    }
    fn entry_center(&self, i: usize) -> Vec2 {
        let per = entries_per_page(SCREEN);
        let n = self.entries().len();
        let page = self.swap().carousel.unwrap().page;
        let on_page = n.saturating_sub(page * per).min(per);
        swap_layout(SCREEN, on_page).entries[i].center()
    }
    fn wait_ready(&mut self, i: usize) {
        let start = Instant::now();
        while !matches!(self.entries()[i].state, EntryState::Ready(_)) {
            assert!(
                start.elapsed() < Duration::from_secs(120),
                "entry {i} never ready"
            );
            self.update();
        }
    }
}

fn bits(v: &[Vec3]) -> Vec<[u32; 3]> {
    v.iter()
        .map(|p| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()])
        .collect()
}

/// Asserts that `a` and `b` hold the same points, normals and colours, bit for bit.
fn assert_same_points(a: &PointCloud, b: &PointCloud) {
    assert_eq!(a.len(), b.len());
    assert!(bits(&a.positions) == bits(&b.positions), "positions differ");
    assert!(
        bits(a.normals.as_deref().unwrap()) == bits(b.normals.as_deref().unwrap()),
        "normals differ"
    );
    assert_eq!(a.colors, b.colors);
}

#[test]
fn a_missing_forearm_is_borrowed_by_touch_reposed_and_undone_exactly() {
    let dir = crate::common::scratch("kiosk_restore_borrow");
    let target = synth(5, &["bone:l_forearm"]);
    let donor = synth(9, &[]);
    let c = setup(&dir, &[("broken", &target, true), ("donor", &donor, true)]);
    let t0 = Instant::now();
    let mut k = Kiosk::new(c);
    let frames = k.wait_for_ghosts();
    println!(
        "ghost bones after {frames} frames ({:.2} s)",
        t0.elapsed().as_secs_f32()
    );
    for s in &k.restoration().support {
        if s.missing || s.partial {
            println!("{s:?}");
        }
    }
    let template = k.restoration().completed.template.clone();
    let idx = |n: &str| template.bone_index(n).unwrap();
    // The ghosts are exactly the cut arm's bones, full size.
    let ghost_bones: Vec<usize> = k.ghosts().iter().map(|g| g.bone).collect();
    let mut cut = vec![idx("l_forearm"), idx("l_hand")];
    cut.sort();
    assert_eq!(ghost_bones, cut, "ghost bones");
    for g in k.ghosts() {
        let truth = target.truth.pose().bones[g.bone];
        let l = (g.shape.c2 - g.shape.c1).length();
        let lt = (truth.c2 - truth.c1).length();
        assert!(
            l > 0.5 * lt && l < 2.0 * lt,
            "ghost bone {} has length {l}, the cut bone {lt}",
            g.bone
        );
    }
    let original = k.cloud();
    let original_binding = k
        .app
        .world()
        .get::<StatueBinding>(k.statue())
        .unwrap()
        .0
        .clone();
    assert_eq!(original.len(), target.cloud.len());

    // A tap away from the statue opens nothing; a tap on a ghost opens the carousel.
    k.tap(Vec2::new(640.0, 780.0));
    assert!(k.swap().carousel.is_none());
    let bone = k.tap_a_ghost();
    assert!(cut.contains(&bone));
    let entries = k.entries();
    assert_eq!(entries.len(), 1, "{entries:?}");
    assert_eq!(entries[0].title, "donor");
    k.wait_ready(0);
    let EntryState::Ready(n_part) = k.entries()[0].state else {
        unreachable!()
    };
    assert!(n_part > 300, "the donor's arm has {n_part} points");

    // Tap the donor: the part flies in.
    let ready_frames = k.frames;
    let max_before = k.max_frame;
    k.max_frame = Duration::ZERO;
    k.tap(k.entry_center(0));
    assert!(k.swap().carousel.is_none(), "the carousel closed");
    let flying = k.swap().flight.as_ref().expect("flying").entity;
    let end: Vec<Vec3> = k
        .swap()
        .flight
        .as_ref()
        .unwrap()
        .prepared
        .transferred
        .cloud
        .positions
        .clone();
    let gap = |k: &Kiosk| -> f32 {
        let p = k.app.world().get::<SkinnedPoints>(flying).unwrap();
        p.positions
            .iter()
            .zip(&end)
            .map(|(a, b)| (*a - *b).length())
            .sum::<f32>()
            / end.len() as f32
    };
    k.update();
    let g0 = gap(&k);
    for _ in 0..30 {
        k.update();
    }
    let g1 = gap(&k);
    println!("flight: mean distance to the landing place {g0:.4} → {g1:.4} after 0.5 s");
    assert!(g0 > 0.05, "the part starts away from where it lands ({g0})");
    assert!(g1 < 0.8 * g0 && g1 > 0.0, "it moves in ({g0} → {g1})");
    // While it flies the arm's ghosts are hidden.
    assert!(k.ghosts().is_empty());
    let frames = k.until("landing", |w| w.resource::<PartSwap>().landed == 1);
    assert!(
        k.app.world().get_entity(flying).is_err(),
        "the flying points are gone"
    );
    println!("landed after {frames} more frames");

    // The merged statue: more points, the new ones from the donor (statue 1 → source 2).
    let restored = k.cloud();
    let n_new = restored.len() - original.len();
    assert!(restored.len() > original.len());
    assert_eq!(n_new, n_part, "every transferred point is kept");
    let prov = k.app.world().get::<Provenance>(k.statue()).unwrap().clone();
    assert_eq!(prov.source.len(), restored.len());
    assert_eq!(
        prov.source.iter().filter(|&&s| s == 0).count(),
        original.len()
    );
    assert_eq!(prov.source.iter().filter(|&&s| s == 2).count(), n_new);
    assert!(prov.source[..original.len()].iter().all(|&s| s == 0));
    // The donor's points came with the forearm and hand (and the margin on the upper arm).
    let arm = [idx("l_upper_arm"), idx("l_forearm"), idx("l_hand")];
    let on_arm = prov.bone[original.len()..]
        .iter()
        .filter(|&&b| arm.contains(&(b as usize)))
        .count();
    assert_eq!(on_arm, n_new);
    // Rebound, shown exactly (fitted pose), no ghost left, the hypothesis strip counts one.
    let binding = k
        .app
        .world()
        .get::<StatueBinding>(k.statue())
        .unwrap()
        .0
        .clone();
    assert_eq!(binding.len(), restored.len());
    k.update();
    let skinned = bits(
        &k.app
            .world()
            .get::<SkinnedPoints>(k.statue())
            .unwrap()
            .positions,
    );
    assert!(skinned == bits(&restored.positions));
    assert!(k.ghosts().is_empty(), "{:?}", k.ghosts());
    assert_eq!(k.restoration().hypotheses.len(), 2);
    assert_eq!(k.restoration().shown, 1);
    // The new forearm and hand lie on the statue's completed skeleton (the mirror limb's pose,
    // the statue's proportions; the statue is 1 tall).
    let completed: Vec<_> = k
        .restoration()
        .completed
        .pose()
        .bones
        .iter()
        .map(|b| b.prepare())
        .collect();
    let near = restored.positions[original.len()..]
        .iter()
        .filter(|p| {
            completed
                .iter()
                .map(|b| b.sdf_fast(**p))
                .fold(f32::INFINITY, f32::min)
                .abs()
                < 0.01
        })
        .count();
    println!("{near} of {n_new} donor points within 0.01 of the completed skeleton's surface");
    assert!(near as f32 > 0.9 * n_new as f32);

    // Re-posed like any other statue: the borrowed arm moves with the pose.
    k.app
        .world_mut()
        .write_message(PoseRequested("arms_raised".into()));
    for _ in 0..40 {
        k.update();
    }
    let posed = k.app.world().get::<SkinnedPoints>(k.statue()).unwrap();
    let moved = posed.positions[original.len()..]
        .iter()
        .zip(&restored.positions[original.len()..])
        .map(|(a, b)| (*a - *b).length())
        .sum::<f32>()
        / n_new as f32;
    println!("arms raised: the borrowed arm's points moved {moved:.3} on average");
    assert!(moved > 0.1, "the borrowed arm moved {moved}");
    let pose = k
        .app
        .world()
        .get::<CurrentPose>(k.statue())
        .unwrap()
        .0
        .clone();
    let hand = pose.pose().bones[idx("l_hand")].c2;
    let shoulder = pose.pose().bones[idx("l_upper_arm")].c1;
    assert!(hand.y > shoulder.y, "the restored arm is raised");

    // Undo: the original points, bit for bit, shown exactly; the ghosts are back.
    let undo = swap_layout(SCREEN, 0).undo.center();
    k.tap(undo);
    k.update();
    assert_same_points(&k.cloud(), &original);
    assert!(Arc::ptr_eq(
        &k.app.world().get::<StatueBinding>(k.statue()).unwrap().0,
        &original_binding
    ));
    let skinned = k.app.world().get::<SkinnedPoints>(k.statue()).unwrap();
    assert!(bits(&skinned.positions) == bits(&original.positions));
    let prov = k.app.world().get::<Provenance>(k.statue()).unwrap();
    assert!(prov.source.len() == original.len() && prov.source.iter().all(|&s| s == 0));
    assert_eq!(k.restoration().hypotheses.len(), 1);
    k.update();
    assert_eq!(k.ghosts().len(), 2, "the ghosts are back");
    println!(
        "frames: longest {:.1} ms during the swap (of {} frames), {:.1} ms before ({} frames)",
        k.max_frame.as_secs_f64() * 1e3,
        k.frames - ready_frames,
        max_before.as_secs_f64() * 1e3,
        ready_frames
    );
    assert!(
        k.max_frame < Duration::from_millis(500),
        "a frame took {:?}",
        k.max_frame
    );
}

#[test]
fn swipes_switch_restorations_and_a_donor_that_cannot_lend_gets_a_gentle_message() {
    let dir = crate::common::scratch("kiosk_restore_swipe");
    let target = synth(5, &["bone:l_forearm"]);
    let donor = synth(9, &[]);
    let also_broken = synth(11, &["bone:l_forearm"]);
    let unfitted = synth(13, &[]);
    let c = setup(
        &dir,
        &[
            ("broken", &target, true),
            ("donor", &donor, true),
            ("also broken", &also_broken, true),
            ("not fitted", &unfitted, false),
        ],
    );
    let texts = c.texts.clone();
    let mut k = Kiosk::new(c);
    k.wait_for_ghosts();
    let original = k.cloud();
    k.tap_a_ghost();
    // Three donors on two pages; the one without a fit is pending (fitted in the background,
    // never in the frame), the one missing the arm too cannot lend it.
    assert_eq!(entries_per_page(SCREEN), 2);
    k.wait_ready(0);
    let start = Instant::now();
    loop {
        let e = k.entries();
        if matches!(e[1].state, EntryState::Unavailable(_)) {
            break;
        }
        assert!(start.elapsed() < Duration::from_secs(120), "{e:?}");
        k.update();
    }
    let e = k.entries();
    assert_eq!(
        e.iter().map(|e| e.title.as_str()).collect::<Vec<_>>(),
        ["donor", "also broken", "not fitted"]
    );
    assert_eq!(e[2].state, EntryState::Pending);
    assert!(matches!(
        k.app.world().resource::<Donors>().status(3),
        Some(DonorStatus::Loading | DonorStatus::Fitting)
    ));
    // Swipe the carousel to its second page and back.
    let panel = swap_layout(SCREEN, 2).panel;
    let y = swap_layout(SCREEN, 2).heading.center().y;
    k.swipe(
        Vec2::new(panel.max.x - 30.0, y),
        Vec2::new(panel.min.x + 30.0, y),
    );
    assert_eq!(k.swap().carousel.unwrap().page, 1);
    k.swipe(
        Vec2::new(panel.min.x + 30.0, y),
        Vec2::new(panel.max.x - 30.0, y),
    );
    assert_eq!(k.swap().carousel.unwrap().page, 0);
    // The donor that lacks the arm: a gentle message, nothing else changes.
    k.tap(k.entry_center(1));
    assert_eq!(
        k.swap().notice.as_ref().map(|n| n.text.as_str()),
        Some(texts.part_failed.as_str())
    );
    assert!(k.swap().flight.is_none());
    assert!(k.swap().carousel.is_some(), "the carousel stays");
    assert!(Arc::ptr_eq(&k.cloud(), &original));
    for _ in 0..10 {
        k.update();
    }
    assert!(matches!(
        k.app.world().get::<StatueState>(k.statue()),
        Some(StatueState::Ready)
    ));

    // First restoration.
    k.tap(k.entry_center(0));
    k.until("landing 1", |w| w.resource::<PartSwap>().landed == 1);
    let first = k.cloud();
    // Swipe right on the strip: back to the statue as found (exactly), ghosts back.
    let strip = swap_layout(SCREEN, 0).strip;
    let y = strip.center().y;
    let (left, right) = (
        Vec2::new(strip.min.x + 20.0, y),
        Vec2::new(strip.max.x - 20.0, y),
    );
    k.swipe(left, right);
    k.update();
    assert_eq!(k.restoration().shown, 0);
    assert_same_points(&k.cloud(), &original);
    assert!(!k.ghosts().is_empty());
    // Second restoration, built on the original.
    k.tap_a_ghost();
    k.tap(k.entry_center(0));
    k.until("landing 2", |w| w.resource::<PartSwap>().landed == 2);
    let second = k.cloud();
    assert_eq!(k.restoration().hypotheses.len(), 3);
    assert_eq!(k.restoration().shown, 2);
    assert!(!Arc::ptr_eq(&first, &second));
    assert_eq!(first.len(), second.len());
    // Swipe right: the first restoration; swipe left: the second again.
    k.swipe(left, right);
    k.update();
    assert_eq!(k.restoration().shown, 1);
    assert!(Arc::ptr_eq(&k.cloud(), &first));
    k.swipe(right, left);
    k.update();
    assert!(Arc::ptr_eq(&k.cloud(), &second));
    // A short drag is not a swipe.
    k.swipe(strip.center(), strip.center() + Vec2::new(30.0, 0.0));
    assert_eq!(k.restoration().shown, 2);
    // Undo the second: back to what it was built on, the statue as found.
    k.tap(swap_layout(SCREEN, 0).undo.center());
    k.update();
    assert_eq!(k.restoration().hypotheses.len(), 2);
    assert_eq!(k.restoration().shown, 0);
    assert_same_points(&k.cloud(), &original);
    // The unfitted donor never blocked a frame.
    println!(
        "longest frame {:.1} ms over {} frames",
        k.max_frame.as_secs_f64() * 1e3,
        k.frames
    );
    assert!(k.max_frame < Duration::from_millis(500));
}

#[test]
fn an_arm_broken_through_the_upper_arm_is_borrowed_from_the_stump() {
    // The upper arm cut at 0.4 of its length: the part grows from the stump's end
    // (`restore::stump`), so the donor's upper arm comes from there (less the margin), not
    // only the forearm and hand from the elbow. The ghosts are the lost bones; the stump is
    // the statue's own.
    let dir = crate::common::scratch("kiosk_restore_stump");
    let target = synth(5, &["bone:l_upper_arm@0.4"]);
    let donor = synth(9, &[]);
    let c = setup(&dir, &[("broken", &target, true), ("donor", &donor, true)]);
    let mut k = Kiosk::new(c);
    k.wait_for_ghosts();
    let template = k.restoration().completed.template.clone();
    let idx = |n: &str| template.bone_index(n).unwrap();
    let ua = idx("l_upper_arm");
    let ghost_bones: Vec<usize> = k.ghosts().iter().map(|g| g.bone).collect();
    assert_eq!(ghost_bones, [idx("l_forearm"), idx("l_hand")]);
    let part = k.restoration().parts[0].clone();
    assert_eq!(part.bones, [ua, idx("l_forearm"), idx("l_hand")]);
    println!("the part starts at {:.3} of the upper arm", part.from);
    assert!((part.from - 0.4).abs() < 0.05, "from {}", part.from);
    let original = k.cloud();
    // A tap on the stump selects the arm for posing, as on any limb; no carousel.
    let stump = {
        let w = k.app.world();
        let b = w.get::<CurrentPose>(k.statue()).unwrap().0.pose().bones[ua];
        b.c1.lerp(b.c2, 0.5 * part.from)
    };
    k.tap(k.view().project(stump).expect("the stump is in view"));
    assert!(
        k.swap().carousel.is_none(),
        "a tap on the stump opened the carousel"
    );
    let arm_chain = template.bones[ua].chain.map(|c| c.0);
    let chosen = k.app.world().resource::<Selection>().chain;
    println!("a tap on the stump selected chain {chosen:?} (the arm: {arm_chain:?})");
    assert_eq!(chosen, arm_chain);
    k.tap_a_ghost();
    k.wait_ready(0);
    k.tap(k.entry_center(0));
    k.until("landing", |w| w.resource::<PartSwap>().landed == 1);
    let restored = k.cloud();
    let prov = k.app.world().get::<Provenance>(k.statue()).unwrap().clone();
    assert!(prov.source[..original.len()].iter().all(|&s| s == 0));
    // The donor's upper-arm points lie past the stump's end less the margin, on the
    // statue's upper arm.
    let posed = k.restoration().completed.pose();
    let (c1, c2) = (posed.bones[ua].c1, posed.bones[ua].c2);
    let margin = pygmalion::restore::transfer::TransferOptions::default().margin;
    let f: Vec<f32> = (original.len()..restored.len())
        .filter(|&i| prov.bone[i] as usize == ua)
        .map(|i| (restored.positions[i] - c1).dot(c2 - c1) / (c2 - c1).length_squared())
        .collect();
    let lo = f.iter().copied().fold(f32::INFINITY, f32::min);
    println!(
        "{} donor points on the upper arm, from {lo:.3} of it",
        f.len()
    );
    assert!(f.len() > 100, "{} donor points on the upper arm", f.len());
    assert!(lo > part.from - margin - 0.02, "a donor point at {lo}");
}
