//! Rate-of-change levels of a limit check (ISA-18.2): `rising` and
//! `falling`, each its own alarm, raised when the value changed by more
//! than `rate` within the last `per`, with the check's hysteresis and
//! delays. This file owns the levels, the window of samples each judges
//! its change over, and their messages; the lifecycle (delays, hysteresis,
//! unknown values) is the check's own ([`super::LimitChecks`]).
//!
//! The change at `now` is the value now minus the value in force at
//! `now - per`: the last sample at or before the window's start is kept
//! for it (or, before the window has filled, the oldest sample). Samples
//! are the tag's values with their source timestamps (a value equal to the
//! one before adds none). A window keeps at most [`MAX_SAMPLES`]: of
//! samples closer than `per / 508` to the one before the newest, only the
//! newest is kept, so the value taken as in force at `now - per` may be one
//! in force up to `per / 508` earlier (0.2 %: 7 s of an hour). An unknown
//! value empties the window: the change is judged again from the first
//! known value after it.

use std::collections::VecDeque;
use std::fmt;

use crate::alarm::{AlarmKind, Severity};
use crate::engine::Finding;

/// The most samples a rate level keeps in its window.
pub const MAX_SAMPLES: usize = 1024;

/// The least time between kept samples of a window of `per` ms (but the
/// newest two): `per / 508`, so that a window holds at most
/// [`MAX_SAMPLES`].
fn gap(per: u64) -> u64 {
    per.div_ceil((MAX_SAMPLES as u64 - 8) / 2)
}

/// Which way a rate level watches the value move.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RateDirection {
    /// The value rising faster than the rate.
    Rising,
    /// The value falling faster than the rate.
    Falling,
}

impl RateDirection {
    /// The name, `rising`.
    pub fn as_str(self) -> &'static str {
        match self {
            RateDirection::Rising => "rising",
            RateDirection::Falling => "falling",
        }
    }

    /// `change` counted in this direction: positive when the value moved
    /// this way.
    fn toward(self, change: f64) -> f64 {
        match self {
            RateDirection::Rising => change,
            RateDirection::Falling => -change,
        }
    }
}

impl fmt::Display for RateDirection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A rate-of-change level of a limit check (`rising = { rate = 5.0, per
/// = "1m" }`).
#[derive(Debug, Clone, PartialEq)]
pub struct RateLevel {
    /// Which way.
    pub direction: RateDirection,
    /// The most the value may change within `per`, in the tag's unit (> 0).
    pub rate: f64,
    /// The window the change is taken over, ms (1 s to 1 h).
    pub per: u64,
    /// The alarm's severity.
    pub severity: Severity,
}

impl RateLevel {
    /// Whether `change` within the window is beyond the rate, and whether
    /// it is back below `rate - hysteresis`.
    pub(super) fn judge(&self, change: f64, hysteresis: f64) -> (bool, bool) {
        let toward = self.direction.toward(change);
        (toward > self.rate, toward < self.rate - hysteresis)
    }
}

/// The samples one rate level judges its change over, oldest first.
#[derive(Debug, Clone, Default)]
pub(super) struct Window {
    /// (source time ms, value); times never fall.
    samples: VecDeque<(u64, f64)>,
}

impl Window {
    /// Takes a known value at source time `at`, and forgets what a window
    /// of `per` ms no longer needs. A value stamped at or before the
    /// newest replaces the newest's value (time never falls).
    pub(super) fn push(&mut self, at: u64, value: f64, per: u64) {
        if let Some(&(last, v)) = self.samples.back() {
            if v == value {
                // The value in force is the same: nothing to keep.
                return;
            }
            if at <= last {
                self.samples.pop_back();
                self.samples.push_back((last, value));
                return;
            }
        }
        // The newest replaces a newest that came less than `gap` after
        // the sample before it: any two samples but the newest two lie at
        // least `gap` apart.
        let n = self.samples.len();
        if n >= 2 && at - self.samples[n - 2].0 < gap(per) {
            self.samples.pop_back();
        }
        self.samples.push_back((at, value));
        // Keep one sample at or before the window's start.
        let start = at.saturating_sub(per);
        while self.samples.len() > 1 && self.samples[1].0 <= start {
            self.samples.pop_front();
        }
        while self.samples.len() > MAX_SAMPLES {
            self.samples.pop_front();
        }
    }

