//! `topspin fit` end to end: a simulated flight in, the JSON of DESIGN §8
//! out and checked against the ground truth; `fit stream` over a multi-ball
//! recording; exit code 2 with one line for every kind of unusable input.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const BIN: &str = env!("CARGO_BIN_EXE_topspin");

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("topspin-fit-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn topspin(args: &[&str], file: &Path) -> Output {
    Command::new(BIN).args(args).arg(file).output().unwrap()
}

fn v3(v: &serde_json::Value) -> [f64; 3] {
    let a = v.as_array().unwrap();
    [a[0].as_f64().unwrap(), a[1].as_f64().unwrap(), a[2].as_f64().unwrap()]
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Writes the pre-bounce part of ball `k` of a simulated set as a CSV.
fn pre_bounce_csv(dir: &Path, sim_dir: &Path, k: usize) -> (PathBuf, serde_json::Value) {
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(sim_dir.join(format!("ball-{k:03}.json"))).unwrap()).unwrap();
    let t_bounce = truth["bounce"]["t"].as_f64().unwrap();
    let csv = std::fs::read_to_string(sim_dir.join(format!("ball-{k:03}.csv"))).unwrap();
    let mut out = String::from("t,x,y,z,extra\n");
    for line in csv.lines().skip(1) {
        let t: f64 = line.split(',').next().unwrap().parse().unwrap();
        if t < t_bounce {
            out.push_str(line);
            out.push_str(",7\n");
        }
    }
    let path = dir.join(format!("pre-{k}.csv"));
    std::fs::write(&path, out).unwrap();
    (path, truth)
}

#[test]
fn fit_json_matches_the_truth_and_names_false_detections() {
    let dir = temp_dir("json");
    let sim = dir.join("sim");
    let status = Command::new(BIN)
        .args(["sim", "--balls", "9", "--seed", "11", "--noise-mm", "1", "--false-starts", "2", "--out"])
        .arg(&sim)
        .output()
        .unwrap();
    assert!(status.status.success());
    for k in 0..9 {
        let (csv, truth) = pre_bounce_csv(&dir, &sim, k);
        let out = topspin(&["fit", "--json", "--noise-mm", "1"], &csv);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        for key in
            ["spin", "spin_rps", "position", "velocity", "bounce", "hit", "hit_plane_x", "samples_used", "outliers"]
        {
            assert!(j.get(key).is_some(), "missing {key}: {j}");
        }
        let spin = v3(&j["spin"]);
        let true_spin = v3(&truth["spin"]);
        // The lift's scale is fitted per flight and trades with
        // the spin's size: the error is what the reported σ says it is.
        let err = dist(spin, true_spin) / dist(true_spin, [0.0; 3]);
        assert!(err < 0.15, "ball {k}: spin {spin:?} vs {true_spin:?}");
        let std = v3(&j["spin_std"]);
        for a in 0..3 {
            assert!(
                (spin[a] - true_spin[a]).abs() < 4.0 * std[a] + 2.0,
                "ball {k}: axis {a}: {spin:?} ± {std:?} vs {true_spin:?}"
            );
        }
        for key in ["lift_scale", "lift_scale_std", "drag_scale", "drag_scale_std"] {
            assert!(j[key].as_f64().is_some_and(|v| v.is_finite() && v >= 0.0), "{key}: {j}");
        }
        assert!((j["drag_scale"].as_f64().unwrap() - 1.0).abs() < 0.1, "ball {k}: the simulator's own drag: {j}");
        assert_eq!(j["outliers"], serde_json::json!([0, 1]), "ball {k}");
        let bx = j["bounce"]["x"].as_f64().unwrap() - truth["bounce"]["pos"][0].as_f64().unwrap();
        let by = j["bounce"]["y"].as_f64().unwrap() - truth["bounce"]["pos"][1].as_f64().unwrap();
        assert!(bx.hypot(by) < 0.01, "ball {k}: bounce off by {bx}, {by}");
        // The hit lies after the bounce, where the table's friction turns
        // the spin's error into position.
        let hit = dist(v3(&j["hit"]["position"]), v3(&truth["hit"]["pos"]));
        assert!(hit < 0.05, "ball {k}: hit off by {hit}");
    }
}

