//! The paper's figures (and ours) as SVG strings, drawn with plotters'
//! SVG backend (no font rendering needed): the caller writes them.
//!
//! - `two_point_velocity`: z and the two-point z-velocity against the
//!   cubic fit (paper Fig. 6);
//! - `accelerations`: gravity, drag and Magnus along a topspin flight,
//!   from the paper's fit and from the truth (Fig. 7);
//! - `logo_plane`: the logo positions of one sequence with the fitted
//!   rotation circle (Fig. 5);
//! - [`predicted`]: predicted against true trajectories per spin type;
//! - `clusters`: the spins per method, coloured by setting (Table IV);
//! - [`latency`]: the latency histograms of a short bench run.

use plotters::coord::Shift;
use plotters::prelude::*;

use super::flights::{Flight, SpinMethod};
use super::report::LatencyRun;
use topspin_core::fit::Cubic;
use topspin_core::fit::{FitConfig, Method, Sample, fit_trajectory};
use topspin_core::logo::RotationFit;
use topspin_core::physics::{FlightModel, Propagator, Vec3, rad_to_rps};
use topspin_sim::{SimBall, true_state_at};

type Area<'a> = DrawingArea<SVGBackend<'a>, Shift>;

/// One plotted series.
#[derive(Clone, Debug)]
pub(crate) struct Series {
    pub label: String,
    pub colour: RGBColor,
    pub points: Vec<(f64, f64)>,
    /// Markers instead of a line.
    pub markers: bool,
}

impl Series {
    pub(crate) fn line(label: &str, colour: RGBColor, points: Vec<(f64, f64)>) -> Self {
        Series { label: label.to_owned(), colour, points, markers: false }
    }
    pub(crate) fn markers(label: &str, colour: RGBColor, points: Vec<(f64, f64)>) -> Self {
        Series { label: label.to_owned(), colour, points, markers: true }
    }
}

const FONT: (&str, u32) = ("sans-serif", 14);
const BLUE_: RGBColor = RGBColor(31, 119, 180);
const GREEN_: RGBColor = RGBColor(44, 160, 44);
const RED_: RGBColor = RGBColor(214, 39, 40);
const GREY_: RGBColor = RGBColor(110, 110, 110);

/// Nine distinguishable colours, one per setting.
const SETTING_COLOURS: [RGBColor; 9] = [
    RGBColor(8, 48, 107),
    RGBColor(33, 113, 181),
    RGBColor(107, 174, 214),
    RGBColor(0, 109, 44),
    RGBColor(65, 171, 93),
    RGBColor(161, 217, 155),
    RGBColor(165, 15, 21),
    RGBColor(239, 59, 44),
    RGBColor(252, 146, 114),
];

fn range(vals: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in vals.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.05).max(1e-9);
    (lo - pad, hi + pad)
}

/// Draws `series` in one chart on `area`.
fn chart(area: &Area<'_>, title: &str, x_desc: &str, y_desc: &str, series: &[Series]) -> anyhow::Result<()> {
    let (x0, x1) = range(series.iter().flat_map(|s| s.points.iter().map(|p| p.0)));
    let (y0, y1) = range(series.iter().flat_map(|s| s.points.iter().map(|p| p.1)));
    let mut c = ChartBuilder::on(area)
        .caption(title, FONT)
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(55)
        .build_cartesian_2d(x0..x1, y0..y1)?;
    c.configure_mesh().x_desc(x_desc).y_desc(y_desc).light_line_style(WHITE).draw()?;
    for s in series {
        let colour = s.colour;
        if s.markers {
            c.draw_series(s.points.iter().map(|p| Circle::new(*p, 2, colour.filled())))?
                .label(s.label.clone())
                .legend(move |(x, y)| Circle::new((x + 7, y), 3, colour.filled()));
        } else {
            c.draw_series(LineSeries::new(s.points.iter().copied(), colour.stroke_width(2)))?
                .label(s.label.clone())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 15, y)], colour.stroke_width(2)));
        }
    }
    c.configure_series_labels().background_style(WHITE.mix(0.85)).border_style(BLACK).label_font(FONT).draw()?;
    Ok(())
}

