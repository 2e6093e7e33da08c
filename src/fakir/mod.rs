//! FAKIR: Forward And bacKward Iterative Registration of a sphere-mesh anatomy to a point set
//! (thesis ch. 2; paper 003; paper 001 appendices A–C).
//!
//! | stage | module |
//! |---|---|
//! | point-to-bone assignment `P_k` with the cone preference | [`assign`] |
//! | world-space skeleton edits and shared radii | [`world`] |
//! | Levenberg–Marquardt on parameter groups (eq. 2.6–2.15) | [`lm`] |
//! | one-bone, two-bone, root-block fits; bootstrap; limb seeding; work units | [`solver`] |
//! | joint-range and proportion priors | [`lm`] ([`lm::RangePrior`]) |
//! | Algorithm 1 on a chain; whole-skeleton order with backtracking | [`schedule`] |
//! | automatic initial placement (PCA, candidate orientations) | [`init`] |
//! | which bones the scan covers (support), completing missing bones | [`support`] |
//! | which bones are lost (level 6), the fit settled without them | [`lost`] |
//! | the bust hypothesis (a portrait bust fitted without its limbs) | [`bust`] |
//! | the pair hypotheses (both arms or legs lost, a Venus) | [`pair`] |
//! | the broken-limb hypothesis (a limb broken part-way, curled by the fit) | [`broken`] |
//! | the working units (a power-of-two scale, a shift for far clouds) | [`frame`] |
//! | levels, the resumable `step(budget)` registration | [`registration`] |

pub mod assign;
pub mod broken;
pub mod bust;
pub mod frame;
pub mod init;
pub mod lm;
pub mod lost;
pub mod pair;
pub mod registration;
pub mod schedule;
pub mod solver;
pub mod support;
pub mod world;

pub use init::Init;
pub use registration::{BASE_LABEL, Fit, Progress, Registration, RegistrationOptions, register};
pub use solver::Attempt;
