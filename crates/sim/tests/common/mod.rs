//! Helpers shared by integration tests.

pub mod logo_cnn;
