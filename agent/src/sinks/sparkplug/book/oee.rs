//! The device's OEE metrics (`OEE/…`, with `[oee]`): the current shift's
//! figures (or the last shift's, between shifts) as the OEE sink computes
//! them on every tick of the cell loop, and which of their changes are
//! worth a DDATA. A tick changes the times and most ratios a little, so:
//! a ratio is sent when it moved by more than [`RATIO_DEADBAND`], became
//! known or unknown (null); a count when it changed; the times when they
//! moved by [`TIME_DEADBAND_MS`] or more, or with any other OEE change (so
//! a host reads ratios and times of the same moment); and everything when
//! the shift changes.

use super::{properties, MetricBook, MetricValue, OeeMetrics};
use crate::sinks::sparkplug::tahu::DataType;
use crate::step::OeeNow;

/// A ratio (0–1) is sent when it moved by more than this.
pub(super) const RATIO_DEADBAND: f64 = 0.0005;

/// The planned and run times are sent alone when they moved by this much.
pub(super) const TIME_DEADBAND_MS: u64 = 60_000;

/// The metrics, in order from the first.
const SHIFT: usize = 0;
const RATIOS: [&str; 4] = [
    "OEE/Availability",
    "OEE/Performance",
    "OEE/Quality",
    "OEE/OEE",
];
const COUNTS: [&str; 2] = ["OEE/Parts", "OEE/Rejects"];
const TIMES: [&str; 2] = ["OEE/Planned Time", "OEE/Run Time"];
const FIRST_RATIO: usize = 1;
const FIRST_COUNT: usize = FIRST_RATIO + RATIOS.len();
const FIRST_TIME: usize = FIRST_COUNT + COUNTS.len();

impl MetricBook {
    /// Declares the OEE metrics, all null until the first tick.
    pub(super) fn declare_oee(&mut self) {
        let first = self.add("OEE/Shift".into(), DataType::String, None);
        for name in RATIOS {
            self.add(name.into(), DataType::Double, None);
        }
        for name in COUNTS {
            self.add(name.into(), DataType::UInt64, None);
        }
        for name in TIMES {
            let at = self.add(name.into(), DataType::UInt64, None);
            self.entries[at].properties = Some(properties(&[("engUnit", "ms")]));
        }
        self.oee = Some(OeeMetrics {
            first,
            shift_start: None,
        });
    }

    /// Takes the OEE figures of `now`: the changes worth sending are held
    /// (the module's doc says which); whether any was.
    pub(crate) fn oee(&mut self, now: &OeeNow) -> bool {
        let Some(metrics) = self.oee else {
            return false;
        };
        let first = metrics.first;
        let f = &now.figures;
        let at = now.at;
        let new_shift = metrics.shift_start != Some(now.shift.start);
        let mut sent = self.set(
            first + SHIFT,
            Some(MetricValue::Text(now.shift.name.clone())),
            at,
        );
        let ratios = [f.availability, f.performance, f.quality, f.oee];
        for (i, ratio) in ratios.into_iter().enumerate() {
            let entry = first + FIRST_RATIO + i;
            if new_shift || ratio_moved(self.entries[entry].value.as_ref(), ratio) {
                sent |= self.set(entry, ratio.map(MetricValue::Double), at);
            }
        }
        for (i, count) in [f.parts, f.rejects].into_iter().enumerate() {
            sent |= self.set(
                first + FIRST_COUNT + i,
                Some(MetricValue::UInt64(count)),
                at,
            );
        }
        for (i, ms) in [f.planned_ms, f.run_ms].into_iter().enumerate() {
            let entry = first + FIRST_TIME + i;
            if new_shift || sent || time_moved(self.entries[entry].value.as_ref(), ms) {
                sent |= self.set(entry, Some(MetricValue::UInt64(ms)), at);
            }
        }
        self.oee = Some(OeeMetrics {
            first,
            shift_start: Some(now.shift.start),
        });
        sent
    }
}

/// Whether a ratio moved from `was` to `now` enough to be sent.
fn ratio_moved(was: Option<&MetricValue>, now: Option<f64>) -> bool {
    match (was, now) {
        (None, None) => false,
        (Some(MetricValue::Double(a)), Some(b)) => (a - b).abs() > RATIO_DEADBAND,
        _ => true,
    }
}

/// Whether a time moved from `was` to `now` enough to be sent alone.
fn time_moved(was: Option<&MetricValue>, now: u64) -> bool {
    match was {
        Some(MetricValue::UInt64(a)) => a.abs_diff(now) >= TIME_DEADBAND_MS,
        _ => true,
    }
}

#[cfg(test)]
mod tests {
    use cellwatch_models::oee::{Figures, ShiftWindow};

    use super::*;
    use crate::sinks::sparkplug::tahu::{Payload, Value};

    fn book() -> MetricBook {
        MetricBook::new(&[], &[], true, true, 100)
    }

    fn now(shift_start: u64, at: u64, f: Figures) -> OeeNow {
        OeeNow {
            shift: ShiftWindow {
                name: "early".into(),
                start: shift_start,
                end: shift_start + 8 * 3_600_000,
                breaks: Vec::new(),
            },
            figures: f,
            at,
        }
    }

