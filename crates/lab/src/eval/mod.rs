//! Offline evaluations on simulated flights with ground truth: the accuracy
//! of the batch spin fit ([`fit`]) and of the streaming estimator
//! ([`stream`]), and the batch fit in worlds unlike its model
//! ([`worlds`]). Seeded and reproducible; the command line prints their
//! tables (`topspin eval ...`).

pub mod fit;
pub mod paper;
pub mod stream;
pub mod worlds;
