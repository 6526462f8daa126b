//! `topspin calibrate cell` as a user runs it, against a robot placed at a
//! known pose that is not the default one (base moved 3.3 cm, 1.2 cm and
//! 2.1 cm, yawed 2.5° from `calib/robot.toml`):
//! - over RSI: the mock KR C4 is moved to each table point's TCP pose under
//!   that true cell while the command answers its requests; Enter takes
//!   each touch from `RIst`; the fit must recover the true base;
//! - from a touches file (CSV, TOML): the recovered lines, the JSON, and
//!   `--write` editing just the two `[cell]` lines of a copy of `calib/`;
//! - unusable input: exit 2 and one line; a refused fit: exit 1.
//!
//! No timing is asserted: the mock's answer deadline is stretched and its
//! late limit lifted, and the test waits for the mock to stand still before
//! each Enter.

#![allow(clippy::disallowed_methods)] // a process test: it waits on the wall clock

use std::io::{BufRead, BufReader, Write};
use std::net::UdpSocket;
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;
use topspin_daemon::calib_files::CalibDir;

use topspin_core::calib::Calibration;
use topspin_sim::mock_krc::{self, MockKrcConfig};

/// The true cell: T←B.
const TRUE_BASE: [f64; 3] = [2.083, -0.012, -0.071];
const TRUE_YAW_DEG: f64 = 182.5;
/// The bat's centre 6 mm above each point (half its thickness).
const OFFSET_M: f64 = 0.006;

/// Points the KR 6 R900 reaches with the bat down (it reaches ~0.9 m
/// from its A1 axis: the table's corners are beyond it): the centre line's
/// end at the robot's end and four marks of our own near that edge.
const POINTS: [(&str, Option<[f64; 3]>); 5] = [
    ("centre_robot_end", None),
    ("mark_edge_pos_y", Some([1.37, 0.35, 0.0])),
    ("mark_edge_neg_y", Some([1.37, -0.35, 0.0])),
    ("mark_in_pos_y", Some([1.28, 0.2, 0.0])),
    ("mark_in_neg_y", Some([1.28, -0.25, 0.0])),
];

fn topspin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_topspin"))
}

fn table_point(name: &str, own: Option<[f64; 3]>) -> [f64; 3] {
    own.unwrap_or_else(|| {
        topspin_core::calib::cell::named_point(&Calibration::default_cell().table, name).expect("a table point")
    })
}

/// Where the TCP is in B when it touches `p_t`: Rz(−yaw) (p_T + offset z − base).
fn tcp_in_b_mm(p_t: [f64; 3]) -> [f64; 3] {
    let (s, c) = TRUE_YAW_DEG.to_radians().sin_cos();
    let d = [p_t[0] - TRUE_BASE[0], p_t[1] - TRUE_BASE[1], p_t[2] + OFFSET_M - TRUE_BASE[2]];
    [(c * d[0] + s * d[1]) * 1e3, (-s * d[0] + c * d[1]) * 1e3, d[2] * 1e3]
}

fn assert_recovered(j: &serde_json::Value, pos_tol_m: f64, yaw_tol_deg: f64) {
    let cell = &j["cell"];
    let yaw = cell["base_yaw_in_table_deg"].as_f64().unwrap();
    let mut line = format!("true base {TRUE_BASE:?} yaw {TRUE_YAW_DEG}; fitted ");
    for i in 0..3 {
        let p = cell["base_in_table_xyz_m"][i].as_f64().unwrap();
        line += &format!("{p:.6} ");
        assert!((p - TRUE_BASE[i]).abs() < pos_tol_m, "axis {i}: {p} vs {} ({j})", TRUE_BASE[i]);
    }
    eprintln!("{line}yaw {yaw:.5}; rms {} mm", j["rms_mm"]);
    assert!((yaw - TRUE_YAW_DEG).abs() < yaw_tol_deg, "yaw {yaw} ({j})");
    assert!(j["full"]["tilt_deg"].as_f64().unwrap() < 0.01, "{j}");
}

