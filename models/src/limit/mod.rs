//! Limit alarms on analog values, after ISA-18.2 and OPC UA Part 9: HH, H,
//! L and LL levels, each its own alarm with its own severity; a deadband
//! (hysteresis) so that a value hovering at a limit does not chatter; an
//! on-delay (the excursion must last that long to raise) and an off-delay
//! (the return must last that long to clear).
//!
//! A level raises when the value passes its limit (`>` for HH and H, `<`
//! for L and LL) and clears when it is back by more than the deadband
//! (below `limit - deadband`, above `limit + deadband`). An unknown value
//! holds every level's verdict and cancels pending delays.
//!
//! Rate-of-change levels (`rising`, `falling`) share that lifecycle: the
//! change within a sliding window of the value's samples takes the place
//! of the value ([`rate`]).

use std::collections::{BTreeSet, HashMap};
use std::fmt;

use crate::alarm::{Alarm, AlarmKind, Severity};
use crate::engine::{CheckSet, Declared, Finding};
use crate::signal::Signal;
use crate::value::Num;

mod rate;

use rate::Window;
pub use rate::{RateDirection, RateLevel, MAX_SAMPLES};

/// A limit level.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Level {
    /// High-high.
    HH,
    /// High.
    H,
    /// Low.
    L,
    /// Low-low.
    LL,
}

impl Level {
    /// Upper levels raise above their limit.
    pub fn is_high(self) -> bool {
        matches!(self, Level::HH | Level::H)
    }

    /// The name, `HH`.
    pub fn as_str(self) -> &'static str {
        match self {
            Level::HH => "HH",
            Level::H => "H",
            Level::L => "L",
            Level::LL => "LL",
        }
    }
}

impl fmt::Display for Level {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// One level of a limit check.
#[derive(Debug, Clone, PartialEq)]
pub struct LimitLevel {
    /// Which.
    pub level: Level,
    /// The limit, in the tag's unit.
    pub limit: f64,
    /// The alarm's severity.
    pub severity: Severity,
}

/// A limit check on one numeric tag (`[[checks.limit]]`).
#[derive(Debug, Clone, PartialEq)]
pub struct LimitCheck {
    /// The check's id; each level's alarm is `<id>-hh`, `<id>-h`, ...,
    /// each rate's `<id>-roc-rising`, `<id>-roc-falling`.
    pub id: String,
    /// The tag's address.
    pub tag: Signal,
    /// What the value is, for messages (`spindle temperature`).
    pub label: String,
    /// The tag's comment from the I/O list, ending each message, as a
    /// switching alarm's culprits end with theirs.
    pub comment: Option<String>,
    /// The unit, for messages (`°C`); may be empty.
    pub unit: String,
    /// Hysteresis, in the tag's unit (≥ 0).
    pub deadband: f64,
    /// How long an excursion must last to raise, ms.
    pub on_delay: u64,
    /// How long the return must last to clear, ms.
    pub off_delay: u64,
    /// The levels configured.
    pub levels: Vec<LimitLevel>,
    /// The rate-of-change levels configured (`rising`, `falling`).
    pub rates: Vec<RateLevel>,
}

impl LimitCheck {
    /// The alarm id of one level.
    pub fn alarm_id(&self, level: Level) -> String {
        format!("{}-{}", self.id, level.as_str().to_ascii_lowercase())
    }

    /// The alarm id of one rate level: `<id>-roc-rising`, `<id>-roc-falling`.
    pub fn rate_alarm_id(&self, direction: RateDirection) -> String {
        format!("{}-roc-{}", self.id, direction.as_str())
    }

    /// The fault type of one rate level: `TEMP ROC-RISING`.
    fn rate_fault_type(&self, direction: RateDirection) -> String {
        format!(
            "{} ROC-{}",
            self.tag,
            direction.as_str().to_ascii_uppercase()
        )
    }

    /// The tag and its label, for messages: `TEMP (spindle temperature)`.
    fn what(&self) -> String {
        if self.label.is_empty() {
            self.tag.to_string()
        } else {
            format!("{} ({})", self.tag, self.label)
        }
    }

    /// Every alarm id of the check, value levels first, then rates.
    fn alarm_ids(&self) -> impl Iterator<Item = String> + '_ {
        let levels = self.levels.iter().map(|l| self.alarm_id(l.level));
        let rates = self.rates.iter().map(|r| self.rate_alarm_id(r.direction));
        levels.chain(rates)
    }
}

