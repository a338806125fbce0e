//! Drift of a transition timer: a motion that slows down (or speeds up, or
//! scatters) over days, seen before its window is left.
//!
//! A [`DriftTracker`] follows one transition's measured durations in O(1)
//! memory: an exponentially weighted mean of the duration and of the
//! difference between one duration and the next (no history is kept). The
//! differences measure the jitter whether or not the mean moves: a motion
//! that slows down, gradually or at once, does not read as one that
//! scatters. It places the
//! mean in the learned window as a *position*: 0 at the learned typical Δt,
//! +1 at the upper limit (`hi`, late), −1 at the lower one (`lo`, early).
//! It warns, by [`DriftRules`]:
//! - *slowing* when the position reaches `+fraction`, *speeding up* at
//!   `−fraction`, held until it is back within `fraction / 2`;
//! - *scattering* when the spread (1.5 × the mean difference between
//!   successive durations: for an even jitter, its half-width) reaches
//!   `spread` times the learned one (half the training range), held until
//!   it is back below halfway.
//!
//! Nothing is judged before `min_samples` measurements. This module knows
//! neither alarms nor signals: [`super::checks`] turns its verdicts into
//! the `<id>-<nnn>-drift` warnings.

use std::fmt;

use super::learn::LearnedTransition;

/// When a drift warning is raised; [`DriftRules::default`] is the
/// recommended setting.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriftRules {
    /// How far the tracked mean may move from the learned typical Δt
    /// towards a limit, as a share of that distance, before a warning
    /// (0 < fraction ≤ 1). It clears below half of it.
    pub fraction: f64,
    /// How many times the learned spread the tracked spread may reach
    /// before a warning (> 1). It clears below halfway back.
    pub spread: f64,
    /// Measurements of a transition before it can warn (≥ 1).
    pub min_samples: u32,
    /// The weight of each new measurement in the moving means
    /// (0 < weight ≤ 1): 0.05 follows about the last 40.
    pub weight: f64,
}

impl Default for DriftRules {
    fn default() -> Self {
        DriftRules {
            fraction: 0.5,
            spread: 2.0,
            min_samples: 30,
            weight: 0.05,
        }
    }
}

/// A setting of [`DriftRules`] out of its range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field} must be {need}, not {got}")]
pub struct DriftRuleProblem {
    /// The field of [`DriftRules`]: `fraction`, `spread`, `min_samples`
    /// or `weight`.
    pub field: &'static str,
    /// The range it must be in, for people.
    pub need: &'static str,
    /// The value given.
    pub got: String,
}

impl DriftRules {
    /// Every setting out of its range (none: the rules are usable).
    pub fn problems(&self) -> Vec<DriftRuleProblem> {
        let mut out = Vec::new();
        let mut check = |ok: bool, field, need, got: String| {
            if !ok {
                out.push(DriftRuleProblem { field, need, got });
            }
        };
        let f = self.fraction;
        check(f > 0.0 && f <= 1.0, "fraction", "in (0, 1]", f.to_string());
        let s = self.spread;
        check(s > 1.0 && s.is_finite(), "spread", "above 1", s.to_string());
        check(
            self.min_samples >= 1,
            "min_samples",
            "at least 1",
            self.min_samples.to_string(),
        );
        let w = self.weight;
        check(w > 0.0 && w <= 1.0, "weight", "in (0, 1]", w.to_string());
        out
    }
}

/// Which way the mean has moved.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tendency {
    /// Towards the upper limit (late).
    Slowing,
    /// Towards the lower limit (early).
    SpeedingUp,
}

/// What a new measurement changed in a transition's warning.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DriftChange {
    /// The warning starts.
    Raised,
    /// It goes on for another reason (slowing and now scattering too).
    Updated,
    /// It is over.
    Cleared,
}

