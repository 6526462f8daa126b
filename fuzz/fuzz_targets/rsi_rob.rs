//! `<Rob>` datagrams from the controller (`rsi::codec`): parse never panics;
//! a parsed frame emits (all elements) without panicking, and where it
//! emits, the text parses back with the same IPOC.
#![no_main]

use libfuzzer_sys::fuzz_target;
use topspin_core::rsi::{RobElement, RobFrame};

const ALL: [RobElement; 5] =
    [RobElement::RIst, RobElement::RSol, RobElement::AIPos, RobElement::ASPos, RobElement::Delay];

fuzz_target!(|data: &[u8]| {
    if let Ok(frame) = RobFrame::parse(data) {
        let mut buf = [0u8; 2048];
        if let Ok(n) = frame.emit(&ALL, 4, &mut buf) {
            let back = RobFrame::parse(&buf[..n]).expect("an emitted <Rob> parses");
            assert_eq!(back.ipoc, frame.ipoc);
            assert_eq!(back.delay, frame.delay);
        }
    }
});
