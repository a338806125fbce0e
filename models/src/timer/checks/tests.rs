//! The timer checks' tests: transitions too early and too late in virtual
//! time, drift warnings, restarts and the engine around them.

use super::*;
use crate::alarm::Transition as AlarmTransition;
use crate::engine::{CellEngine, EngineEvent, Reading, StateRules, Tag};
use crate::timer::learn::{Event, LearnedTransition, MODEL_VERSION};

fn model() -> TimerModel {
    TimerModel {
        version: MODEL_VERSION,
        method: "common".into(),
        signals: vec!["move".into(), "arrived".into()],
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
    }
}

#[test]
fn a_transition_alarm_and_its_drift_warning_read_the_transition_signals() {
    let mut m = model();
    m.signals.push("clamped".into());
    m.signals.push("spare".into());
    m.transitions[0].from = vec!["-clamped".into()];
    let address = |n: &str| Some(Signal::new(&format!("@{n}")));
    let checks = TimerChecks::new("line", &m, Severity::High, address)
        .unwrap()
        .drifting(Some(DriftRules::default()));
    let reads = |id: &str| {
        let mut out = Vec::new();
        checks.reads(id, &mut out);
        out.iter().map(Signal::to_string).collect::<Vec<_>>()
    };
    assert_eq!(reads("line-007"), ["@clamped", "@move", "@arrived"]);
    assert_eq!(reads("line-007-drift"), reads("line-007"));
    for other in ["line-7", "line-008", "lines-007", "line-007-x", "other-007"] {
        assert!(reads(other).is_empty(), "{other}");
    }
}

#[test]
fn late_event_latches_until_reset() {
    let tags = vec![
        Tag {
            name: "move".into(),
            address: Signal::new("Y1.00"),
        },
        Tag {
            name: "arrived".into(),
            address: Signal::new("X1.00"),
        },
    ];
    let checks = TimerChecks::new("line", &model(), Severity::High, |n| {
        tags.iter().find(|t| t.name == n).map(|t| t.address.clone())
    })
    .unwrap();
    let mut e = CellEngine::new(
        "c",
        tags.clone(),
        vec![Box::new(checks)],
        StateRules::default(),
    )
    .unwrap();
    e.on_connection(true, 0);
    e.on_reading(0, Reading::Good(false), 0, 0);
    e.on_reading(1, Reading::Good(false), 0, 0);
    assert_eq!(e.next_deadline(), None);
    e.on_reading(0, Reading::Good(true), 1000, 1000);
    // The agent wakes exactly when the window closes.
    assert_eq!(e.next_deadline(), Some(7300));
    assert!(e
        .advance(7299)
        .events
        .iter()
        .all(|ev| !matches!(ev, EngineEvent::Alarm { .. })));
    let ev = e.advance(7300).events;
    let EngineEvent::Alarm {
        alarm,
        transition: AlarmTransition::Raised,
        ..
    } = &ev[0]
    else {
        panic!("{ev:?}")
    };
    assert_eq!(alarm.id, "line-007");
    assert_eq!(
        alarm.message,
        "transition #007 (+arrived after +move) too late: nothing by 6300 ms"
    );
    assert_eq!(alarm.culprits[0].to_string(), "X1.00 = 0 (expected 1)");
    assert!(alarm.active && alarm.latched);
    assert_eq!(e.next_deadline(), None);
    // A normal cycle is measured.
    e.on_reading(0, Reading::Good(false), 7400, 7400);
    e.on_reading(0, Reading::Good(true), 7500, 7500);
    // The sensor arrives late: still latched.
    let observed = e.on_reading(1, Reading::Good(true), 8000, 8000);
    assert!(e.alarms().any(|a| a.id == "line-007" && a.active));
    // Re-armed at 7500, the sensor at 8000 is early (500 ms): measured too.
    assert_eq!(
        observed.observations,
        [crate::engine::Observation {
            check: "line-007".into(),
            ms: 500
        }]
    );
    let ev = e.reset("line-007", "kim", 9000).unwrap().events;
    assert!(matches!(
        &ev[0],
        EngineEvent::Alarm {
            transition: AlarmTransition::Cleared,
            ..
        }
    ));
}