/// One transition's recent durations and its warning, in fixed memory.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriftTracker {
    /// The learned typical Δt (inside the window), ms.
    typical: f64,
    lo: f64,
    hi: f64,
    /// Half the training range (at least a tenth of τ), ms.
    learned_spread: f64,
    samples: u64,
    /// Moving mean of the duration, ms.
    mean: f64,
    /// Moving mean of the difference between successive durations, ms.
    step: f64,
    /// The latest duration, ms.
    previous: f64,
    /// When the first and the latest measurement ended, ms.
    since: u64,
    last: u64,
    tendency: Option<Tendency>,
    scattering: bool,
    /// The warning as announced (also when restored with no reason known).
    active: bool,
}

impl DriftTracker {
    /// A tracker for `t`'s window, with nothing measured yet.
    pub fn new(t: &LearnedTransition) -> DriftTracker {
        let [lo, hi] = t.window_ms;
        let typical = t.delta_ms.clamp(lo, hi.max(lo));
        let range = t.max_ms.saturating_sub(t.min_ms) as f64 / 2.0;
        DriftTracker {
            typical: typical as f64,
            lo: lo as f64,
            hi: hi as f64,
            learned_spread: range.max(hi.saturating_sub(lo) as f64 / 20.0).max(1.0),
            samples: 0,
            mean: 0.0,
            step: 0.0,
            previous: 0.0,
            since: 0,
            last: 0,
            tendency: None,
            scattering: false,
            active: false,
        }
    }

    /// Takes a duration of `ms` that ended at `at`, and says whether the
    /// warning changed.
    pub fn measure(&mut self, ms: u64, at: u64, rules: &DriftRules) -> Option<DriftChange> {
        let x = ms as f64;
        self.samples = self.samples.saturating_add(1);
        if self.samples == 1 {
            self.mean = x;
            self.step = 0.0;
            self.since = at;
        } else {
            // A plain mean while there are fewer than 1 / weight: no start
            // value to forget.
            let n = self.samples as f64;
            let w = rules.weight.max(1.0 / n);
            let wd = rules.weight.max(1.0 / (n - 1.0));
            self.step += wd * ((x - self.previous).abs() - self.step);
            self.mean += w * (x - self.mean);
        }
        self.previous = x;
        self.last = self.last.max(at);
        if self.samples < u64::from(rules.min_samples) {
            return None;
        }
        self.judge(rules)
    }

    fn judge(&mut self, rules: &DriftRules) -> Option<DriftChange> {
        let (p, r) = (self.position_now(), self.spread_ratio());
        let f = rules.fraction;
        let tendency = match self.tendency {
            Some(Tendency::Slowing) if p >= f / 2.0 => Some(Tendency::Slowing),
            Some(Tendency::SpeedingUp) if p <= -f / 2.0 => Some(Tendency::SpeedingUp),
            _ if p >= f => Some(Tendency::Slowing),
            _ if p <= -f => Some(Tendency::SpeedingUp),
            _ => None,
        };
        let halfway = (1.0 + rules.spread) / 2.0;
        let scattering = r
            >= if self.scattering {
                halfway
            } else {
                rules.spread
            };
        let reasons = tendency.is_some() || scattering;
        let before = (self.tendency, self.scattering);
        // Restored with no reason known: held while in the hysteresis band.
        let held = self.active && before == (None, false) && (p.abs() >= f / 2.0 || r >= halfway);
        self.tendency = tendency;
        self.scattering = scattering;
        let change = match (self.active, reasons) {
            (false, true) => Some(DriftChange::Raised),
            (true, true) if before != (tendency, scattering) => Some(DriftChange::Updated),
            (true, false) if !held => Some(DriftChange::Cleared),
            _ => None,
        };
        self.active = reasons || held;
        change
    }

    /// The warning was active when the agent stopped: it is taken as
    /// holding, and clears once `min_samples` fresh measurements say so.
    pub fn restored(&mut self) {
        self.active = true;
    }

    /// Whether the warning is active.
    pub fn active(&self) -> bool {
        self.active
    }

    /// Measurements taken.
    pub fn samples(&self) -> u64 {
        self.samples
    }

    /// The moving mean of the duration, ms (`None` before a measurement).
    pub fn mean_ms(&self) -> Option<f64> {
        (self.samples > 0).then_some(self.mean)
    }

