//! # Pygmalion
//!
//! Bring scanned statues to life: fit a simple articulated sphere-mesh anatomy to a raw point
//! set (FAKIR), re-pose it with point-set skinning, and restore broken statues by borrowing
//! limbs from others.
//!
//! ## The pipeline (data flows one way)
//!
//! ```text
//! PLY file ─► PointCloud ─► Registration (FAKIR) ─► FittedSkeleton ─► Binding ─► deform(pose) ─► skinned points ─► render
//! ```
//!
//! ## Modules (the bevy-free core)
//!
//! | module | what lives there |
//! |---|---|
//! | [`cloud`] | [`cloud::PointCloud`] (structure of arrays), PLY in/out ([`cloud::ply`]), normal estimation ([`cloud::normals`]) |
//! | [`geometry`] | the sphere-mesh bone ([`geometry::Bone`]): orthogonal and normal-constrained projection, distances, surface sampling |
//! | [`anatomy`] | templates loaded from `config/templates/`, the skeleton state, forward kinematics, fitted-skeleton JSON |
//! | [`skinning`] | point-set skinning: [`skinning::Binding`], baseline (ch. 4), heightfield (ch. 3), LBS/DQS |
//! | [`restore`] | virtual restoration: support of bones, part transfer, overlap merge (eq. 5.1) |
//! | [`kiosk`] | the Bevy kiosk: plugins over the core (loading, incremental FAKIR, animation, splats, gestures, attract mode, UI) |
//! | [`render`] | a software point-cloud renderer ([`render::render`]: splats, z-buffer, eye-dome lighting), [`render::Camera`], overlays, PNG output ([`render::Image`]) |
//! | [`synth`] | synthetic statues with ground truth (tests and benches) |
//! | [`mod@bench`] | the `pygmalion bench` harness |
//!
//! The core uses only `bevy::math` (glam) from Bevy; the kiosk ([`kiosk`]) is a set of Bevy
//! plugins over it and the CLI (`src/main.rs`, [`cli`]) a thin wrapper.

// `!(x > 0.0)` is used on purpose throughout: unlike `x <= 0.0` it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod anatomy;
pub mod bench;
pub mod cli;
pub mod cloud;
pub mod error;
pub mod fakir;
pub mod geometry;
pub mod kiosk;
pub mod render;
pub mod restore;
pub mod rng;
pub mod skinning;
pub mod synth;

/// The one linear-algebra crate of the project: glam, as re-exported by Bevy.
pub use bevy::math;
pub use error::{Error, Result};