fn svg(size: (u32, u32), draw: impl FnOnce(&Area<'_>) -> anyhow::Result<()>) -> anyhow::Result<String> {
    let mut out = String::new();
    {
        let root = SVGBackend::with_string(&mut out, size).into_drawing_area();
        root.fill(&WHITE)?;
        draw(&root)?;
        root.present()?;
    }
    Ok(out)
}

fn pre_bounce(ball: &SimBall) -> Vec<Sample> {
    let end = ball.truth.bounce.as_ref().map_or(f64::INFINITY, |b| b.t);
    ball.observations.iter().filter(|o| o.t < end && !o.outlier).map(|o| Sample::new(o.t, o.pos)).collect()
}

/// Paper Fig. 6: z of the observations before the bounce with the cubic,
/// and the z-velocity between neighbouring points against P′_z.
pub(crate) fn two_point_velocity(ball: &SimBall, noise_mm: f64) -> anyhow::Result<String> {
    let s = pre_bounce(ball);
    let cubic = Cubic::fit(s.iter()).ok_or_else(|| anyhow::anyhow!("no cubic"))?;
    let z: Vec<(f64, f64)> = s.iter().map(|p| (p.t, p.pos.z)).collect();
    let zc: Vec<(f64, f64)> = s.iter().map(|p| (p.t, cubic.pos(p.t).z)).collect();
    let vz: Vec<(f64, f64)> =
        s.windows(2).map(|w| (0.5 * (w[0].t + w[1].t), (w[1].pos.z - w[0].pos.z) / (w[1].t - w[0].t))).collect();
    let vc: Vec<(f64, f64)> = s.iter().map(|p| (p.t, cubic.vel(p.t).z)).collect();
    svg((800, 700), |root| {
        let halves = root.split_evenly((2, 1));
        chart(
            &halves[0],
            &format!("{}: height (tracker, {noise_mm} mm noise) and the cubic P(t)", ball.truth.setting),
            "t (s)",
            "z (m)",
            &[Series::markers("observations", BLUE_, z), Series::line("cubic fit", RED_, zc)],
        )?;
        chart(
            &halves[1],
            "z-velocity: between neighbouring points vs P'(t)",
            "t (s)",
            "vz (m/s)",
            &[Series::markers("two-point", BLUE_, vz), Series::line("cubic P'", RED_, vc)],
        )
    })
}

/// Paper Fig. 7: |gravity|, |drag| and |Magnus| acceleration along a
/// flight, from the paper's fit (cubic + Magnus solve) and the truth.
pub(crate) fn accelerations(ball: &SimBall, prop: &Propagator, noise: f64) -> anyhow::Result<String> {
    let s = pre_bounce(ball);
    let fm: &FlightModel = &prop.flight;
    let cubic = Cubic::fit(s.iter()).ok_or_else(|| anyhow::anyhow!("no cubic"))?;
    let fit = fit_trajectory(&s, prop, &FitConfig::new(Method::Paper, ball.truth.hit_plane_x).with_noise(noise))?;
    let launch = ball.truth.to_launch();
    let mut series = vec![
        Series::line("gravity", GREY_, s.iter().map(|p| (p.t, fm.gravity())).collect()),
        Series::line("drag (fit)", BLUE_, vec![]),
        Series::line("Magnus (fit)", RED_, vec![]),
        Series::markers("drag (truth)", BLUE_, vec![]),
        Series::markers("Magnus (truth)", RED_, vec![]),
    ];
    for p in &s {
        let v = cubic.vel(p.t);
        series[1].points.push((p.t, fm.k_d() * v.norm() * v.norm()));
        series[2].points.push((p.t, (fm.k_m(&v, &fit.spin) * fit.spin.cross(&v)).norm()));
        let st = true_state_at(&launch, prop, p.t);
        series[3].points.push((p.t, fm.k_d() * st.vel.norm_squared()));
        series[4].points.push((p.t, (fm.k_m(&st.vel, &st.spin) * st.spin.cross(&st.vel)).norm()));
    }
    svg((800, 450), |root| {
        chart(
            root,
            &format!(
                "{} ({:.0} rps): accelerations along the flight",
                ball.truth.setting,
                rad_to_rps(Vec3::from(ball.truth.spin).norm())
            ),
            "t (s)",
            "|a| (m/s²)",
            &series,
        )
    })
}

/// Paper Fig. 5: logo positions (camera frame, time order) and the circle
/// of the fitted rotation plane on the unit sphere.
pub(crate) fn logo_plane(title: &str, positions: &[Vec3], fit: &RotationFit) -> anyhow::Result<String> {
    let n = fit.axis.normalize();
    let d = fit.plane_offset;
    let rho = (1.0 - d * d).max(0.0).sqrt();
    let e1 = if n.x.abs() < 0.9 { Vec3::x() } else { Vec3::y() };
    let e1 = (e1 - n * n.dot(&e1)).normalize();
    let e2 = n.cross(&e1);
    let circle: Vec<(f64, f64, f64)> = (0..=120)
        .map(|i| {
            let a = i as f64 / 120.0 * std::f64::consts::TAU;
            let p = n * d + (e1 * a.cos() + e2 * a.sin()) * rho;
            (p.x, p.y, p.z)
        })
        .collect();
    svg((700, 650), |root| {
        let mut c = ChartBuilder::on(root).caption(title, FONT).margin(10).build_cartesian_3d(
            -1.1..1.1,
            -1.1..1.1,
            -1.1..1.1,
        )?;
        c.with_projection(|mut p| {
            p.pitch = 0.5;
            p.yaw = 0.6;
            p.scale = 0.85;
            p.into_matrix()
        });
        c.configure_axes().light_grid_style(WHITE).max_light_lines(3).draw()?;
        // The sphere: three great circles.
        for k in 0..3 {
            let ring: Vec<(f64, f64, f64)> = (0..=90)
                .map(|i| {
                    let a = i as f64 / 90.0 * std::f64::consts::TAU;
                    let (s, co) = a.sin_cos();
                    [(co, s, 0.0), (co, 0.0, s), (0.0, co, s)][k]
                })
                .collect();
            c.draw_series(LineSeries::new(ring, GREY_.mix(0.4)))?;
        }
        // The plane's grid: chords of the circle.
        for k in -3..=3 {
            let off = k as f64 / 4.0 * rho;
            let half = (rho * rho - off * off).max(0.0).sqrt();
            for (u, w) in [(e1, e2), (e2, e1)] {
                let a = n * d + u * off - w * half;
                let b = n * d + u * off + w * half;
                c.draw_series(LineSeries::new([(a.x, a.y, a.z), (b.x, b.y, b.z)], GREEN_.mix(0.35)))?;
            }
        }
        c.draw_series(LineSeries::new(circle, GREEN_.stroke_width(2)))?
            .label("fitted rotation circle")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 15, y)], GREEN_.stroke_width(2)));
        let m = positions.len().max(2) - 1;
        c.draw_series(positions.iter().enumerate().map(|(i, p)| {
            let f = i as f64 / m as f64;
            let col = RGBColor((40.0 + 200.0 * f) as u8, 60, (220.0 - 180.0 * f) as u8);
            Circle::new((p.x, p.y, p.z), 4, col.filled())
        }))?
        .label("logo centres (blue → red in time)")
        .legend(|(x, y)| Circle::new((x + 7, y), 4, RED_.filled()));
        c.configure_series_labels().background_style(WHITE.mix(0.85)).border_style(BLACK).label_font(FONT).draw()?;
        Ok(())
    })
}

