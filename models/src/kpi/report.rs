//! The figures for a period ([`alarm_report`], for `cellwatch report
//! alarms`): per fixed 10-minute interval from the period's start, the
//! rate and the floods, the most frequent, chattering and stale alarms,
//! acknowledgement times, and the standard's benchmark table
//! ([`AlarmReport::benchmarks`]). The live figures are `live.rs`'s.

use std::collections::{BTreeMap, BTreeSet};

use super::{KpiRules, INTERVAL_MS};
use crate::alarm::{Severity, Transition};

/// `ms` for people: `60 s`, `2 min`, `24 h`, `1.5 h`.
fn span(ms: u64) -> String {
    let s = ms as f64 / 1000.0;
    if ms % 3_600_000 == 0 {
        format!("{} h", ms / 3_600_000)
    } else if ms % 60_000 == 0 && ms >= 120_000 {
        format!("{} min", ms / 60_000)
    } else if s >= 3600.0 {
        format!("{:.1} h", s / 3600.0)
    } else {
        format!("{s} s")
    }
}

/// One alarm transition, as the journal keeps it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AlarmEvent {
    /// When, ms.
    pub at: u64,
    /// The alarm.
    pub id: String,
    /// What happened.
    pub transition: Transition,
    /// How urgent.
    pub severity: Severity,
    /// When its occurrence was raised, ms.
    pub raised_at: u64,
    /// Active after the transition.
    pub active: bool,
    /// Raised as the consequence of another active alarm.
    pub consequence: bool,
    /// Suppressed by design (a machine mode) at the transition: in no
    /// figure but [`AlarmReport::by_design`].
    pub by_design: bool,
}

/// One of the most frequent alarms.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Frequent {
    /// The alarm.
    pub id: String,
    /// Raises in the period.
    pub raised: u64,
    /// Its share of all raises, %.
    pub share: f64,
}

/// A chattering alarm: its most raises within the chattering window.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct Chattering {
    /// The alarm.
    pub id: String,
    /// Raises in its busiest chattering window.
    pub raises_in_window: u64,
}

/// An occurrence active longer than the stale threshold in the period.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Stale {
    /// The alarm.
    pub id: String,
    /// When it was raised, ms.
    pub raised_at: u64,
    /// How long it had been active at its end or the period's, hours.
    pub hours: f64,
}

/// Acknowledgement times in a period, seconds.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct AckTimes {
    /// Acknowledgements counted.
    pub count: u64,
    /// Mean, median and longest; `None` with none.
    pub mean: Option<f64>,
    /// The median.
    pub median: Option<f64>,
    /// The longest.
    pub max: Option<f64>,
}

/// The ISA-18.2 benchmark figures of a period.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct AlarmReport {
    /// The period, ms: from, to (the end counted: the period's, or now).
    pub from: u64,
    /// See `from`.
    pub to: u64,
    /// 10-minute intervals in it.
    pub intervals: u64,
    /// Raises in it.
    pub raised: u64,
    /// Raises per 10 minutes, on average.
    pub average_rate: f64,
    /// The most raises in one 10-minute interval.
    pub peak_rate: u64,
    /// Intervals in flood.
    pub flood_intervals: u64,
    /// Those, % of all intervals.
    pub flood_percent: f64,
    /// Raises that were no consequence of another active alarm.
    pub first_outs: u64,
    /// Raises suppressed by design (a machine mode in which they mean
    /// nothing): reported apart, counted in no other figure (ISA-18.2).
    pub by_design: u64,
    /// Intervals in flood counting first-outs only.
    pub first_out_flood_intervals: u64,
    /// Those, % of all intervals.
    pub first_out_flood_percent: f64,
    /// The 10 most frequent alarms, most first.
    pub top: Vec<Frequent>,
    /// Their share of all raises, %.
    pub top_share: f64,
    /// Raises by severity (`low`, `medium`, `high`, `critical`), %.
    pub priorities: BTreeMap<String, f64>,
    /// Alarms that chattered.
    pub chattering: Vec<Chattering>,
    /// Occurrences that were stale.
    pub stale: Vec<Stale>,
    /// Shelves put on, and distinct alarms shelved.
    pub shelved: u64,
    /// See `shelved`.
    pub alarms_shelved: u64,
    /// Alarms taken out of service.
    pub out_of_service: u64,
    /// Acknowledgement times.
    pub ack: AckTimes,
    /// The rules the figures were judged by.
    pub rules: KpiRules,
}