#[derive(Debug, Clone, Default)]
struct LevelState {
    active: bool,
    /// The condition has wanted the other verdict since then (source
    /// time); waiting out the delay.
    pending_since: Option<u64>,
    /// When the current excursion began (for "for how long").
    excursion_since: Option<u64>,
    /// Why the verdict it waits for was judged across a gap in the
    /// source's delivery, if it was.
    across_gap: Option<String>,
}

/// Every limit check of a cell.
pub struct LimitChecks {
    checks: Vec<LimitCheck>,
    /// Per check, per level: the value levels, then the rate levels.
    states: Vec<Vec<LevelState>>,
    /// Per check: the last known value.
    values: Vec<Option<f64>>,
    /// Per check, per rate level: the samples its change is taken over.
    windows: Vec<Vec<Window>>,
    /// Per check: the source time it was last judged at, from which the
    /// windows' next slides are found.
    judged_at: Vec<u64>,
    by_tag: HashMap<Signal, Vec<usize>>,
    /// Per level's alarm id: its check.
    by_alarm: HashMap<String, usize>,
    /// (when a delay runs out or a window's start passes a sample, check):
    /// checks to evaluate again as time passes. An entry may outlive its
    /// delay (the value went back); it then costs one evaluation that
    /// changes nothing.
    due: BTreeSet<(u64, usize)>,
}

impl LimitChecks {
    /// The checks, all levels normal.
    pub fn new(checks: Vec<LimitCheck>) -> LimitChecks {
        let mut by_tag: HashMap<Signal, Vec<usize>> = HashMap::new();
        for (i, c) in checks.iter().enumerate() {
            by_tag.entry(c.tag.clone()).or_default().push(i);
        }
        let by_alarm = checks
            .iter()
            .enumerate()
            .flat_map(|(i, c)| c.alarm_ids().map(move |id| (id, i)))
            .collect();
        LimitChecks {
            by_alarm,
            states: checks
                .iter()
                .map(|c| vec![LevelState::default(); c.levels.len() + c.rates.len()])
                .collect(),
            values: vec![None; checks.len()],
            windows: checks
                .iter()
                .map(|c| vec![Window::default(); c.rates.len()])
                .collect(),
            judged_at: vec![0; checks.len()],
            checks,
            by_tag,
            due: BTreeSet::new(),
        }
    }

    /// Judges check `i`'s delays that ran out before `now` (the source time of
    /// its next value), each at its own time with the value that held
    /// until then: values sampled over a while and delivered together, late
    /// or republished, raise and clear as they happened. So are the rate
    /// levels as their windows slide past samples.
    fn run_out(&mut self, i: usize, now: u64, out: &mut Vec<Finding>) {
        loop {
            let check = &self.checks[i];
            let delays = self.states[i].iter().filter_map(|s| {
                let since = s.pending_since?;
                // Pending: the level wants the other verdict.
                let delay = if s.active {
                    check.off_delay
                } else {
                    check.on_delay
                };
                Some(since.saturating_add(delay))
            });
            let judged_at = self.judged_at[i];
            let slides = (self.values[i].is_some())
                .then(|| {
                    check
                        .rates
                        .iter()
                        .zip(&self.windows[i])
                        .filter_map(move |(r, w)| w.next_slide(judged_at, r.per))
                })
                .into_iter()
                .flatten();
            let earliest = delays.chain(slides).min();
            match earliest {
                // A delay ending just as the next value comes is judged
                // on that value.
                Some(due) if due < now => {
                    self.due.remove(&(due, i));
                    self.evaluate(i, due, out);
                }
                _ => break,
            }
        }
    }

