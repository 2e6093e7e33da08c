//! Anatomy: templates ([`template`]), skeleton state and forward kinematics ([`skeleton`]).

pub mod skeleton;
pub mod template;

pub use skeleton::{BoneState, Posed, Skeleton, SkeletonJson};
pub use template::{BoneKind, Template};
