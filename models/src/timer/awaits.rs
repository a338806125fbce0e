//! What a transition timer's alarm waits for, and whether it would have
//! come without another alarm's fault: the counterfactual by which the
//! alarm is judged a consequence ([`crate::consequence`]).
//!
//! A transition armed by a request A (its trigger, paper 001's `common`
//! method) waits for its event E. Its alarm is late when E has not come.
//! With the signals a cause's fault holds taken back to their values
//! without that fault, E would have come when
//! - E's own signal is one of them, at the value E brings (the fault held
//!   it: a forced output the timer waits for); or
//! - the request A is one of them, standing without the fault where it is
//!   withdrawn now (the fault took the request back, so the motion it
//!   starts was never commanded; E follows its request as learned).
//!
//! Otherwise what did not come is the timer's own: E's signal did not
//! change though nothing the cause holds kept it. An early event would not
//! have come when its signal, held by the fault at the value it came to,
//! is at the other value without it. The transition's start state does not
//! count: a state left disarms the timer, so it never stands in the way.
//! This file owns that judgement; [`super::checks`] asks it.

use super::learn::{Event, LearnedTransition, SignalEdge};
use crate::signal::Signal;

/// What one transition waits for.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Awaited {
    /// Its event's signal and the value the event brings.
    pub event: (Signal, bool),
    /// The request whose edge starts its timer (its signal and the value
    /// it rises or falls to), if one does.
    pub request: Option<(Signal, bool)>,
}

impl Awaited {
    /// What transition `t` waits for, its model signals named by
    /// `signal`; `None` if its event's signal is not there.
    pub fn of(t: &LearnedTransition, signal: impl Fn(&str) -> Option<Signal>) -> Option<Awaited> {
        let at = |e: &Event| Some((signal(&e.tag)?, e.edge == SignalEdge::Rise));
        Some(Awaited {
            event: at(&t.event)?,
            request: t.trigger.as_ref().and_then(at),
        })
    }

    /// Whether the transition's alarm, `late` (else early), would still
    /// hold with the signals of `instead` at the values given and every
    /// other at its value `now`; `None` while the event's signal is
    /// unknown.
    pub fn would_hold(
        &self,
        late: bool,
        instead: &[(Signal, bool)],
        now: impl Fn(&Signal) -> Option<bool>,
    ) -> Option<bool> {
        let without = |s: &Signal| {
            instead
                .iter()
                .find(|(x, _)| x == s)
                .map(|&(_, v)| v)
                .or_else(|| now(s))
        };
        let (event, brings) = (&self.event.0, self.event.1);
        let current = now(event)?;
        if !late {
            return Some(!(current == brings && without(event) == Some(!brings)));
        }
        let would_come = current != brings && without(event) == Some(brings);
        let taken_back = self
            .request
            .as_ref()
            .is_some_and(|(r, v)| now(r) == Some(!*v) && without(r) == Some(*v));
        Some(!(would_come || taken_back))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn awaited() -> Awaited {
        Awaited {
            event: (Signal::new("X1.02"), true),
            request: Some((Signal::new("Y2.00"), true)),
        }
    }

    #[test]
    fn a_late_event_would_have_come_when_the_cause_holds_it_or_takes_its_request_back() {
        let now = |valve: bool, closed: bool| {
            move |s: &Signal| match s.name() {
                "Y2.00" => Some(valve),
                "X1.02" => Some(closed),
                _ => None,
            }
        };
        let a = awaited();
        let held = |s: &str, v: bool| vec![(Signal::new(s), v)];
        // The cause holds the end switch itself.
        assert_eq!(
            a.would_hold(true, &held("X1.02", true), now(true, false)),
            Some(false)
        );
        // The cause dropped the valve that starts the motion.
        assert_eq!(
            a.would_hold(true, &held("Y2.00", true), now(false, false)),
            Some(false)
        );
        // The valve is on, and on without the cause too: the switch is the
        // timer's own.
        assert_eq!(
            a.would_hold(true, &held("Y2.00", true), now(true, false)),
            Some(true)
        );
        // Nothing the timer waits for is held.
        assert_eq!(
            a.would_hold(true, &held("G10.00", false), now(false, false)),
            Some(true)
        );
        // The event's signal unknown: no verdict.
        assert_eq!(a.would_hold(true, &[], |_| None), None);
    }

    #[test]
    fn an_early_event_would_not_have_come_when_the_cause_held_its_signal_there() {
        let a = awaited();
        let closed = |s: &Signal| (s.name() == "X1.02").then_some(true);
        let held = [(Signal::new("X1.02"), false)];
        assert_eq!(a.would_hold(false, &held, closed), Some(false));
        assert_eq!(a.would_hold(false, &[], closed), Some(true));
    }
}
