//! `<Sen>` answers (`rsi::codec`, the mock KR C4's side): parse never
//! panics; re-emitting what parsed (where its texts are writable) parses
//! back to the same IPOC and texts.
#![no_main]

use libfuzzer_sys::fuzz_target;
use topspin_core::rsi::{SenFrame, check_text};

fuzz_target!(|data: &[u8]| {
    let Ok(v) = SenFrame::parse(data) else { return };
    let (Ok(sentype), estr) = (std::str::from_utf8(v.sentype), v.estr.map(std::str::from_utf8)) else { return };
    let estr = match estr {
        None => None,
        Some(Ok(e)) => Some(e),
        Some(Err(_)) => return,
    };
    if check_text(sentype).is_err() || estr.is_some_and(|e| check_text(e).is_err()) {
        return;
    }
    let frame = SenFrame { sentype, estr, rkorr: v.rkorr, akorr: v.akorr, ipoc: v.ipoc };
    let mut buf = [0u8; 1024];
    if let Ok(n) = frame.emit(4, &mut buf) {
        let back = SenFrame::parse(&buf[..n]).expect("an emitted <Sen> parses");
        assert_eq!(back.ipoc, v.ipoc);
        assert_eq!(back.sentype, v.sentype);
        assert_eq!(back.estr, v.estr);
    }
});