/// The figures of `[from, to)` from `events` (time order); `before` holds
/// each alarm's last event before `from` (what was active then). A period
/// still running ends at `now`. Judged by `rules`.
pub fn alarm_report(
    events: &[AlarmEvent],
    before: &[AlarmEvent],
    from: u64,
    to: u64,
    now: u64,
    rules: &KpiRules,
) -> AlarmReport {
    let end = to.min(now).max(from);
    let intervals = (end - from).div_ceil(INTERVAL_MS).max(1);
    let in_period: Vec<&AlarmEvent> = events
        .iter()
        .filter(|e| e.at >= from && e.at < end)
        .collect();
    let by_design = in_period
        .iter()
        .filter(|e| e.transition == Transition::Raised && e.by_design)
        .count() as u64;
    let in_period: Vec<&AlarmEvent> = in_period.into_iter().filter(|e| !e.by_design).collect();
    let raises: Vec<&AlarmEvent> = in_period
        .iter()
        .copied()
        .filter(|e| e.transition == Transition::Raised)
        .collect();
    let raised = raises.len() as u64;
    let mut per_interval = vec![0u64; intervals as usize];
    let mut first_outs_per_interval = vec![0u64; intervals as usize];
    for e in &raises {
        let i = ((e.at - from) / INTERVAL_MS) as usize;
        per_interval[i] += 1;
        if !e.consequence {
            first_outs_per_interval[i] += 1;
        }
    }
    let floods = |per_interval: &[u64]| {
        let mut flooding = false;
        per_interval
            .iter()
            .filter(|&&n| {
                flooding = n > rules.flood_raises || (flooding && n >= rules.flood_ends_below);
                flooding
            })
            .count() as u64
    };
    let flood_intervals = floods(&per_interval);
    let first_out_flood_intervals = floods(&first_outs_per_interval);
    let share = |n: u64| {
        if raised == 0 {
            0.0
        } else {
            100.0 * n as f64 / raised as f64
        }
    };
    // Most frequent, and chattering, per alarm.
    let mut by_id: BTreeMap<&str, Vec<u64>> = BTreeMap::new();
    let mut by_severity: BTreeMap<String, u64> = Severity::ALL
        .iter()
        .map(|s| (s.as_str().to_string(), 0))
        .collect();
    for e in &raises {
        by_id.entry(&e.id).or_default().push(e.at);
        *by_severity.entry(e.severity.as_str().into()).or_default() += 1;
    }
    let mut top: Vec<Frequent> = by_id
        .iter()
        .map(|(id, times)| Frequent {
            id: id.to_string(),
            raised: times.len() as u64,
            share: share(times.len() as u64),
        })
        .collect();
    top.sort_by(|a, b| b.raised.cmp(&a.raised).then(a.id.cmp(&b.id)));
    top.truncate(10);
    let top_share = share(top.iter().map(|f| f.raised).sum());
    let chattering = by_id
        .iter()
        .filter_map(|(id, times)| {
            // The most raises in any chattering window (two pointers).
            let (mut most, mut first) = (0usize, 0usize);
            for (last, &t) in times.iter().enumerate() {
                while t - times[first] >= rules.chatter_window_ms {
                    first += 1;
                }
                most = most.max(last - first + 1);
            }
            (most >= rules.chatter_raises).then(|| Chattering {
                id: id.to_string(),
                raises_in_window: most as u64,
            })
        })
        .collect();
    // Stale: occurrences active at some moment of the period for longer
    // than the rules allow; those active at its start come from `before`.
    let mut open: BTreeMap<&str, u64> = before
        .iter()
        .filter(|e| e.active)
        .map(|e| (e.id.as_str(), e.raised_at))
        .collect();
    let mut stale = Vec::new();
    let mut note = |id: &str, raised_at: u64, until: u64| {
        let lasted = until.saturating_sub(raised_at);
        if lasted > rules.stale_ms {
            stale.push(Stale {
                id: id.to_string(),
                raised_at,
                hours: lasted as f64 / 3_600_000.0,
            });
        }
    };
    for e in &in_period {
        if e.active {
            open.insert(&e.id, e.raised_at);
        } else if let Some(raised_at) = open.remove(e.id.as_str()) {
            note(&e.id, raised_at, e.at);
        }
    }
    for (id, raised_at) in open {
        note(id, raised_at, end);
    }
    stale.sort_by(|a, b| a.raised_at.cmp(&b.raised_at).then(a.id.cmp(&b.id)));
    let of = |t: Transition| in_period.iter().filter(move |e| e.transition == t);
    let alarms_shelved = of(Transition::Shelved)
        .map(|e| e.id.as_str())
        .collect::<BTreeSet<_>>()
        .len() as u64;
    let mut acks: Vec<f64> = of(Transition::Acknowledged)
        .map(|e| e.at.saturating_sub(e.raised_at) as f64 / 1000.0)
        .collect();
    acks.sort_by(f64::total_cmp);
    let ack = AckTimes {
        count: acks.len() as u64,
        mean: (!acks.is_empty()).then(|| acks.iter().sum::<f64>() / acks.len() as f64),
        median: (!acks.is_empty()).then(|| {
            let n = acks.len();
            if n % 2 == 1 {
                acks[n / 2]
            } else {
                (acks[n / 2 - 1] + acks[n / 2]) / 2.0
            }
        }),
        max: acks.last().copied(),
    };
    AlarmReport {
        from,
        to: end,
        intervals,
        raised,
        average_rate: raised as f64 / intervals as f64,
        peak_rate: per_interval.iter().copied().max().unwrap_or(0),
        flood_intervals,
        flood_percent: 100.0 * flood_intervals as f64 / intervals as f64,
        first_outs: raises.iter().filter(|e| !e.consequence).count() as u64,
        by_design,
        first_out_flood_intervals,
        first_out_flood_percent: 100.0 * first_out_flood_intervals as f64 / intervals as f64,
        top,
        top_share,
        priorities: by_severity
            .into_iter()
            .map(|(s, n)| (s, share(n)))
            .collect(),
        chattering,
        stale,
        shelved: of(Transition::Shelved).count() as u64,
        alarms_shelved,
        out_of_service: of(Transition::OutOfService).count() as u64,
        ack,
        rules: *rules,
    }
}

