//! Progress of long offline runs: one indicatif bar that each stage of a
//! run resets ([`StageBar`], the [`Progress`] of `eval paper`), and the
//! size of the worker pool the runs use.

use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use crate::eval::paper::Progress;

/// An indicatif bar on stderr, reset per stage (hidden when quiet).
#[derive(Debug)]
pub struct StageBar {
    bar: ProgressBar,
}

impl StageBar {
    /// A bar on stderr, or a hidden one when `quiet`.
    pub fn new(quiet: bool) -> Self {
        let bar = ProgressBar::with_draw_target(
            Some(0),
            if quiet { ProgressDrawTarget::hidden() } else { ProgressDrawTarget::stderr() },
        );
        bar.set_style(
            ProgressStyle::with_template("{msg:45} [{bar:30}] {pos}/{len} {elapsed_precise} eta {eta}")
                .expect("valid template")
                .progress_chars("=> "),
        );
        bar.enable_steady_tick(Duration::from_millis(500));
        StageBar { bar }
    }

    /// Clears the bar at the end of the run.
    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

impl Progress for StageBar {
    fn stage(&self, name: &str, total: u64) {
        self.bar.set_message(name.to_owned());
        self.bar.set_length(total);
        self.bar.set_position(0);
        self.bar.reset_eta();
    }
    fn inc(&self, n: u64) {
        self.bar.inc(n);
    }
}

/// Threads in the pool the evaluations run on (rayon's global pool).
pub fn worker_threads() -> usize {
    rayon::current_num_threads()
}