    /// The tracked spread (1.5 × the moving mean difference between
    /// successive durations), ms.
    pub fn spread_ms(&self) -> Option<f64> {
        (self.samples > 0).then(|| self.spread_now())
    }

    /// Of durations spread evenly over ±a, two successive ones differ by
    /// 2a/3 on average.
    fn spread_now(&self) -> f64 {
        1.5 * self.step
    }

    /// Where the mean is in the window: 0 at the learned typical Δt, +1 at
    /// the upper limit, −1 at the lower one, beyond ±1 outside (`None`
    /// before a measurement).
    pub fn position(&self) -> Option<f64> {
        (self.samples > 0).then(|| self.position_now())
    }

    fn position_now(&self) -> f64 {
        let d = self.mean - self.typical;
        if d >= 0.0 {
            d / (self.hi - self.typical).max(1.0)
        } else {
            d / (self.typical - self.lo).max(1.0)
        }
    }

    fn spread_ratio(&self) -> f64 {
        self.spread_now() / self.learned_spread
    }

    /// The evidence, for the warning's message: `slowing: mean 4.90 s →
    /// 5.03 s over 2.6 h, limit 5.15 s`, or back to normal.
    pub fn evidence(&self) -> Evidence<'_> {
        Evidence(self)
    }
}

/// A tracker's state in words (see [`DriftTracker::evidence`]).
pub struct Evidence<'a>(&'a DriftTracker);

impl fmt::Display for Evidence<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let t = self.0;
        let over = Span(t.last.saturating_sub(t.since));
        let mut first = true;
        if let Some(tendency) = t.tendency {
            let (what, limit) = match tendency {
                Tendency::Slowing => ("slowing", t.hi),
                Tendency::SpeedingUp => ("speeding up", t.lo),
            };
            write!(
                f,
                "{what}: mean {} → {} over {over}, limit {}",
                Seconds(t.typical),
                Seconds(t.mean),
                Seconds(limit)
            )?;
            first = false;
        }
        if t.scattering {
            if !first {
                f.write_str("; ")?;
            }
            write!(
                f,
                "scattering: spread ±{} → ±{} over {over}, window {}",
                Seconds(t.learned_spread),
                Seconds(t.spread_now()),
                Window(t.lo, t.hi)
            )?;
            first = false;
        }
        if first {
            write!(
                f,
                "back to normal: mean {} (learned {}), spread ±{} (learned ±{}), window {}",
                Seconds(t.mean),
                Seconds(t.typical),
                Seconds(t.spread_now()),
                Seconds(t.learned_spread),
                Window(t.lo, t.hi)
            )?;
        }
        Ok(())
    }
}

/// Milliseconds written as seconds: `4.90 s`.
struct Seconds(f64);

impl fmt::Display for Seconds {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:.2} s", self.0 / 1000.0)
    }
}

/// A window in ms written in seconds: `4.65–5.15 s`.
struct Window(f64, f64);

impl fmt::Display for Window {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:.2}–{:.2} s", self.0 / 1000.0, self.1 / 1000.0)
    }
}

/// A time span in ms, in the unit that reads best: `45 s`, `12 min`,
/// `2.6 h`, `3.1 days`.
struct Span(u64);

