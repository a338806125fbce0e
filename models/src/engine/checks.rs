//! The check interface: what a family of checks reads, and what it finds.
//!
//! A [`CheckSet`] is told about every change of a signal it reads and about
//! the passing of time; it answers with [`Finding`]s (a condition started
//! or ended) and [`Observation`]s (measurements). The engine turns findings
//! into alarm transitions. To add a check kind, implement [`CheckSet`] in
//! its own module (see [`super::switching`] and [`crate::timer::checks`])
//! and hand it to [`super::CellEngine::new`].

use crate::alarm::{Alarm, AlarmKind, Severity};
use crate::explain::Culprit;
use crate::signal::Signal;
use crate::value::{CmpOperand, Comparison, Num};

/// An alarm a check set can raise, known before it ever is (so that it
/// can be taken out of service before its first occurrence).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Declared {
    /// The alarm id.
    pub id: String,
    /// The kind of check.
    pub kind: AlarmKind,
    /// How urgent.
    pub severity: Severity,
    /// The fault type for machine-state history.
    pub fault_type: String,
    /// Whether it stays active until reset.
    pub latched: bool,
}

/// What a check found: its condition started or ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Finding {
    /// The alarm id (the check's id).
    pub id: String,
    /// The kind of check.
    pub kind: AlarmKind,
    /// How urgent.
    pub severity: Severity,
    /// The fault type for machine-state history.
    pub fault_type: String,
    /// Whether the alarm stays active until reset.
    pub latched: bool,
    /// The condition holds.
    pub active: bool,
    /// The step at which the fault formed.
    pub fault_step: Option<usize>,
    /// The contacts responsible.
    pub culprits: Vec<Culprit>,
    /// One line for people.
    pub message: String,
    /// When the condition changed, in source time, if not at the value
    /// being judged (a delay that ran out between two values).
    pub at: Option<u64>,
}

/// A family of checks sharing one view of the signals.
///
/// The engine tells it about every change of a signal it reads, with the
/// value before; `None` means the value is unknown and every check reading it
/// must hold its verdict.
pub trait CheckSet: Send + Sync {
    /// The signals it reads.
    fn inputs(&self) -> Vec<Signal>;

    /// Every alarm it can raise.
    fn alarms(&self) -> Vec<Declared>;

    /// A signal changed value or became unknown (`value` None); `before` is
    /// its last known value.
    fn on_change(
        &mut self,
        signal: &Signal,
        value: Option<bool>,
        before: Option<bool>,
        now: u64,
        out: &mut Vec<Finding>,
    );

    /// A change like [`CheckSet::on_change`] that came out of time order:
    /// its source time was earlier than one the engine had already seen,
    /// and `now` is that latest time instead. A set that measures the time
    /// between changes measures nothing through this one (no verdict on a
    /// time that is not known); others take it as any change.
    fn on_change_out_of_order(
        &mut self,
        signal: &Signal,
        value: Option<bool>,
        before: Option<bool>,
        now: u64,
        out: &mut Vec<Finding>,
    ) {
        self.on_change(signal, value, before, now, out);
    }

    /// The signals it reads as numbers (limit checks).
    fn number_inputs(&self) -> Vec<Signal> {
        Vec::new()
    }

    /// A number it reads changed or became unknown (`None`).
    fn on_number(
        &mut self,
        _signal: &Signal,
        _value: Option<Num>,
        _now: u64,
        _out: &mut Vec<Finding>,
    ) {
    }

    /// Changes of `signals` (`None`: of every signal) may have been lost
    /// for good, for the reason `why`: a verdict a set is waiting out a
    /// delay for was judged across the gap, and is to say so when it
    /// comes (`trigger uncertain`). Default: nothing waits.
    fn on_gap(&mut self, _signals: Option<&[Signal]>, _why: &str) {}

    /// Time passed; timers fire here.
    fn advance(&mut self, _now: u64, _out: &mut Vec<Finding>) {}

    /// The earliest time at which [`CheckSet::advance`] has something to
    /// do, if any: the agent wakes then rather than on a fixed tick.
    fn next_deadline(&self) -> Option<u64> {
        None
    }

    /// An operator reset a latched alarm of this set.
    fn reset(&mut self, _id: &str) {}

