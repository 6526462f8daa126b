//! Re-running a recorded session (`topspin replay`): the recorded datagrams
//! through a fresh [`Ingest`] and [`Estimator`] set up from the recorded
//! configuration and calibration, the plans compared bit for bit with the
//! recorded ones (see the module doc of [`crate::record`] for what the
//! daemon must guarantee).

use serde::Serialize;

use super::{RecordError, Recording, plan_floats};
use topspin_core::estimator::Estimator;
use topspin_core::ingest::{Ingest, IngestCounters};
use topspin_core::plan::StrikePlan;

/// The first plan that differs.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Difference {
    /// 0-based index in the plan sequence.
    pub index: usize,
    /// The fields that differ (e.g. `position.x`, `seq`), or `missing` /
    /// `extra` when one side has no plan at that index.
    pub fields: Vec<String>,
    /// The recorded plan, debug-formatted (`None`: the recording has none at that index).
    pub recorded: Option<String>,
    /// The replayed plan, debug-formatted (`None`: the replay made none at that index).
    pub replayed: Option<String>,
}

/// What a replay found.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ReplayReport {
    /// Tracker datagrams in the recording.
    pub datagrams: usize,
    /// Datagrams the replay's ingest accepted.
    pub accepted: u64,
    /// The replay's ingest counters.
    pub ingest: IngestCounters,
    /// Plans in the recording.
    pub recorded_plans: usize,
    /// Plans the replay made.
    pub replayed_plans: usize,
    /// Plans compared (both sides have them).
    pub compared: usize,
    /// Compared plans that are bit for bit the same.
    pub identical: usize,
    /// Compared plans that differ.
    pub different: usize,
    /// Plans on one side only (counted as different unless the file is truncated).
    pub unmatched: usize,
    /// The first plan that differs, if one does.
    pub first_difference: Option<Difference>,
    /// Why the file ended early, if it did: plans beyond the shorter side
    /// are then not compared.
    pub truncated: Option<String>,
}

impl ReplayReport {
    /// Every plan the recording and the replay both hold is identical, and
    /// (for a complete file) both hold the same number.
    pub fn identical(&self) -> bool {
        self.different == 0 && (self.unmatched == 0 || self.truncated.is_some())
    }
}

/// The names of the fields in which two plans differ (floats by their bits).
pub(crate) fn differing_fields(a: &StrikePlan, b: &StrikePlan) -> Vec<String> {
    const NAMES: [&str; 13] = [
        "position.x",
        "position.y",
        "position.z",
        "velocity.x",
        "velocity.y",
        "velocity.z",
        "orientation.a",
        "orientation.b",
        "orientation.c",
        "spin.x",
        "spin.y",
        "spin.z",
        "confidence",
    ];
    let mut out = Vec::new();
    if a.seq != b.seq {
        out.push("seq".to_owned());
    }
    if a.trajectory != b.trajectory {
        out.push("trajectory".to_owned());
    }
    if a.made_at != b.made_at {
        out.push("made_at".to_owned());
    }
    if a.hit_time != b.hit_time {
        out.push("hit_time".to_owned());
    }
    for ((x, y), name) in plan_floats(a).iter().zip(plan_floats(b).iter()).zip(NAMES) {
        if x.to_bits() != y.to_bits() {
            out.push(name.to_owned());
        }
    }
    out
}

/// The plans the daemon's ingest and estimator make from the recorded datagrams.
pub(crate) fn replay_plans(session: &Recording) -> Result<(Vec<StrikePlan>, IngestCounters), RecordError> {
    let cal = session.calibration()?;
    let cfg = &session.config;
    let mut ingest = Ingest::new(Some(cfg.network.tracker_source), cfg.fixed_latency_ns());
    let mut est = Estimator::new(&cal, cfg.estimator_config());
    let mut plans = Vec::new();
    for d in &session.observations {
        if let Ok(a) = ingest.accept(&d.bytes, d.from, d.arrival)
            && let Some(p) = est.observe(a.capture, a.pos).plan
        {
            plans.push(p);
        }
    }
    Ok((plans, ingest.counters()))
}

/// Replays `session` and compares its plans with the recorded ones.
pub fn replay_recording(session: &Recording) -> Result<ReplayReport, RecordError> {
    let (replayed, ingest) = replay_plans(session)?;
    let recorded = &session.plans;
    let compared = recorded.len().min(replayed.len());
    let mut identical = 0;
    let mut first_difference = None;
    for (i, (r, p)) in recorded.iter().zip(&replayed).enumerate() {
        let fields = differing_fields(r, p);
        if fields.is_empty() {
            identical += 1;
        } else if first_difference.is_none() {
            first_difference = Some(Difference {
                index: i,
                fields,
                recorded: Some(format!("{r:?}")),
                replayed: Some(format!("{p:?}")),
            });
        }
    }
    let unmatched = recorded.len().max(replayed.len()) - compared;
    if first_difference.is_none() && unmatched > 0 && session.truncated.is_none() {
        let (field, r, p) = if recorded.len() > compared {
            ("missing", Some(format!("{:?}", recorded[compared])), None)
        } else {
            ("extra", None, Some(format!("{:?}", replayed[compared])))
        };
        first_difference =
            Some(Difference { index: compared, fields: vec![field.to_owned()], recorded: r, replayed: p });
    }
    Ok(ReplayReport {
        datagrams: session.observations.len(),
        accepted: ingest.accepted,
        ingest,
        recorded_plans: recorded.len(),
        replayed_plans: replayed.len(),
        compared,
        identical,
        different: compared - identical,
        unmatched,
        first_difference,
        truncated: session.truncated.clone(),
    })
}
