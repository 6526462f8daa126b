//! `topspin eval paper` end to end, tiny: one ball per setting for Table III,
//! two filmed flights per setting for Table IV, no latency run. Checks that
//! the folder holds tables.md, a results.json of the expected shape and at
//! least one SVG figure. Asserts no timing.

use std::path::PathBuf;
use std::process::Command;

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

    // Table IV: every method has nine per-setting accuracies in [0, 1];
    // the CNN and the fusion have no model here.
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
    assert_eq!(method("trajectory_refined")["available"], true);
    assert_eq!(method("cnn")["available"], false);
    assert!(!r["logo"].as_array().unwrap().is_empty());

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