/// One panel group of [`predicted`]: a flight and two predictions of it.
#[derive(Clone, Debug)]
pub struct PredictedCase {
    /// Title of the panels.
    pub title: String,
    /// The true trajectory, table frame, m.
    pub truth: Vec<Vec3>,
    /// The observations before the net that the predictions start from, m.
    pub observed: Vec<Vec3>,
    /// The path predicted with the refined spin fit, m.
    pub with_spin: Vec<Vec3>,
    /// The path predicted by the Kalman filter without spin, m.
    pub without_spin: Vec<Vec3>,
}

/// Predicted against true trajectories: per case a side view (x–z) and a
/// top view (x–y).
pub fn predicted(cases: &[PredictedCase]) -> anyhow::Result<String> {
    svg((1100, 330 * cases.len().max(1) as u32), |root| {
        let rows = root.split_evenly((cases.len().max(1), 2));
        for (i, c) in cases.iter().enumerate() {
            for (j, (axis, name)) in [(2usize, "z (m)"), (1, "y (m)")].into_iter().enumerate() {
                let p = |v: &[Vec3]| v.iter().map(|q| (q.x, q[axis])).collect::<Vec<_>>();
                chart(
                    &rows[2 * i + j],
                    &format!("{}: {}", c.title, if j == 0 { "side view" } else { "top view" }),
                    "x (m)",
                    name,
                    &[
                        Series::line("truth", GREY_, p(&c.truth)),
                        Series::markers("observed before the net", BLUE_, p(&c.observed)),
                        Series::line("predicted, fitted spin", GREEN_, p(&c.with_spin)),
                        Series::line("predicted, no spin (Kalman)", RED_, p(&c.without_spin)),
                    ],
                )?;
            }
        }
        Ok(())
    })
}