#[test]
fn rsi_touches_of_the_mock_robot_recover_its_true_base() {
    let port = UdpSocket::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let mut names = Vec::new();
    let mut args: Vec<String> =
        ["calibrate", "cell", "--rsi", "--bind", &format!("127.0.0.1:{port}"), "--json"].map(String::from).into();
    args.extend(["--contact-offset-mm".into(), format!("{}", OFFSET_M * 1e3)]);
    for (name, own) in POINTS {
        names.push(name);
        args.push("--touch".into());
        args.push(match own {
            None => name.to_owned(),
            Some(p) => format!("{name}={},{},{}", p[0], p[1], p[2]),
        });
    }
    let mut child =
        topspin().args(&args).stdin(Stdio::piped()).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
    let (tx, rx) = mpsc::channel::<String>();
    let stderr = child.stderr.take().unwrap();
    std::thread::spawn(move || {
        for l in BufReader::new(stderr).lines().map_while(Result::ok) {
            if tx.send(l).is_err() {
                break;
            }
        }
    });
    let next_line = |what: &str| -> String {
        let l = rx.recv_timeout(Duration::from_secs(60)).unwrap_or_else(|_| panic!("no line: {what}"));
        eprintln!("topspin: {l}");
        l
    };
    assert!(next_line("listening").starts_with("listening for RSI on"));

    let mut cfg = MockKrcConfig::default_cell().unwrap();
    cfg.sensor = format!("127.0.0.1:{port}").parse().unwrap();
    cfg.bind = "127.0.0.1:0".parse().unwrap();
    cfg.controller.late_limit = u64::MAX; // a loaded machine must not stop RSI
    cfg.answer_deadline = topspin_core::time::Duration::from_millis(50);
    let start = cfg.controller.start;
    let mock = mock_krc::spawn(cfg).unwrap();
    let mut stdin = child.stdin.take().unwrap();
    for (name, own) in POINTS {
        let b = tcp_in_b_mm(table_point(name, own));
        let pose = [b[0], b[1], b[2], start[3], start[4], start[5]];
        mock.move_to(pose);
        // Wait until the robot stands at the point: there on 20 polls in
        // a row, each at least a cycle apart (the robot arrives at speed
        // and may pass the point once). The wall clock bounds the wait, it
        // is not asserted.
        let (mut settled, mut there) = (false, 0);
        for _ in 0..12000 {
            if mock.actual().is_some_and(|a| a.iter().zip(&pose).all(|(x, y)| (x - y).abs() < 1e-6)) {
                there += 1;
                if there == 20 {
                    settled = true;
                    break;
                }
            } else {
                there = 0;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        assert!(settled, "the mock never reached {name}: {:?} vs {pose:?}", mock.actual());
        assert!(next_line("prompt").starts_with(&format!("touch {name} ")));
        writeln!(stdin,).unwrap();
        let got = next_line("the touch");
        assert!(got.starts_with(&format!("{name}: TCP at")), "{got}");
    }
    drop(stdin);
    let out = child.wait_with_output().unwrap();
    let result = mock.stop().unwrap();
    assert!(!result.stopped_by_limit && !result.stopped_by_monitor, "{:?}", result.late);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stdout));
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(j["ok"], true, "{j}");
    assert_eq!(j["points"].as_array().unwrap().len(), POINTS.len());
    assert_eq!(j["contact_offset_mm"], OFFSET_M * 1e3);
    // RIst carries 4 decimals of a mm: the fit is exact to well within the
    // 1 mm / 0.1° asked for.
    assert_recovered(&j, 0.001, 0.1);
    assert!(j["rms_mm"].as_f64().unwrap() < 0.01, "{j}");
}

#[test]
fn touches_in_another_base_are_refused_with_exit_2() {
    // The KRL program's BASE_DATA is turned 2° about z from the robot's
    // foot: RIst is not the kinematics of AIPos under calib/robot.toml.
    let port = UdpSocket::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let args = [
        "calibrate",
        "cell",
        "--rsi",
        "--bind",
        &format!("127.0.0.1:{port}"),
        "--touch",
        "centre_robot_end",
        "--touch",
        "mark_a=1.37,0.35,0",
        "--touch",
        "mark_b=1.37,-0.35,0",
        "--touch",
        "mark_c=1.28,0.2,0",
    ];
    let mut child =
        topspin().args(args).stdin(Stdio::piped()).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
    let mut cfg = MockKrcConfig::default_cell().unwrap();
    cfg.sensor = format!("127.0.0.1:{port}").parse().unwrap();
    cfg.bind = "127.0.0.1:0".parse().unwrap();
    cfg.controller.late_limit = u64::MAX;
    cfg.answer_deadline = topspin_core::time::Duration::from_millis(50);
    cfg.controller.base = topspin_core::kinematics::Pose::from_xyz_abc([0.0; 3], [2f64.to_radians(), 0.0, 0.0]);
    let q = cfg.controller.start_joints;
    cfg.controller.stand_at(q);
    std::thread::sleep(Duration::from_millis(300));
    let mock = mock_krc::spawn(cfg).unwrap();
    writeln!(child.stdin.take().unwrap()).unwrap();
    let out = child.wait_with_output().unwrap();
    mock.stop().unwrap();
    assert_eq!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stderr));
    let err = String::from_utf8_lossy(&out.stderr);
    let last = err.trim().lines().last().unwrap();
    assert!(last.contains("refused at the first request") && last.contains("most likely BASE_DATA"), "{err}");
}

