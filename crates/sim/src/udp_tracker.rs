//! The simulated tracker on the network: every observation of a run of
//! balls as a TTB1 datagram (DESIGN §5.1), sent at its arrival time
//! (capture + latency) on the process clock. Capture times are on the same
//! clock, so a demo in one process knows the truth in its own time.

use std::io;
use std::net::UdpSocket;
use std::sync::atomic::{AtomicBool, Ordering};

use super::SimBall;
use topspin_core::time::{Duration, Instant};
use topspin_core::wire::{OBSERVATION_LEN, Observation};
use topspin_daemon::clock;

/// What a stream sent.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
pub struct StreamStats {
    /// Datagrams sent.
    pub sent: u64,
    /// Datagrams nobody received (ICMP port unreachable): a tracker does
    /// not stop for that.
    pub refused: u64,
}

/// The capture time of observation `t` (s after its ball's launch) of a
/// ball launched `start` s after `t0`.
pub(crate) fn capture_time(t0: Instant, start: f64, t: f64) -> Instant {
    t0 + Duration::from_nanos(((start + t) * 1e9).round() as u64)
}

/// Sequence numbers the tracker leaves after each ball's observations for
/// the frames that see its return (`return_feed`).
pub(crate) const RETURN_SEQ_ROOM: u32 = 256;

/// Sends the observations of `balls` (ball k launched `starts[k]` s after
/// `t0`) over the connected `socket`, each at capture + `latency`, until
/// done or `stop`; each ball's sequence numbers `RETURN_SEQ_ROOM` after
/// the last's (room for its return's frames, as `plan_datagrams` numbers
/// them).
pub fn stream(
    socket: &UdpSocket,
    balls: &[SimBall],
    starts: &[f64],
    latency: f64,
    t0: Instant,
    stop: &AtomicBool,
) -> io::Result<StreamStats> {
    let mut stats = StreamStats::default();
    let mut seq: u32 = 0;
    let mut buf = [0u8; OBSERVATION_LEN];
    let latency = Duration::from_nanos((latency.max(0.0) * 1e9) as u64);
    for (b, &start) in balls.iter().zip(starts) {
        for o in &b.observations {
            if stop.load(Ordering::Relaxed) {
                return Ok(stats);
            }
            let capture = capture_time(t0, start, o.t);
            let arrival = capture + latency;
            let now = clock::now();
            if arrival > now {
                std::thread::sleep(std::time::Duration::from_nanos((arrival - now).0));
            }
            Observation {
                seq,
                capture,
                pos: [o.pos.x as f32, o.pos.y as f32, o.pos.z as f32],
                residual: f32::NAN,
                cameras: 2,
                valid: true,
            }
            .emit(&mut buf);
            match socket.send(&buf) {
                Ok(_) => stats.sent += 1,
                Err(e) if e.kind() == io::ErrorKind::ConnectionRefused => stats.refused += 1,
                Err(e) => return Err(e),
            }
            seq = seq.wrapping_add(1);
        }
        seq = seq.wrapping_add(RETURN_SEQ_ROOM);
    }
    Ok(stats)
}
