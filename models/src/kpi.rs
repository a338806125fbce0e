//! Alarm-system performance after ISA-18.2 / IEC 62682 (and EEMUA 191):
//! the figures the standard's benchmark table is written in, live
//! ([`LiveKpis`], for the metrics) and for a period ([`alarm_report`], for
//! `cellwatch report alarms`). One cell is one operator position.
//!
//! Definitions (the same on both sides):
//! - the *alarm rate* counts raises (new occurrences) per 10 minutes;
//! - a *flood* begins with more than [`KpiRules::flood_raises`] raises
//!   within 10 minutes and ends when fewer than
//!   [`KpiRules::flood_ends_below`] are left (ISA-18.2's hysteresis: 10 and
//!   5): live, over the sliding last 10 minutes; in a report, per fixed
//!   10-minute interval from the period's start (an interval after one in
//!   flood stays in flood while it has at least `flood_ends_below` raises);
//! - an alarm *chatters* when it is raised [`KpiRules::chatter_raises`]
//!   times or more within [`KpiRules::chatter_window_ms`];
//! - an occurrence is *stale* once active longer than
//!   [`KpiRules::stale_ms`];
//! - the *acknowledgement time* runs from the raise to the acknowledgement.
//!
//! Everything here is bounded: the live side keeps one counter per second
//! of the window and, per alarm, its last three raise times.

use std::collections::{BTreeMap, BTreeSet, HashMap, VecDeque};

use crate::alarm::{Severity, Transition};

/// The rate window and report interval: 10 minutes, ms.
pub const INTERVAL_MS: u64 = 600_000;
/// More raises than this within [`INTERVAL_MS`] is a flood (ISA-18.2).
pub const FLOOD_RAISES: u64 = 10;
/// A flood ends when fewer raises than this are left within
/// [`INTERVAL_MS`] (ISA-18.2).
pub const FLOOD_ENDS_BELOW: u64 = 5;
/// Raises of one alarm within [`CHATTER_WINDOW_MS`] that make it chatter.
pub const CHATTER_RAISES: usize = 3;
/// See [`CHATTER_RAISES`]: 60 s.
pub const CHATTER_WINDOW_MS: u64 = 60_000;
/// Active longer than this is stale: 24 h.
pub const STALE_MS: u64 = 24 * 3_600_000;

const SECONDS: usize = (INTERVAL_MS / 1000) as usize;

/// The plant's rules the figures are judged by; by default ISA-18.2's
/// example figures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct KpiRules {
    /// More raises than this within 10 minutes begins a flood.
    pub flood_raises: u64,
    /// Fewer raises than this within 10 minutes ends it (at most
    /// `flood_raises + 1`, which is no hysteresis).
    pub flood_ends_below: u64,
    /// Raises of one alarm within `chatter_window_ms` that make it chatter.
    pub chatter_raises: usize,
    /// See `chatter_raises`, ms.
    pub chatter_window_ms: u64,
    /// Active longer than this is stale, ms.
    pub stale_ms: u64,
}

impl Default for KpiRules {
    fn default() -> Self {
        KpiRules {
            flood_raises: FLOOD_RAISES,
            flood_ends_below: FLOOD_ENDS_BELOW,
            chatter_raises: CHATTER_RAISES,
            chatter_window_ms: CHATTER_WINDOW_MS,
            stale_ms: STALE_MS,
        }
    }
}

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

/// Raises over the sliding last 10 minutes, and the floods they make.
#[derive(Debug)]
struct Floods {
    /// Raises per second of the last 10 minutes, by second mod 600.
    per_second: Box<[u32; SECONDS]>,
    /// The second last counted into `per_second`.
    second: Option<u64>,
    /// Raises in the last 10 minutes.
    in_window: u64,
    /// Whether a flood is on (begun, not yet ended).
    in_flood: bool,
    /// Time spent in flood, ms, and up to when it is counted.
    flood_ms: u64,
    counted_to: Option<u64>,
}