/// A touch: name, TCP in B (mm), the point's own table coordinates.
type TouchRow = (String, [f64; 3], Option<[f64; 3]>);

fn copy_calib(dir: &Path) {
    for f in ["physics.toml", "table.toml", "strike.toml", "robot.toml", "camera.toml"] {
        std::fs::copy(Path::new(env!("CARGO_MANIFEST_DIR")).join("calib").join(f), dir.join(f)).unwrap();
    }
}

fn csv_text(tcps: &[TouchRow]) -> String {
    let mut s = "name,x_mm,y_mm,z_mm,table_x_m,table_y_m,table_z_m\n".to_owned();
    for (n, b, own) in tcps {
        let own = own.map_or(",,".to_owned(), |p| format!("{},{},{}", p[0], p[1], p[2]));
        s += &format!("{n},{:.2},{:.2},{:.2},{own}\n", b[0], b[1], b[2]);
    }
    s
}

fn touches() -> Vec<TouchRow> {
    POINTS.iter().map(|(n, own)| (n.to_string(), tcp_in_b_mm(table_point(n, *own)), *own)).collect()
}

/// `topspin calibrate cell --points` on `touches` written as a CSV in
/// `dir`, writing into the calibration copied there (`--json`).
fn calibrate_from_points(dir: &Path, touches: &[TouchRow]) -> std::process::Output {
    let csv = dir.join("touches.csv");
    std::fs::write(&csv, csv_text(touches)).unwrap();
    topspin()
        .args(["calibrate", "cell", "--points"])
        .arg(&csv)
        .args(["--contact-offset-mm", "6", "--json", "--write"])
        .arg(dir)
        .output()
        .unwrap()
}

#[test]
fn a_points_file_gives_the_cell_lines_and_writes_them() {
    let dir = tempfile::tempdir().unwrap();
    copy_calib(dir.path());
    let out = calibrate_from_points(dir.path(), &touches());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(j["ok"], true);
    // The pendant's 0.01 mm.
    assert_recovered(&j, 0.0001, 0.005);
    assert_eq!(j["written"], dir.path().join("robot.toml").to_str().unwrap());
    // Only the two lines changed, and the folder loads with the new cell.
    let old = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("calib/robot.toml")).unwrap();
    let new = std::fs::read_to_string(dir.path().join("robot.toml")).unwrap();
    let changed: Vec<_> = old.lines().zip(new.lines()).filter(|(a, b)| a != b).map(|(_, b)| b).collect();
    assert_eq!(old.lines().count(), new.lines().count());
    let lines: Vec<&str> = j["cell_lines"].as_str().unwrap().lines().collect();
    assert_eq!(changed, lines);
    let c = Calibration::load(Some(dir.path())).unwrap();
    assert!((c.robot.cell.base_yaw_in_table_deg - TRUE_YAW_DEG).abs() < 0.005);

    // The same touches as TOML, text report: the lines are printed.
    let toml_path = dir.path().join("touches.toml");
    let mut t = "contact_offset_mm = 6.0\n".to_owned();
    for (n, b, own) in touches() {
        t += &format!("[[point]]\nname = \"{n}\"\ntcp_mm = [{:.2}, {:.2}, {:.2}]\n", b[0], b[1], b[2]);
        if let Some(p) = own {
            t += &format!("table_xyz_m = [{}, {}, {}]\n", p[0], p[1], p[2]);
        }
    }
    std::fs::write(&toml_path, t).unwrap();
    let out = topspin().args(["calibrate", "cell", "--points"]).arg(&toml_path).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains(lines[0]) && text.contains(lines[1]), "{text}");
    assert!(text.contains("contact offset 6.0 mm"), "{text}");
}

