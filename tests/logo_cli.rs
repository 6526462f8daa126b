//! `topspin render` → `topspin logo` end to end: rendered folders in, the
//! spin out and checked against the renderer's truth; the TTI1 stream;
//! exit code 2 with one line for every kind of unusable folder.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use topspin_core::wire::{CROP_MAX_LEN, Crop};

const BIN: &str = env!("CARGO_BIN_EXE_topspin");

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("topspin-logo-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn topspin(args: &[&str]) -> Output {
    Command::new(BIN).args(args).output().unwrap()
}

fn v3(v: &serde_json::Value) -> [f64; 3] {
    let a = v.as_array().unwrap();
    [a[0].as_f64().unwrap(), a[1].as_f64().unwrap(), a[2].as_f64().unwrap()]
}

fn angle_deg(a: [f64; 3], b: [f64; 3]) -> f64 {
    let dot: f64 = (0..3).map(|i| a[i] * b[i]).sum();
    let na = a.iter().map(|x| x * x).sum::<f64>().sqrt();
    let nb = b.iter().map(|x| x * x).sum::<f64>().sqrt();
    (dot / (na * nb)).clamp(-1.0, 1.0).acos().to_degrees()
}

fn render(dir: &Path) {
    let out = topspin(&[
        "render",
        "--out",
        dir.to_str().unwrap(),
        "--balls",
        "2",
        "--seed",
        "4",
        "--setting",
        "topspin-medium,backspin-low",
        "--colour",
        "both",
        "--frames-per-ball",
        "20",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

#[test]
fn rendered_folders_give_the_true_spin() {
    let dir = temp_dir("render");
    render(&dir);
    let labels = std::fs::read_to_string(dir.join("labels.csv")).unwrap();
    assert!(labels.starts_with("file,ball,setting,colour,frame,t,u,v,radius,true_u"));
    let mut folders: Vec<PathBuf> =
        std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().path()).filter(|p| p.is_dir()).collect();
    folders.sort();
    assert_eq!(folders.len(), 4, "{folders:?}");
    assert!((1 + 4 * 10..=1 + 4 * 20).contains(&labels.lines().count()));
    let mut good = 0;
    for f in &folders {
        let truth: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(f.join("truth.json")).unwrap()).unwrap();
        let out = topspin(&["logo", f.to_str().unwrap(), "--json"]);
        if !out.status.success() {
            // A ball whose logo stays out of view is reported, not guessed.
            assert_eq!(out.status.code(), Some(2));
            assert_eq!(String::from_utf8_lossy(&out.stderr).lines().count(), 1);
            continue;
        }
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        let (fit, want) = (v3(&v["spin"]), v3(&truth["spin"]));
        let norm = |a: [f64; 3]| a.iter().map(|x| x * x).sum::<f64>().sqrt();
        assert!(angle_deg(fit, want) < 10.0, "{f:?}: {fit:?} vs {want:?}");
        assert!((norm(fit) - norm(want)).abs() < 0.05 * norm(want), "{f:?}: {fit:?} vs {want:?}");
        assert_eq!(v["frame"], "table");
        good += 1;
    }
    assert!(good >= 2, "only {good} folders fitted");
    // Deterministic: the same command writes the same bytes.
    let again = temp_dir("render-again");
    render(&again);
    assert_eq!(std::fs::read(dir.join("labels.csv")).unwrap(), std::fs::read(again.join("labels.csv")).unwrap());
    let name = folders[0].file_name().unwrap();
    assert_eq!(
        std::fs::read(folders[0].join("frame-03.png")).unwrap(),
        std::fs::read(again.join(name).join("frame-03.png")).unwrap()
    );
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&again);
}

#[test]
fn eval_is_a_subcommand_and_the_older_flag_still_works() {
    let args = ["--balls", "1", "--setting", "topspin-high", "--colour", "orange", "--frames", "10", "--json"];
    let new = Command::new(BIN).args(["logo", "eval"]).args(args).output().unwrap();
    assert!(new.status.success(), "{}", String::from_utf8_lossy(&new.stderr));
    let rows: serde_json::Value = serde_json::from_slice(&new.stdout).unwrap();
    assert!(!rows["balls"].as_array().unwrap().is_empty(), "{rows}");
    let old = Command::new(BIN).args(["logo", "--eval"]).args(args).output().unwrap();
    assert_eq!(old.stdout, new.stdout);
    // A typed option names what it accepts.
    let out = Command::new(BIN).args(["logo", "eval", "--colour", "green"]).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("orange") && err.lines().count() == 1, "{err}");
}

#[test]
fn unusable_folders_exit_2_with_one_line() {
    let dir = temp_dir("bad");
    let check = |args: &[&str], needle: &str| {
        let out = topspin(args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(err.contains(needle), "{args:?}: {err}");
    };
    let d = dir.to_str().unwrap();
    check(&["logo", "/nonexistent/topspin-logo"], "not a folder");
    check(&["logo", d], "frames.csv");
    std::fs::write(dir.join("frames.csv"), "file,t,u,v\n").unwrap();
    check(&["logo", d], "radius");
    std::fs::write(dir.join("frames.csv"), "file,t,u,v,radius\nmissing.png,0.0,900,600,23\n").unwrap();
    check(&["logo", d], "missing.png");
    std::fs::write(dir.join("frames.csv"), "file,t,u,v,radius\nx.png,zero,900,600,23\n").unwrap();
    check(&["logo", d], "not a finite number");
    std::fs::write(dir.join("frames.csv"), "file,t,u,v,radius\n").unwrap();
    check(&["logo", d], "crops");
    check(&["logo", d, "--method", "magic"], "--method");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn crops_stream_as_tti1() {
    let sock = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    sock.set_read_timeout(Some(std::time::Duration::from_secs(10))).unwrap();
    let addr = sock.local_addr().unwrap().to_string();
    let child = std::thread::spawn(move || {
        topspin(&["render", "--to", &addr, "--balls", "1", "--setting", "backspin-low", "--frames-per-ball", "12"])
    });
    let mut buf = vec![0u8; CROP_MAX_LEN + 16];
    let mut got = Vec::new();
    while got.len() < 12 {
        let n = sock.recv(&mut buf).unwrap();
        let c = Crop::parse(&buf[..n]).unwrap();
        assert_eq!((c.width, c.height), (60, 60));
        assert!((15.0..35.0).contains(&c.radius));
        got.push((c.seq, c.capture));
    }
    let out = child.join().unwrap();
    assert!(out.status.success());
    assert!(got.windows(2).all(|w| w[1].0 == w[0].0 + 1 && w[1].1 > w[0].1));
}
