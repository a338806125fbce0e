//! Production reports from machine-state history (paper 002, Tables 3–5).
//!
//! A [`DailyReport`] gives, for each hour of one day, the minutes the
//! machine was running, idle, in fault and offline (no data), the day's
//! availability, its stop causes (each stop interval classified by a
//! configured code, paper 002's Table 4) and its production count. A
//! [`MonthlyReport`] gives the same per day. Everything is computed from the
//! history rows and part timestamps given; times are ms since the epoch and
//! day boundaries are passed in, so the caller decides the time zone.
//!
//! Rules:
//! - before the first history row, and after `now`, the state is unknown
//!   and counts as `offline`;
//! - availability = running / (running + idle + fault): the share of the
//!   time the machine could be observed that it was producing;
//! - a stop is a maximal interval of `idle` or `fault` (a change of fault
//!   type starts a new stop); its minutes inside the day count for the day.

use std::collections::BTreeMap;

use serde::Serialize;

const MINUTE: f64 = 60_000.0;
const HOUR: u64 = 3_600_000;

/// One row of machine-state history.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StateChange {
    /// When, ms since the epoch.
    pub at: u64,
    /// `running`, `idle`, `fault`, `offline`.
    pub state: String,
    /// For faults: the fault type (`ESE`).
    pub fault_type: Option<String>,
}

/// A change of the work order (paper 002's item code / mould and target).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OrderChange {
    /// When, ms since the epoch.
    pub at: u64,
    /// The item (mould, product) code.
    pub item: Option<String>,
    /// The target quantity.
    pub target: Option<u64>,
}

/// One work order within a report's period: what was made, when, how many.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct OrderSpan {
    /// The item (mould, product) code.
    pub item: Option<String>,
    /// The target quantity.
    pub target: Option<u64>,
    /// From, ms since the epoch (clipped to the period).
    pub from: u64,
    /// Until, ms since the epoch (clipped to the period and to now).
    pub to: u64,
    /// Parts made in that time.
    pub parts: u64,
}

/// One configured stop cause (paper 002, Table 4).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StopCause {
    /// Code (`01`).
    pub code: String,
    /// Name (`front door open`).
    pub name: String,
    /// Matches faults of this type.
    #[serde(default)]
    pub fault_type: Option<String>,
    /// Matches this state (`idle`).
    #[serde(default)]
    pub state: Option<String>,
}

/// The stop-cause table.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StopCauses {
    /// Causes, first match wins.
    #[serde(default, rename = "cause")]
    pub causes: Vec<StopCause>,
}

impl StopCauses {
    /// The cause of a stop in `state` with `fault_type`; unmatched faults
    /// are named by their type with code `--`.
    pub fn classify(&self, state: &str, fault_type: Option<&str>) -> (String, String) {
        let found = self
            .causes
            .iter()
            .find(|c| match (&c.fault_type, &c.state) {
                (Some(t), _) => fault_type == Some(t.as_str()),
                (None, Some(s)) => s == state,
                (None, None) => false,
            });
        match found {
            Some(c) => (c.code.clone(), c.name.clone()),
            None => (
                "--".into(),
                fault_type.map_or_else(|| state.to_string(), |t| format!("fault {t}")),
            ),
        }
    }
}

/// Minutes in each state over some span.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Minutes {
    /// Producing.
    pub running: f64,
    /// Connected, not producing, no fault.
    pub idle: f64,
    /// In fault.
    pub fault: f64,
    /// No connection or no data.
    pub offline: f64,
}

impl Minutes {
    fn add(&mut self, state: &str, minutes: f64) {
        match state {
            "running" => self.running += minutes,
            "idle" => self.idle += minutes,
            "fault" => self.fault += minutes,
            _ => self.offline += minutes,
        }
    }

    /// running / (running + idle + fault) in percent, if anything was observed.
    pub fn availability(&self) -> Option<f64> {
        let observed = self.running + self.idle + self.fault;
        (observed > 0.0).then(|| 100.0 * self.running / observed)
    }
}

/// Stops of one cause.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CauseTotal {
    /// Code.
    pub code: String,
    /// Name.
    pub name: String,
    /// How many stops.
    pub count: u32,
    /// Their minutes within the period.
    pub minutes: f64,
}

