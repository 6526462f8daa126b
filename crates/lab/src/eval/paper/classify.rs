//! Table IV of the paper: spin-type classification. For each method, the
//! median spin (per component) of each setting's flights is that setting's
//! cluster centre; each flight is assigned to the nearest centre; the
//! accuracy is the share of a setting's flights assigned to their own
//! setting. A flight the method gave no spin for counts as misclassified
//! (the paper counts all 50 flights of a setting).

use serde::Serialize;

use super::flights::{Estimate, Flight, SpinMethod};
use topspin_core::physics::Vec3;
use topspin_core::stats::quantile_sorted;
use topspin_sim::Setting;

/// The paper's Table IV per setting (paper order) and in total, percent:
/// background subtraction, + segment fit, CNN, trajectory fitting.
pub(crate) const PAPER_TABLE_IV: [[f64; 10]; 4] = [
    [88.0, 84.0, 70.0, 94.0, 68.0, 60.0, 84.0, 78.0, 90.0, 79.6],
    [94.0, 92.0, 86.0, 98.0, 58.0, 68.0, 90.0, 86.0, 96.0, 85.3],
    [96.0, 94.0, 80.0, 98.0, 74.0, 66.0, 88.0, 88.0, 96.0, 86.7],
    [100.0, 58.0, 60.0, 100.0, 94.0, 100.0, 86.0, 96.0, 100.0, 88.2],
];

/// The paper's column for a method, if the paper has one.
pub(crate) fn paper_column(m: SpinMethod) -> Option<&'static [f64; 10]> {
    match m {
        SpinMethod::BgCentroid => Some(&PAPER_TABLE_IV[0]),
        SpinMethod::BgSegment => Some(&PAPER_TABLE_IV[1]),
        SpinMethod::Cnn => Some(&PAPER_TABLE_IV[2]),
        SpinMethod::TrajectoryPaper => Some(&PAPER_TABLE_IV[3]),
        _ => None,
    }
}

/// One method's classification.
#[derive(Clone, Debug, Serialize)]
pub struct MethodClasses {
    /// The method.
    pub method: SpinMethod,
    /// Its row name ([`SpinMethod::label`]).
    pub label: &'static str,
    /// False when the method is not available in this run (no model).
    pub available: bool,
    /// Cluster centre per setting, rps (None: no flight of that setting
    /// had a spin).
    pub centres_rps: Vec<Option<[f64; 3]>>,
    /// Flights per setting (`Setting::ALL` order).
    pub flights: [usize; 9],
    /// Flights classified right, per setting.
    pub right: [usize; 9],
    /// Flights the method gave no spin for, per setting.
    pub no_spin: [usize; 9],
    /// Accuracy per setting, fraction (NaN for a setting without flights).
    pub accuracy: [f64; 9],
    /// Accuracy over all flights, fraction (NaN without flights).
    pub total: f64,
    /// Median ‖ω̂ − ω‖ / ‖ω‖ over the flights with a spin, percent.
    pub spin_err_pct: f64,
}

/// The component-wise median of `v`.
pub(crate) fn median_vec(v: &[Vec3]) -> Option<Vec3> {
    if v.is_empty() {
        return None;
    }
    let mut out = Vec3::zeros();
    for c in 0..3 {
        let mut x: Vec<f64> = v.iter().map(|p| p[c]).collect();
        x.sort_by(f64::total_cmp);
        out[c] = quantile_sorted(&x, 0.5);
    }
    Some(out)
}

/// Index of the nearest centre (None when there is none).
pub fn nearest(centres: &[Option<Vec3>], p: &Vec3) -> Option<usize> {
    centres
        .iter()
        .enumerate()
        .filter_map(|(i, c)| c.map(|c| (i, (c - p).norm())))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(i, _)| i)
}

fn setting_index(s: &Setting) -> usize {
    Setting::ALL.iter().position(|x| x == s).expect("one of the nine")
}

