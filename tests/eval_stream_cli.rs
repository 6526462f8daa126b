//! `topspin eval stream` end to end: human strokes judged on a plane of
//! one's own, and the exit code for unusable input.

use std::process::{Command, Output};

const BIN: &str = env!("CARGO_BIN_EXE_topspin");

fn stream(extra: &[&str]) -> Output {
    Command::new(BIN).args(["eval", "stream", "--balls", "12", "--json"]).args(extra).output().unwrap()
}

#[test]
fn human_strokes_are_judged_on_the_plane_asked_for() {
    let out = stream(&["--strokes", "human-rally", "--hit-plane-x", "1.2"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["setup"]["strokes"], "human-rally");
    assert_eq!(v["setup"]["hit_plane_x"], 1.2);
    let (reachable, tracked) = (v["reachable"].as_u64().unwrap(), v["tracked"].as_u64().unwrap());
    assert!(reachable >= 4 && tracked == reachable, "{reachable} in the window, {tracked} tracked");
}

#[test]
fn unusable_input_exits_2_with_one_line() {
    for args in [["--strokes", "aimed-launcher"], ["--hit-plane-x", "-1"], ["--hit-plane-x", "NaN"]] {
        let args = [args[0].to_owned() + "=" + args[1]];
        let out = Command::new(BIN).args(["eval", "stream"]).args(&args).output().unwrap();
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8(out.stderr).unwrap();
        assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
        assert!(err.contains(args[0].split('=').next().unwrap()), "{args:?}: {err}");
    }
}
