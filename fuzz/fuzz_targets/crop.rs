//! TTI1 crop datagrams (`wire::crop`): parse never panics, and what parses
//! emits back to the same bytes.
#![no_main]

use libfuzzer_sys::fuzz_target;
use topspin_core::wire::{Crop, CropPacket};

fuzz_target!(|data: &[u8]| {
    if let Ok(p) = CropPacket::new_checked(data) {
        let _ =
            (p.seq(), p.capture_ns(), p.circle(), p.width(), p.height(), p.format(), p.reserved(), p.pixels().len());
    }
    if let Ok(crop) = Crop::parse(data) {
        let mut buf = vec![0u8; crop.buffer_len()];
        let n = crop.emit(&mut buf).expect("a parsed crop emits");
        assert_eq!(&buf[..n], data, "emit(parse(bytes)) differs from bytes");
    }
});
