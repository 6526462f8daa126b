//! The Foxglove view of a short loopback demo (2 balls):
//!
//! - live: a `foxglove.websocket.v1` client (negotiated as `foxglove.sdk.v1`; the library's probe, built on
//!   tungstenite) connects to `--live`, subscribes to every advertised
//!   channel, and receives scene, pose and latency messages with the right
//!   schemas, stamped with wall-clock log times;
//! - recorded: the demo's MCAP file opens with the `mcap` crate and holds
//!   every channel (the recording's own and the viewer's), with messages on
//!   the scene and plot channels, `record::read_session` still reads it and
//!   `topspin replay`'s comparison finds every plan identical, and its
//!   `--live` path (the recording through the viewer) reaches a client.
//!
//! No timing is asserted: the mock's answer deadline is stretched as in
//! `tests/demo.rs`, and the verdicts are not checked here.

#![allow(clippy::disallowed_methods)] // a process test: it waits on the wall clock

use std::collections::BTreeMap;
use std::net::{SocketAddr, TcpListener};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use foxglove::Decode;
use foxglove::messages::{FrameTransform, PosesInFrame, SceneUpdate};
use topspin_core::calib::Calibration;
use topspin_core::time::Duration;
use topspin_daemon::record::replay::replay_session;
use topspin_daemon::record::{TOPIC_COUNTERS, TOPIC_DATAGRAM, TOPIC_PLAN, TOPIC_RSI, read_session};
use topspin_daemon::viewer::replay::view_session;
use topspin_daemon::viewer::{LiveServer, TOPICS, Topic, ViewerSink};
use topspin_sim::demo::{DemoConfig, run};
use topspin_sim::probe;

/// 2020-01-01 in Unix ns: log times are wall clock, not the monotonic clock.
const WALL_CLOCK_AFTER: u64 = 1_577_836_800_000_000_000;

fn demo_config() -> DemoConfig {
    DemoConfig {
        balls: 2,
        seed: 3,
        gap: 1.2,
        answer_deadline: Some(Duration::from_millis(50)),
        ..DemoConfig::default()
    }
}

fn free_port() -> SocketAddr {
    let l = TcpListener::bind("127.0.0.1:0").unwrap();
    l.local_addr().unwrap()
}

#[test]
fn a_live_client_receives_the_scene_and_latency() {
    let addr = free_port();
    let stop = Arc::new(AtomicBool::new(false));
    let client = probe::spawn(addr, stop.clone(), std::time::Duration::from_secs(30));
    let cfg = DemoConfig { live: Some(addr), live_wait: Duration::from_millis(30_000), ..demo_config() };
    let report = run(&cfg, &Calibration::default_cell()).unwrap();
    stop.store(true, Ordering::Relaxed);
    let seen = client.join().unwrap().unwrap();
    let counts: BTreeMap<_, _> = seen.channels.iter().map(|(t, c)| (t.as_str(), c.messages)).collect();
    eprintln!("demo hits {}/{}; live client: {counts:?}", report.hits, report.reachable);

    assert!(seen.server_name.starts_with("topspin"), "{}", seen.server_name);
    assert_eq!(seen.malformed, 0);
    for t in TOPICS {
        let c = seen.channels.get(t.name()).unwrap_or_else(|| panic!("{} not advertised", t.name()));
        let want = t.schema();
        assert_eq!(c.schema_name, want.name, "{}", t.name());
        assert_eq!(c.encoding, t.encoding(), "{}", t.name());
    }
    for t in [Topic::Cell, Topic::Tf, Topic::Ball, Topic::Robot, Topic::Tcp, Topic::PlanPose, Topic::Spin, Topic::Rsi] {
        assert!(counts[t.name()] > 0, "nothing on {}", t.name());
    }
    assert_eq!(seen.channels["/view/ball"].schema_name, "foxglove.SceneUpdate");
    assert_eq!(seen.channels["/plot/rsi"].schema_name, "topspin.RsiPlot");

    let first = |t: Topic| seen.channels[t.name()].first.clone().unwrap();
    let (log_time, bytes) = first(Topic::Ball);
    assert!(log_time > WALL_CLOCK_AFTER, "log time {log_time}");
    let ball = SceneUpdate::decode(bytes.as_slice()).unwrap();
    assert!(!ball.entities.is_empty());
    assert!(ball.entities.iter().all(|e| e.frame_id == "table"));
    let cell = SceneUpdate::decode(first(Topic::Cell).1.as_slice()).unwrap();
    let ids: Vec<_> = cell.entities.iter().map(|e| e.id.as_str()).collect();
    assert_eq!(ids, ["table", "robot", "hitting_window"]);
    let tf = FrameTransform::decode(first(Topic::Tf).1.as_slice()).unwrap();
    assert_eq!((tf.parent_frame_id.as_str(), tf.child_frame_id.as_str()), ("table", "robot_base"));
    let tcp = PosesInFrame::decode(first(Topic::Tcp).1.as_slice()).unwrap();
    assert_eq!(tcp.frame_id, "robot_base");
    assert!(!tcp.poses.is_empty());
    let rsi: serde_json::Value = serde_json::from_slice(&first(Topic::Rsi).1).unwrap();
    assert!(rsi["latency_us"].as_u64().unwrap() >= 1, "{rsi}");
    let spin: serde_json::Value = serde_json::from_slice(&first(Topic::Spin).1).unwrap();
    assert!(spin["norm_rps"].as_f64().unwrap().is_finite(), "{spin}");
}