impl fmt::Display for Span {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let s = self.0 / 1000;
        let h = self.0 as f64 / 3_600_000.0;
        if s < 120 {
            write!(f, "{s} s")
        } else if s < 7200 {
            write!(f, "{} min", s / 60)
        } else if h < 48.0 {
            write!(f, "{h:.1} h")
        } else {
            write!(f, "{:.1} days", h / 24.0)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::timer::learn::{Event, SignalEdge};
    use crate::timer::line::Rng;

    /// A motion learned at 4.90 s, training 4.80–5.00 s, window 4.65–5.15 s.
    fn tracker() -> DriftTracker {
        DriftTracker::new(&LearnedTransition {
            id: 20,
            from: vec![],
            event: Event {
                tag: "WR2B_DONE".into(),
                edge: SignalEdge::Rise,
            },
            to: vec![],
            delta_ms: 4900,
            min_ms: 4800,
            max_ms: 5000,
            support: 4,
            window_ms: [4650, 5150],
            from_numbered: None,
            trigger: None,
        })
    }

    const MINUTE: u64 = 60_000;

    /// Feeds `ms` `n` times, one a minute from `at`; the changes seen.
    fn feed(
        t: &mut DriftTracker,
        rules: &DriftRules,
        ms: &mut dyn FnMut(u64) -> u64,
        n: u64,
        at: &mut u64,
    ) -> Vec<(u64, DriftChange)> {
        let mut out = Vec::new();
        for i in 0..n {
            *at += MINUTE;
            if let Some(c) = t.measure(ms(i), *at, rules) {
                out.push((i, c));
            }
        }
        out
    }

    #[test]
    fn memory_is_fixed_and_old_durations_are_forgotten() {
        // Copy: it owns no heap, so nothing grows with the measurements.
        fn fixed<T: Copy>() {}
        fixed::<DriftTracker>();
        assert!(std::mem::size_of::<DriftTracker>() <= 128);
        let rules = DriftRules::default();
        let mut t = tracker();
        let mut at = 0;
        feed(&mut t, &rules, &mut |_| 4900, 10_000, &mut at);
        feed(&mut t, &rules, &mut |_| 5000, 200, &mut at);
        // A moving mean: the last 200 count, the 10 000 before do not (a
        // plain mean would be 4902).
        let mean = t.mean_ms().unwrap();
        assert!((mean - 5000.0).abs() < 0.01, "{mean}");
        assert_eq!(t.samples(), 10_200);
    }

    #[test]
    fn nothing_is_judged_before_min_samples() {
        let rules = DriftRules {
            min_samples: 30,
            ..DriftRules::default()
        };
        let mut t = tracker();
        let mut at = 0;
        // Every duration at the limit: a warning, but only at the 30th.
        let changes = feed(&mut t, &rules, &mut |_| 5100, 40, &mut at);
        assert_eq!(changes, [(29, DriftChange::Raised)]);
        assert_eq!(t.position(), Some(0.8));
        assert!(tracker().position().is_none());
    }

    #[test]
    fn warns_at_the_fraction_and_clears_at_half_of_it_without_chatter() {
        // weight 1: the mean is the last duration (the worst case for
        // chatter); the spread out of the way. Trigger at 4.90 + 0.5 ×
        // 0.25 = 5.025 s, clear below 4.9625 s.
        let rules = DriftRules {
            min_samples: 1,
            weight: 1.0,
            spread: 1000.0,
            ..DriftRules::default()
        };
        let mut t = tracker();
        let mut at = 0;
        let steps = [
            4900, 5020, 5030, 5000, 4970, 5030, 4965, 4960, 5000, 5024, 5025,
        ];
        let changes = feed(&mut t, &rules, &mut |i| steps[i as usize], 11, &mut at);
        assert_eq!(
            changes,
            [
                (2, DriftChange::Raised),
                (7, DriftChange::Cleared),
                (10, DriftChange::Raised)
            ]
        );
        // Back and forth across the trigger: one warning, no chatter.
        let mut t = tracker();
        let changes = feed(
            &mut t,
            &rules,
            &mut |i| if i % 2 == 0 { 5030 } else { 4970 },
            100,
            &mut at,
        );
        assert_eq!(changes, [(0, DriftChange::Raised)]);
    }

    #[test]
    fn speeding_up_warns_towards_the_lower_limit() {
        let rules = DriftRules {
            min_samples: 10,
            ..DriftRules::default()
        };
        let mut t = tracker();
        let mut at = 0;
        let changes = feed(&mut t, &rules, &mut |_| 4760, 10, &mut at);
        assert_eq!(changes, [(9, DriftChange::Raised)]);
        assert_eq!(t.position(), Some(-0.56));
        assert_eq!(
            t.evidence().to_string(),
            "speeding up: mean 4.90 s → 4.76 s over 9 min, limit 4.65 s"
        );
    }

    #[test]
    fn a_spread_grown_beyond_the_learned_one_warns() {
        let rules = DriftRules::default();
        let mut t = tracker();
        let mut at = 0;
        // Learned ±0.10 s. An even ±0.10 s now: nothing.
        let mut rng = Rng::new(1);
        let mut even = |_| 4800 + rng.between(0, 200);
        assert!(feed(&mut t, &rules, &mut even, 100, &mut at).is_empty());
        let spread = t.spread_ms().unwrap();
        assert!((spread - 100.0).abs() < 30.0, "{spread}");
        // ±0.25 s, mean unchanged: scattering, and back.
        let mut rng = Rng::new(2);
        let mut wide = |_| 4650 + rng.between(0, 500);
        let changes = feed(&mut t, &rules, &mut wide, 100, &mut at);
        assert_eq!(changes.len(), 1);
        assert_eq!(changes[0].1, DriftChange::Raised);
        assert_eq!(
            t.evidence().to_string(),
            "scattering: spread ±0.10 s → ±0.25 s over 3.3 h, window 4.65–5.15 s"
        );
        let mut rng = Rng::new(3);
        let mut even = |_| 4800 + rng.between(0, 200);
        let changes = feed(&mut t, &rules, &mut even, 100, &mut at);
        assert_eq!(changes.len(), 1);
        assert_eq!(changes[0].1, DriftChange::Cleared);
    }

    #[test]
    fn slowing_then_scattering_updates_the_warning_once() {
        let rules = DriftRules {
            min_samples: 5,
            ..DriftRules::default()
        };
        let mut t = tracker();
        let mut at = 0;
        let changes = feed(&mut t, &rules, &mut |_| 5060, 100, &mut at);
        assert_eq!(changes, [(4, DriftChange::Raised)]);
        let mut rng = Rng::new(4);
        let mut wide = |_| 4810 + rng.between(0, 500);
        let changes = feed(&mut t, &rules, &mut wide, 60, &mut at);
        assert_eq!(changes.len(), 1);
        assert_eq!(changes[0].1, DriftChange::Updated);
        assert_eq!(
            t.evidence().to_string(),
            "slowing: mean 4.90 s → 5.07 s over 2.6 h, limit 5.15 s; \
             scattering: spread ±0.10 s → ±0.24 s over 2.6 h, window 4.65–5.15 s"
        );
    }

    #[test]
    fn a_restored_warning_clears_after_min_samples_of_normal() {
        let rules = DriftRules {
            min_samples: 10,
            ..DriftRules::default()
        };
        let mut t = tracker();
        t.restored();
        assert!(t.active());
        let mut at = 0;
        let changes = feed(&mut t, &rules, &mut |_| 4900, 20, &mut at);
        assert_eq!(changes, [(9, DriftChange::Cleared)]);
        assert_eq!(
            t.evidence().to_string(),
            "back to normal: mean 4.90 s (learned 4.90 s), spread ±0.00 s (learned ±0.10 s), \
             window 4.65–5.15 s"
        );
        // Still slow after the restart: it stays, and says why.
        let mut t = tracker();
        t.restored();
        let changes = feed(&mut t, &rules, &mut |_| 5100, 20, &mut at);
        assert_eq!(changes, [(9, DriftChange::Updated)]);
        assert!(t.active());
    }

    #[test]
    fn rules_out_of_range_are_each_named() {
        assert!(DriftRules::default().problems().is_empty());
        let bad = DriftRules {
            fraction: 1.5,
            spread: 1.0,
            min_samples: 0,
            weight: 0.0,
        };
        let text: Vec<String> = bad.problems().iter().map(|p| p.to_string()).collect();
        assert_eq!(
            text,
            [
                "fraction must be in (0, 1], not 1.5",
                "spread must be above 1, not 1",
                "min_samples must be at least 1, not 0",
                "weight must be in (0, 1], not 0"
            ]
        );
    }

    #[test]
    fn spans_read_in_their_unit() {
        let s = |ms| Span(ms).to_string();
        assert_eq!(s(45_000), "45 s");
        assert_eq!(s(12 * MINUTE), "12 min");
        assert_eq!(s(156 * MINUTE), "2.6 h");
        assert_eq!(s(3 * 24 * 60 * MINUTE), "3.0 days");
    }
}