/// The spins of each method, ω_y against ω_z in rps, one colour per setting.
pub(crate) fn clusters(flights: &[Flight], methods: &[SpinMethod]) -> anyhow::Result<String> {
    let cols = 3usize;
    let rows_n = methods.len().div_ceil(cols).max(1);
    svg((1200, 380 * rows_n as u32), |root| {
        let areas = root.split_evenly((rows_n, cols));
        for (m, area) in methods.iter().zip(areas.iter()) {
            let series: Vec<Series> = topspin_sim::Setting::ALL
                .iter()
                .enumerate()
                .map(|(i, s)| {
                    let pts = flights
                        .iter()
                        .filter(|f| f.setting == *s)
                        .filter_map(|f| f.estimate(*m).spin())
                        .map(|w| (rad_to_rps(w.y), rad_to_rps(w.z)))
                        .collect();
                    Series::markers(&s.to_string(), SETTING_COLOURS[i], pts)
                })
                .collect();
            chart(area, m.label(), "ω_y (rps)", "ω_z (rps)", &series)?;
        }
        Ok(())
    })
}

/// The latency histograms of a bench run (counts per bucket).
pub fn latency(run: &LatencyRun) -> anyhow::Result<String> {
    svg((1000, 420), |root| {
        let areas = root.split_evenly((1, run.histograms.len().max(1)));
        for (h, area) in run.histograms.iter().zip(areas.iter()) {
            let top = (h.p999.max(1) as f64 * 1.5).min(h.max as f64).max(10.0) as u64;
            let data: Vec<(u64, u64)> = h.buckets.iter().copied().filter(|(us, _)| *us <= top).collect();
            let step = (top / 60).max(1);
            let ymax = data.iter().map(|d| d.1).max().unwrap_or(1).max(1);
            let mut c = ChartBuilder::on(area)
                .caption(format!("{}: p50 {} / p99 {} / p99.9 {} µs", h.name, h.p50, h.p99, h.p999), FONT)
                .margin(10)
                .x_label_area_size(35)
                .y_label_area_size(55)
                .build_cartesian_2d((0u64..top + step).into_segmented(), 0u64..ymax + ymax / 10 + 1)?;
            c.configure_mesh().x_desc("µs").y_desc("count").light_line_style(WHITE).draw()?;
            let mut binned = std::collections::BTreeMap::new();
            for (us, n) in data {
                *binned.entry(us / step * step).or_insert(0u64) += n;
            }
            c.draw_series(Histogram::vertical(&c).style(BLUE_.filled()).margin(0).data(binned))?;
        }
        Ok(())
    })
}