/// One day.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DailyReport {
    /// Start of the day, ms since the epoch.
    pub day_start: u64,
    /// Minutes per state for each of the 24 hours.
    pub hours: Vec<Minutes>,
    /// The whole day.
    pub total: Minutes,
    /// Availability in percent.
    pub availability: Option<f64>,
    /// Stop causes, by code.
    pub stop_causes: Vec<CauseTotal>,
    /// Parts produced.
    pub production: u64,
    /// The work orders of the day (item or mould, target), with the parts
    /// made under each.
    pub orders: Vec<OrderSpan>,
}

/// One month, day by day.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MonthlyReport {
    /// The days, first of the month first.
    pub days: Vec<DailyReport>,
    /// The whole month.
    pub total: Minutes,
    /// Availability over the month.
    pub availability: Option<f64>,
    /// Stop causes over the month.
    pub stop_causes: Vec<CauseTotal>,
    /// Parts produced in the month.
    pub production: u64,
}

/// The state intervals `[from, to)` clipped to `[start, end)`, `now` and
/// the history; times outside the history are `offline`.
fn intervals(
    changes: &[StateChange],
    start: u64,
    end: u64,
    now: u64,
) -> Vec<(u64, u64, &str, Option<&str>)> {
    let mut out = Vec::new();
    let horizon = end.min(now.max(start));
    let mut t = start;
    let mut current: (&str, Option<&str>) = ("offline", None);
    for c in changes {
        if c.at <= start {
            current = (c.state.as_str(), c.fault_type.as_deref());
            continue;
        }
        if c.at >= horizon {
            break;
        }
        if c.at > t {
            out.push((t, c.at, current.0, current.1));
        }
        t = c.at;
        current = (c.state.as_str(), c.fault_type.as_deref());
    }
    if t < horizon {
        out.push((t, horizon, current.0, current.1));
    }
    if horizon < end {
        out.push((horizon, end, "offline", None));
    }
    out
}

/// The report of the day `[day_start, day_start + 24 h)`.
///
/// `changes` must be sorted by time; `parts` are the parts made, `(time,
/// how many)`; `orders` the work-order changes, sorted, including the last
/// one before the day.
pub fn daily(
    changes: &[StateChange],
    parts: &[(u64, u64)],
    orders: &[OrderChange],
    day_start: u64,
    causes: &StopCauses,
    now: u64,
) -> DailyReport {
    let day_end = day_start + 24 * HOUR;
    let mut hours = vec![Minutes::default(); 24];
    let mut total = Minutes::default();
    for (from, to, state, _) in intervals(changes, day_start, day_end, now) {
        let mut t = from;
        while t < to {
            let h = ((t - day_start) / HOUR) as usize;
            let slot_end = (day_start + (h as u64 + 1) * HOUR).min(to);
            let m = (slot_end - t) as f64 / MINUTE;
            hours[h].add(state, m);
            total.add(state, m);
            t = slot_end;
        }
    }
    let stop_causes = stops(changes, day_start, day_end, now, causes);
    let production = parts
        .iter()
        .filter(|&&(p, _)| p >= day_start && p < day_end)
        .map(|&(_, n)| n)
        .sum();
    DailyReport {
        day_start,
        availability: total.availability(),
        hours,
        total,
        stop_causes,
        production,
        orders: spans(orders, parts, day_start, day_end.min(now.max(day_start))),
    }
}

/// The orders in force within `[start, end)`, clipped to it, with the parts
/// made under each; the same order repeated (a restart) is one span.
fn spans(orders: &[OrderChange], parts: &[(u64, u64)], start: u64, end: u64) -> Vec<OrderSpan> {
    let mut out: Vec<OrderSpan> = Vec::new();
    for (i, o) in orders.iter().enumerate() {
        let next = orders.get(i + 1).map_or(u64::MAX, |n| n.at);
        let (from, to) = (o.at.max(start), next.min(end));
        if from >= to {
            continue;
        }
        let made: u64 = parts
            .iter()
            .filter(|&&(at, _)| at >= from && at < to)
            .map(|&(_, n)| n)
            .sum();
        match out.last_mut() {
            Some(last) if last.item == o.item && last.target == o.target && last.to == from => {
                last.to = to;
                last.parts += made;
            }
            _ => out.push(OrderSpan {
                item: o.item.clone(),
                target: o.target,
                from,
                to,
                parts: made,
            }),
        }
    }
    out
}

