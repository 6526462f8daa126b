//! `topspin fit` CSV (`cli::fit::parse_samples`): never panics, and every
//! sample it returns is finite.
#![no_main]

use libfuzzer_sys::fuzz_target;
use topspin::cli::fit::parse_samples;

fuzz_target!(|data: &[u8]| {
    if let Ok(samples) = parse_samples(data, "fuzz.csv") {
        for s in &samples {
            assert!(s.t.is_finite() && s.pos.x.is_finite() && s.pos.y.is_finite() && s.pos.z.is_finite());
        }
    }
});