    /// Moves check `i`'s levels on, at `now`.
    fn evaluate(&mut self, i: usize, now: u64, out: &mut Vec<Finding>) {
        self.judged_at[i] = now;
        let Some(value) = self.values[i] else {
            for s in &mut self.states[i] {
                s.pending_since = None;
            }
            return;
        };
        let check = &self.checks[i];
        let n = check.levels.len();
        // The windows' next slides: a rate may change with no new value.
        for (r, w) in check.rates.iter().zip(&self.windows[i]) {
            if let Some(at) = w.next_slide(now, r.per) {
                self.due.insert((at, i));
            }
        }
        for l in 0..n + check.rates.len() {
            let s = &mut self.states[i][l];
            // The rate levels judge the change within their window.
            let (beyond, back, change) = match check.levels.get(l) {
                Some(level) if level.level.is_high() => (
                    value > level.limit,
                    value < level.limit - check.deadband,
                    0.0,
                ),
                Some(level) => (
                    value < level.limit,
                    value > level.limit + check.deadband,
                    0.0,
                ),
                None => {
                    let rate = &check.rates[l - n];
                    let change = self.windows[i][l - n].change(now, rate.per).unwrap_or(0.0);
                    let (beyond, back) = rate.judge(change, check.deadband);
                    (beyond, back, change)
                }
            };
            if beyond && s.excursion_since.is_none() {
                s.excursion_since = Some(now);
            }
            let wants = if s.active { !back } else { beyond };
            if wants == s.active {
                s.pending_since = None;
                s.across_gap = None;
                if !s.active && !beyond {
                    s.excursion_since = None;
                }
                continue;
            }
            let since = *s.pending_since.get_or_insert(now);
            let delay = if wants {
                check.on_delay
            } else {
                check.off_delay
            };
            // At most the end of time: a delay that runs past it has run
            // out there.
            let due = since.saturating_add(delay);
            if now < due {
                self.due.insert((due, i));
                continue;
            }
            s.active = wants;
            s.pending_since = None;
            let lasted = now.saturating_sub(s.excursion_since.unwrap_or(now));
            if !wants {
                s.excursion_since = None;
            }
            let mut f = match check.levels.get(l) {
                Some(level) => finding(check, level, value, wants, lasted),
                None => {
                    let level = &check.rates[l - n];
                    let named = rate::Named {
                        what: check.what(),
                        unit: &check.unit,
                        comment: check.comment.as_deref(),
                        hysteresis: check.deadband,
                        id: check.rate_alarm_id(level.direction),
                        fault_type: check.rate_fault_type(level.direction),
                    };
                    rate::finding(&named, level, change, wants, lasted)
                }
            };
            // Judged at `now`: the source time its delay ran out, when
            // values sampled over a while came together.
            f.at = Some(now);
            if let Some(why) = s.across_gap.take() {
                f.message = format!("{} (trigger uncertain: {why})", f.message);
            }
            out.push(f);
        }
    }
}

fn finding(
    check: &LimitCheck,
    level: &LimitLevel,
    value: f64,
    active: bool,
    lasted: u64,
) -> Finding {
    let unit = if check.unit.is_empty() {
        String::new()
    } else {
        format!(" {}", check.unit)
    };
    let what = check.what();
    let message = if active {
        format!(
            "{what} = {value}{unit}, {} the {} limit {}{unit} for {:.1} s",
            if level.level.is_high() {
                "above"
            } else {
                "below"
            },
            level.level,
            level.limit,
            lasted as f64 / 1000.0
        )
    } else {
        format!(
            "{what} = {value}{unit}, back within the {} limit {}{unit} (deadband {}) after {:.1} s",
            level.level,
            level.limit,
            check.deadband,
            lasted as f64 / 1000.0
        )
    };
    let message = match &check.comment {
        Some(comment) => format!("{message}: {comment}"),
        None => message,
    };
    Finding {
        at: None,
        id: check.alarm_id(level.level),
        kind: AlarmKind::Limit,
        severity: level.severity,
        fault_type: format!("{} {}", check.tag, level.level),
        latched: false,
        active,
        fault_step: None,
        culprits: Vec::new(),
        message,
    }
}

impl CheckSet for LimitChecks {
    fn inputs(&self) -> Vec<Signal> {
        Vec::new()
    }

    fn alarms(&self) -> Vec<Declared> {
        self.checks
            .iter()
            .flat_map(|c| {
                let levels = c.levels.iter().map(|level| Declared {
                    id: c.alarm_id(level.level),
                    kind: AlarmKind::Limit,
                    severity: level.severity,
                    fault_type: format!("{} {}", c.tag, level.level),
                    latched: false,
                });
                let rates = c.rates.iter().map(|rate| Declared {
                    id: c.rate_alarm_id(rate.direction),
                    kind: AlarmKind::Limit,
                    severity: rate.severity,
                    fault_type: c.rate_fault_type(rate.direction),
                    latched: false,
                });
                levels.chain(rates)
            })
            .collect()
    }

    fn number_inputs(&self) -> Vec<Signal> {
        self.by_tag.keys().cloned().collect()
    }