    /// `alarm`, one of this set's, was active when the agent stopped and
    /// is back ([`super::CellEngine::restore`]). A set that reports only
    /// changes of its own verdict takes the condition as holding, so that
    /// fresh values saying otherwise clear the alarm; a set that reports
    /// its first verdict anyway has nothing to do.
    fn restored(&mut self, _alarm: &Alarm) {}

    /// Moves the measurements made since the last call into `out`.
    fn take_observations(&mut self, _out: &mut Vec<Observation>) {}

    /// Adds, per alarm it can raise, the signals its check reads and those
    /// its fault holds at their fault value, from which the cell's
    /// consequence relation is derived ([`crate::consequence`]). Default:
    /// nothing (its alarms neither follow from nor cause another).
    fn facts(&self, _out: &mut Vec<crate::consequence::AlarmFacts>) {}

    /// Adds where each tracked transition's recent durations lie in its
    /// window (timer checks with drift tracking on; others add nothing).
    fn window_positions(&self, _out: &mut Vec<WindowPosition>) {}

    /// Adds to `out` the signals alarm `id`'s own check reads (contacts
    /// and numbers, each among [`CheckSet::inputs`] or
    /// [`CheckSet::number_inputs`]); nothing for an alarm not of this set.
    /// The flight recorder keeps their changes around the alarm's raise.
    fn reads(&self, _id: &str, _out: &mut Vec<Signal>) {}

    /// Alarm `id`'s condition in words, for the master alarm database
    /// (`cellwatch mad export`): the switching function, the limit, the
    /// transition's window, the step's supervision time. `None`: not an
    /// alarm of this set.
    fn describe(&self, _id: &str) -> Option<String> {
        None
    }

    /// The signals alarm `id`'s fault holds, each with the value it would
    /// have now without that fault: its coil (or contact) at its normal
    /// value, and each output the program derives from the coil
    /// re-derived with the coil normal, its other contacts at their values
    /// `now` gives (the cell's, whichever set reads them). `None`: not an
    /// alarm of this set, or one whose held signals cannot be taken back.
    fn without(
        &self,
        _id: &str,
        _now: &dyn Fn(&Signal) -> Option<bool>,
    ) -> Option<Vec<(Signal, bool)>> {
        None
    }

    /// Whether alarm `id`'s fault would hold now with the signals of
    /// `instead` at the values given and every other at its own: the
    /// counterfactual a consequence is judged by. For a switching check,
    /// its function; for a transition timer, whether its event would have
    /// come ([`crate::timer::checks`]); for a stuck step, whether what it
    /// waits for would ([`crate::sfc::SfcChecks`]). `None`: not an alarm of
    /// this set, or what it would be is unknown.
    fn would_hold(&self, _id: &str, _instead: &[(Signal, bool)]) -> Option<bool> {
        None
    }

    /// Says fault `f`, found while the first values were coming and held
    /// since (`settling.rs`), again with the values now: its culprits and
    /// what is still unknown. Left as it is when not this set's.
    fn restate(&self, _f: &mut Finding) {}
}

/// Adds `signal` to `out`, and, when it is a comparison contact
/// (`D100 > 5`), the variables it compares after it; each unless `out`
/// has it already.
pub(crate) fn read_with_compared(signal: Signal, out: &mut Vec<Signal>) {
    let compared = Comparison::of_signal(&signal);
    let mut add = |s: Signal| {
        if !out.contains(&s) {
            out.push(s);
        }
    };
    add(signal);
    if let Some(c) = compared {
        add(c.lhs);
        if let CmpOperand::Tag(t) = c.rhs {
            add(t);
        }
    }
}

/// Where a transition's recent durations lie in its learned window.
#[derive(Debug, Clone, PartialEq)]
pub struct WindowPosition {
    /// The transition's alarm id (`line-007`).
    pub check: String,
    /// The moving mean's place: 0 at the learned typical Δt, +1 at the
    /// upper limit (late), −1 at the lower one (early), beyond ±1 outside.
    pub position: f64,
    /// The moving mean of the duration, ms.
    pub mean_ms: f64,
    /// The tracked spread (1.5 × the moving mean difference between
    /// successive durations: for an even jitter, its half-width), ms.
    pub spread_ms: f64,
    /// Durations measured since the agent started.
    pub samples: u64,
}

/// A measurement a check made: a transition's observed duration.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Observation {
    /// Which check or transition (`line-007`).
    pub check: String,
    /// The duration, ms.
    pub ms: u64,
}
