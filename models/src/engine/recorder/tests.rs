//! The flight recorder through the engine: the recordings of a switching
//! fault, a limit alarm and a timer alarm, the value at a window's start,
//! and a model test that a recording says what the engine held.

use super::*;
use crate::alarm::{Severity, Transition};
use crate::engine::tag::Value;
use crate::engine::{CellEngine, CheckSet, EngineStep, Reading, StateRules, SwitchingChecks, Tag};
use crate::limit::{Level, LimitCheck, LimitChecks, LimitLevel};
use crate::signal::Signal;
use crate::value::Num;

const NORMAL: &str = include_str!("../../../../config/cnc/ese-normal.values");

pub(super) fn config(before: u64, after: u64) -> RecorderConfig {
    RecorderConfig {
        before,
        after,
        ..RecorderConfig::default()
    }
}

/// The ESE check of paper 000 over its contacts (named in lower case),
/// then a tag no check reads (`M9.00`), then with `limit` a number
/// `TEMP` with a limit check (H above 80), recording by `config`.
fn ese_engine(limit: bool, config: RecorderConfig) -> CellEngine {
    let (mut tags, ese) = crate::engine::fixture::ese();
    tags.push(Tag {
        name: "spare".into(),
        address: Signal::new("M9.00"),
    });
    let mut sets: Vec<Box<dyn CheckSet>> = vec![Box::new(SwitchingChecks::new(vec![ese]))];
    if limit {
        tags.push(Tag {
            name: "spindle temperature".into(),
            address: Signal::new("TEMP"),
        });
        sets.push(Box::new(LimitChecks::new(vec![LimitCheck {
            comment: None,
            id: "temp".into(),
            tag: Signal::new("TEMP"),
            label: "spindle temperature".into(),
            unit: "°C".into(),
            deadband: 1.0,
            on_delay: 0,
            off_delay: 0,
            rates: Vec::new(),
            levels: vec![LimitLevel {
                level: Level::H,
                limit: 80.0,
                severity: Severity::High,
            }],
        }])));
    }
    let mut e = CellEngine::new("m01", tags, sets, StateRules::default())
        .unwrap()
        .recording(config);
    e.on_connection(true, 0);
    e
}

fn load_normal(e: &mut CellEngine, at: u64) {
    for line in NORMAL
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("address"))
    {
        let (a, v) = line.split_once(',').unwrap();
        let t = e.tag_index(&Signal::new(a)).unwrap();
        e.on_reading(t, Reading::Good(v == "1"), at, at);
    }
}

fn set(e: &mut CellEngine, address: &str, reading: Reading, at: u64) -> EngineStep {
    let t = e.tag_index(&Signal::new(address)).unwrap();
    e.on_reading(t, reading, at, at)
}

fn raised(step: &EngineStep) -> Vec<String> {
    step.alarms()
        .filter(|(_, t, _)| *t == Transition::Raised)
        .map(|(a, _, _)| a.id.clone())
        .collect()
}

pub(super) fn bool_changes(s: &RecordedSignal) -> Vec<(u64, Option<bool>)> {
    s.changes
        .iter()
        .map(|(at, v)| match v {
            Some(Sample::Bool(b)) => (*at, Some(*b)),
            None => (*at, None),
            other => panic!("{other:?}"),
        })
        .collect()
}

