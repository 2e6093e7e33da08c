//! Benchmark of virtual restoration: one limb (left forearm and hand) of a 100k-point
//! synthetic statue restored from a differently proportioned and posed 100k-point donor,
//! with the true skeletons as fits (the registration is timed by the FAKIR entries). Times the
//! whole [`crate::restore::restore`]: support, completion, the donor's binding and skinning,
//! the merge.

use super::{BenchResult, Entry, time_it};
use crate::anatomy::Template;
use crate::error::Result;
use crate::restore::{Donor, RestoreOptions, restore};
use crate::synth::{Cut, SynthOptions, generate};
use std::sync::Arc;

pub(super) fn entries() -> Vec<Entry> {
    vec![Entry {
        name: "restore/limb_100k",
        run: limb_100k,
    }]
}

fn limb_100k(runs: usize) -> Result<BenchResult> {
    let t = Arc::new(Template::builtin("human")?);
    let target = generate(
        t.clone(),
        &SynthOptions {
            points: 100_000,
            seed: 5,
            cuts: vec![Cut::parse("bone:l_forearm")?, Cut::parse("bone:l_hand")?],
            ..Default::default()
        },
    )?;
    let donor = generate(
        t,
        &SynthOptions {
            points: 100_000,
            seed: 9,
            ..Default::default()
        },
    )?;
    let mut added = 0;
    let mut r = time_it("restore/limb_100k", target.cloud.len() as u64, runs, || {
        let out = restore(
            &target.cloud,
            &target.truth,
            &[Donor {
                name: "donor".into(),
                cloud: &donor.cloud,
                fit: &donor.truth,
                missing: None,
            }],
            &RestoreOptions::default(),
        )
        .expect("restore");
        added = out.cloud.len() - target.cloud.len();
    });
    r.extra.insert("donor_points".into(), added as f64);
    Ok(r)
}
