//! The logo methods (`topspin_core::logo`) measured on rendered flights.
//!
//! - [`eval`]: accuracy on rendered sequences against their ground truth.
//! - [`compare`]: trajectory, background, CNN and fused spins on the same
//!   simulated flights.

pub mod compare;
pub mod eval;
