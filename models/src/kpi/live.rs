//! The live figures ([`LiveKpis`], for the metrics): raises over the
//! sliding last 10 minutes and the floods they make, over every raise and
//! over first-outs only, chattering and stale alarms now. Bounded: one
//! counter per second of the window and, per alarm, its last three raise
//! times. The figures for a period are `report.rs`'s.

use std::collections::{BTreeSet, HashMap, VecDeque};

use super::{KpiRules, INTERVAL_MS};
use crate::alarm::Transition;

const SECONDS: usize = (INTERVAL_MS / 1000) as usize;

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
    /// Raises suppressed by design (a machine mode): reported apart, in
    /// no other figure (ISA-18.2).
    by_design: Floods,
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
    /// Raises in the last 10 minutes suppressed by design (a machine mode
    /// in which they mean nothing): counted in no other figure.
    pub by_design_last_10m: u64,
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
        self.by_design.advance(now, &self.rules);
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
    /// whether it was raised as the consequence of another, `by_design`
    /// whether a machine mode suppresses it by design (then it counts in
    /// [`KpiSnapshot::by_design_last_10m`] only).
    pub fn on_transition(
        &mut self,
        id: &str,
        transition: Transition,
        (raised_at, active, consequence, by_design): (u64, bool, bool, bool),
        at: u64,
    ) {
        self.advance(at);
        if by_design {
            if transition == Transition::Raised {
                self.by_design.raise(at, &self.rules);
            }
            if let Some(since) = self.active_since.remove(id) {
                self.active.remove(&(since, id.to_string()));
            }
            return;
        }
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
            by_design_last_10m: self.by_design.in_window,
            chattering: self.chattering.len() as u64,
            stale: now
                .checked_sub(self.rules.stale_ms)
                .map_or(0, |raised_before| {
                    self.active.range(..(raised_before, String::new())).count() as u64
                }),
        }
    }
}
