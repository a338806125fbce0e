//! Source timestamps in any order never stop the engine:
//! - the transition-timer monitor fed arbitrary changes at arbitrary times
//!   (backwards, repeated, at both ends of `u64`) never panics, and gives
//!   no verdict (early or normal) on a change earlier than the latest known
//!   value;
//! - the cell engine with timers (and their drift warnings), limits with delays and rates, step supervision and
//!   a delayed alarm, fed arbitrary readings, connection changes and the
//!   passing of time at arbitrary times, never panics, and counts as out of
//!   order exactly the readings (not duplicates) stamped before the latest
//!   one it took.

#![allow(clippy::unwrap_used)] // test helpers fail loudly by design

use cellwatch_models::alarm::Severity;
use cellwatch_models::comments::CommentDb;
use cellwatch_models::engine::{CheckSet, Reading, Tag, TagReading};
use cellwatch_models::limit::{
    Level, LimitCheck, LimitChecks, LimitLevel, RateDirection, RateLevel,
};
use cellwatch_models::signal::Signal;
use cellwatch_models::timer::drift::DriftRules;
use cellwatch_models::timer::learn::{LearnedTransition, SignalEdge, TimerModel};
use cellwatch_models::timer::monitor::{Outcome, TimerMonitor};
use cellwatch_models::value::Num;
use proptest::prelude::*;

mod kit;
use kit::event;

/// Times as they may come: small and close together (so that deadlines
/// fall due), repeated, and at both ends of the range.
fn time() -> impl Strategy<Value = u64> {
    prop_oneof![
        6 => 0..20_000u64,
        1 => Just(0u64),
        1 => Just(u64::MAX),
        1 => (u64::MAX - 20_000)..=u64::MAX,
        1 => any::<u64>(),
    ]
}

/// A window bound: an ordinary one, or the end of the range.
fn bound() -> impl Strategy<Value = u64> {
    prop_oneof![4 => 0..5_000u64, 1 => Just(u64::MAX), 1 => any::<u64>()]
}

/// Two transitions over A, B, C: full-state (+B in A:-B) and common (+C
/// after +A), with windows `w1` and `w2`.
fn model(w1: [u64; 2], w2: [u64; 2]) -> TimerModel {
    let transition = |id, from: &[&str], ev, trigger, window: [u64; 2]| LearnedTransition {
        id,
        from: from.iter().map(|s| s.to_string()).collect(),
        event: ev,
        to: Vec::new(),
        delta_ms: window[0],
        min_ms: window[0],
        max_ms: window[1],
        support: 1,
        window_ms: window,
        from_numbered: None,
        trigger,
    };
    kit::timer_model(
        "full-state",
        &["A", "B", "C"],
        vec![
            transition(1, &["A", "-B"], event("B", SignalEdge::Rise), None, w1),
            transition(
                2,
                &[],
                event("C", SignalEdge::Rise),
                Some(event("A", SignalEdge::Rise)),
                w2,
            ),
        ],
    )
}

fn window() -> impl Strategy<Value = [u64; 2]> {
    (bound(), bound()).prop_map(|(a, b)| [a.min(b), a.max(b)])
}

#[derive(Debug, Clone)]
enum MonitorOp {
    Set(usize, Option<bool>, u64),
    Advance(u64),
}

fn monitor_op() -> impl Strategy<Value = MonitorOp> {
    prop_oneof![
        4 => (0..3usize, prop::option::weighted(0.9, any::<bool>()), time())
            .prop_map(|(s, v, t)| MonitorOp::Set(s, v, t)),
        1 => time().prop_map(MonitorOp::Advance),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn the_timer_monitor_takes_any_times(
        w1 in window(),
        w2 in window(),
        ops in prop::collection::vec(monitor_op(), 0..80),
    ) {
        let mut m = TimerMonitor::new(&model(w1, w2)).unwrap();
        let mut latest: Option<u64> = None;
        for op in ops {
            match op {
                MonitorOp::Set(s, v, at) => {
                    let out_of_order = latest.is_some_and(|l| at < l);
                    let outcomes = m.set(s, v, at);
                    for o in &outcomes {
                        match *o {
                            Outcome::Early { at_ms, observed_ms, .. }
                            | Outcome::Normal { at_ms, observed_ms, .. } => {
                                prop_assert!(!out_of_order, "a verdict on a change out of order: {o:?}");
                                prop_assert!(observed_ms <= at_ms);
                            }
                            Outcome::Late { .. } => {}
                        }
                    }
                    if v.is_some() && !out_of_order {
                        latest = Some(at);
                    }
                }
                MonitorOp::Advance(now) => {
                    for o in m.advance(now) {
                        let Outcome::Late { at_ms, .. } = o else {
                            panic!("time passing gave {o:?}");
                        };
                        prop_assert!(at_ms <= now);
                    }
                }
            }
            let _ = m.next_deadline();
        }
    }
}

/// What a reading carries, in the test's terms.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Value {
    Bool(bool),
    Number(f64),
    Bad,
}

impl Value {
    fn reading(self) -> Reading {
        match self {
            Value::Bool(b) => Reading::Good(b),
            Value::Number(n) => Reading::Number(Num::Float(n)),
            Value::Bad => Reading::Bad,
        }
    }
}

