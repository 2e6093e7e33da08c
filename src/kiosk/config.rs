//! `config/kiosk.toml`: what the kiosk shows and how it behaves (bevy-free, so it is tested
//! on its own and the CLI can validate a file without opening a window).
//!
//! The kiosk must start whatever the file says: [`KioskConfig::load`] never fails. A missing
//! file gives the defaults; every missing value takes its default; every invalid value (wrong
//! type, out of range, unknown key, a statue outside the assets root) is replaced by its default
//! (or the statue is skipped) and reported in [`KioskConfig::problems`] with the file name,
//! which the kiosk logs and shows on the operator panel.

use crate::skinning::Method;
use std::path::{Component, Path, PathBuf};

/// One statue of the carousel.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StatueEntry {
    /// Path relative to the assets root.
    pub file: PathBuf,
    /// Template name (built-in) or template file.
    pub template: String,
    /// Title shown on the carousel.
    pub title: String,
    /// Credit line (author, licence).
    pub credit: String,
    /// The statue's up axis (`x`, `y`, `z`, `-y`, …) when known; automatic otherwise.
    pub up: Option<String>,
    /// The direction the figure faces (same form as `up`) when known; automatic otherwise
    /// ([`crate::fakir::RegistrationOptions::front`]).
    pub front: Option<String>,
    /// Bones the statue is known to have lost (a broken statue's limbs, each with the bones
    /// it carries: [`crate::fakir::RegistrationOptions::lost`]); registration looks for other
    /// lost limbs too. They show as ghost limbs to borrow.
    pub missing: Vec<String>,
}

/// Idle behaviour.
#[derive(Clone, Debug, PartialEq)]
pub struct IdleConfig {
    pub attract_after_s: f32,
    pub still_there_after_s: f32,
    pub countdown_s: f32,
}

/// Per-frame budgets.
#[derive(Clone, Debug, PartialEq)]
pub struct BudgetConfig {
    pub fakir_ms_per_frame: f32,
    pub point_budget: usize,
}

/// Skinning and pose changes.
#[derive(Clone, Debug, PartialEq)]
pub struct SkinningConfig {
    pub method: Method,
    pub pose_seconds: f32,
    pub poses: Vec<String>,
}

/// Rendering.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderConfig {
    pub point_scale: f32,
    pub edl: bool,
    pub background: [u8; 3],
}

/// The window.
#[derive(Clone, Debug, PartialEq)]
pub struct WindowConfig {
    pub fullscreen: bool,
    pub width: u32,
    pub height: u32,
}

/// Every text the visitor sees (so a museum can translate them).
#[derive(Clone, Debug, PartialEq)]
pub struct Texts {
    pub title: String,
    pub hint: String,
    pub fitting: String,
    /// Shown instead of `fitting` while FAKIR registers the figure a second time without
    /// limbs it found lost (a bust's or an armless figure's hypothesis, [`crate::fakir::Attempt`]),
    /// with that attempt's share done (`{percent}` as in `fitting`).
    pub fitting_again: String,
    pub loading: String,
    pub still_there: String,
    pub touch_to_continue: String,
    pub load_failed: String,
    pub reset: String,
    /// Part swapping ([`super::restore`]): a hint shown while ghost bones are on screen.
    pub ghost_hint: String,
    /// Heading of the donor carousel; `{part}` becomes the part's name.
    pub part_choose: String,
    /// A donor still being prepared (loaded, fitted, its part brought to size).
    pub part_pending: String,
    /// A donor ready to give its part.
    pub part_ready: String,
    /// A donor that cannot give this part.
    pub part_unavailable: String,
    /// The gentle message after a part could not be borrowed.
    pub part_failed: String,
    pub close: String,
    pub undo: String,
    /// The hypothesis strip; `{i}` and `{n}` become the restoration shown and their count.
    pub restoration: String,
    /// The hypothesis strip on the statue as found.
    pub original: String,
}

/// The whole configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct KioskConfig {
    pub assets_root: PathBuf,
    pub cache_dir: PathBuf,
    pub statues: Vec<StatueEntry>,
    pub idle: IdleConfig,
    pub budget: BudgetConfig,
    pub skinning: SkinningConfig,
    pub render: RenderConfig,
    pub window: WindowConfig,
    pub texts: Texts,
    /// What was wrong with the file (each message names it); empty when all was fine.
    pub problems: Vec<String>,
}

