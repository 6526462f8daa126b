//! Benchmarks of `logo` (DESIGN §9 budget): logo positions from one 60 × 60
//! crop, background method (< 30 µs; paper: 300 µs), and the rotation fit
//! over a 20-frame sequence.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use topspin_core::calib::Calibration;
use topspin_core::calib::CameraCalib;
use topspin_core::logo::views;
use topspin_core::logo::{
    BallReference, CropImage, CropInput, DetectorConfig, LogoSample, RotationFitConfig, detect, fit_rotation,
};
use topspin_sim::render::{BallColour, Scene, Sequence, SequenceOptions, render_sequence};
use topspin_sim::{Setting, TrackerModel, simulate_ball};

/// The first filmed topspin-medium ball of seed 1.
fn sequence(cam: &CameraCalib) -> Sequence {
    let cal = Calibration::default_cell();
    let prop = cal.propagator();
    let scene = Scene::new(cam.clone(), BallColour::Orange);
    (0..100)
        .find_map(|j| {
            let k = 7 + 9 * j;
            let b =
                simulate_ball(1, k, Setting::ALL[7], &prop, cal.strike.hit_plane_x, &TrackerModel::default()).ok()?;
            let s = render_sequence(&scene, &b.truth, &prop, 1, k, &SequenceOptions { frames: 20 });
            (s.frames.len() == 20).then_some(s)
        })
        .expect("a filmed ball")
}

fn benches(c: &mut Criterion) {
    let cam = CameraCalib::default_camera();
    let seq = sequence(&cam);
    let inputs: Vec<CropInput<'_>> = seq
        .frames
        .iter()
        .map(|f| CropInput {
            t: f.label.t,
            crop: CropImage::new(f.crop.x0, f.crop.y0, 60, 60, &f.crop.rgb).unwrap(),
            circle: f.label.measured,
        })
        .collect();
    let views = views(&cam, &inputs).unwrap();
    let pairs: Vec<_> = inputs.iter().zip(&views).map(|(i, v)| (i.crop, *v)).collect();
    let det = DetectorConfig::for_logo(cam.logo_angular_radius());
    let reference = BallReference::from_crops(&pairs, det.colour_fraction).unwrap();
    // The crop with the most logo pixels, and one without a logo.
    let found: Vec<_> = pairs.iter().map(|(c, v)| detect(&det, &reference, c, v)).collect();
    let best = (0..pairs.len()).max_by_key(|&i| found[i].map_or(0, |m| m.pixels)).unwrap();
    let none = (0..pairs.len()).find(|&i| found[i].is_none()).unwrap_or(0);
    c.bench_function("logo/detect_60x60_logo", |b| {
        let (crop, view) = &pairs[best];
        b.iter(|| detect(&det, &reference, black_box(crop), black_box(view)))
    });
    c.bench_function("logo/detect_60x60_no_logo", |b| {
        let (crop, view) = &pairs[none];
        b.iter(|| detect(&det, &reference, black_box(crop), black_box(view)))
    });
    c.bench_function("logo/reference_20_crops", |b| {
        b.iter(|| BallReference::from_crops(black_box(&pairs), det.colour_fraction))
    });
    let samples: Vec<LogoSample> =
        inputs.iter().zip(&found).map(|(i, m)| LogoSample::new(i.t, m.map(|m| m.corrected))).collect();
    let cfg = RotationFitConfig::default();
    c.bench_function("logo/fit_rotation_20", |b| b.iter(|| fit_rotation(black_box(&samples), &cfg)));
}

criterion_group!(logo, benches);
criterion_main!(logo);
