//! `topspin eval worlds` end to end: the JSON a script reads, the known
//! table's switch, and the exit code for unusable input.

use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_topspin");

fn worlds(extra: &[&str]) -> std::process::Output {
    Command::new(BIN)
        .args(["eval", "worlds", "--balls", "9", "--noise-mm", "1", "--json"])
        .args(extra)
        .output()
        .unwrap()
}

/// Median hit-time error of the default in other-table to the bounce.
fn other_table_hit_dt(out: &std::process::Output) -> f64 {
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let worlds = v["worlds"].as_array().unwrap();
    assert_eq!(worlds.len(), 8);
    let w = worlds.iter().find(|w| w["world"] == "other-table").unwrap();
    let row =
        w["rows"].as_array().unwrap().iter().find(|r| r["method"] == "refined" && r["window"] == "pre_bounce").unwrap();
    row["hit_dt_ms"]["median"].as_f64().unwrap()
}

#[test]
fn the_known_table_is_a_switch_of_the_fit_not_of_the_world() {
    let calibrated = worlds(&[]);
    let known = worlds(&["--known-table"]);
    let v: serde_json::Value = serde_json::from_slice(&known.stdout).unwrap();
    assert_eq!(v["known_table"], true);
    let (c, k) = (other_table_hit_dt(&calibrated), other_table_hit_dt(&known));
    assert!(k < c, "known table {k} ms, the calibration's {c} ms");
}

#[test]
fn unusable_input_exits_2_with_one_line() {
    for args in [vec!["--noise-mm", "-1"], vec!["--calib", "/nonexistent/topspin-calib"]] {
        let out = Command::new(BIN).args(["eval", "worlds", "--balls", "9"]).args(&args).output().unwrap();
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8(out.stderr).unwrap();
        assert_eq!(err.lines().count(), 1, "{err}");
    }
}