#[derive(Debug, Clone)]
enum EngineOp {
    /// One publish: `(tag, value, source time)`, handed in as the cell
    /// loop does (cut after each alarm), at `now`.
    Publish(Vec<(usize, Value, u64)>, u64),
    Advance(u64),
    Connection(bool, u64),
}

fn value() -> impl Strategy<Value = Value> {
    prop_oneof![
        6 => any::<bool>().prop_map(Value::Bool),
        2 => prop_oneof![Just(0.0), Just(50.0), Just(95.0), Just(120.0)].prop_map(Value::Number),
        1 => Just(Value::Bad),
    ]
}

fn engine_op(tags: usize) -> impl Strategy<Value = EngineOp> {
    let reading = (0..tags, value(), time());
    prop_oneof![
        6 => (prop::collection::vec(reading, 1..6), time())
            .prop_map(|(rs, now)| EngineOp::Publish(rs, now)),
        2 => time().prop_map(EngineOp::Advance),
        1 => (any::<bool>(), time()).prop_map(|(up, t)| EngineOp::Connection(up, t)),
    ]
}

/// The robot's charts (step supervision), the timers over A, B, C and
/// limits on TEMP; the tags every check reads.
fn checks(w1: [u64; 2], w2: [u64; 2], delays: (u64, u64)) -> (Vec<Tag>, Vec<Box<dyn CheckSet>>) {
    let sfc = kit::charts(
        "robot.sfc.toml",
        include_str!("../../config/robot/robot.sfc.toml"),
    );
    let sfc = kit::supervision(sfc, CommentDb::default());
    // Drift tracked from the first duration, so that it is judged too.
    let timers = kit::timer_checks("tmr", &model(w1, w2)).drifting(Some(DriftRules {
        min_samples: 1,
        ..DriftRules::default()
    }));
    let level = |level, limit| LimitLevel {
        level,
        limit,
        severity: Severity::High,
    };
    let limits = LimitChecks::new(vec![LimitCheck {
        comment: None,
        id: "temp".into(),
        tag: Signal::new("TEMP"),
        label: String::new(),
        unit: String::new(),
        deadband: 1.0,
        on_delay: delays.0,
        off_delay: delays.1,
        levels: vec![level(Level::H, 90.0), level(Level::HH, 110.0)],
        rates: [RateDirection::Rising, RateDirection::Falling]
            .map(|direction| RateLevel {
                direction,
                rate: 5.0,
                per: 1_000,
                severity: Severity::High,
            })
            .to_vec(),
    }]);
    let mut names: Vec<Signal> = sfc.inputs();
    names.extend(["A", "B", "C", "TEMP"].map(Signal::new));
    names.sort();
    names.dedup();
    (
        kit::tags_as_named(names),
        vec![Box::new(sfc), Box::new(timers), Box::new(limits)],
    )
}

/// The engine's duplicate and time-order rules, kept naively per tag.
#[derive(Default)]
struct Naive {
    connected: Option<bool>,
    values: Vec<Option<Value>>,
    stamps: Vec<Option<u64>>,
    latest: Option<u64>,
    out_of_order: u64,
}

impl Naive {
    fn reading(&mut self, tag: usize, v: Value, at: u64) {
        if let Some(last) = self.stamps[tag] {
            if v != Value::Bad && self.values[tag] == Some(v) && at <= last {
                return;
            }
        }
        match self.latest {
            Some(l) if at < l => self.out_of_order += 1,
            _ => self.latest = Some(at),
        }
        self.stamps[tag] = Some(at);
        self.values[tag] = (v != Value::Bad).then_some(v);
    }

    fn connection(&mut self, up: bool) {
        if self.connected == Some(up) {
            return;
        }
        self.connected = Some(up);
        if !up {
            self.values.iter_mut().for_each(|v| *v = None);
            self.stamps.iter_mut().for_each(|t| *t = None);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn the_engine_takes_any_times_and_counts_what_came_out_of_order(
        w1 in window(),
        w2 in window(),
        delays in (bound(), bound()),
        alarm_delays in (bound(), bound()),
        ops in prop::collection::vec(engine_op(48), 0..60),
    ) {
        let (tags, sets) = checks(w1, w2, delays);
        let n = tags.len();
        let mut e = kit::cell("c", tags, sets).delaying("tmr-001", alarm_delays.0, alarm_delays.1);
        let mut naive = Naive {
            values: vec![None; n],
            stamps: vec![None; n],
            ..Naive::default()
        };
        let mut counted = 0;
        for op in ops {
            match op {
                EngineOp::Publish(rs, now) => {
                    let readings: Vec<TagReading> = rs
                        .iter()
                        .map(|&(tag, v, at)| TagReading {
                            tag: tag % n,
                            reading: v.reading(),
                            source_time: at,
                        })
                        .collect();
                    for &(tag, v, at) in &rs {
                        naive.reading(tag % n, v, at);
                    }
                    let mut rest = &readings[..];
                    while !rest.is_empty() {
                        let (step, used) = e.on_readings_to_alarm(rest, now);
                        counted += step.out_of_order;
                        rest = &rest[used..];
                    }
                }
                EngineOp::Advance(now) => {
                    counted += e.advance(now).out_of_order;
                }
                EngineOp::Connection(up, now) => {
                    naive.connection(up);
                    counted += e.on_connection(up, now).out_of_order;
                }
            }
            let _ = e.next_deadline();
            prop_assert_eq!(counted, naive.out_of_order);
        }
    }
}
