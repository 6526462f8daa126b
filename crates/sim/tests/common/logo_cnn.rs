//! Checks shared by the two backend tests (each backend needs its own
//! process: ONNX Runtime's API pointer is process-global).

use std::path::PathBuf;

use topspin_cnn::{Backend, CnnOutput, INPUT_SIZE, LogoCnn, default_model};
use topspin_core::calib::Calibration;
use topspin_core::calib::CameraCalib;
use topspin_sim::render::{BallColour, Scene, SequenceOptions, render_sequence};
use topspin_sim::{Setting, TrackerModel, simulate_ball};

/// The committed model and its metrics (with the reference outputs).
pub fn model() -> (PathBuf, serde_json::Value) {
    let model = default_model();
    let metrics = model.with_extension("json");
    let text = std::fs::read_to_string(&metrics).unwrap_or_else(|e| panic!("{}: {e}", metrics.display()));
    (model, serde_json::from_str(&text).expect("metrics JSON"))
}

/// Runs the whole check on `backend`.
pub fn check(backend: Backend) {
    let (path, metrics) = model();
    let mut net = LogoCnn::load(&path, &backend).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(net.backend(), &backend);

    // 1. The same answers as PyTorch on the reference batch of
    //    tools/logo_cnn/train.py (floats, so through `infer_floats`).
    let reference = &metrics["reference"];
    let n = reference["visibility"].as_array().expect("reference").len();
    let x: Vec<f32> = (0..n)
        .flat_map(|b| {
            (0..3).flat_map(move |c| {
                (0..INPUT_SIZE).flat_map(move |i| {
                    (0..INPUT_SIZE).map(move |j| {
                        0.5 + 0.4 * (0.11 * i as f32 + 0.17 * j as f32 + 0.7 * c as f32 + 1.3 * b as f32).sin()
                    })
                })
            })
        })
        .collect();
    let mut out = vec![CnnOutput::default(); n];
    net.infer_floats(&x, &mut out).expect("inference");
    for (b, o) in out.iter().enumerate() {
        let v = reference["visibility"][b].as_f64().unwrap();
        assert!((o.visibility as f64 - v).abs() < 2e-3, "crop {b}: visibility {} vs {v}", o.visibility);
        let q: Vec<f64> = (0..4).map(|k| reference["quaternion"][b][k].as_f64().unwrap()).collect();
        let c = o.orientation.coords;
        // (x, y, z, w) in nalgebra's storage; the model writes (w, x, y, z).
        let got = [c[3], c[0], c[1], c[2]];
        for k in 0..4 {
            assert!((got[k] - q[k]).abs() < 2e-3, "crop {b}: quaternion {got:?} vs {q:?}");
        }
    }

    // 2. Rendered crops: the logo found where it is.
    let cal = Calibration::default_cell();
    let prop = cal.propagator();
    let cam = CameraCalib::default_camera();
    let scene = Scene::new(cam.clone(), BallColour::Orange);
    let (mut right, mut total, mut angles) = (0, 0, Vec::new());
    for k in 0..40 {
        let b =
            simulate_ball(77, k, Setting::ALL[k % 9], &prop, cal.strike.hit_plane_x, &TrackerModel::default()).unwrap();
        let seq = render_sequence(&scene, &b.truth, &prop, 77, k, &SequenceOptions { frames: 10 });
        if seq.frames.len() < 10 {
            continue;
        }
        let crops: Vec<&[u8]> = seq.frames.iter().map(|f| f.crop.rgb.as_slice()).collect();
        let mut out = vec![out[0]; crops.len()];
        net.infer(&crops, &mut out).expect("inference");
        for (f, o) in seq.frames.iter().zip(&out) {
            let m = f.label.measured;
            let view = topspin_core::logo::BallView::new(&cam, m.u, m.v, m.radius).unwrap();
            let truth = view.to_view(&f.label.logo_camera);
            total += 1;
            right += ((o.visibility >= 0.5) == (truth.z > 0.0)) as usize;
            if truth.z > 0.2 {
                angles.push(o.logo_view().angle(&truth).to_degrees());
            }
        }
        if total >= 60 {
            break;
        }
    }
    assert!(total >= 40, "only {total} crops rendered");
    angles.sort_by(f64::total_cmp);
    let median = angles[angles.len() / 2];
    let accuracy = right as f64 / total as f64;
    eprintln!("{backend:?}: {total} crops, accuracy {accuracy:.3}, median vector angle {median:.2}°");
    assert!(accuracy > 0.85, "classification accuracy {accuracy}");
    assert!(median < 12.0, "median vector angle {median}°");

    // 3. Bad input is an error, not a panic.
    assert!(net.infer(&[&[0u8; 10][..]], &mut out[..1]).is_err());
}