    /// Forgets every sample (the value became unknown).
    pub(super) fn clear(&mut self) {
        self.samples.clear();
    }

    /// How many samples it keeps.
    #[cfg(test)]
    pub(super) fn len(&self) -> usize {
        self.samples.len()
    }

    /// The index of the sample in force at `now - per` (the oldest, before
    /// the window has filled).
    fn reference(&self, now: u64, per: u64) -> usize {
        let start = now.saturating_sub(per);
        self.samples
            .partition_point(|&(t, _)| t <= start)
            .saturating_sub(1)
    }

    /// The change within `per` up to `now`: the newest value minus the one
    /// in force at `now - per`. None while it holds no sample.
    pub(super) fn change(&self, now: u64, per: u64) -> Option<f64> {
        let &(_, newest) = self.samples.back()?;
        let (_, old) = self.samples[self.reference(now, per)];
        Some(newest - old)
    }

    /// The next time after `now` at which the window's start passes a
    /// sample, so that the change differs with no new value; None if none
    /// comes before the end of time.
    pub(super) fn next_slide(&self, now: u64, per: u64) -> Option<u64> {
        let next = self.samples.get(self.reference(now, per) + 1)?;
        next.0.checked_add(per).filter(|&at| at > now)
    }
}

/// A duration in words: `1m`, `90s`, `1h`, `1500ms`.
pub(super) fn duration(ms: u64) -> String {
    match ms {
        0 => "0s".to_string(),
        _ if ms % 3_600_000 == 0 => format!("{}h", ms / 3_600_000),
        _ if ms % 60_000 == 0 => format!("{}m", ms / 60_000),
        _ if ms % 1000 == 0 => format!("{}s", ms / 1000),
        _ => format!("{ms}ms"),
    }
}

/// A change for people: to three decimals, without trailing zeros.
fn amount(x: f64) -> f64 {
    (x.abs() * 1000.0).round() / 1000.0
}

/// The check a rate level belongs to, as its alarm names it.
pub(super) struct Named<'a> {
    /// The tag and its label (`TEMP (spindle temperature)`).
    pub(super) what: String,
    /// The unit, for messages; may be empty.
    pub(super) unit: &'a str,
    /// The tag's comment, ending each message.
    pub(super) comment: Option<&'a str>,
    /// The check's hysteresis.
    pub(super) hysteresis: f64,
    /// The level's alarm id and fault type.
    pub(super) id: String,
    pub(super) fault_type: String,
}

