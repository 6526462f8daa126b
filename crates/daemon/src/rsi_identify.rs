//! `topspin identify`'s socket shell: a thin loop around the sans-IO
//! [`Identifier`], the way [`crate::rsi_server`] is around the session.
//! It waits for the controller's first `<Rob>`, answers every request the
//! moment it arrives, and after the excitation keeps answering zero until
//! the controller falls silent or the hold time is up. The clock is read
//! here and handed in; the fit runs afterwards, in the caller.

use std::io;
use std::net::{IpAddr, SocketAddr, UdpSocket};

use crate::clock;
use crate::rsi_server::MAX_REQUEST_LEN;
use topspin_core::rsi::MAX_ANSWER_LEN;
use topspin_core::rsi::identify::Identifier;
use topspin_core::time::{Duration, Instant};

/// How long the receive call blocks at most, to look at the clock.
pub(crate) const POLL: std::time::Duration = std::time::Duration::from_millis(10);

/// How the loop runs.
#[derive(Clone, Debug, PartialEq)]
pub struct IdentifyLoop {
    /// Only requests from this address are answered (others are counted).
    pub controller: Option<IpAddr>,
    /// How long to wait for the first request.
    pub wait_first: Duration,
    /// No request for this long: the controller stopped.
    pub silence: Duration,
    /// Zero is held this long after the excitation before the loop ends.
    pub hold: Duration,
    /// SCHED_FIFO priority for the loop's thread (`None`: leave it).
    pub realtime_priority: Option<i32>,
}

/// Why the loop ended.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum LoopEnd {
    /// No request within `wait_first`.
    NoRequest,
    /// The controller stopped sending (during or after the excitation).
    ControllerSilent,
    /// The hold time after the excitation is over.
    HoldElapsed,
}

/// What the loop saw besides the identifier's own counters.
#[derive(Clone, Debug, PartialEq)]
pub struct LoopOutcome {
    /// Why it ended.
    pub end: LoopEnd,
    /// Requests from other addresses, ignored.
    pub foreign: u64,
    /// The last of those addresses.
    pub foreign_from: Option<SocketAddr>,
    /// Requests longer than [`MAX_REQUEST_LEN`], ignored.
    pub oversized: u64,
    /// Answers the socket would not take.
    pub send_failed: u64,
    /// What the real-time set-up refused, if anything.
    pub rt_warning: Option<String>,
}

/// Something the operator should see while it runs.
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum Progress {
    /// The first request came from this address.
    Started(SocketAddr),
    /// The excitation is over; zero is held.
    ExcitationDone,
}

/// Runs the loop on `socket` (bound by the caller) until it ends.
pub fn run(
    socket: &UdpSocket,
    id: &mut Identifier,
    cfg: &IdentifyLoop,
    mut progress: impl FnMut(Progress),
) -> io::Result<LoopOutcome> {
    socket.set_read_timeout(Some(POLL))?;
    let rt_warning = cfg
        .realtime_priority
        .and_then(|p| crate::runtime::rt::fifo_current("identify", p).err())
        .map(|w| w.to_string());
    let mut out = LoopOutcome {
        end: LoopEnd::NoRequest,
        foreign: 0,
        foreign_from: None,
        oversized: 0,
        send_failed: 0,
        rt_warning,
    };
    let mut rx = [0u8; MAX_REQUEST_LEN + 1];
    let mut tx = [0u8; MAX_ANSWER_LEN];
    let start = clock::now();
    let mut last_rx: Option<Instant> = None;
    let mut done_at: Option<Instant> = None;
    loop {
        match socket.recv_from(&mut rx) {
            Ok((n, from)) => {
                let now = clock::now();
                if cfg.controller.is_some_and(|ip| ip != from.ip()) {
                    out.foreign += 1;
                    out.foreign_from = Some(from);
                } else if n > MAX_REQUEST_LEN {
                    out.oversized += 1;
                } else if let Ok(len) = id.handle_datagram(now, &rx[..n], &mut tx) {
                    match socket.send_to(&tx[..len], from) {
                        Ok(_) => id.answer_sent(clock::now()),
                        Err(_) => out.send_failed += 1,
                    }
                    if last_rx.is_none() {
                        progress(Progress::Started(from));
                    }
                    last_rx = Some(now);
                    if id.is_done() && done_at.is_none() {
                        done_at = Some(now);
                        progress(Progress::ExcitationDone);
                    }
                }
            }
            Err(e) if matches!(e.kind(), io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut) => {}
            Err(e) => return Err(e),
        }
        let now = clock::now();
        match last_rx {
            None if now - start > cfg.wait_first => {
                out.end = LoopEnd::NoRequest;
                return Ok(out);
            }
            Some(t) if now - t > cfg.silence => {
                out.end = LoopEnd::ControllerSilent;
                return Ok(out);
            }
            _ => {}
        }
        if done_at.is_some_and(|t| now - t > cfg.hold) {
            out.end = LoopEnd::HoldElapsed;
            return Ok(out);
        }
    }
}