#[test]
fn an_ese_fault_is_recorded_with_its_contacts_from_before_to_after_the_raise() {
    let mut e = ese_engine(false, config(10_000, 5_000));
    load_normal(&mut e, 1_000);
    // Inside the window, before the raise: R1024.00 (machine ready)
    // drops and comes back, which alone is no fault.
    set(&mut e, "R1024.00", Reading::Good(false), 4_000);
    set(&mut e, "R1024.00", Reading::Good(true), 6_000);
    // A tag no check reads: not kept.
    set(&mut e, "M9.00", Reading::Good(true), 8_000);
    let step = set(&mut e, "X0.06", Reading::Good(false), 12_000);
    assert_eq!(raised(&step), ["ese"]);
    assert!(step.recordings.is_empty());
    assert_eq!(e.next_deadline(), Some(17_001));
    // After the raise, up to its end.
    set(&mut e, "X0.06", Reading::Good(true), 13_000);
    set(&mut e, "R1024.00", Reading::Bad, 15_000);
    assert!(set(&mut e, "R1024.00", Reading::Good(false), 17_000)
        .recordings
        .is_empty());
    // The first change past the end completes it, without that change.
    let step = set(&mut e, "R1024.00", Reading::Good(true), 17_001);
    assert!(!step.is_empty());
    let [r] = &step.recordings[..] else {
        panic!("{:?}", step.recordings)
    };
    assert_eq!(e.next_deadline(), None);
    assert_eq!(
        (r.alarm.as_str(), r.raised_at, r.from, r.to),
        ("ese", 12_000, 2_000, 17_000)
    );
    assert_eq!((r.holds_from, r.holds_to), (2_000, 17_000));
    assert_eq!(r.truncated, Truncated::default());
    // Exactly the ESE's contacts, in the check's order.
    let leaves: Vec<String> = e.tags()[..e.tags().len() - 1]
        .iter()
        .map(|t| t.address.to_string())
        .collect();
    let addresses: Vec<&str> = r.signals.iter().map(|s| s.address.as_str()).collect();
    assert_eq!(addresses, leaves);
    let normal: Vec<(String, bool)> = NORMAL
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("address"))
        .map(|l| {
            let (a, v) = l.split_once(',').unwrap();
            (a.to_string(), v == "1")
        })
        .collect();
    for s in &r.signals {
        assert_eq!(s.name.as_deref(), Some(s.address.to_lowercase().as_str()));
        let v = normal.iter().find(|(a, _)| *a == s.address).unwrap().1;
        assert_eq!(s.start, Some(Sample::Bool(v)), "{}", s.address);
        let expected: Vec<(u64, Option<bool>)> = match s.address.as_str() {
            "R1024.00" => vec![
                (4_000, Some(false)),
                (6_000, Some(true)),
                (15_000, None),
                (17_000, Some(false)),
            ],
            "X0.06" => vec![(12_000, Some(false)), (13_000, Some(true))],
            _ => Vec::new(),
        };
        assert_eq!(bool_changes(s), expected, "{}", s.address);
    }
    // As a timing chart, 500 ms a column, the raise in column 20.
    let chart = r.timeline(30);
    let row = |a: &str| {
        let line = chart.lines().find(|l| l.starts_with(a)).unwrap();
        line.rsplit(' ').next().unwrap().to_string()
    };
    assert_eq!(row("X0.06 "), "▔▔▔▔▔▔▔▔▔▔▔▔▔▔▔▔▔▔▔▔╲▁╱▔▔▔▔▔▔▔");
    assert_eq!(row("R1024.00 "), "▔▔▔▔╲▁▁▁╱▔▔▔▔▔▔▔▔▔▔▔▔▔▔▔▔▔░░░░");
    // The ring holds the 21 contacts' changes, none of the spare tag.
    let fill = e.recorder_fill().unwrap();
    assert_eq!((fill.changes, fill.open), (21 + 7, 0));
}