/// Stops within `[start, end)`: counted when they start in it, minutes
/// clipped to it.
fn stops(
    changes: &[StateChange],
    start: u64,
    end: u64,
    now: u64,
    causes: &StopCauses,
) -> Vec<CauseTotal> {
    let mut by_code: BTreeMap<String, CauseTotal> = BTreeMap::new();
    // Walk the whole history so that a stop begun before `start` is one
    // stop, not counted again here.
    let all = intervals(changes, 0, end, now);
    let mut previous: Option<(&str, Option<&str>)> = None;
    for (from, to, state, fault_type) in all {
        let stopped = matches!(state, "idle" | "fault");
        let same_stop = stopped && previous == Some((state, fault_type));
        previous = stopped.then_some((state, fault_type));
        if !stopped {
            continue;
        }
        let (lo, hi) = (from.max(start), to.min(end));
        if lo >= hi && !(from >= start && from < end) {
            continue;
        }
        let (code, name) = causes.classify(state, fault_type);
        let e = by_code.entry(code.clone()).or_insert(CauseTotal {
            code,
            name,
            count: 0,
            minutes: 0.0,
        });
        if !same_stop && from >= start && from < end {
            e.count += 1;
        }
        if hi > lo {
            e.minutes += (hi - lo) as f64 / MINUTE;
        }
    }
    by_code
        .into_values()
        .filter(|c| c.count > 0 || c.minutes > 0.0)
        .collect()
}