/// What a rate level found: the value moved by `change` within its
/// window, beyond the rate (`active`) or back below it.
pub(super) fn finding(
    check: &Named<'_>,
    level: &RateLevel,
    change: f64,
    active: bool,
    lasted: u64,
) -> Finding {
    let unit = if check.unit.is_empty() {
        String::new()
    } else {
        format!(" {}", check.unit)
    };
    let what = &check.what;
    let per = duration(level.per);
    let moved = if change > 0.0 {
        format!("rose {}{unit}", amount(change))
    } else if change < 0.0 {
        format!("fell {}{unit}", amount(change))
    } else {
        "did not change".to_string()
    };
    let message = if active {
        format!(
            "{what} {moved} in {per} (more than {} per {per})",
            level.rate
        )
    } else {
        format!(
            "{what} {moved} in {per}, back within the {} rate {} per {per} (hysteresis {}) after {:.1} s",
            level.direction,
            level.rate,
            check.hysteresis,
            lasted as f64 / 1000.0
        )
    };
    let message = match check.comment {
        Some(comment) => format!("{message}: {comment}"),
        None => message,
    };
    Finding {
        at: None,
        id: check.id.clone(),
        kind: AlarmKind::Limit,
        severity: level.severity,
        fault_type: check.fault_type.clone(),
        latched: false,
        active,
        fault_step: None,
        culprits: Vec::new(),
        message,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::alarm::Alarm;
    use crate::engine::CheckSet;
    use crate::limit::{LimitCheck, LimitChecks, LimitLevel};
    use crate::signal::Signal;
    use crate::value::Num;

    const MIN: u64 = 60_000;

    /// TEMP with `rising` and `falling` at 5 °C per minute, and the H
    /// level at 80 °C.
    fn check(hysteresis: f64, on_delay: u64) -> LimitChecks {
        LimitChecks::new(vec![LimitCheck {
            comment: None,
            id: "temp".into(),
            tag: Signal::new("TEMP"),
            label: String::new(),
            unit: "°C".into(),
            deadband: hysteresis,
            on_delay,
            off_delay: 0,
            levels: vec![LimitLevel {
                level: super::super::Level::H,
                limit: 80.0,
                severity: Severity::High,
            }],
            rates: [RateDirection::Rising, RateDirection::Falling]
                .into_iter()
                .map(|direction| RateLevel {
                    direction,
                    rate: 5.0,
                    per: MIN,
                    severity: Severity::High,
                })
                .collect(),
        }])
    }

    fn feed(c: &mut LimitChecks, values: &[(u64, Option<f64>)]) -> Vec<Finding> {
        let mut out = Vec::new();
        for &(at, v) in values {
            c.on_number(&Signal::new("TEMP"), v.map(Num::Float), at, &mut out);
        }
        out
    }

    fn seen(out: &[Finding]) -> Vec<(String, bool, u64)> {
        out.iter()
            .map(|f| (f.id.clone(), f.active, f.at.unwrap_or(u64::MAX)))
            .collect()
    }

    /// A ramp of `per_minute` °C from 20 °C, a value every 10 s, from
    /// `from` to `to` ms.
    fn ramp(per_minute: f64, from: u64, to: u64) -> Vec<(u64, Option<f64>)> {
        (from..=to)
            .step_by(10_000)
            .map(|t| (t, Some(20.0 + per_minute * (t - from) as f64 / MIN as f64)))
            .collect()
    }

    #[test]
    fn the_alarm_ids_and_messages_name_the_direction() {
        let c = check(0.0, 0);
        let ids: Vec<String> = c.alarms().into_iter().map(|d| d.id).collect();
        assert_eq!(ids, ["temp-h", "temp-roc-rising", "temp-roc-falling"]);
        let mut reads = Vec::new();
        c.reads("temp-roc-falling", &mut reads);
        assert_eq!(reads, [Signal::new("TEMP")]);
        let said = c.describe("temp-roc-rising").unwrap();
        assert!(
            said.starts_with("TEMP (") && said.contains("rises by more than"),
            "{said}"
        );
        assert_eq!(duration(90_000), "90s");
        assert_eq!(duration(3_600_000), "1h");
        assert_eq!(duration(1_500), "1500ms");
    }

    #[test]
    fn a_ramp_faster_than_the_rate_raises_once() {
        let mut c = check(1.0, 0);
        // 6.2 °C per minute for five minutes: beyond 5 from 50 s on, the
        // window not yet full (the change from the first value).
        let out = feed(&mut c, &ramp(6.2, 0, 5 * MIN));
        assert_eq!(seen(&out), [("temp-roc-rising".into(), true, 50_000)]);
        assert_eq!(
            out[0].message,
            "TEMP rose 5.167 °C in 1m (more than 5 per 1m)"
        );
        assert_eq!(out[0].fault_type, "TEMP ROC-RISING");
        assert!(out[0].culprits.is_empty(), "the tag is read as levels are");
        // Falling as fast raises the falling alarm and clears the rising one.
        let down: Vec<_> = (1..=6)
            .map(|k| (5 * MIN + k * 10_000, Some(51.0 - 1.1 * k as f64)))
            .collect();
        let out = feed(&mut c, &down);
        let ids: Vec<_> = seen(&out).into_iter().map(|(id, on, _)| (id, on)).collect();
        assert_eq!(
            ids,
            [
                ("temp-roc-rising".into(), false),
                ("temp-roc-falling".into(), true)
            ]
        );
        assert_eq!(
            out[1].message,
            "TEMP fell 6.6 °C in 1m (more than 5 per 1m)"
        );
        // The message in words, with the label and the comment.
        let mut c = check(0.0, 0);
        c.checks[0].label = "spindle temperature".into();
        c.checks[0].comment = Some("Spindle temperature".into());
        let out = feed(&mut c, &[(0, Some(20.0)), (MIN, Some(26.2))]);
        assert_eq!(
            out[0].message,
            "TEMP (spindle temperature) rose 6.2 °C in 1m (more than 5 per 1m): Spindle temperature"
        );
    }

    #[test]
    fn a_slow_ramp_never_raises() {
        let mut c = check(0.0, 0);
        // 4.9 °C per minute for ten minutes: 49 °C in all, never 5 in one.
        assert!(feed(&mut c, &ramp(4.9, 0, 10 * MIN)).is_empty());
        // The window slides on: judged again when its start passes the
        // next sample, 10 s later.
        assert_eq!(c.next_deadline(), Some(10 * MIN + 10_000));
        let mut out = Vec::new();
        c.advance(20 * MIN, &mut out);
        assert!(out.is_empty());
    }

    #[test]
    fn the_hysteresis_holds_a_rate_hovering_at_the_limit() {
        let mut c = check(2.0, 0);
        // 6 °C per minute, then 4, then 3.5 (still above 5 - 2), then 1.
        let mut values = ramp(6.0, 0, MIN);
        let mut at = MIN;
        let mut value = 26.0;
        for per_minute in [4.0, 3.5, 1.0] {
            for _ in 0..6 {
                at += 10_000;
                value += per_minute / 6.0;
                values.push((at, Some(value)));
            }
        }
        let out = feed(&mut c, &values);
        assert_eq!(
            seen(&out),
            [
                ("temp-roc-rising".into(), true, 60_000),
                // Within the minute up to 200 s: 3.5 * 4 / 6 + 1 * 2 / 6 < 3.
                ("temp-roc-rising".into(), false, 200_000),
            ],
        );
        assert!(
            out[1]
                .message
                .ends_with("back within the rising rate 5 per 1m (hysteresis 2) after 140.0 s"),
            "{}",
            out[1].message
        );
    }

    #[test]
    fn time_passing_with_no_new_value_clears_a_raised_rate() {
        let mut c = check(0.0, 0);
        // A jump of 10 °C at 30 s, then nothing.
        let out = feed(&mut c, &[(0, Some(20.0)), (30_000, Some(30.0))]);
        assert_eq!(seen(&out), [("temp-roc-rising".into(), true, 30_000)]);
        // The window's start passes the jump a minute later.
        assert_eq!(c.next_deadline(), Some(90_000));
        let mut out = Vec::new();
        c.advance(89_999, &mut out);
        assert!(out.is_empty());
        c.advance(90_000, &mut out);
        assert_eq!(seen(&out), [("temp-roc-rising".into(), false, 90_000)]);
        assert_eq!(
            out[0].message,
            "TEMP did not change in 1m, back within the rising rate 5 per 1m (hysteresis 0) after 60.0 s"
        );
        assert_eq!(c.next_deadline(), None);
        // Values delivered together later judge the slide at its own time.
        let mut c = check(0.0, 0);
        let out = feed(
            &mut c,
            &[(0, Some(20.0)), (30_000, Some(30.0)), (200_000, Some(30.5))],
        );
        assert_eq!(
            seen(&out),
            [
                ("temp-roc-rising".into(), true, 30_000),
                ("temp-roc-rising".into(), false, 90_000)
            ]
        );
    }

    #[test]
    fn an_on_delay_holds_a_short_burst() {
        let mut c = check(0.0, 20_000);
        // A jump of 10 °C that the window holds for a minute: raised 20 s
        // after it, when the delay has run out.
        assert!(feed(&mut c, &[(0, Some(20.0)), (30_000, Some(30.0))]).is_empty());
        let mut out = Vec::new();
        c.advance(50_000, &mut out);
        assert_eq!(seen(&out), [("temp-roc-rising".into(), true, 50_000)]);
    }

    #[test]
    fn an_unknown_value_suspends_the_judgement() {
        let mut c = check(0.0, 0);
        let out = feed(&mut c, &[(0, Some(20.0)), (10_000, Some(30.0))]);
        assert_eq!(out.len(), 1);
        // Unknown: the raised alarm holds, no slide clears it meanwhile.
        assert!(feed(&mut c, &[(20_000, None)]).is_empty());
        let mut out = Vec::new();
        c.advance(10 * MIN, &mut out);
        assert!(out.is_empty());
        assert_eq!(c.next_deadline(), None);
        // Known again: judged from the first known value, not across the
        // gap (50 °C would be a rise of 20 from before it).
        let out = feed(
            &mut c,
            &[(10 * MIN, Some(50.0)), (10 * MIN + 1, Some(51.0))],
        );
        assert_eq!(seen(&out), [("temp-roc-rising".into(), false, 10 * MIN)]);
        // A change across the gap raises nothing.
        let mut c = check(0.0, 0);
        let out = feed(
            &mut c,
            &[(0, Some(20.0)), (1_000, None), (2_000, Some(40.0))],
        );
        assert!(out.is_empty(), "{out:?}");
    }

    #[test]
    fn a_restored_rate_clears_on_the_first_value() {
        let mut c = check(0.0, 0);
        c.restored(&Alarm::active_since(
            "temp-roc-rising",
            AlarmKind::Limit,
            1_000,
        ));
        let out = feed(&mut c, &[(5_000, Some(20.0))]);
        assert_eq!(seen(&out), [("temp-roc-rising".into(), false, 5_000)]);
    }

    #[test]
    fn the_window_keeps_at_most_its_cap_of_samples() {
        let mut w = Window::default();
        // A sample every millisecond for two windows of a minute.
        for t in 0..2 * MIN {
            w.push(t, (t % 7) as f64, MIN);
            assert!(w.len() <= MAX_SAMPLES, "{} at {t}", w.len());
        }
        assert!(w.len() > MAX_SAMPLES / 4, "{}", w.len());
        // The change is still taken over about a minute: a ramp of 1 per
        // ms reads close to 60,000.
        let mut w = Window::default();
        for t in 0..3 * MIN {
            w.push(t, t as f64, MIN);
        }
        let change = w.change(3 * MIN - 1, MIN).unwrap();
        let gap = gap(MIN) as f64;
        assert!(
            (MIN as f64..=MIN as f64 + gap).contains(&change),
            "{change}"
        );
        // A value every 10 s keeps the seven the minute needs.
        let mut w = Window::default();
        for t in (0..10 * MIN).step_by(10_000) {
            w.push(t, t as f64, MIN);
        }
        assert_eq!(w.len(), 7);
        // And the checks keep their windows so.
        let mut c = check(0.0, 0);
        let dense: Vec<_> = (0..MIN)
            .step_by(3)
            .map(|t| (t, Some(t as f64 / 1e4)))
            .collect();
        feed(&mut c, &dense);
        assert!(c.samples_kept() <= 2 * MAX_SAMPLES, "{}", c.samples_kept());
    }
}