impl Default for Floods {
    fn default() -> Self {
        Floods {
            per_second: Box::new([0; SECONDS]),
            second: None,
            in_window: 0,
            in_flood: false,
            flood_ms: 0,
            counted_to: None,
        }
    }
}

impl Floods {
    /// Time passed up to `now`. Time in flood is counted exactly: the
    /// window's count changes only when a second falls out of it.
    fn advance(&mut self, now: u64, rules: &KpiRules) {
        let (Some(mut t), Some(last)) = (self.counted_to, self.second) else {
            self.counted_to = Some(now);
            self.second = Some(now / 1000);
            return;
        };
        if now > t {
            let s = now / 1000;
            for gone in (last + 1)..=s {
                // At the start of second `gone`, the raises of second
                // `gone - 600` fall out of the window.
                let at = gone * 1000;
                if self.in_flood {
                    self.flood_ms += at.saturating_sub(t);
                }
                t = t.max(at);
                let slot = &mut self.per_second[(gone % SECONDS as u64) as usize];
                self.in_window -= u64::from(*slot);
                *slot = 0;
                if self.in_window < rules.flood_ends_below {
                    self.in_flood = false;
                }
                if self.in_window == 0 {
                    // Every slot is empty: nothing more falls out.
                    break;
                }
            }
            if self.in_flood {
                self.flood_ms += now - t;
            }
            self.counted_to = Some(now);
            self.second = Some(s);
        }
    }

    /// One raise at `at` (after [`Floods::advance`] to it).
    fn raise(&mut self, at: u64, rules: &KpiRules) {
        // A raise at a time before the window's newest second counts
        // there (the loop's steps are in time order, to the ms).
        let s = self.second.unwrap_or(at / 1000);
        self.per_second[(s % SECONDS as u64) as usize] += 1;
        self.in_window += 1;
        if self.in_window > rules.flood_raises {
            self.in_flood = true;
        }
    }
}

/// The live figures, updated from alarm transitions and the passing of
/// time (ms since the epoch, passed in).
#[derive(Debug, Default)]
pub struct LiveKpis {
    /// Every raise.
    all: Floods,
    /// Raises that are no consequence of another active alarm.
    first_outs: Floods,
    /// Per alarm: its last raise times (at most `chatter_raises`).
    raises: HashMap<String, VecDeque<u64>>,
    /// Chattering alarms by (until when, id).
    chattering: BTreeSet<(u64, String)>,
    chatter_until: HashMap<String, u64>,
    /// Active occurrences by (raised_at, id).
    active: BTreeSet<(u64, String)>,
    active_since: HashMap<String, u64>,
    rules: KpiRules,
}

/// The live figures at one moment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct KpiSnapshot {
    /// Raises in the last 10 minutes.
    pub raised_last_10m: u64,
    /// Whether that is a flood.
    pub in_flood: bool,
    /// Time spent in flood so far, ms.
    pub flood_ms: u64,
    /// The same three counting only first-outs: raises that are no
    /// consequence of another active alarm.
    pub first_outs_last_10m: u64,
    /// See `first_outs_last_10m`.
    pub first_outs_in_flood: bool,
    /// See `first_outs_last_10m`.
    pub first_outs_flood_ms: u64,
    /// Alarms chattering now.
    pub chattering: u64,
    /// Active occurrences older than 24 h.
    pub stale: u64,
}

impl LiveKpis {
    /// Figures from no alarm at all, by ISA-18.2's rules.
    pub fn new() -> LiveKpis {
        LiveKpis::default()
    }

    /// Figures from no alarm at all, by `rules`.
    pub fn with_rules(rules: KpiRules) -> LiveKpis {
        LiveKpis {
            rules,
            ..LiveKpis::default()
        }
    }

    /// Time passed up to `now`.
    pub fn advance(&mut self, now: u64) {
        self.all.advance(now, &self.rules);
        self.first_outs.advance(now, &self.rules);
        while let Some((until, id)) = self.chattering.first().cloned() {
            if until > now {
                break;
            }
            self.chattering.pop_first();
            self.chatter_until.remove(&id);
        }
    }

