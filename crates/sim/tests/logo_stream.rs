//! The logo thread's sans-IO stream (`topspin_core::logo::LogoStream`) fed
//! with rendered crops of a simulated ball: one spin per ball, near the
//! truth, repeated crops dropped.

use topspin_core::calib::Calibration;
use topspin_core::calib::CameraCalib;
use topspin_core::logo::LogoMethod;
use topspin_core::logo::{LogoEngine, LogoStream, SEQUENCE_LEN};
use topspin_core::physics::Vec3;
use topspin_core::time::{Duration, Instant};
use topspin_sim::render::{BallColour, Scene, SequenceOptions, render_sequence};
use topspin_sim::{Setting, TrackerModel, simulate_ball};

#[test]
fn a_ball_passing_the_strip_gives_one_spin_near_the_truth() {
    let cal = Calibration::default_cell();
    let prop = cal.propagator();
    let cam = CameraCalib::default_camera();
    let scene = Scene::new(cam.clone(), BallColour::Orange);
    let (truth, seq) = (0..30)
        .find_map(|k| {
            let b =
                simulate_ball(5, k, Setting::ALL[1], &prop, cal.strike.hit_plane_x, &TrackerModel::default()).ok()?;
            let seq = render_sequence(&scene, &b.truth, &prop, 5, k, &SequenceOptions { frames: SEQUENCE_LEN });
            (seq.frames.len() == SEQUENCE_LEN).then_some((Vec3::from(b.truth.spin), seq))
        })
        .expect("a filmed ball");
    let mut stream = LogoStream::new(cam, LogoEngine::Background(LogoMethod::Segment));
    let mut spins = Vec::new();
    let t0 = Instant::from_nanos(1_000_000_000);
    let at = |t: f64| t0 + Duration::from_nanos((t * 1e9) as u64);
    for f in &seq.frames {
        let c = f.wire_crop(f.label.frame as u32, at(f.label.t));
        spins.extend(stream.crop(&c));
        // A repeated crop (same capture time) is dropped, not counted twice.
        assert!(stream.crop(&c).is_none());
    }
    let last = at(seq.frames.last().unwrap().label.t);
    assert!(stream.poll(last + Duration::from_millis(50)).is_none());
    assert_eq!(spins.len(), 1, "{:?}", stream.counters());
    let s = spins[0];
    assert!((s.spin - truth).norm() < 0.15 * truth.norm(), "{:?} vs {truth:?}", s.spin);
    assert!(s.cov.cholesky().is_some(), "covariance SPD");
    let c = stream.counters();
    assert_eq!((c.crops, c.dropped, c.sequences, c.fitted), (2 * SEQUENCE_LEN as u64, SEQUENCE_LEN as u64, 1, 1));
}