/// The report of the days starting at `day_starts` (a month, usually).
pub fn monthly(
    changes: &[StateChange],
    parts: &[(u64, u64)],
    orders: &[OrderChange],
    day_starts: &[u64],
    causes: &StopCauses,
    now: u64,
) -> MonthlyReport {
    let days: Vec<DailyReport> = day_starts
        .iter()
        .map(|&d| daily(changes, parts, orders, d, causes, now))
        .collect();
    let mut total = Minutes::default();
    let mut merged: BTreeMap<String, CauseTotal> = BTreeMap::new();
    for d in &days {
        total.running += d.total.running;
        total.idle += d.total.idle;
        total.fault += d.total.fault;
        total.offline += d.total.offline;
        for c in &d.stop_causes {
            let e = merged.entry(c.code.clone()).or_insert(CauseTotal {
                code: c.code.clone(),
                name: c.name.clone(),
                count: 0,
                minutes: 0.0,
            });
            e.count += c.count;
            e.minutes += c.minutes;
        }
    }
    MonthlyReport {
        availability: total.availability(),
        production: days.iter().map(|d| d.production).sum(),
        days,
        total,
        stop_causes: merged.into_values().collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MIN: u64 = 60_000;

    fn change(min: u64, state: &str, fault: Option<&str>) -> StateChange {
        StateChange {
            at: min * MIN,
            state: state.into(),
            fault_type: fault.map(str::to_string),
        }
    }

    fn causes() -> StopCauses {
        StopCauses {
            causes: vec![
                StopCause {
                    code: "03".into(),
                    name: "mould-clamp abnormal".into(),
                    fault_type: Some("CLAMP".into()),
                    state: None,
                },
                StopCause {
                    code: "05".into(),
                    name: "stopped".into(),
                    fault_type: None,
                    state: Some("idle".into()),
                },
            ],
        }
    }

    #[test]
    fn minutes_per_hour_availability_and_stops() {
        // 00:00 running; 00:50-01:10 fault CLAMP; 01:10 running; 02:00-02:30 idle;
        // 02:30 running; 03:00 offline (agent stopped) for the rest of the day.
        let h = vec![
            change(0, "running", None),
            change(50, "fault", Some("CLAMP")),
            change(70, "running", None),
            change(120, "idle", None),
            change(150, "running", None),
            change(180, "offline", None),
        ];
        let parts = [
            (5 * MIN, 1),
            (30 * MIN, 1),
            (75 * MIN, 1),
            (25 * 60 * MIN, 1),
        ];
        let r = daily(&h, &parts, &[], 0, &causes(), 48 * 60 * MIN);
        assert_eq!(
            r.hours[0],
            Minutes {
                running: 50.0,
                idle: 0.0,
                fault: 10.0,
                offline: 0.0
            }
        );
        assert_eq!(
            r.hours[1],
            Minutes {
                running: 50.0,
                idle: 0.0,
                fault: 10.0,
                offline: 0.0
            }
        );
        assert_eq!(
            r.hours[2],
            Minutes {
                running: 30.0,
                idle: 30.0,
                fault: 0.0,
                offline: 0.0
            }
        );
        assert_eq!(r.hours[3].offline, 60.0);
        assert_eq!(
            r.total,
            Minutes {
                running: 130.0,
                idle: 30.0,
                fault: 20.0,
                offline: 21.0 * 60.0
            }
        );
        let a = r.availability.unwrap();
        assert!((a - 100.0 * 130.0 / 180.0).abs() < 1e-9);
        assert_eq!(
            r.stop_causes,
            vec![
                CauseTotal {
                    code: "03".into(),
                    name: "mould-clamp abnormal".into(),
                    count: 1,
                    minutes: 20.0
                },
                CauseTotal {
                    code: "05".into(),
                    name: "stopped".into(),
                    count: 1,
                    minutes: 30.0
                },
            ]
        );
        assert_eq!(r.production, 3);
    }

    #[test]
    fn a_stop_across_midnight_counts_once_and_splits_its_minutes() {
        let day = 24 * 60;
        let h = vec![
            change(0, "running", None),
            change(day - 10, "fault", Some("ESE")),
            change(day + 20, "running", None),
        ];
        let m = monthly(&h, &[], &[], &[0, day * MIN], &causes(), 3 * day * MIN);
        assert_eq!(
            m.days[0].stop_causes,
            vec![CauseTotal {
                code: "--".into(),
                name: "fault ESE".into(),
                count: 1,
                minutes: 10.0
            }]
        );
        assert_eq!(
            m.days[1].stop_causes,
            vec![CauseTotal {
                code: "--".into(),
                name: "fault ESE".into(),
                count: 0,
                minutes: 20.0
            }]
        );
        assert_eq!(m.stop_causes[0].count, 1);
        assert_eq!(m.stop_causes[0].minutes, 30.0);
        assert_eq!(m.total.fault, 30.0);
    }

    #[test]
    fn the_future_and_the_past_before_history_are_offline() {
        let h = vec![change(60, "running", None)];
        let r = daily(&h, &[], &[], 0, &causes(), 120 * MIN);
        assert_eq!(
            r.total,
            Minutes {
                running: 60.0,
                idle: 0.0,
                fault: 0.0,
                offline: 23.0 * 60.0
            }
        );
        assert_eq!(r.availability, Some(100.0));
    }

    #[test]
    fn a_days_orders_are_clipped_to_it_with_the_parts_of_each_and_restarts_merged() {
        let order = |min: u64, item: &str, target: u64| OrderChange {
            at: min * MIN,
            item: Some(item.into()),
            target: Some(target),
        };
        let day = 24 * 60;
        // From yesterday, repeated by a restart at 02:00, a mould change at
        // 10:00, target raised at 12:00.
        let orders = [
            order(day - 60, "A-1", 500),
            order(day + 120, "A-1", 500),
            order(day + 600, "B-2", 300),
            order(day + 720, "B-2", 400),
        ];
        let parts = [
            ((day - 30) * MIN, 9),
            ((day + 60) * MIN, 5),
            ((day + 300) * MIN, 7),
            ((day + 650) * MIN, 4),
            ((day + 800) * MIN, 6),
        ];
        let r = daily(
            &[],
            &parts,
            &orders,
            day * MIN,
            &causes(),
            (day + 900) * MIN,
        );
        let span = |item: &str, target, from: u64, to: u64, parts| OrderSpan {
            item: Some(item.into()),
            target: Some(target),
            from: from * MIN,
            to: to * MIN,
            parts,
        };
        assert_eq!(
            r.orders,
            [
                span("A-1", 500, day, day + 600, 12),
                span("B-2", 300, day + 600, day + 720, 4),
                span("B-2", 400, day + 720, day + 900, 6),
            ]
        );
        assert_eq!(r.production, 22);
    }
}