#[test]
fn the_value_at_the_window_start_comes_from_the_change_that_left_it() {
    let mut e = ese_engine(false, config(3_000, 1_000));
    load_normal(&mut e, 1_000);
    // R1024.00 left its normal value long before the window, then
    // changed inside it: its value at the start is the one before that.
    set(&mut e, "R1024.00", Reading::Good(false), 2_000);
    set(&mut e, "R1024.00", Reading::Good(true), 8_000);
    set(&mut e, "X0.06", Reading::Good(false), 10_000);
    let step = e.advance(11_001);
    let [r] = &step.recordings[..] else {
        panic!("{step:?}")
    };
    assert_eq!((r.from, r.to), (7_000, 11_000));
    let s = r.signals.iter().find(|s| s.address == "R1024.00").unwrap();
    assert_eq!(s.start, Some(Sample::Bool(false)));
    assert_eq!(bool_changes(s), [(8_000, Some(true))]);
    assert_eq!(r.value_at(0, 6_999), None);
    let i = r
        .signals
        .iter()
        .position(|s| s.address == "R1024.00")
        .unwrap();
    assert_eq!(r.value_at(i, 7_999), Some(Some(&Sample::Bool(false))));
    assert_eq!(r.value_at(i, 8_000), Some(Some(&Sample::Bool(true))));
}

/// A PLC whose clock is an hour ahead is not believed: its alarm is
/// stamped by the agent's clock, and so are the changes recorded
/// around it — the recording holds the fault, not an empty window.
#[test]
fn a_plc_clock_not_believed_still_gives_the_fault_its_recording() {
    const AHEAD: u64 = 3_600_000;
    let mut e = ese_engine(false, config(3_000, 1_000)).trusting_source_time(60_000);
    let at = |e: &mut CellEngine, address: &str, v: bool, now: u64| {
        let t = e.tag_index(&Signal::new(address)).unwrap();
        e.on_reading(t, Reading::Good(v), now + AHEAD, now)
    };
    for line in NORMAL
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("address"))
    {
        let (a, v) = line.split_once(',').unwrap();
        at(&mut e, a, v == "1", 1_000);
    }
    let step = at(&mut e, "X0.06", false, 10_000);
    let (_, _, raised_at) = step.alarms().next().unwrap();
    assert_eq!(raised_at, 10_000, "stamped by the agent's clock");
    let step = e.advance(11_001);
    let [r] = &step.recordings[..] else {
        panic!("{step:?}")
    };
    assert_eq!((r.raised_at, r.from, r.to), (10_000, 7_000, 11_000));
    let y = r.signals.iter().position(|s| s.address == "X0.06").unwrap();
    assert_eq!(r.value_at(y, 9_999), Some(Some(&Sample::Bool(true))));
    assert_eq!(r.value_at(y, 10_000), Some(Some(&Sample::Bool(false))));
}

#[test]
fn a_limit_alarm_records_its_number_and_a_lost_connection_as_unknown() {
    let mut e = ese_engine(true, config(3_000, 4_000));
    load_normal(&mut e, 1_000);
    let n = |x: f64| Reading::Number(Num::Float(x));
    set(&mut e, "TEMP", n(50.0), 1_000);
    set(&mut e, "TEMP", n(70.0), 3_000);
    let step = set(&mut e, "TEMP", n(85.0), 5_000);
    assert_eq!(raised(&step), ["temp-h"]);
    set(&mut e, "TEMP", Reading::Number(Num::Int(90)), 6_000);
    e.on_connection(false, 7_000);
    let step = e.advance(9_001);
    let [r] = &step.recordings[..] else {
        panic!("{step:?}")
    };
    assert_eq!((r.alarm.as_str(), r.from, r.to), ("temp-h", 2_000, 9_000));
    let [s] = &r.signals[..] else { panic!("{r:?}") };
    assert_eq!(
        (s.address.as_str(), s.name.as_deref(), &s.start),
        (
            "TEMP",
            Some("spindle temperature"),
            &Some(Sample::Float(50.0))
        )
    );
    assert_eq!(
        s.changes,
        [
            (3_000, Some(Sample::Float(70.0))),
            (5_000, Some(Sample::Float(85.0))),
            (6_000, Some(Sample::UInt(90))),
            (7_000, None)
        ]
    );
}

