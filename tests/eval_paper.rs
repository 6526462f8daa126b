//! `topspin eval paper` end to end, tiny: one ball per setting for Table III,
//! two filmed flights per setting for Table IV (the committed CNN on tract),
//! no latency run. Checks that the folder holds tables.md, a results.json of
//! the expected shape with every method's rows filled, and at least one SVG
//! figure; and the CNN's exits. Asserts no timing.

use std::path::PathBuf;
use std::process::Command;

use topspin_lab::eval::paper::flights::SpinMethod;

const BIN: &str = env!("CARGO_BIN_EXE_topspin");

const SETTINGS: [&str; 9] = [
    "backspin-low",
    "backspin-medium",
    "backspin-high",
    "sidespin-low",
    "sidespin-medium",
    "sidespin-high",
    "topspin-low",
    "topspin-medium",
    "topspin-high",
];

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("topspin-eval-paper-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

#[test]
fn a_tiny_run_writes_the_tables_the_json_and_figures() {
    let dir = temp_dir("tiny");
    let out = Command::new(BIN)
        .args([
            "eval",
            "paper",
            "--out",
            dir.to_str().unwrap(),
            "--flights",
            "2",
            "--bounce-balls",
            "1",
            "--latency-s",
            "0",
            "--backend",
            "tract",
            "--quiet",
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "stdout:\n{}\nstderr:\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );

    let tables = std::fs::read_to_string(dir.join("tables.md")).unwrap();
    assert!(tables.contains("Table III"), "{tables}");
    assert!(tables.contains("Table IV"), "{tables}");

    let json = std::fs::read_to_string(dir.join("results.json")).unwrap();
    let r: serde_json::Value = serde_json::from_str(&json).unwrap();
    for key in
        ["command", "config", "physics", "bounce", "classes", "logo", "flights", "figures", "wall_seconds", "machine"]
    {
        assert!(r.get(key).is_some(), "results.json lacks {key:?}");
    }
    assert_eq!(r["config"]["flights"], 2);
    assert_eq!(r["config"]["bounce_balls"], 1);

    // Table III: the nine launcher settings, each with the paper's numbers.
    let rows = r["bounce"]["rows"].as_array().unwrap();
    let settings: Vec<&str> = rows.iter().map(|row| row["setting"].as_str().unwrap()).collect();
    assert_eq!(settings, SETTINGS);
    for row in rows {
        assert!(!row["ours"].as_array().unwrap().is_empty());
        assert_eq!(row["paper"].as_array().unwrap().len(), 4);
    }

    // Table IV: every method has nine per-setting accuracies in [0, 1].
    let classes = r["classes"].as_array().unwrap();
    assert!(classes.len() >= 6, "{} methods", classes.len());
    for c in classes {
        let acc = c["accuracy"].as_array().unwrap();
        assert_eq!(acc.len(), 9, "{}", c["method"]);
        for a in acc {
            let a = a.as_f64().unwrap();
            assert!((0.0..=1.0).contains(&a), "{}: {a}", c["method"]);
        }
        let total = c["total"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&total));
    }
    let method = |m: &str| classes.iter().find(|c| c["method"] == m).unwrap();
    for m in ["trajectory_refined", "cnn", "fused"] {
        assert_eq!(method(m)["available"], true, "{m}");
    }
    assert!(r["cnn"].as_str().unwrap().contains("logo-compact.onnx on tract"), "{}", r["cnn"]);
    assert!(r["fusion"].as_str().unwrap().contains("logo fused on"), "{}", r["fusion"]);
    // The fusion falls back on the trajectory: it answers wherever that does.
    let answered = |m: SpinMethod| {
        r["flights"].as_array().unwrap().iter().filter(|f| f["estimates"][m.index()].get("spin").is_some()).count()
    };
    assert_eq!(answered(SpinMethod::Fused), answered(SpinMethod::TrajectoryRefined));

    // The logo metrics: the CNN sees the logo about as well as it did on
    // its own test crops (0.99; the rendered flights are the same camera).
    let logo = r["logo"].as_array().unwrap();
    let cnn = logo.iter().find(|l| l["method"] == "cnn").unwrap();
    assert_eq!(cnn["available"], true);
    assert!(cnn["classification"].as_f64().unwrap() > 0.9, "{cnn}");
    assert!(cnn["vector_angle"]["median"].as_f64().unwrap() < 10.0, "{cnn}");
    assert!(cnn["geodesic"]["median"].as_f64().unwrap() < 10.0, "{cnn}");

    // The figures: listed in results.json, and at least one SVG on disk.
    let figures = r["figures"].as_array().unwrap();
    assert!(!figures.is_empty());
    for f in figures {
        let path = dir.join(f.as_str().unwrap());
        let svg = std::fs::read_to_string(&path).unwrap();
        assert!(svg.contains("<svg"), "{}", path.display());
    }
    let svgs = std::fs::read_dir(&dir)
        .unwrap()
        .filter(|e| e.as_ref().unwrap().path().extension().is_some_and(|x| x == "svg"))
        .count();
    assert!(svgs >= 1);

    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_cnn_can_be_left_out_and_a_missing_model_is_one_line() {
    let dir = temp_dir("nocnn");
    let run = |extra: &[&str]| {
        let mut args = vec!["eval", "paper", "--out", dir.to_str().unwrap(), "--flights", "2", "--bounce-balls", "1"];
        args.extend(["--latency-s", "0", "--quiet"]);
        args.extend(extra);
        Command::new(BIN).args(&args).output().unwrap()
    };
    let out = run(&["--no-cnn"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("results.json")).unwrap()).unwrap();
    let cnn = r["classes"].as_array().unwrap().iter().find(|c| c["method"] == "cnn").unwrap();
    assert_eq!(cnn["available"], false);
    assert!(String::from_utf8_lossy(&out.stdout).contains("no model"));

    for extra in [&["--model", "/nonexistent/model.onnx"][..], &["--no-cnn", "--fuse-logo", "cnn"]] {
        let out = run(extra);
        assert_eq!(out.status.code(), Some(2), "{extra:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim().lines().count(), 1, "{extra:?}: {err}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
