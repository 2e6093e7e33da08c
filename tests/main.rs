//! The one integration-test binary of Pygmalion (every extra test binary would link Bevy
//! again). Modules mirror `src/`.
//!
//! Checks over the whole real data set (`../shared/data`) run only when the environment
//! variable `PYGMALION_DATA` names that folder (`.ci/run` sets it when the folder exists);
//! everything else runs on bundled assets and synthetic statues.
//!
//! The long tier (registrations of single regression statues, `#[ignore = "long tier …"]`,
//! see `fakir`) runs only when asked: `bash tests/run.sh --include-ignored`.

mod common;

mod anatomy;
mod anatomy_compare;
mod anatomy_pose;
mod cli;
mod cloud_base;
mod cloud_grid;
mod cloud_normals;
mod cloud_ply;
mod fakir;
mod fakir_broken;
mod fakir_bust;
mod fakir_frame;
mod fakir_pair;
mod geometry_bone;
mod kiosk_app;
mod kiosk_attract;
mod kiosk_config;
mod kiosk_gestures;
mod kiosk_ik;
mod kiosk_render;
mod kiosk_restore;
mod render;
mod restore;
mod restore_stump;
mod skinning;
mod synth;
