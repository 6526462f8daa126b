//! The Foxglove view of a short loopback demo (2 balls):
//!
//! - live: a `foxglove.websocket.v1` client (negotiated as `foxglove.sdk.v1`; the library's probe, built on
//!   tungstenite) connects to `--live`, subscribes to every advertised
//!   channel, and receives scene, pose and latency messages with the right
//!   schemas, stamped with wall-clock log times;
//! - recorded: the demo's MCAP file opens with the `mcap` crate and holds
//!   every channel (the recording's own and the viewer's), with messages on
//!   the scene and plot channels, `record::read_recording` still reads it and
//!   `topspin replay`'s comparison finds every plan identical, and its
//!   `--live` path (the recording through the viewer) reaches a client;
//! - the arm: on `/view/robot` of the recording, and again of its replay
//!   through the viewer, `arm_actual`'s joints are the forward kinematics
//!   of the `AIPos` the mock sent in that cycle (`ipoc`), the foot on the
//!   calibrated base, the bat at `RIst`; the commanded ghost is there and
//!   leads it; every arm and TCP entity has a lifetime; log times never
//!   run backwards.
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
use topspin_core::kinematics::{FRAMES, Joints};
use topspin_core::physics::Vec3;
use topspin_core::rsi::RobFrame;
use topspin_core::time::Duration;
use topspin_daemon::channels::{TOPICS, Topic};
use topspin_daemon::record::RecordingSink;
use topspin_daemon::record::replay_recording;
use topspin_daemon::record::{
    Recorder, Recording, TOPIC_COUNTERS, TOPIC_DATAGRAM, TOPIC_PLAN, TOPIC_RSI, read_recording,
};
use topspin_daemon::viewer::view_recording;
use topspin_daemon::viewer::{LiveServer, ViewerSink};
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
    // The hitting plane's window and the volume's nearest plane's.
    let xs: Vec<f64> = cell.entities[2].lines.iter().map(|l| l.points[0].x).collect();
    assert_eq!(xs, [1.60, 1.45], "{xs:?}");
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

    let session = read_recording(&path).unwrap();
    assert!(session.truncated.is_none(), "{:?}", session.truncated);
    let arms = check_the_arm(&bytes, &session);
    eprintln!("recorded arms: {arms}");
    // The recording through the viewer (`topspin replay FILE --live`'s
    // path) into a second file: the same arm from the recorded requests.
    let again = dir.path().join("again.mcap");
    let cal = session.calibration().unwrap();
    let rec = RecordingSink::new(Recorder::create(&again, &session.config, &session.calib_files).unwrap());
    let mut sink = ViewerSink::new(&cal, None, Some(rec), None).with_offset(session.log_time_offset);
    view_recording(&session, &mut sink, None, &AtomicBool::new(false)).unwrap();
    drop(sink);
    let replayed = check_the_arm(&std::fs::read(&again).unwrap(), &session);
    // One every fifth cycle in both (the replay starts its count afresh).
    assert!(replayed.abs_diff(arms) <= 1, "replayed {replayed}, recorded {arms}");
    assert!(!session.plans.is_empty());
    // The demo's recording replays bit for bit, as the daemon's does.
    let replay = replay_recording(&session).unwrap();
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
    view_recording(&session, &mut sink, None, &AtomicBool::new(false)).unwrap();
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

/// Checks `/view/robot` in the MCAP `bytes` against the RSI requests of
/// `session` (see the module doc); returns the `arm_actual` entities seen.
fn check_the_arm(bytes: &[u8], session: &Recording) -> usize {
    let cal = session.calibration().unwrap();
    let arm = cal.robot.arm();
    let base = Vec3::from(cal.robot.cell.base_in_table_xyz_m);
    let requests: BTreeMap<u64, RobFrame> =
        session.exchanges.iter().map(|x| RobFrame::parse(&x.request).unwrap()).map(|r| (r.ipoc, r)).collect();
    let points = |e: &foxglove::messages::SceneEntity| -> Vec<Vec3> {
        e.spheres
            .iter()
            .map(|s| {
                let p = s.pose.as_ref().unwrap().position.unwrap();
                Vec3::new(p.x, p.y, p.z)
            })
            .collect()
    };
    let (mut arms, mut ghosts, mut last_log) = (0, 0, 0);
    // Per message: the actual and the commanded bat in T.
    let mut bats: Vec<(Vec3, Vec3)> = Vec::new();
    for m in mcap::MessageStream::new(bytes).unwrap() {
        let m = m.unwrap();
        if m.channel.topic != Topic::Robot.name() {
            continue;
        }
        assert!(m.log_time >= last_log, "/view/robot ran backwards: {} after {last_log}", m.log_time);
        last_log = m.log_time;
        let scene = SceneUpdate::decode(&m.data[..]).unwrap();
        let mut actual_tcp = None;
        for e in &scene.entities {
            if e.id != "bat_plan" {
                assert!(e.lifetime.is_some_and(|l| l.sec() > 0 || l.nsec() > 0), "{} without a lifetime", e.id);
            }
            if !e.id.starts_with("arm_") {
                continue;
            }
            assert_eq!(e.frame_id, "table");
            let ipoc: u64 = e.metadata.iter().find(|kv| kv.key == "ipoc").unwrap().value.parse().unwrap();
            let rob = &requests[&ipoc];
            let (deg, rist) = (if e.id == "arm_actual" { rob.aipos } else { rob.aspos }.unwrap(), rob.rist.unwrap());
            let want = arm.frames(&Joints::from_degrees(deg)).map(|f| cal.robot.b_to_t(f.position));
            let got = points(e);
            assert_eq!(got, want, "{} of ipoc {ipoc}", e.id);
            assert_eq!(e.cylinders.len(), FRAMES - 1);
            assert_eq!(got[0], base);
            let tcp = got[FRAMES - 1];
            if e.id == "arm_actual" {
                arms += 1;
                // RIst is the FK of the joints, both sent with 4 decimals.
                let rist_t = cal.robot.b_to_t(Vec3::new(rist.x, rist.y, rist.z) * 1e-3);
                assert!((tcp - rist_t).norm() < 1e-5, "ipoc {ipoc}: bat {tcp:?}, RIst {rist_t:?}");
                actual_tcp = Some(tcp);
            } else {
                ghosts += 1;
                assert!(e.cylinders.iter().all(|c| c.color.unwrap().a < 1.0));
                bats.push((actual_tcp.expect("the actual arm first"), tcp));
            }
        }
    }
    assert!(arms > 100, "{arms} arms");
    assert_eq!(ghosts, arms);
    // Ahead: where the ghost is furthest from the arm (in a stroke), the
    // arm gets there within the next 100 ms (5 messages), the robot's
    // dead time and lag later.
    let (k, lead) = bats.iter().map(|(a, c)| (a - c).norm()).enumerate().max_by(|a, b| a.1.total_cmp(&b.1)).unwrap();
    assert!(lead > 0.01, "the ghost at most {lead} m from the arm");
    let ghost = bats[k].1;
    let later = bats[k + 1..(k + 6).min(bats.len())].iter().map(|(a, _)| (a - ghost).norm()).fold(f64::MAX, f64::min);
    assert!(later < lead / 2.0, "the ghost {lead} m ahead, the arm no nearer than {later} m in 100 ms");
    eprintln!("the ghost up to {:.1} mm ahead; the arm {:.1} mm from there within 100 ms", lead * 1e3, later * 1e3);
    arms
}
