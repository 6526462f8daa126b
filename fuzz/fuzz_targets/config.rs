//! The daemon configuration (`config::DaemonConfig`, TOML): parsing never
//! panics, and a configuration that validates prints and reads back to
//! itself.
#![no_main]

use libfuzzer_sys::fuzz_target;
use topspin_daemon::config::DaemonConfig;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    if let Ok(cfg) = DaemonConfig::from_toml(text) {
        let printed = cfg.to_toml();
        let back = DaemonConfig::from_toml(&printed).expect("a printed configuration reads back");
        assert_eq!(back, cfg);
    }
});