#[test]
fn a_timer_alarm_records_its_transition_signals() {
    use crate::timer::checks::TimerChecks;
    use crate::timer::learn::{Event, LearnedTransition, SignalEdge, TimerModel, MODEL_VERSION};
    let model = TimerModel {
        version: MODEL_VERSION,
        method: "common".into(),
        signals: vec!["move".into(), "arrived".into(), "other".into()],
        transitions: vec![LearnedTransition {
            id: 7,
            from: vec![],
            event: Event {
                tag: "arrived".into(),
                edge: SignalEdge::Rise,
            },
            to: vec![],
            delta_ms: 6000,
            min_ms: 5950,
            max_ms: 6050,
            support: 4,
            window_ms: [5700, 6300],
            from_numbered: None,
            trigger: Some(Event {
                tag: "move".into(),
                edge: SignalEdge::Rise,
            }),
        }],
    };
    let tags: Vec<Tag> = [("move", "Y1.00"), ("arrived", "X1.00"), ("other", "X1.01")]
        .into_iter()
        .map(|(n, a)| Tag {
            name: n.into(),
            address: Signal::new(a),
        })
        .collect();
    let checks = TimerChecks::new("line", &model, Severity::High, |n| {
        tags.iter().find(|t| t.name == n).map(|t| t.address.clone())
    })
    .unwrap();
    let mut e = CellEngine::new("c", tags, vec![Box::new(checks)], StateRules::default())
        .unwrap()
        .recording(config(7_000, 2_000));
    e.on_connection(true, 0);
    for t in 0..3 {
        e.on_reading(t, Reading::Good(false), 0, 0);
    }
    e.on_reading(0, Reading::Good(true), 1_000, 1_000);
    e.on_reading(2, Reading::Good(true), 2_000, 2_000);
    let step = e.advance(7_300);
    assert_eq!(raised(&step), ["line-007"]);
    // The recording ends 2 s after the raise; the clock completes it the
    // millisecond after.
    assert_eq!(e.next_deadline(), Some(9_301));
    e.on_reading(1, Reading::Good(true), 8_000, 8_000);
    let step = e.advance(9_301);
    let [r] = &step.recordings[..] else {
        panic!("{step:?}")
    };
    let y100 = RecordedSignal {
        address: "Y1.00".into(),
        name: Some("move".into()),
        start: Some(Sample::Bool(false)),
        changes: vec![(1_000, Some(Sample::Bool(true)))],
    };
    let x100 = RecordedSignal {
        address: "X1.00".into(),
        name: Some("arrived".into()),
        start: Some(Sample::Bool(false)),
        changes: vec![(8_000, Some(Sample::Bool(true)))],
    };
    assert_eq!(r.signals, [y100, x100]);
    assert_eq!((r.from, r.to, r.holds_to), (300, 9_300, 9_300));
}

mod model {
    use super::*;
    use proptest::prelude::*;

    #[derive(Debug, Clone)]
    enum Op {
        /// A tag's reading, `dt` ms after the last (or before it, when
        /// `back`).
        Read {
            tag: usize,
            value: u8,
            dt: u64,
            back: bool,
        },
        /// The connection drops and comes back.
        Cut { dt: u64 },
        /// Time passes.
        Wait { dt: u64 },
    }