    fn figures(planned_ms: u64, run_ms: u64, parts: u64, rejects: u64) -> Figures {
        let ratio = |a: u64, b: u64| (b > 0).then(|| a as f64 / b as f64);
        let ideal_ms = parts * 30_000;
        let availability = ratio(run_ms, planned_ms);
        let performance = ratio(ideal_ms, run_ms);
        let quality = ratio(parts - rejects, parts);
        Figures {
            planned_ms,
            run_ms,
            ideal_ms,
            parts,
            rejects,
            availability,
            performance,
            quality,
            oee: availability
                .zip(performance)
                .zip(quality)
                .map(|((a, p), q)| a * p * q),
            ..Figures::default()
        }
    }

    fn metric<'a>(p: &'a Payload, name: &str) -> &'a crate::sinks::sparkplug::tahu::Metric {
        p.metrics
            .iter()
            .find(|m| m.name.as_deref() == Some(name))
            .unwrap()
    }

    /// The names of the metrics the waiting changes are of, and the
    /// changes taken.
    fn sent(b: &mut MetricBook) -> Vec<String> {
        b.take_changes(usize::MAX)
            .into_iter()
            .map(|c| b.entries[c.entry].name.clone())
            .collect()
    }

    #[test]
    fn the_birth_declares_the_oee_metrics_null_until_the_first_tick() {
        let mut b = book();
        let (dbirth, _) = b.device_birth(1, 1000);
        let oee: Vec<(&str, u32, Option<bool>)> = dbirth
            .metrics
            .iter()
            .filter(|m| m.name.as_deref().is_some_and(|n| n.starts_with("OEE/")))
            .map(|m| (m.name.as_deref().unwrap(), m.datatype.unwrap(), m.is_null))
            .collect();
        let (string, double, count) = (
            DataType::String as u32,
            DataType::Double as u32,
            DataType::UInt64 as u32,
        );
        assert_eq!(
            oee,
            [
                ("OEE/Shift", string, Some(true)),
                ("OEE/Availability", double, Some(true)),
                ("OEE/Performance", double, Some(true)),
                ("OEE/Quality", double, Some(true)),
                ("OEE/OEE", double, Some(true)),
                ("OEE/Parts", count, Some(true)),
                ("OEE/Rejects", count, Some(true)),
                ("OEE/Planned Time", count, Some(true)),
                ("OEE/Run Time", count, Some(true)),
            ]
        );
        // Without [oee], none.
        let (plain, _) = MetricBook::new(&[], &[], true, false, 100).device_birth(1, 1000);
        assert_eq!(plain.metrics.len(), 4);
    }

    #[test]
    fn ratios_go_past_a_deadband_times_with_them_or_a_minute_on() {
        let mut b = book();
        let start = 1_000_000;
        // The first tick: every metric known, the ratios of no parts null
        // still.
        assert!(b.oee(&now(start, start + 10_000, figures(10_000, 10_000, 0, 0))));
        assert_eq!(
            sent(&mut b),
            [
                "OEE/Shift",
                "OEE/Availability",
                "OEE/Performance",
                "OEE/Parts",
                "OEE/Rejects",
                "OEE/Planned Time",
                "OEE/Run Time",
            ]
        );
        let (dbirth, _) = b.device_birth(1, 2000);
        let quality = metric(&dbirth, "OEE/Quality");
        assert_eq!((quality.is_null, &quality.value), (Some(true), &None));
        // A second on, nothing else: availability stays 1, performance 0;
        // the times moved by less than a minute.
        assert!(!b.oee(&now(start, start + 11_000, figures(11_000, 11_000, 0, 0))));
        assert!(sent(&mut b).is_empty());
        // A minute on: the times alone.
        assert!(b.oee(&now(start, start + 70_000, figures(70_000, 70_000, 0, 0))));
        assert_eq!(sent(&mut b), ["OEE/Planned Time", "OEE/Run Time"]);
        // Idle for a little: availability 70/70.02 moved by less than the
        // deadband.
        assert!(!b.oee(&now(start, start + 70_020, figures(70_020, 70_000, 0, 0))));
        // A part and a reject: the counts, the ratios that moved, and the
        // times of the same moment.
        assert!(b.oee(&now(start, start + 71_000, figures(71_000, 70_000, 2, 1))));
        assert_eq!(
            sent(&mut b),
            [
                "OEE/Availability",
                "OEE/Performance",
                "OEE/Quality",
                "OEE/OEE",
                "OEE/Parts",
                "OEE/Rejects",
                "OEE/Planned Time",
            ],
            "the run time did not change"
        );
        let (dbirth, _) = b.device_birth(2, 3000);
        let value = |name: &str| metric(&dbirth, name).value.clone();
        assert_eq!(value("OEE/Quality"), Some(Value::DoubleValue(0.5)));
        assert_eq!(value("OEE/Parts"), Some(Value::LongValue(2)));
        assert_eq!(value("OEE/Shift"), Some(Value::StringValue("early".into())));
        // The next shift: every metric that differs, even by a little.
        let next = start + 8 * 3_600_000;
        assert!(b.oee(&now(next, next + 1, figures(1, 1, 0, 0))));
        let names = sent(&mut b);
        assert!(names.contains(&"OEE/Planned Time".to_string()), "{names:?}");
        assert!(names.contains(&"OEE/Quality".to_string()), "{names:?}");
    }
}
