//! The calibration files (`calib`): the first byte picks the file the rest
//! replaces (physics, table, strike, robot, camera), the other files keep
//! the repository's; parsing and validation never panic.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use topspin_core::calib::{CameraCalib, Calibration, DEFAULT_PHYSICS, DEFAULT_ROBOT, DEFAULT_STRIKE, DEFAULT_TABLE};

const FILES: [&str; 4] = [DEFAULT_PHYSICS, DEFAULT_TABLE, DEFAULT_STRIKE, DEFAULT_ROBOT];

fuzz_target!(|data: &[u8]| {
    let Some((&which, rest)) = data.split_first() else { return };
    let Ok(text) = std::str::from_utf8(rest) else { return };
    let path = Path::new("fuzz.toml");
    match which % 5 {
        4 => {
            let _ = CameraCalib::parse(text, path);
        }
        k => {
            let mut t = FILES;
            t[k as usize] = text;
            let _ = Calibration::from_texts((t[0], path), (t[1], path), (t[2], path), (t[3], path));
        }
    }
});