    /// Alarm `id` went through `transition` at `at`; `raised_at` is its
    /// occurrence's, `active` whether it is active after it, `consequence`
    /// whether it was raised as the consequence of another.
    pub fn on_transition(
        &mut self,
        id: &str,
        transition: Transition,
        (raised_at, active, consequence): (u64, bool, bool),
        at: u64,
    ) {
        self.advance(at);
        if transition == Transition::Raised {
            self.all.raise(at, &self.rules);
            if !consequence {
                self.first_outs.raise(at, &self.rules);
            }
            let chatter = self.rules.chatter_raises;
            let times = self.raises.entry(id.to_string()).or_default();
            times.push_back(at);
            if times.len() > chatter {
                times.pop_front();
            }
            if times.len() == chatter {
                let until = times[0] + self.rules.chatter_window_ms;
                if until > at {
                    if let Some(old) = self.chatter_until.insert(id.to_string(), until) {
                        self.chattering.remove(&(old, id.to_string()));
                    }
                    self.chattering.insert((until, id.to_string()));
                }
            }
        }
        if let Some(since) = self.active_since.remove(id) {
            self.active.remove(&(since, id.to_string()));
        }
        if active {
            self.active_since.insert(id.to_string(), raised_at);
            self.active.insert((raised_at, id.to_string()));
        }
    }