#[test]
fn an_event_out_of_time_order_is_counted_and_raises_nothing() {
    let tags = vec![
        Tag {
            name: "move".into(),
            address: Signal::new("Y1.00"),
        },
        Tag {
            name: "arrived".into(),
            address: Signal::new("X1.00"),
        },
    ];
    let checks = TimerChecks::new("line", &model(), Severity::High, |n| {
        tags.iter().find(|t| t.name == n).map(|t| t.address.clone())
    })
    .unwrap();
    // Every alarm of low severity or above is a fault here: a drift
    // warning is none all the same.
    let rules = StateRules {
        fault_severity: Severity::Low,
        ..StateRules::default()
    };
    let mut e = CellEngine::new("c", tags, vec![Box::new(checks)], rules).unwrap();
    e.on_connection(true, 0);
    e.on_reading(0, Reading::Good(false), 0, 0);
    e.on_reading(1, Reading::Good(false), 0, 0);
    e.on_reading(0, Reading::Good(true), 10_000, 10_000);
    // The sensor stamped 2 s before the motion started: no "early", no
    // panic, counted.
    let step = e.on_reading(1, Reading::Good(true), 8_000, 10_010);
    assert_eq!(step.out_of_order, 1);
    assert!(step.events.is_empty(), "{:?}", step.events);
    assert!(step.observations.is_empty());
    // Nothing armed is left to fall late.
    assert_eq!(e.next_deadline(), None);
    assert!(e.advance(20_000).events.is_empty());
    // The next cycle in order is measured again.
    e.on_reading(0, Reading::Good(false), 20_000, 20_000);
    e.on_reading(1, Reading::Good(false), 20_000, 20_000);
    e.on_reading(0, Reading::Good(true), 21_000, 21_000);
    let step = e.on_reading(1, Reading::Good(true), 27_000, 27_000);
    assert_eq!(step.out_of_order, 0);
    assert_eq!(
        step.observations,
        [crate::engine::Observation {
            check: "line-007".into(),
            ms: 6000
        }]
    );
}

/// An engine over `model()` with drift tracking by `rules`.
fn drifting_engine(rules: Option<DriftRules>) -> CellEngine {
    let tags = vec![
        Tag {
            name: "move".into(),
            address: Signal::new("Y1.00"),
        },
        Tag {
            name: "arrived".into(),
            address: Signal::new("X1.00"),
        },
    ];
    let checks = TimerChecks::new("line", &model(), Severity::High, |n| {
        tags.iter().find(|t| t.name == n).map(|t| t.address.clone())
    })
    .unwrap()
    .drifting(rules)
    .commented(
        CommentDb::parse("io.csv", "X1.00,slide in front\n", |a| Ok(Signal::new(a))).unwrap(),
    );
    let mut e = CellEngine::new("c", tags, vec![Box::new(checks)], StateRules::default()).unwrap();
    e.on_connection(true, 0);
    e.on_reading(0, Reading::Good(false), 0, 0);
    e.on_reading(1, Reading::Good(false), 0, 0);
    e
}

/// One cycle a minute from `*t`: the motion takes `ms`. The alarm
/// transitions it caused.
fn cycle(e: &mut CellEngine, t: &mut u64, ms: u64) -> Vec<(Alarm, AlarmTransition)> {
    *t += 60_000;
    let mut out = Vec::new();
    for (tag, v, at) in [(0, true, *t), (1, true, *t + ms), (0, false, *t + ms + 100)] {
        let step = e.on_reading(tag, Reading::Good(v), at, at);
        out.extend(step.alarms().map(|(a, tr, _)| (a.clone(), tr)));
    }
    e.on_reading(1, Reading::Good(false), *t + ms + 200, *t + ms + 200);
    out
}