#[test]
fn a_demo_recording_opens_and_holds_every_channel() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("demo.mcap");
    let cfg = DemoConfig { record: Some(path.clone()), ..demo_config() };
    run(&cfg, &Calibration::default_cell()).unwrap();

    let bytes = std::fs::read(&path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().expect("a summary section");
    let mut channels: BTreeMap<String, (String, String)> = BTreeMap::new();
    for c in summary.channels.values() {
        let schema = c.schema.as_ref().map_or(String::new(), |s| s.name.clone());
        channels.insert(c.topic.clone(), (schema, c.message_encoding.clone()));
    }
    for topic in [TOPIC_DATAGRAM, TOPIC_PLAN, TOPIC_RSI, TOPIC_COUNTERS] {
        assert!(channels.contains_key(topic), "no channel {topic}");
    }
    for t in TOPICS {
        let (schema, encoding) = channels.get(t.name()).unwrap_or_else(|| panic!("no channel {}", t.name()));
        assert_eq!(schema, &t.schema().name, "{}", t.name());
        assert_eq!(encoding, t.encoding(), "{}", t.name());
    }

    let mut counts: BTreeMap<String, u64> = BTreeMap::new();
    let mut min_log_time = u64::MAX;
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        *counts.entry(m.channel.topic.clone()).or_default() += 1;
        min_log_time = min_log_time.min(m.log_time);
        if m.channel.topic == "/view/ball" {
            SceneUpdate::decode(&m.data[..]).unwrap();
        }
    }
    eprintln!("recorded: {counts:?}");
    assert!(min_log_time > WALL_CLOCK_AFTER, "log time {min_log_time}");
    for topic in [
        TOPIC_DATAGRAM,
        TOPIC_PLAN,
        TOPIC_RSI,
        "/view/cell",
        "/tf",
        "/view/ball",
        "/view/robot",
        "/view/verdict",
        "/plot/spin",
        "/plot/prediction_error",
        "/plot/rsi",
        "/plot/queues",
    ] {
        assert!(counts.get(topic).copied().unwrap_or(0) > 0, "nothing on {topic}");
    }

    let session = read_session(&path).unwrap();
    assert!(session.truncated.is_none(), "{:?}", session.truncated);
    assert!(!session.plans.is_empty());
    // The demo's recording replays bit for bit, as the daemon's does.
    let replay = replay_session(&session).unwrap();
    assert!(replay.identical(), "{:?}", replay.first_difference);
    // `topspin replay FILE --live`: the recording through the viewer to a client.
    let server = LiveServer::start("127.0.0.1:0".parse().unwrap(), None).unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let client = probe::spawn(server.addr(), stop.clone(), std::time::Duration::from_secs(30));
    let patience = std::time::Instant::now();
    while server.clients() == 0 && patience.elapsed() < std::time::Duration::from_secs(30) {
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    std::thread::sleep(std::time::Duration::from_millis(500)); // its subscriptions
    let cal = session.calibration().unwrap();
    let mut sink = ViewerSink::new(&cal, Some(server), None, None).with_offset(session.log_time_offset);
    view_session(&session, &mut sink, None, &AtomicBool::new(false)).unwrap();
    drop(sink);
    stop.store(true, Ordering::Relaxed);
    let seen = client.join().unwrap().unwrap();
    for t in [Topic::Ball, Topic::Robot, Topic::Spin, Topic::Rsi] {
        assert!(seen.channels[t.name()].messages > 0, "replay sent nothing on {}", t.name());
    }

    // Counters come back on the monotonic clock (the log-time offset removed).
    let first_datagram = session.observations.first().unwrap().arrival;
    for (at, _) in &session.counters {
        assert!(at.as_nanos() < first_datagram.as_nanos() + 60_000_000_000, "{at:?}");
    }
}
