//! topspin's lab: the offline evaluations that measure the product —
//! accuracy on simulated flights ([`eval`]), the real MPI recordings and
//! their calibration ([`data`]), the logo methods on rendered flights
//! ([`logo`]), and the paper's tables and figures. plotters, rayon and
//! indicatif live here and nowhere else.
//!
//! - [`eval`]: batch fit, streaming estimator and `eval paper`.
//! - [`data`]: the real MPI launcher recordings and the study on them.
//! - [`logo`]: logo spin against ground truth, and the sources compared.
//! - [`progress`]: progress bars and the worker pool of long runs.
//!
//! Where to start: [`eval::stream::evaluate`] (the streaming estimator
//! over a session of simulated balls), [`eval::worlds`] (the batch fit in
//! worlds unlike ours) and [`eval::paper`] (the paper's tables and
//! figures). Each `eval` and `logo` module is one command of
//! `topspin eval` or `topspin logo`.
//!
//! `DESIGN §n` in these docs cites section n of `docs/design.md`.

#![warn(missing_docs)]
#![deny(unreachable_pub)]

pub mod data;
pub mod eval;
pub mod logo;
pub mod progress;