#[test]
fn a_slowing_motion_warns_low_before_its_window_closes_and_clears_when_back() {
    let rules = DriftRules {
        min_samples: 10,
        ..DriftRules::default()
    };
    let mut e = drifting_engine(Some(rules));
    assert!(e.can_raise("line-007-drift"));
    let mut t = 0;
    for _ in 0..20 {
        assert!(cycle(&mut e, &mut t, 6000).is_empty());
    }
    // 6.2 s, inside the window [5.7, 6.3] s: no timer alarm, but the
    // mean walks towards 6.3 s and warns past 6.15 s.
    let mut raised = Vec::new();
    for i in 0..60 {
        for (a, tr) in cycle(&mut e, &mut t, 6200) {
            raised.push((i, a, tr));
        }
    }
    assert_eq!(raised.len(), 1, "{raised:?}");
    let (i, a, tr) = &raised[0];
    assert_eq!((*i, *tr), (27, AlarmTransition::Raised));
    assert_eq!(a.id, "line-007-drift");
    assert!(
        !matches!(e.state(), crate::engine::MachineState::Fault { .. }),
        "{:?}",
        e.state()
    );
    assert_eq!(
        a.message,
        "transition #007 (+arrived after +move) slowing: \
         mean 6.00 s → 6.15 s over 47 min, limit 6.30 s: slide in front"
    );
    assert_eq!(
        (a.severity, a.kind, a.latched),
        (Severity::Low, AlarmKind::Drift, false)
    );
    let p = &e.window_positions()[0];
    assert_eq!((p.check.as_str(), p.samples), ("line-007", 80));
    assert!(p.position > 0.6 && p.position < 0.67, "{p:?}");
    // Back to 6.0 s: cleared once the mean is below 6.075 s.
    let mut cleared = Vec::new();
    for i in 0..60 {
        for (a, tr) in cycle(&mut e, &mut t, 6000) {
            cleared.push((i, a, tr));
        }
    }
    assert_eq!(cleared.len(), 1, "{cleared:?}");
    assert_eq!(cleared[0].2, AlarmTransition::Cleared);
    assert!(!e.alarms().any(|a| a.active));
}

#[test]
fn a_drift_warning_restored_clears_when_fresh_durations_are_normal() {
    let rules = DriftRules {
        min_samples: 10,
        ..DriftRules::default()
    };
    let mut e = drifting_engine(Some(rules));
    let mut t = 0;
    for _ in 0..60 {
        cycle(&mut e, &mut t, 6250);
    }
    let warning = e
        .alarms()
        .find(|a| a.id == "line-007-drift")
        .unwrap()
        .clone();
    assert!(warning.active);
    // The agent restarts with the warning in its journal.
    let mut e = drifting_engine(Some(rules));
    e.restore(vec![warning], None, t);
    for i in 0..20 {
        let changes = cycle(&mut e, &mut t, 6000);
        if i < 9 {
            assert!(changes.is_empty(), "{i}: {changes:?}");
        } else if i == 9 {
            assert_eq!(changes.len(), 1);
            assert_eq!(changes[0].1, AlarmTransition::Cleared);
            assert_eq!(
                changes[0].0.message,
                "transition #007 (+arrived after +move) back to normal: mean 6.00 s \
                 (learned 6.00 s), spread ±0.00 s (learned ±0.05 s), window 5.70–6.30 s: \
                 slide in front"
            );
        }
    }
}

#[test]
fn without_drift_rules_nothing_is_tracked_or_declared() {
    let mut e = drifting_engine(None);
    assert!(!e.can_raise("line-007-drift"));
    let mut t = 0;
    for _ in 0..100 {
        assert!(cycle(&mut e, &mut t, 6250).is_empty());
    }
    assert!(e.window_positions().is_empty());
}

#[test]
fn unknown_model_signal_is_refused() {
    let err = TimerChecks::new("line", &model(), Severity::High, |_| None)
        .err()
        .unwrap();
    assert_eq!(
        err.to_string(),
        "the timer model reads 'move', which is no tag of this cell"
    );
}