#[test]
fn a_wrong_touch_is_refused_with_exit_1_and_nothing_written() {
    let dir = tempfile::tempdir().unwrap();
    copy_calib(dir.path());
    let mut t = touches();
    t[1].1[2] += 15.0; // 15 mm high
    let before = std::fs::read_to_string(dir.path().join("robot.toml")).unwrap();
    let out = calibrate_from_points(dir.path(), &t);
    assert_eq!(out.status.code(), Some(1));
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(j["ok"], false);
    assert!(j["refusal"].as_str().unwrap().contains("mark_edge_pos_y"), "{j}");
    let err = String::from_utf8(out.stderr).unwrap();
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.starts_with("topspin: refused: ") && err.contains("mark_edge_pos_y"), "{err}");
    assert_eq!(std::fs::read_to_string(dir.path().join("robot.toml")).unwrap(), before);
    // A looser bound accepts it.
    let out = topspin()
        .args(["calibrate", "cell", "--points"])
        .arg(dir.path().join("touches.csv"))
        .args(["--contact-offset-mm", "6", "--max-rms-mm", "20", "--max-worst-mm", "20", "--max-tilt-deg", "5"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

#[test]
fn unusable_input_exits_2_with_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str, text: &str| {
        let f = dir.path().join(name);
        std::fs::write(&f, text).unwrap();
        f.to_str().unwrap().to_owned()
    };
    let t = touches();
    let three = p("three.csv", &csv_text(&t[..3]));
    let mut twice = t.clone();
    twice[4].0 = twice[0].0.clone();
    twice[4].2 = None;
    let twice = p("twice.csv", &csv_text(&twice));
    let line: Vec<_> = ["corner_robot_pos_y", "corner_robot_neg_y", "centre_robot_end"]
        .iter()
        .map(|n| (n.to_string(), tcp_in_b_mm(table_point(n, None)), None))
        .chain([("on_the_end_line".to_string(), [500.0, 300.0, 60.0], Some([1.37, 0.3, 0.0]))])
        .collect();
    let line = p("line.csv", &csv_text(&line));
    let cases: Vec<(Vec<String>, &str)> = vec![
        (vec!["--points".into(), "/nonexistent/touches.csv".into()], "/nonexistent/touches.csv"),
        (vec![], "--points FILE or --rsi"),
        (vec!["--points".into(), three], "3 points: at least 4"),
        (vec!["--points".into(), twice], "centre_robot_end is given twice"),
        (vec!["--points".into(), line], "lie on one line"),
        (vec!["--points".into(), p("bad.csv", "name,x,y\na,1,2\n")], "name,x_mm,y_mm,z_mm"),
        (vec!["--points".into(), p("nan.csv", "name,x_mm,y_mm,z_mm\ncentre_robot_end,1,two,3\n")], "line 2"),
        (
            vec!["--points".into(), p("who.csv", "name,x_mm,y_mm,z_mm\nnet_centre,1,2,3\n")],
            "\"net_centre\" is not a table point",
        ),
        (vec!["--points".into(), p("bad.toml", "[[point]]\nname = 3\n")], "bad.toml"),
        (vec!["--rsi".into(), "--touch".into(), "centre_robot_end,corner".into()], "\"corner\" is not a table point"),
        (vec!["--rsi".into(), "--touch".into(), "centre_robot_end,corner_robot_pos_y".into()], "2 points"),
        (vec!["--max-rms-mm=-1".into(), "--points".into(), "x.csv".into()], "--max-rms-mm -1"),
    ];
    for (args, want) in cases {
        let out = topspin().args(["calibrate", "cell"]).args(&args).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
        assert!(err.contains(want), "{args:?}: {err}");
        assert!(out.stdout.is_empty(), "{args:?}");
    }
}

#[test]
fn help_has_an_example_and_the_points_are_listed() {
    let out = topspin().args(["calibrate", "cell", "--help"]).output().unwrap();
    let help = String::from_utf8(out.stdout).unwrap();
    assert!(help.contains("topspin calibrate cell --points touches.csv --write calib"), "{help}");
    assert!(help.contains("--max-rms-mm") && help.contains("[default: 3]"), "{help}");
    let out = topspin().args(["calibrate", "cell", "--list-points", "--json"]).output().unwrap();
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(j["net_post_pos_y"], serde_json::json!([0.0, 0.915, 0.1525]));
    assert_eq!(j.as_object().unwrap().len(), 8);
}
