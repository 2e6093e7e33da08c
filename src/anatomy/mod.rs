//! Anatomy: templates ([`template`]), skeleton state and forward kinematics ([`skeleton`]),
//! poses and proportions as data ([`pose`]), comparison with a ground truth of another
//! topology ([`compare`]).

pub mod compare;
pub mod pose;
pub mod skeleton;
pub mod template;

pub use pose::{BonePose, Pose, PoseBase, Proportions, interpolate};
pub use skeleton::{BoneState, Posed, Skeleton, SkeletonJson};
pub use template::{BoneKind, Template};
