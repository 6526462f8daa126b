//! The logo method on rendered balls, at the library level: logo positions
//! within a few degrees of the truth, the segment correction helping on
//! cut logos, the rotation fit on the true positions exact.

use topspin_core::calib::Calibration;
use topspin_core::calib::CameraCalib;
use topspin_lab::logo::eval::{EvalOptions, evaluate, spin_errors, summarise};
use topspin_sim::Setting;
use topspin_sim::render::BallColour;

#[test]
fn rendered_balls_are_read_to_a_few_degrees() {
    let cal = Calibration::default_cell();
    let cam = CameraCalib::default_camera();
    let opts = EvalOptions {
        seed: 11,
        balls: 2,
        frames: 20,
        settings: vec![Setting::ALL[1], Setting::ALL[7]],
        colours: vec![BallColour::Orange, BallColour::White],
        max_tries: 24,
        fit: Default::default(),
    };
    let balls = evaluate(&cal, &cam, &opts);
    assert_eq!(balls.len(), 8);
    let all: Vec<_> = balls.iter().collect();
    let row = summarise("all", &all);
    // Centroid (paper), segment, weighted.
    assert!(row.angle_mean.iter().all(|&e| e < 4.0), "{row:?}");
    assert!(row.angle_mean_cut[1] < row.angle_mean_cut[0], "{row:?}");
    assert!(row.detection_accuracy > 0.75, "{row:?}");
    // The fit on the true positions is exact up to the integration.
    for b in &balls {
        if let Ok(f) = &b.spin_fit_truth {
            let (axis, mag) = spin_errors(f, &b.spin_true);
            assert!(axis < 0.1 && mag.abs() < 0.05, "{b:?}");
        }
    }
    assert!(row.fitted[1] >= 5, "{row:?}");
    assert!(row.axis_median[1] < 5.0 && row.magnitude_median[1] < 1.0, "{row:?}");
}