impl Default for KioskConfig {
    fn default() -> Self {
        let statue = |file: &str, title: &str, credit: &str, up: Option<&str>| StatueEntry {
            file: PathBuf::from(file),
            template: "human".into(),
            title: title.into(),
            credit: credit.into(),
            up: up.map(String::from),
            front: None,
            missing: Vec::new(),
        };
        KioskConfig {
            assets_root: PathBuf::from("assets"),
            cache_dir: PathBuf::from("target/kiosk-cache"),
            statues: vec![
                StatueEntry {
                    front: Some("z".into()),
                    ..statue(
                        "statues/statue_dancing_girl_thorvaldsen.ply",
                        "Dancing Girl",
                        "Bertel Thorvaldsen, 1817–22 · scan Geoffrey Marchal, CC BY 4.0",
                        None,
                    )
                },
                StatueEntry {
                    front: Some("z".into()),
                    ..statue(
                        "statues/statue_dancing_faun_pompeii.ply",
                        "Dancing Faun",
                        "Pompeii, 2nd c. BC · scan Cosmo Wenman, CC BY 3.0",
                        Some("y"),
                    )
                },
                StatueEntry {
                    front: Some("z".into()),
                    missing: vec!["l_upper_arm".into(), "r_upper_arm".into()],
                    ..statue(
                        "statues/statue_venus_de_milo_cast_incomplete.ply",
                        "Venus de Milo",
                        "plaster cast · scan Cosmo Wenman, CC BY 3.0",
                        Some("y"),
                    )
                },
            ],
            idle: IdleConfig {
                attract_after_s: 60.0,
                still_there_after_s: 180.0,
                countdown_s: 15.0,
            },
            budget: BudgetConfig {
                fakir_ms_per_frame: 4.0,
                point_budget: 300_000,
            },
            skinning: SkinningConfig {
                method: Method::Baseline,
                pose_seconds: 1.0,
                poses: [
                    "identity",
                    "greeting",
                    "arms_raised",
                    "contrapposto",
                    "walking",
                    "thinker",
                ]
                .map(String::from)
                .to_vec(),
            },
            render: RenderConfig {
                point_scale: 1.0,
                edl: true,
                background: [24, 26, 32],
            },
            window: WindowConfig {
                fullscreen: false,
                width: 1280,
                height: 800,
            },
            texts: Texts {
                title: "Pygmalion".into(),
                hint: "Touch the statue to turn it · choose a pose below".into(),
                fitting: "Revealing the anatomy…".into(),
                fitting_again: "Looking for lost limbs…".into(),
                loading: "Loading…".into(),
                still_there: "Still there?".into(),
                touch_to_continue: "Touch the screen to continue".into(),
                load_failed: "This statue could not be shown.".into(),
                reset: "Reset".into(),
                ghost_hint: "Tap a ghost limb to borrow it from another statue".into(),
                part_choose: "Borrow the {part} from:".into(),
                part_pending: "Preparing…".into(),
                part_ready: "Tap to borrow".into(),
                part_unavailable: "Cannot lend this part".into(),
                part_failed: "That part could not be borrowed. Please try another statue.".into(),
                close: "Close".into(),
                undo: "Undo".into(),
                restoration: "Restoration {i} of {n}".into(),
                original: "As found".into(),
            },
            problems: Vec::new(),
        }
    }
}

/// Reads values out of one TOML table, recording problems.
/// A statue's `missing` list: text entries naming limb bones of its template (see
/// [`crate::fakir::support::lost_from_names`]); anything else is reported and left out.
fn missing_bones(s: &mut Section, template: &str) -> Vec<String> {
    let Some(v) = s.get("missing") else {
        return Vec::new();
    };
    let Some(list) = v.as_array() else {
        s.report("missing", "expected a list of bone names, ignored".into());
        return Vec::new();
    };
    // The names are checked against the template when it can be read here (a template that
    // cannot is reported when the statue loads).
    let t = crate::anatomy::Template::resolve(template).ok();
    let mut out = Vec::new();
    for item in list {
        match item.as_str() {
            Some(name) => match &t {
                Some(t) => match crate::fakir::support::lost_from_names(t, &[name.to_string()]) {
                    Ok(_) => out.push(name.to_string()),
                    Err(e) => s.report("missing", format!("{e}; left out")),
                },
                None => out.push(name.to_string()),
            },
            None => s.report(
                "missing",
                format!("expected a bone name, not {item}; left out"),
            ),
        }
    }
    out
}