/// One line of the benchmark table: the figure and the ISA-18.2 target.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Benchmark {
    /// What is measured.
    pub metric: String,
    /// The figure, as text.
    pub value: String,
    /// The target (ISA-18.2 / EEMUA 191), or `-` where the standard sets
    /// none.
    pub target: String,
    /// Whether the target is met; `None` without a target.
    pub met: Option<bool>,
}

impl AlarmReport {
    /// The benchmark table: each figure against its target.
    pub fn benchmarks(&self) -> Vec<Benchmark> {
        let secs = |s: Option<f64>| s.map_or("-".into(), |s| format!("{s:.1} s"));
        let p = |s: &str| self.priorities.get(s).copied().unwrap_or(0.0);
        let r = &self.rules;
        let line = |metric: String, value: String, target: &str, met: Option<bool>| Benchmark {
            metric,
            value,
            target: target.to_string(),
            met,
        };
        vec![
            line(
                "average alarm rate (per 10 min)".into(),
                format!("{:.2}", self.average_rate),
                "<= 1 (2 at most)",
                Some(self.average_rate <= 1.0),
            ),
            line(
                "peak alarm rate (per 10 min)".into(),
                self.peak_rate.to_string(),
                &format!("<= {}", r.flood_raises),
                Some(self.peak_rate <= r.flood_raises),
            ),
            line(
                format!(
                    "10-min intervals in flood (> {}, until < {})",
                    r.flood_raises, r.flood_ends_below
                ),
                format!("{:.2} %", self.flood_percent),
                "< 1 %",
                Some(self.flood_percent < 1.0),
            ),
            line(
                "  the same, first-outs only (consequences left out)".into(),
                format!(
                    "{:.2} % ({} of {} raises first-outs)",
                    self.first_out_flood_percent, self.first_outs, self.raised
                ),
                "-",
                None,
            ),
            line(
                "top 10 alarms' share of all alarms".into(),
                format!("{:.1} %", self.top_share),
                "< 5 %",
                Some(self.top_share < 5.0),
            ),
            line(
                format!(
                    "chattering alarms ({}+ raises in {})",
                    r.chatter_raises,
                    span(r.chatter_window_ms)
                ),
                self.chattering.len().to_string(),
                "0",
                Some(self.chattering.is_empty()),
            ),
            line(
                format!("stale alarms (active > {})", span(r.stale_ms)),
                self.stale.len().to_string(),
                "< 5",
                Some(self.stale.len() < 5),
            ),
            line(
                "priority: low / medium / high / critical".into(),
                format!(
                    "{:.0} / {:.0} / {:.0} / {:.0} %",
                    p("low"),
                    p("medium"),
                    p("high"),
                    p("critical")
                ),
                "~80 / 15 / 5 / < 1 %",
                None,
            ),
            line(
                "shelves (alarms shelved)".into(),
                format!("{} ({})", self.shelved, self.alarms_shelved),
                "-",
                None,
            ),
            line(
                "taken out of service".into(),
                self.out_of_service.to_string(),
                "-",
                None,
            ),
            line(
                "acknowledgement time: mean / median / max".into(),
                format!(
                    "{} / {} / {} ({} acks)",
                    secs(self.ack.mean),
                    secs(self.ack.median),
                    secs(self.ack.max),
                    self.ack.count
                ),
                "-",
                None,
            ),
            line(
                "raises suppressed by design (machine modes; in no figure above)".into(),
                self.by_design.to_string(),
                "-",
                None,
            ),
        ]
    }
}