    fn op() -> impl Strategy<Value = Op> {
        prop_oneof![
            6 => (0usize..24, 0u8..6, 0u64..400, prop::bool::weighted(0.05))
                .prop_map(|(tag, value, dt, back)| Op::Read { tag, value, dt, back }),
            1 => (0u64..400).prop_map(|dt| Op::Cut { dt }),
            1 => (0u64..3_000).prop_map(|dt| Op::Wait { dt }),
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// The value a recording says a signal had at any time it holds
        /// is the value the engine held then.
        #[test]
        fn a_recording_says_what_the_engine_held(
            ops in prop::collection::vec(op(), 1..300),
            capacity in 20usize..400,
            max_changes in 2usize..60,
        ) {
            let mut e = ese_engine(true, RecorderConfig {
                capacity,
                max_changes,
                max_open: 2,
                ..config(1_500, 800)
            });
            let n = e.tags().len();
            let (x006, temp) = (
                e.tag_index(&Signal::new("X0.06")).unwrap(),
                e.tag_index(&Signal::new("TEMP")).unwrap(),
            );
            load_normal(&mut e, 1);
            // The latest time of anything; the engine's latest source
            // time; the recorder's latest change; the clock's latest
            // look (no reading goes back past it: a change delivered
            // after its window was closed by the clock is not in it).
            let (mut clock, mut source_latest, mut kept, mut floor) = (1u64, 1u64, 1u64, 0u64);
            // Per tag: (time, value) after each change.
            let mut held: Vec<Vec<(u64, Option<Value>)>> =
                (0..n).map(|tag| vec![(0, None), (1, e.value(tag))]).collect();
            let mut recordings = Vec::new();
            for op in ops {
                let step = match op {
                    Op::Read { tag, value, dt, back } => {
                        // Most readings are of X0.06 and TEMP, which
                        // raise alarms.
                        let tag = match tag {
                            0..=5 => x006,
                            6..=11 => temp,
                            t => t % n,
                        };
                        let source = if back {
                            clock.saturating_sub(dt).max(floor)
                        } else {
                            clock + dt
                        };
                        let reading = match (tag == temp, value) {
                            (_, 0) => Reading::Bad,
                            (true, v) => Reading::Number(Num::Float(f64::from(v) * 20.0)),
                            (false, v) => Reading::Good(v % 2 == 1),
                        };
                        let was = e.value(tag);
                        let step = e.on_reading(tag, reading, source, source.max(clock));
                        source_latest = source_latest.max(source);
                        clock = clock.max(source);
                        if e.value(tag) != was {
                            kept = kept.max(source_latest);
                            held[tag].push((kept, e.value(tag)));
                        }
                        step
                    }
                    Op::Cut { dt } => {
                        clock += dt;
                        floor = clock;
                        kept = clock;
                        let mut step = e.on_connection(false, clock);
                        step.recordings.extend(e.on_connection(true, clock).recordings);
                        for (tag, h) in held.iter_mut().enumerate() {
                            h.push((clock, e.value(tag)));
                        }
                        step
                    }
                    Op::Wait { dt } => {
                        clock += dt;
                        floor = clock;
                        e.advance(clock)
                    }
                };
                recordings.extend(step.recordings);
            }
            recordings.extend(e.advance(clock + 10_000).recordings);
            prop_assert_eq!(e.recorder_fill().unwrap().open, 0);
            for rec in &recordings {
                for (i, s) in rec.signals.iter().enumerate() {
                    let tag = e.tag_index(&Signal::new(&s.address)).unwrap();
                    let mut times: Vec<u64> = held[tag].iter().map(|(at, _)| *at).collect();
                    times.extend([rec.holds_from, rec.holds_to]);
                    for at in times {
                        for at in [at.saturating_sub(1), at] {
                            let Some(said) = rec.value_at(i, at) else { continue };
                            let k = held[tag].partition_point(|(h, _)| *h <= at);
                            let was = held[tag][k - 1].1.as_ref().map(Sample::from);
                            prop_assert_eq!(
                                said, was.as_ref(),
                                "{} at {} in {:?}", s.address, at, rec
                            );
                        }
                    }
                    prop_assert!(s.changes.windows(2).all(|w| w[0].0 <= w[1].0));
                }
                // Changes in the raise's millisecond may be on either
                // side of it.
                let before = rec.signals.iter().flat_map(|s| &s.changes)
                    .filter(|(at, _)| *at < rec.raised_at).count();
                prop_assert!(before <= max_changes);
                prop_assert!(rec.changes() <= 2 * max_changes);
            }
        }
    }
}