struct Section<'a> {
    table: Option<&'a toml::Table>,
    name: &'a str,
    file: &'a Path,
    problems: &'a mut Vec<String>,
    seen: Vec<&'static str>,
}

impl<'a> Section<'a> {
    fn report(&mut self, key: &str, what: String) {
        let at = if self.name.is_empty() {
            key.to_string()
        } else {
            format!("{}.{key}", self.name)
        };
        self.problems
            .push(format!("{}: {at}: {what}", self.file.display()));
    }
    fn get(&mut self, key: &'static str) -> Option<&'a toml::Value> {
        self.seen.push(key);
        self.table?.get(key)
    }
    fn f32(&mut self, key: &'static str, default: f32, min: f32, max: f32) -> f32 {
        let Some(v) = self.get(key) else {
            return default;
        };
        let x = match v {
            toml::Value::Float(f) => *f as f32,
            toml::Value::Integer(i) => *i as f32,
            _ => {
                self.report(key, format!("expected a number, using {default}"));
                return default;
            }
        };
        if !(x >= min && x <= max) {
            self.report(
                key,
                format!("{x} is outside [{min}, {max}], using {default}"),
            );
            return default;
        }
        x
    }
    fn uint(&mut self, key: &'static str, default: u64, min: u64, max: u64) -> u64 {
        let Some(v) = self.get(key) else {
            return default;
        };
        match v.as_integer() {
            Some(i) if i >= min as i64 && i <= max as i64 => i as u64,
            _ => {
                self.report(
                    key,
                    format!("expected an integer in [{min}, {max}], using {default}"),
                );
                default
            }
        }
    }
    fn bool(&mut self, key: &'static str, default: bool) -> bool {
        match self.get(key) {
            None => default,
            Some(toml::Value::Boolean(b)) => *b,
            Some(_) => {
                self.report(key, format!("expected true or false, using {default}"));
                default
            }
        }
    }
    fn string(&mut self, key: &'static str, default: &str) -> String {
        match self.get(key) {
            None => default.to_string(),
            Some(toml::Value::String(s)) => s.clone(),
            Some(_) => {
                self.report(key, format!("expected text, using \"{default}\""));
                default.to_string()
            }
        }
    }
    /// Reports keys nobody asked for (typos).
    fn finish(mut self) {
        let Some(t) = self.table else { return };
        let unknown: Vec<String> = t
            .keys()
            .filter(|k| !self.seen.contains(&k.as_str()))
            .cloned()
            .collect();
        for k in unknown {
            self.report(&k, "unknown setting, ignored".into());
        }
    }
}

/// True when `rel` is a relative path that stays inside its root (no `..`, no root or prefix).
pub fn stays_inside(rel: &Path) -> bool {
    !rel.as_os_str().is_empty()
        && rel
            .components()
            .all(|c| matches!(c, Component::Normal(_) | Component::CurDir))
}

impl KioskConfig {
    /// Reads `path`; never fails (see the module docs).
    pub fn load(path: &Path) -> KioskConfig {
        match std::fs::read_to_string(path) {
            Ok(text) => KioskConfig::from_toml(&text, path),
            Err(e) => {
                let mut c = KioskConfig::default();
                c.problems.push(format!(
                    "{}: cannot read ({e}); using the defaults",
                    path.display()
                ));
                c
            }
        }
    }

