//! Geometry of the sphere-mesh model: the bone ([`bone`]) and rotation helpers ([`frames`]).

pub mod bone;
pub mod frames;
pub mod pca;

pub use bone::{Bone, BoneGradient, Part, PreparedBone, Projection};
