//! Hostile input on the daemon's two sockets (security): only the
//! configured peers are heard, oversized datagrams are dropped rather than
//! truncated into something that parses, and the default configuration
//! binds loopback only. Loopback addresses other than 127.0.0.1 stand in
//! for foreign hosts.

use std::net::UdpSocket;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration as StdDuration;

use topspin_core::calib::Calibration;
use topspin_core::rsi::{RsiSession, SessionConfig};
use topspin_core::time::Instant;
use topspin_core::wire::{OBSERVATION_LEN, Observation};
use topspin_daemon::config::DaemonConfig;
use topspin_daemon::rsi_server::{MAX_REQUEST_LEN, RsiServer, WaitStrategy, plan_slot};
use topspin_daemon::runtime::{Daemon, RuntimeConfig};

fn observation(seq: u32) -> [u8; OBSERVATION_LEN] {
    let mut buf = [0u8; OBSERVATION_LEN];
    Observation {
        seq,
        capture: Instant::from_nanos(1_000_000_000 + seq as u64 * 6_666_667),
        pos: [0.5, 0.1, 0.3],
        residual: f32::NAN,
        cameras: 2,
        valid: true,
    }
    .emit(&mut buf);
    buf
}

#[test]
fn tracker_datagrams_from_a_foreign_address_or_oversized_are_counted_and_dropped() {
    let cal = Calibration::default_cell();
    let daemon = Daemon::start(&RuntimeConfig::loopback(), &cal, None).unwrap();
    let ours = UdpSocket::bind("127.0.0.1:0").unwrap();
    let foreign = UdpSocket::bind("127.0.0.2:0").unwrap();
    // A datagram whose first 36 bytes are a valid observation: it must not
    // be truncated into one.
    let mut oversized = vec![0u8; 1000];
    oversized[..OBSERVATION_LEN].copy_from_slice(&observation(1));
    foreign.send_to(&observation(0), daemon.tracker_addr).unwrap();
    ours.send_to(&oversized, daemon.tracker_addr).unwrap();
    ours.send_to(&observation(2)[..20], daemon.tracker_addr).unwrap();
    ours.send_to(&observation(3), daemon.tracker_addr).unwrap();
    // The ingest thread takes them within microseconds; a second leaves
    // room for a descheduled thread on a busy machine (not a timing check).
    std::thread::sleep(StdDuration::from_secs(1));
    daemon.request_stop();
    let s = daemon.join().unwrap();
    assert_eq!(s.ingest.foreign, 1, "{:?}", s.ingest);
    assert_eq!(s.ingest.malformed, 2, "{:?}", s.ingest);
    assert_eq!(s.ingest.accepted, 1, "{:?}", s.ingest);
}

#[test]
fn rsi_requests_from_a_foreign_address_or_oversized_are_not_answered() {
    let cal = Calibration::default_cell();
    let session = RsiSession::new(SessionConfig::from_calibration(&cal, "ImFree")).unwrap();
    let mut server = RsiServer::bind("127.0.0.1:0".parse().unwrap(), session, WaitStrategy::Blocking).unwrap();
    server.allow_only("127.0.0.1".parse().unwrap());
    let addr = server.local_addr().unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let s2 = stop.clone();
    let t = std::thread::spawn(move || {
        server.run(&s2, &mut plan_slot().1, |_| {}).unwrap();
        (server.foreign(), server.oversized(), *server.session().stats())
    });
    let request = b"<Rob Type=\"KUKA\"><IPOC>4</IPOC></Rob>";
    let timeout = Some(StdDuration::from_millis(300));
    // From a foreign host: silence.
    let foreign = UdpSocket::bind("127.0.0.2:0").unwrap();
    foreign.set_read_timeout(timeout).unwrap();
    foreign.send_to(request, addr).unwrap();
    let mut buf = [0u8; 4096];
    assert!(foreign.recv_from(&mut buf).is_err(), "a foreign host was answered");
    // Too long (a valid request padded past the limit): silence.
    let ctrl = UdpSocket::bind("127.0.0.1:0").unwrap();
    ctrl.set_read_timeout(timeout).unwrap();
    let mut long = request.to_vec();
    long.resize(MAX_REQUEST_LEN + 100, b' ');
    ctrl.send_to(&long, addr).unwrap();
    assert!(ctrl.recv_from(&mut buf).is_err(), "an oversized request was answered");
    // The controller's well-formed request: answered.
    ctrl.set_read_timeout(Some(StdDuration::from_secs(10))).unwrap();
    ctrl.send_to(request, addr).unwrap();
    let (n, _) = ctrl.recv_from(&mut buf).unwrap();
    assert!(std::str::from_utf8(&buf[..n]).unwrap().contains("<IPOC>4</IPOC>"));
    stop.store(true, Ordering::Relaxed);
    let (foreign, oversized, stats) = t.join().unwrap();
    assert_eq!((foreign, oversized), (1, 1));
    assert_eq!(stats.requests, 1, "{stats:?}");
}

#[test]
fn default_configuration_binds_loopback_and_names_its_peers() {
    for cfg in [DaemonConfig::default(), DaemonConfig::from_toml(include_str!("../../../deploy/topspin.toml")).unwrap()]
    {
        let n = &cfg.network;
        for bind in [n.tracker_bind, n.rsi_bind] {
            assert!(!bind.ip().is_unspecified(), "{bind} listens on every interface");
        }
        for peer in [n.tracker_source, n.controller_source] {
            assert!(!peer.is_unspecified() && !peer.is_multicast(), "{peer}");
        }
    }
    // And an explicit wildcard peer is refused.
    assert!(DaemonConfig::from_toml("[network]\ntracker_source = \"0.0.0.0\"\n").is_err());
}