    /// The tag past the level's limit, the hysteresis and delays.
    fn describe(&self, id: &str) -> Option<String> {
        let c = &self.checks[*self.by_alarm.get(id)?];
        let unit = if c.unit.is_empty() {
            String::new()
        } else {
            format!(" {}", c.unit)
        };
        if let Some(r) = c.rates.iter().find(|r| c.rate_alarm_id(r.direction) == id) {
            let per = r.per as f64 / 1000.0;
            return Some(format!(
                "{} ({}) {} by more than {}{unit} within {per} s",
                c.tag,
                c.label,
                match r.direction {
                    RateDirection::Rising => "rises",
                    RateDirection::Falling => "falls",
                },
                r.rate
            ));
        }
        let level = c.levels.iter().find(|l| c.alarm_id(l.level) == id)?;
        let (past, back) = if level.level.is_high() {
            (">", "below")
        } else {
            ("<", "above")
        };
        let mut text = format!(
            "{} ({}) {past} {}{unit} ({})",
            c.tag, c.label, level.limit, level.level
        );
        if c.deadband > 0.0 {
            text += &format!("; clears {back} the limit by {}{unit}", c.deadband);
        }
        Some(text)
    }

    /// The number a level's alarm watches.
    fn reads(&self, id: &str, out: &mut Vec<Signal>) {
        if let Some(&i) = self.by_alarm.get(id) {
            out.push(self.checks[i].tag.clone());
        }
    }

    fn on_change(
        &mut self,
        _signal: &Signal,
        _value: Option<bool>,
        _before: Option<bool>,
        _now: u64,
        _out: &mut Vec<Finding>,
    ) {
    }

    fn on_number(&mut self, signal: &Signal, value: Option<Num>, now: u64, out: &mut Vec<Finding>) {
        // No copy of the check list on this path: one lookup per check.
        let n = self.by_tag.get(signal).map_or(0, Vec::len);
        for k in 0..n {
            let i = self.by_tag[signal][k];
            self.run_out(i, now, out);
            let value = value.map(Num::as_f64);
            self.values[i] = value;
            for (r, w) in self.checks[i].rates.iter().zip(&mut self.windows[i]) {
                match value {
                    Some(v) => w.push(now, v, r.per),
                    None => w.clear(),
                }
            }
            // A slide or delay due now is judged on this value.
            self.due.remove(&(now, i));
            self.evaluate(i, now, out);
        }
    }

    /// A level waiting out its delay across the gap says so when it
    /// raises or clears.
    fn on_gap(&mut self, signals: Option<&[Signal]>, why: &str) {
        let checks: Vec<usize> = match signals {
            None => (0..self.checks.len()).collect(),
            Some(s) => s
                .iter()
                .filter_map(|s| self.by_tag.get(s))
                .flatten()
                .copied()
                .collect(),
        };
        for i in checks {
            for s in &mut self.states[i] {
                if s.pending_since.is_some() {
                    s.across_gap = Some(why.to_string());
                }
            }
        }
    }

    fn advance(&mut self, now: u64, out: &mut Vec<Finding>) {
        while let Some(&(at, i)) = self.due.first() {
            if at > now {
                break;
            }
            self.due.pop_first();
            self.evaluate(i, now, out);
        }
    }

    fn next_deadline(&self) -> Option<u64> {
        self.due.first().map(|&(at, _)| at)
    }

    /// The level is taken as passed since the alarm was raised: the first
    /// value back inside its deadband clears it (a rate level's first
    /// value: its window starts empty).
    fn restored(&mut self, alarm: &Alarm) {
        for (i, check) in self.checks.iter().enumerate() {
            for (l, id) in check.alarm_ids().enumerate() {
                if id == alarm.id {
                    let s = &mut self.states[i][l];
                    s.active = true;
                    s.excursion_since = Some(alarm.raised_at);
                }
            }
        }
    }
}