#[test]
fn stream_prints_one_plan_per_ball() {
    let dir = temp_dir("stream");
    let status = Command::new(BIN).args(["sim", "--balls", "6", "--seed", "5", "--out"]).arg(&dir).output().unwrap();
    assert!(status.status.success());
    let out = topspin(&["fit", "stream", "--json"], &dir.join("stream.csv"));
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    // The older spelling is the same command.
    let older = topspin(&["fit", "--stream", "--json"], &dir.join("stream.csv"));
    assert_eq!(older.stdout, out.stdout);
    let balls: Vec<serde_json::Value> = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(balls.len(), 6, "{balls:?}");
    let planned = balls.iter().filter(|b| !b["plan"].is_null()).count();
    assert!(planned >= 4, "{planned} of 6 balls planned");
}

#[test]
fn stream_on_a_plane_of_ones_own_predicts_every_ball_there() {
    let dir = temp_dir("stream-plane");
    let status = Command::new(BIN).args(["sim", "--balls", "6", "--seed", "5", "--out"]).arg(&dir).output().unwrap();
    assert!(status.status.success());
    let xs = |args: &[&str]| -> Vec<f64> {
        let out = topspin(args, &dir.join("stream.csv"));
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let balls: Vec<serde_json::Value> = serde_json::from_slice(&out.stdout).unwrap();
        balls.iter().filter(|b| !b["plan"].is_null()).map(|b| v3(&b["plan"]["position"])[0]).collect()
    };
    // The daemon's planes: the hitting volume, within the arm's reach.
    let volume = xs(&["fit", "stream", "--json"]);
    assert!(volume.len() >= 4 && volume.iter().all(|x| (1.45 - 1e-9..=1.60 + 1e-9).contains(x)), "{volume:?}");
    // One plane asked for, over the table where the arm does not reach:
    // every ball predicted there, after its bounce.
    let asked = xs(&["fit", "stream", "--json", "--hit-plane-x", "1.2"]);
    assert!(asked.len() >= 4 && asked.iter().all(|x| (x - 1.2).abs() < 1e-9), "{asked:?}");
}

#[test]
fn unusable_input_exits_2_with_one_line() {
    let dir = temp_dir("bad");
    let good_rows: String =
        (0..20).map(|i| format!("{},{},0.1,0.3\n", i as f64 * 0.006, -1.4 + i as f64 * 0.04)).collect();
    let cases: Vec<(&str, String)> = vec![
        ("header", format!("t,x,z\n{good_rows}")),
        ("number", format!("t,x,y,z\n{good_rows}0.5,abc,0.1,0.3\n")),
        ("nan", format!("t,x,y,z\n{good_rows}0.5,NaN,0.1,0.3\n")),
        ("few", "t,x,y,z\n0,0,0,0.3\n0.01,0.05,0,0.3\n".to_owned()),
        ("order", format!("t,x,y,z\n{good_rows}0.01,0.5,0.1,0.3\n")),
        ("empty", String::new()),
    ];
    for (name, text) in cases {
        let path = dir.join(format!("{name}.csv"));
        std::fs::write(&path, text).unwrap();
        let out = topspin(&["fit"], &path);
        assert_eq!(out.status.code(), Some(2), "{name}: {}", String::from_utf8_lossy(&out.stdout));
        let err = String::from_utf8(out.stderr).unwrap();
        assert_eq!(err.lines().count(), 1, "{name}: {err}");
        assert!(err.contains(&format!("{name}.csv")), "{name}: {err}");
    }
    let out = topspin(&["fit"], &dir.join("missing.csv"));
    assert_eq!(out.status.code(), Some(2));
}
