//! The current shift's OEE as the snapshot carries it (`oee`): the
//! shift, its ratios, times and counts, the six big losses and the
//! breakdowns by stop cause, as `[oee]` and `models::oee` compute them.

use cellwatch_models::oee::{Figures, ShiftWindow};
use serde::{Deserialize, Serialize};

use crate::clock::rfc3339;

/// A shift's OEE so far.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OeePayload {
    /// The shift's name (`[[oee.shifts]]`).
    pub shift: String,
    /// When it began (RFC 3339).
    pub from: String,
    /// When it ends (RFC 3339).
    pub until: String,
    /// When the figures were computed (RFC 3339): they run up to then.
    pub at: String,
    /// Run time ÷ planned production time (0–1); `null` with no planned
    /// time.
    pub availability: Option<f64>,
    /// Ideal time of the parts ÷ run time (0–1); `null` with no run time.
    pub performance: Option<f64>,
    /// Good parts ÷ parts (0–1); `null` with no part.
    pub quality: Option<f64>,
    /// Availability × performance × quality; `null` when one is.
    pub oee: Option<f64>,
    /// Planned production time, ms.
    pub planned_ms: u64,
    /// Run time, ms.
    pub run_ms: u64,
    /// Breaks and planned stops, ms.
    pub not_planned_ms: u64,
    /// Time the machine was not observed (`offline`), ms.
    pub unobserved_ms: u64,
    /// Parts made, rejects included.
    pub parts: u64,
    /// Parts rejected.
    pub rejects: u64,
    /// The six big losses, ms.
    pub losses: LossesPayload,
    /// Breakdown time by stop cause.
    pub breakdowns: Vec<BreakdownPayload>,
}

/// The six big losses, each as time (ms).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct LossesPayload {
    /// Faults and long idle stops.
    pub breakdowns_ms: u64,
    /// Setup and adjustment.
    pub setup_ms: u64,
    /// Idle stops shorter than `oee.small_stop`.
    pub small_stops_ms: u64,
    /// Run time neither small stops nor the parts' ideal time.
    pub reduced_speed_ms: u64,
    /// The ideal time of the rejects soon after a start.
    pub startup_rejects_ms: u64,
    /// The ideal time of the other rejects.
    pub production_rejects_ms: u64,
}

/// Breakdown time of one stop cause.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct BreakdownPayload {
    /// The cause's code (paper 002's Table 4; `--` unmatched).
    pub code: String,
    /// Its name.
    pub name: String,
    /// Stops begun in the shift.
    pub stops: u32,
    /// Their planned time, ms.
    pub ms: u64,
}

impl OeePayload {
    /// The figures of `shift` computed at `at` (ms since the epoch).
    pub fn new(shift: &ShiftWindow, f: &Figures, at: u64) -> OeePayload {
        let l = &f.losses;
        OeePayload {
            shift: shift.name.clone(),
            from: rfc3339(shift.start),
            until: rfc3339(shift.end),
            at: rfc3339(at),
            availability: f.availability,
            performance: f.performance,
            quality: f.quality,
            oee: f.oee,
            planned_ms: f.planned_ms,
            run_ms: f.run_ms,
            not_planned_ms: f.not_planned_ms,
            unobserved_ms: f.unobserved_ms,
            parts: f.parts,
            rejects: f.rejects,
            losses: LossesPayload {
                breakdowns_ms: l.breakdowns_ms,
                setup_ms: l.setup_ms,
                small_stops_ms: l.small_stops_ms,
                reduced_speed_ms: l.reduced_speed_ms,
                startup_rejects_ms: l.startup_rejects_ms,
                production_rejects_ms: l.production_rejects_ms,
            },
            breakdowns: f
                .breakdowns
                .iter()
                .map(|b| BreakdownPayload {
                    code: b.code.clone(),
                    name: b.name.clone(),
                    stops: b.stops,
                    ms: b.ms,
                })
                .collect(),
        }
    }
}