impl LimitChecks {
    /// The samples all rate windows keep.
    #[cfg(test)]
    fn samples_kept(&self) -> usize {
        self.windows.iter().flatten().map(Window::len).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(deadband: f64, on_delay: u64) -> LimitChecks {
        LimitChecks::new(vec![LimitCheck {
            comment: None,
            id: "temp".into(),
            tag: Signal::new("TEMP"),
            label: "spindle temperature".into(),
            unit: "°C".into(),
            deadband,
            on_delay,
            off_delay: 0,
            levels: vec![
                LimitLevel {
                    level: Level::HH,
                    limit: 95.0,
                    severity: Severity::Critical,
                },
                LimitLevel {
                    level: Level::H,
                    limit: 80.0,
                    severity: Severity::High,
                },
                LimitLevel {
                    level: Level::L,
                    limit: 10.0,
                    severity: Severity::Low,
                },
                LimitLevel {
                    level: Level::LL,
                    limit: 5.0,
                    severity: Severity::Medium,
                },
            ],
            rates: Vec::new(),
        }])
    }

    #[test]
    fn each_level_reads_its_number() {
        let c = check(1.0, 0);
        let reads = |id: &str| {
            let mut out = Vec::new();
            c.reads(id, &mut out);
            out
        };
        for id in ["temp-hh", "temp-h", "temp-l", "temp-ll"] {
            assert_eq!(reads(id), [Signal::new("TEMP")], "{id}");
        }
        for id in ["temp", "temp-x", "other-h"] {
            assert!(reads(id).is_empty(), "{id}");
        }
    }

    fn feed(c: &mut LimitChecks, values: &[(u64, f64)]) -> Vec<(String, bool)> {
        let mut out = Vec::new();
        for &(at, v) in values {
            c.on_number(&Signal::new("TEMP"), Some(Num::Float(v)), at, &mut out);
        }
        out.into_iter().map(|f| (f.id, f.active)).collect()
    }

    #[test]
    fn a_restored_level_clears_on_the_first_value_back_inside() {
        let mut c = check(2.0, 0);
        c.restored(&Alarm::active_since("temp-h", AlarmKind::Limit, 1_000));
        // Still beyond: nothing new (the alarm is already active).
        assert!(feed(&mut c, &[(5_000, 79.0)]).is_empty());
        // Back past the deadband: cleared, the excursion counted from the
        // raise before the restart.
        let mut out = Vec::new();
        c.on_number(
            &Signal::new("TEMP"),
            Some(Num::Float(70.0)),
            9_000,
            &mut out,
        );
        assert_eq!((out[0].id.as_str(), out[0].active), ("temp-h", false));
        assert_eq!(out.len(), 1, "{out:?}");
        assert!(out[0].message.contains("8.0 s"), "{}", out[0].message);
        // Another check's alarm is none of this set's business.
        let mut c = check(2.0, 0);
        c.restored(&Alarm::active_since("pressure-h", AlarmKind::Limit, 1_000));
        assert!(feed(&mut c, &[(5_000, 70.0)]).is_empty());
    }

    #[test]
    fn a_value_hovering_inside_the_deadband_raises_once() {
        let mut c = check(2.0, 0);
        let seen = feed(
            &mut c,
            &[
                (0, 79.0),
                (1, 80.5),
                (2, 79.5),
                (3, 80.2),
                (4, 78.5),
                (5, 81.0),
                (6, 77.9),
            ],
        );
        assert_eq!(seen, [("temp-h".into(), true), ("temp-h".into(), false)]);
    }

    #[test]
    fn every_level_raises_in_turn_with_its_own_alarm() {
        let mut c = check(0.0, 0);
        let seen = feed(&mut c, &[(0, 50.0), (1, 96.0), (2, 50.0), (3, 4.0)]);
        assert_eq!(
            seen,
            [
                ("temp-hh".into(), true),
                ("temp-h".into(), true),
                ("temp-hh".into(), false),
                ("temp-h".into(), false),
                ("temp-l".into(), true),
                ("temp-ll".into(), true),
            ]
        );
    }

    #[test]
    fn the_on_delay_ignores_a_short_excursion_and_raises_a_long_one() {
        let mut c = check(0.0, 2000);
        assert!(feed(&mut c, &[(0, 50.0), (1000, 85.0), (2000, 70.0)]).is_empty());
        let mut out = Vec::new();
        c.advance(10_000, &mut out);
        assert!(out.is_empty(), "a 1 s excursion raises nothing");
        assert_eq!(c.next_deadline(), None);
        assert!(feed(&mut c, &[(20_000, 85.0)]).is_empty());
        assert_eq!(c.next_deadline(), Some(22_000));
        c.advance(21_999, &mut out);
        assert!(out.is_empty());
        c.advance(22_000, &mut out);
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].id, "temp-h");
        assert_eq!(
            out[0].message,
            "TEMP (spindle temperature) = 85 °C, above the H limit 80 °C for 2.0 s"
        );
        assert_eq!(c.next_deadline(), None);
    }

    #[test]
    fn an_unknown_value_holds_the_verdict() {
        let mut c = check(0.0, 0);
        assert_eq!(feed(&mut c, &[(0, 85.0)]), [("temp-h".into(), true)]);
        let mut out = Vec::new();
        c.on_number(&Signal::new("TEMP"), None, 1, &mut out);
        assert!(out.is_empty());
        assert!(feed(&mut c, &[(2, 85.0)]).is_empty());
    }
}
