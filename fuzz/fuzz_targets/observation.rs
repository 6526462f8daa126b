//! TTB1 observation datagrams (`wire::observation`): parse never panics, and
//! what parses emits back to the same 36 bytes.
#![no_main]

use libfuzzer_sys::fuzz_target;
use topspin_core::wire::{OBSERVATION_LEN, Observation, ObservationPacket};

fuzz_target!(|data: &[u8]| {
    if let Ok(p) = ObservationPacket::new_checked(data) {
        let _ = (p.seq(), p.capture_ns(), p.position(), p.residual(), p.cameras(), p.flags());
    }
    if let Ok(obs) = Observation::parse(data) {
        let mut buf = [0u8; OBSERVATION_LEN];
        obs.emit(&mut buf);
        assert_eq!(&buf[..], data, "emit(parse(bytes)) differs from bytes");
    }
});
