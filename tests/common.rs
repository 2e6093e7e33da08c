//! Shared helpers of the integration tests.
#![allow(dead_code)]

use std::path::PathBuf;

/// The crate root.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// `assets/statues/` (bundled CC BY scans).
pub fn statues_dir() -> PathBuf {
    root().join("assets/statues")
}

/// The real data folder for the extended run, when `PYGMALION_DATA` names an existing folder.
pub fn shared_data() -> Option<PathBuf> {
    let dir = PathBuf::from(std::env::var_os("PYGMALION_DATA")?);
    dir.is_dir().then_some(dir)
}

/// Every `.ply` file of the extended data set (empty when the extended run is off).
pub fn shared_plys() -> Vec<PathBuf> {
    let Some(dir) = shared_data() else {
        return Vec::new();
    };
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .expect("read PYGMALION_DATA")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "ply"))
        .collect();
    files.sort();
    files
}

/// A fresh scratch directory under the target directory, unique per test name.
pub fn scratch(name: &str) -> PathBuf {
    let dir = root().join("target/test-scratch").join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create scratch dir");
    dir
}

/// The bones a synthetic statue's cuts took every point from (what a registration of it
/// should report lost), one flag per bone.
pub fn cut_bones(s: &pygmalion::synth::SynthStatue) -> Vec<bool> {
    let mut counts = vec![0usize; s.truth.bones.len()];
    for &b in &s.labels {
        if let Some(c) = counts.get_mut(b as usize) {
            *c += 1;
        }
    }
    counts.iter().map(|&c| c == 0).collect()
}

/// Runs `f` on a rayon pool of one thread of its own, so the kiosk's frame-budget test running
/// beside a long registration does not queue behind its parallel loops.
pub fn on_one_thread(f: impl FnOnce() + Send) {
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(f)
}

/// The support of every bone of `t` as a whole, well-covered figure's: covered and reached
/// through, nothing missing, partial or shrunk (tests then change the bones they study).
pub fn full_support(
    t: &pygmalion::anatomy::Template,
) -> Vec<pygmalion::fakir::support::BoneSupport> {
    t.bones
        .iter()
        .map(|b| pygmalion::fakir::support::BoneSupport {
            bone: b.name.clone(),
            coverage: 1.0,
            reach: 1.0,
            missing: false,
            partial: false,
            shrunk: false,
        })
        .collect()
}