    /// The figures at `now` (after [`LiveKpis::advance`] to it).
    pub fn snapshot(&self, now: u64) -> KpiSnapshot {
        KpiSnapshot {
            raised_last_10m: self.all.in_window,
            in_flood: self.all.in_flood,
            flood_ms: self.all.flood_ms,
            first_outs_last_10m: self.first_outs.in_window,
            first_outs_in_flood: self.first_outs.in_flood,
            first_outs_flood_ms: self.first_outs.flood_ms,
            chattering: self.chattering.len() as u64,
            stale: now
                .checked_sub(self.rules.stale_ms)
                .map_or(0, |raised_before| {
                    self.active.range(..(raised_before, String::new())).count() as u64
                }),
        }
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
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MIN: u64 = 60_000;

    #[test]
    fn the_live_window_forgets_what_is_older_than_10_minutes() {
        let mut k = LiveKpis::new();
        for i in 0..11 {
            k.on_transition(
                &format!("a{i}"),
                Transition::Raised,
                (i * 1000, false, false),
                i * 1000,
            );
        }
        assert_eq!(k.snapshot(10_000).raised_last_10m, 11);
        assert!(k.snapshot(10_000).in_flood);
        k.advance(10 * MIN - 1);
        assert_eq!(k.snapshot(10 * MIN - 1).raised_last_10m, 11);
        // The first raise (second 0) leaves the window at 600 s: 10 left,
        // still a flood until fewer than 5 are (ISA-18.2), at 606 s.
        k.advance(10 * MIN);
        let s = k.snapshot(10 * MIN);
        assert_eq!((s.raised_last_10m, s.in_flood), (10, true));
        k.advance(10 * MIN + 5_999);
        assert!(k.snapshot(10 * MIN + 5_999).in_flood);
        k.advance(10 * MIN + 6_000);
        let s = k.snapshot(10 * MIN + 6_000);
        assert_eq!((s.raised_last_10m, s.in_flood), (4, false));
        assert_eq!(s.flood_ms, 10 * MIN + 6_000 - 10_000);
        // A long gap empties it.
        k.advance(60 * MIN);
        assert_eq!(k.snapshot(60 * MIN).raised_last_10m, 0);
    }

    #[test]
    fn a_cascade_is_a_flood_of_raises_and_no_flood_of_first_outs() {
        // One emergency stop and ten alarms that follow from it.
        let mut k = LiveKpis::new();
        let mut events = Vec::new();
        for i in 0..11u64 {
            let consequence = i > 0;
            k.on_transition(
                &format!("a{i}"),
                Transition::Raised,
                (i, true, consequence),
                i,
            );
            events.push(AlarmEvent {
                consequence,
                ..ev(i, &format!("a{i}"), Transition::Raised, i, true)
            });
        }
        let s = k.snapshot(11);
        assert_eq!((s.raised_last_10m, s.in_flood), (11, true));
        assert_eq!((s.first_outs_last_10m, s.first_outs_in_flood), (1, false));
        k.advance(MIN);
        let s = k.snapshot(MIN);
        assert_eq!((s.flood_ms, s.first_outs_flood_ms), (MIN - 10, 0));
        let r = alarm_report(
            &events,
            &[],
            0,
            INTERVAL_MS,
            INTERVAL_MS,
            &KpiRules::default(),
        );
        assert_eq!((r.raised, r.flood_intervals), (11, 1));
        assert_eq!((r.first_outs, r.first_out_flood_intervals), (1, 0));
        let line = r
            .benchmarks()
            .into_iter()
            .find(|b| b.metric.contains("first-outs only"))
            .unwrap();
        assert_eq!(line.value, "0.00 % (1 of 11 raises first-outs)");
    }

    #[test]
    fn a_plant_sets_its_own_flood_chatter_and_stale_rules() {
        // A flood above 3, ended at once below 4 (no hysteresis); two
        // raises in 5 min chatter; stale after 1 h.
        let rules = KpiRules {
            flood_raises: 3,
            flood_ends_below: 4,
            chatter_raises: 2,
            chatter_window_ms: 5 * MIN,
            stale_ms: 3_600_000,
        };
        let mut k = LiveKpis::with_rules(rules);
        for i in 0..4 {
            k.on_transition("a", Transition::Raised, (i * MIN, i == 3, false), i * MIN);
        }
        let s = k.snapshot(3 * MIN);
        assert_eq!((s.in_flood, s.chattering), (true, 1));
        k.advance(10 * MIN);
        let s = k.snapshot(10 * MIN);
        assert_eq!((s.raised_last_10m, s.in_flood), (3, false));
        assert_eq!(s.flood_ms, 7 * MIN);
        assert_eq!(k.snapshot(3 * MIN + 3_600_001).stale, 1);
        // The report judges by the same rules, and says them.
        let events: Vec<AlarmEvent> = (0..4)
            .map(|i| AlarmEvent {
                at: i * MIN,
                id: "a".into(),
                transition: Transition::Raised,
                severity: Severity::High,
                raised_at: i * MIN,
                active: false,
                consequence: false,
            })
            .collect();
        let r = alarm_report(&events, &[], 0, 20 * MIN, 20 * MIN, &rules);
        assert_eq!(r.flood_intervals, 1);
        assert_eq!(r.chattering[0].raises_in_window, 4);
        let b = r.benchmarks();
        assert_eq!(b[1].target, "<= 3");
        assert_eq!(b[2].metric, "10-min intervals in flood (> 3, until < 4)");
        assert_eq!(b[5].metric, "chattering alarms (2+ raises in 5 min)");
        assert_eq!(b[6].metric, "stale alarms (active > 1 h)");
    }

    #[test]
    fn a_report_interval_after_a_flood_stays_in_flood_until_fewer_than_5() {
        let raise = |at: u64| AlarmEvent {
            at,
            id: format!("a{at}"),
            transition: Transition::Raised,
            severity: Severity::Low,
            raised_at: at,
            active: false,
            consequence: false,
        };
        // 11, 6, 4, 6 raises in four intervals: flood, flood (6 >= 5),
        // over (4 < 5), not again (6 is no more than 10).
        let mut events = Vec::new();
        for (interval, n) in [11u64, 6, 4, 6].into_iter().enumerate() {
            for k in 0..n {
                events.push(raise(interval as u64 * 10 * MIN + k * 1000));
            }
        }
        let r = alarm_report(&events, &[], 0, 40 * MIN, 40 * MIN, &KpiRules::default());
        assert_eq!((r.intervals, r.flood_intervals), (4, 2));
        assert_eq!(
            r.benchmarks()[2].metric,
            "10-min intervals in flood (> 10, until < 5)"
        );
        assert_eq!(r.benchmarks()[6].metric, "stale alarms (active > 24 h)");
        assert_eq!(
            r.benchmarks()[5].metric,
            "chattering alarms (3+ raises in 60 s)"
        );
    }

    #[test]
    fn three_raises_within_a_minute_chatter_until_the_minute_is_over() {
        let mut k = LiveKpis::new();
        for at in [0, 20_000, 50_000] {
            k.on_transition("x", Transition::Raised, (at, true, false), at);
            k.on_transition("x", Transition::Cleared, (at, false, false), at + 1);
        }
        assert_eq!(k.snapshot(50_001).chattering, 1);
        k.advance(59_999);
        assert_eq!(k.snapshot(59_999).chattering, 1);
        k.advance(60_000);
        assert_eq!(k.snapshot(60_000).chattering, 0);
        // Three raises spread over more than a minute: no chatter.
        for at in [100_000, 140_000, 170_000] {
            k.on_transition("y", Transition::Raised, (at, false, false), at);
        }
        assert_eq!(k.snapshot(170_000).chattering, 0);
    }

    #[test]
    fn an_occurrence_is_stale_after_24_hours() {
        let mut k = LiveKpis::new();
        k.on_transition("x", Transition::Raised, (0, true, false), 0);
        k.on_transition("x", Transition::Acknowledged, (0, true, false), 5);
        assert_eq!(k.snapshot(STALE_MS).stale, 0);
        assert_eq!(k.snapshot(STALE_MS + 1).stale, 1);
        k.on_transition("x", Transition::Cleared, (0, false, false), STALE_MS + 2);
        assert_eq!(k.snapshot(STALE_MS + 3).stale, 0);
    }

    fn ev(at: u64, id: &str, transition: Transition, raised_at: u64, active: bool) -> AlarmEvent {
        AlarmEvent {
            consequence: false,
            at,
            id: id.into(),
            transition,
            severity: Severity::High,
            raised_at,
            active,
        }
    }

    #[test]
    fn a_report_counts_acknowledgements_shelves_and_what_was_active_before() {
        use Transition::*;
        let day = 86_400_000;
        let events = [
            ev(day + 1_000, "a", Raised, day + 1_000, true),
            ev(day + 11_000, "a", Acknowledged, day + 1_000, true),
            ev(day + 20_000, "a", Cleared, day + 1_000, false),
            ev(day + 31_000, "a", Raised, day + 31_000, true),
            ev(day + 40_000, "a", Shelved, day + 31_000, true),
            ev(day + 91_000, "a", Acknowledged, day + 31_000, true),
            ev(day + 95_000, "b", OutOfService, day + 95_000, false),
        ];
        // "old" was raised the day before, at 06:00, and never cleared.
        let before = [ev(6 * 3_600_000, "old", Raised, 6 * 3_600_000, true)];
        let r = alarm_report(
            &events,
            &before,
            day,
            2 * day,
            3 * day,
            &KpiRules::default(),
        );
        assert_eq!((r.raised, r.intervals, r.peak_rate), (2, 144, 2));
        assert_eq!(r.ack.count, 2);
        assert_eq!(r.ack.mean, Some(35.0));
        assert_eq!(r.ack.median, Some(35.0));
        assert_eq!(r.ack.max, Some(60.0));
        assert_eq!((r.shelved, r.alarms_shelved, r.out_of_service), (1, 1, 1));
        assert_eq!(r.stale.len(), 1);
        assert_eq!(r.stale[0].id, "old");
        assert!((r.stale[0].hours - 42.0).abs() < 1e-9);
        // "a" is still active at the end, for less than 24 h: not stale.
        // A day still running ends now.
        let r = alarm_report(
            &events,
            &before,
            day,
            2 * day,
            day + 600_001,
            &KpiRules::default(),
        );
        assert_eq!((r.intervals, r.to), (2, day + 600_001));
    }
}
