//! The committed logo CNN on the embedded tract backend: PyTorch's answers
//! on the reference batch, the logo found on rendered crops, bad input
//! refused.

mod common;

#[test]
fn the_committed_model_runs_on_tract() {
    common::logo_cnn::check(topspin_cnn::Backend::Tract);
}