/// Classifies `flights` with `method`.
pub fn classify(flights: &[Flight], method: SpinMethod) -> MethodClasses {
    let available = flights.iter().any(|f| !matches!(f.estimate(method), Estimate::NoModel));
    let mut per: Vec<Vec<Vec3>> = vec![Vec::new(); 9];
    for f in flights {
        if let Some(s) = f.estimate(method).spin() {
            per[setting_index(&f.setting)].push(s);
        }
    }
    let centres: Vec<Option<Vec3>> = per.iter().map(|v| median_vec(v)).collect();
    let (mut n, mut right, mut none) = ([0usize; 9], [0usize; 9], [0usize; 9]);
    let mut errs = Vec::new();
    for f in flights {
        let i = setting_index(&f.setting);
        n[i] += 1;
        match f.estimate(method).spin() {
            Some(s) => {
                right[i] += (nearest(&centres, &s) == Some(i)) as usize;
                let t = Vec3::from(f.spin_true);
                errs.push((s - t).norm() / t.norm() * 100.0);
            }
            None => none[i] += 1,
        }
    }
    errs.sort_by(f64::total_cmp);
    let accuracy = std::array::from_fn(|i| if n[i] == 0 { f64::NAN } else { right[i] as f64 / n[i] as f64 });
    let total_n: usize = n.iter().sum();
    MethodClasses {
        method,
        label: method.label(),
        available,
        centres_rps: centres.iter().map(|c| c.map(|c| (c / std::f64::consts::TAU).into())).collect(),
        flights: n,
        right,
        no_spin: none,
        accuracy,
        total: if total_n == 0 { f64::NAN } else { right.iter().sum::<usize>() as f64 / total_n as f64 },
        spin_err_pct: quantile_sorted(&errs, 0.5),
    }
}

/// Table IV: every method of [`SpinMethod::ALL`].
pub fn table(flights: &[Flight]) -> Vec<MethodClasses> {
    SpinMethod::ALL.iter().map(|&m| classify(flights, m)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flight(setting: usize, spin: Option<[f64; 3]>) -> Flight {
        let mut estimates = vec![Estimate::NoModel; SpinMethod::ALL.len()];
        estimates[SpinMethod::TrajectoryPaper.index()] = match spin {
            Some(s) => Estimate::Spin(s),
            None => Estimate::Failed("x".into()),
        };
        Flight {
            setting: Setting::ALL[setting],
            ball: 0,
            colour: "orange",
            frames: 0,
            truth_visible: 0,
            bg_classified_right: 0,
            bg_angle_err: Default::default(),
            bg_seconds: 0.0,
            cnn_seconds: 0.0,
            cnn: None,
            spin_true: [0.0, 100.0, 0.0],
            estimates,
        }
    }

    #[test]
    fn nearest_median_classification() {
        // Setting 0 around y = −100, setting 1 around y = −200; one flight
        // of setting 0 strays to −190, one of setting 1 has no spin.
        let flights = vec![
            flight(0, Some([0.0, -100.0, 0.0])),
            flight(0, Some([0.0, -105.0, 0.0])),
            flight(0, Some([0.0, -190.0, 0.0])),
            flight(1, Some([0.0, -200.0, 0.0])),
            flight(1, Some([0.0, -210.0, 0.0])),
            flight(1, None),
        ];
        let c = classify(&flights, SpinMethod::TrajectoryPaper);
        assert!(c.available);
        assert_eq!(c.flights[..2], [3, 3]);
        assert_eq!(c.right[..2], [2, 2]);
        assert_eq!(c.no_spin[..2], [0, 1]);
        assert!((c.total - 4.0 / 6.0).abs() < 1e-12);
        assert!(c.centres_rps[2].is_none());
        let none = classify(&flights, SpinMethod::Cnn);
        assert!(!none.available);
        assert_eq!(none.total, 0.0);
    }
}