    /// Parses the text of a configuration file named `path` (for messages).
    pub fn from_toml(text: &str, path: &Path) -> KioskConfig {
        let mut c = KioskConfig::default();
        let root: toml::Table = match text.parse() {
            Ok(t) => t,
            Err(e) => {
                c.problems.push(format!(
                    "{}: not valid TOML ({}); using the defaults",
                    path.display(),
                    e.to_string().lines().next().unwrap_or("syntax error")
                ));
                return c;
            }
        };
        let d = KioskConfig::default();
        let mut problems = Vec::new();
        let table = |key: &str, problems: &mut Vec<String>| -> Option<&toml::Table> {
            match root.get(key) {
                None => None,
                Some(toml::Value::Table(t)) => Some(t),
                Some(_) => {
                    problems.push(format!(
                        "{}: {key}: expected a [{key}] section, ignored",
                        path.display()
                    ));
                    None
                }
            }
        };
        // Top level.
        {
            let mut s = Section {
                table: Some(&root),
                name: "",
                file: path,
                problems: &mut problems,
                seen: vec![
                    "statues", "idle", "budget", "skinning", "render", "window", "texts",
                ],
            };
            c.assets_root =
                PathBuf::from(s.string("assets_root", &d.assets_root.to_string_lossy()));
            c.cache_dir = PathBuf::from(s.string("cache_dir", &d.cache_dir.to_string_lossy()));
            s.finish();
        }
        // Statues.
        if let Some(v) = root.get("statues") {
            match v.as_array() {
                Some(list) => {
                    let mut statues = Vec::new();
                    for (i, item) in list.iter().enumerate() {
                        let name = format!("statues[{i}]");
                        let Some(t) = item.as_table() else {
                            problems.push(format!(
                                "{}: {name}: expected a [[statues]] entry, skipped",
                                path.display()
                            ));
                            continue;
                        };
                        let mut s = Section {
                            table: Some(t),
                            name: &name,
                            file: path,
                            problems: &mut problems,
                            seen: Vec::new(),
                        };
                        let file = s.string("file", "");
                        let template = s.string("template", "human");
                        let title = s.string("title", "");
                        let credit = s.string("credit", "");
                        let mut axis = |key: &'static str| match s.get(key) {
                            None => None,
                            Some(toml::Value::String(u))
                                if crate::cli::register::parse_axis(u).is_ok() =>
                            {
                                Some(u.clone())
                            }
                            Some(_) => {
                                s.report(key, "expected text like \"y\" or \"-z\", ignored".into());
                                None
                            }
                        };
                        let up = axis("up");
                        let front = axis("front");
                        let missing = missing_bones(&mut s, &template);
                        s.finish();
                        let rel = PathBuf::from(&file);
                        if file.is_empty() {
                            problems.push(format!("{}: {name}: no file, skipped", path.display()));
                        } else if !stays_inside(&rel) {
                            problems.push(format!(
                                "{}: {name}: '{file}' is not inside the assets root, skipped",
                                path.display()
                            ));
                        } else {
                            let title = if title.is_empty() {
                                rel.file_stem()
                                    .map(|s| s.to_string_lossy().into_owned())
                                    .unwrap_or_default()
                            } else {
                                title
                            };
                            statues.push(StatueEntry {
                                file: rel,
                                template,
                                title,
                                credit,
                                up,
                                front,
                                missing,
                            });
                        }
                    }
                    if statues.is_empty() {
                        problems.push(format!(
                            "{}: statues: no usable statue, showing the bundled ones",
                            path.display()
                        ));
                    } else {
                        c.statues = statues;
                    }
                }
                None => problems.push(format!(
                    "{}: statues: expected [[statues]] entries, showing the bundled ones",
                    path.display()
                )),
            }
        }
        // Idle.
        {
            let t = table("idle", &mut problems);
            let mut s = Section {
                table: t,
                name: "idle",
                file: path,
                problems: &mut problems,
                seen: Vec::new(),
            };
            c.idle.attract_after_s =
                s.f32("attract_after_s", d.idle.attract_after_s, 1.0, 86_400.0);
            c.idle.still_there_after_s = s.f32(
                "still_there_after_s",
                d.idle.still_there_after_s,
                1.0,
                86_400.0,
            );
            c.idle.countdown_s = s.f32("countdown_s", d.idle.countdown_s, 1.0, 600.0);
            s.finish();
            if c.idle.still_there_after_s < c.idle.attract_after_s {
                problems.push(format!(
                    "{}: idle.still_there_after_s ({}) is shorter than attract_after_s ({}); using {}",
                    path.display(),
                    c.idle.still_there_after_s,
                    c.idle.attract_after_s,
                    c.idle.attract_after_s
                ));
                c.idle.still_there_after_s = c.idle.attract_after_s;
            }
        }
        // Budget.
        {
            let t = table("budget", &mut problems);
            let mut s = Section {
                table: t,
                name: "budget",
                file: path,
                problems: &mut problems,
                seen: Vec::new(),
            };
            c.budget.fakir_ms_per_frame = s.f32(
                "fakir_ms_per_frame",
                d.budget.fakir_ms_per_frame,
                0.2,
                100.0,
            );
            c.budget.point_budget = s.uint(
                "point_budget",
                d.budget.point_budget as u64,
                1_000,
                20_000_000,
            ) as usize;
            s.finish();
        }
        // Skinning.
        {
            let t = table("skinning", &mut problems);
            let mut s = Section {
                table: t,
                name: "skinning",
                file: path,
                problems: &mut problems,
                seen: Vec::new(),
            };
            let m = s.string("method", d.skinning.method.name());
            c.skinning.method = match m.parse() {
                Ok(m) => m,
                Err(e) => {
                    s.report("method", format!("{e}; using baseline"));
                    Method::Baseline
                }
            };
            c.skinning.pose_seconds = s.f32("pose_seconds", d.skinning.pose_seconds, 0.05, 30.0);
            match s.get("poses") {
                None => {}
                Some(toml::Value::Array(a)) => {
                    let names: Vec<String> = a
                        .iter()
                        .filter_map(|v| v.as_str().map(String::from))
                        .collect();
                    if names.len() != a.len() || names.is_empty() {
                        s.report(
                            "poses",
                            "expected a list of pose names, using the defaults".into(),
                        );
                    } else {
                        c.skinning.poses = names;
                    }
                }
                Some(_) => s.report(
                    "poses",
                    "expected a list of pose names, using the defaults".into(),
                ),
            }
            s.finish();
        }
        // Render.
        {
            let t = table("render", &mut problems);
            let mut s = Section {
                table: t,
                name: "render",
                file: path,
                problems: &mut problems,
                seen: Vec::new(),
            };
            c.render.point_scale = s.f32("point_scale", d.render.point_scale, 0.1, 10.0);
            c.render.edl = s.bool("edl", d.render.edl);
            match s.get("background") {
                None => {}
                Some(toml::Value::Array(a))
                    if a.len() == 3
                        && a.iter()
                            .all(|v| v.as_integer().is_some_and(|i| (0..=255).contains(&i))) =>
                {
                    for (k, v) in a.iter().enumerate() {
                        c.render.background[k] = v.as_integer().unwrap_or(0) as u8;
                    }
                }
                Some(_) => s.report(
                    "background",
                    "expected [r, g, b] with values 0–255, using the default".into(),
                ),
            }
            s.finish();
        }
        // Window.
        {
            let t = table("window", &mut problems);
            let mut s = Section {
                table: t,
                name: "window",
                file: path,
                problems: &mut problems,
                seen: Vec::new(),
            };
            c.window.fullscreen = s.bool("fullscreen", d.window.fullscreen);
            c.window.width = s.uint("width", d.window.width as u64, 320, 16_384) as u32;
            c.window.height = s.uint("height", d.window.height as u64, 240, 16_384) as u32;
            s.finish();
        }
        // Texts.
        {
            let t = table("texts", &mut problems);
            let mut s = Section {
                table: t,
                name: "texts",
                file: path,
                problems: &mut problems,
                seen: Vec::new(),
            };
            let x = &d.texts;
            c.texts = Texts {
                title: s.string("title", &x.title),
                hint: s.string("hint", &x.hint),
                fitting: s.string("fitting", &x.fitting),
                fitting_again: s.string("fitting_again", &x.fitting_again),
                loading: s.string("loading", &x.loading),
                still_there: s.string("still_there", &x.still_there),
                touch_to_continue: s.string("touch_to_continue", &x.touch_to_continue),
                load_failed: s.string("load_failed", &x.load_failed),
                reset: s.string("reset", &x.reset),
                ghost_hint: s.string("ghost_hint", &x.ghost_hint),
                part_choose: s.string("part_choose", &x.part_choose),
                part_pending: s.string("part_pending", &x.part_pending),
                part_ready: s.string("part_ready", &x.part_ready),
                part_unavailable: s.string("part_unavailable", &x.part_unavailable),
                part_failed: s.string("part_failed", &x.part_failed),
                close: s.string("close", &x.close),
                undo: s.string("undo", &x.undo),
                restoration: s.string("restoration", &x.restoration),
                original: s.string("original", &x.original),
            };
            s.finish();
        }
        c.problems = problems;
        c
    }

    /// The full path of a statue entry.
    pub fn statue_path(&self, entry: &StatueEntry) -> PathBuf {
        self.assets_root.join(&entry.file)
    }
}
