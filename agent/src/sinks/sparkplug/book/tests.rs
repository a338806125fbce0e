//! The book: births declare every metric with its alias, changes are held
//! in order and bounded, data names metrics by alias only.

use cellwatch_models::alarm::{Alarm, AlarmKind, Severity, Transition};
use cellwatch_models::engine::{EngineEvent, EngineStep, HistoryKind, MachineState};
use prost::Message;

use super::*;
use crate::step::{CellStep, Input};

fn alarm(id: &str, active: bool, acknowledged: bool) -> Alarm {
    Alarm {
        id: id.into(),
        kind: AlarmKind::Switching,
        severity: Severity::Critical,
        fault_type: "ESE".into(),
        active,
        acknowledged,
        latched: false,
        raised_at: 1,
        cleared_at: None,
        acked_by: None,
        ack_comment: None,
        fault_step: None,
        culprits: Vec::new(),
        message: String::new(),
        shelved: None,
        out_of_service: None,
        consequence: None,
        designed: None,
        guidance: None,
    }
}

fn step(at: u64, engine: EngineStep) -> CellStep {
    CellStep {
        at,
        input: Input::Readings,
        engine,
        alarms: Vec::new(),
        state: None,
        queue_depth: 0,
        received: None,
        positions: Vec::new(),
        recordings: Vec::new(),
    }
}

fn book(max_held: usize) -> MetricBook {
    MetricBook::new(
        &[Declared {
            id: "ese".into(),
            kind: AlarmKind::Switching,
            severity: Severity::Critical,
            fault_type: "ESE".into(),
        }],
        &[(4, "spindle_temperature".into())],
        true,
        false,
        max_held,
    )
}

fn names(p: &Payload) -> Vec<(String, u64)> {
    p.metrics
        .iter()
        .map(|m| (m.name.clone().unwrap_or_default(), m.alias.unwrap_or(0)))
        .collect()
}

#[test]
fn the_births_declare_every_metric_with_its_alias() {
    let mut b = book(10);
    let nbirth = b.node_birth(7, 1000);
    assert_eq!(nbirth.seq, Some(0));
    assert_eq!(nbirth.metrics[0].name.as_deref(), Some(BD_SEQ));
    assert_eq!(nbirth.metrics[0].value, Some(Value::LongValue(7)));
    assert_eq!(nbirth.metrics[0].datatype, Some(DataType::Int64 as u32));
    assert_eq!(names(&nbirth)[1], (REBIRTH.to_string(), REBIRTH_ALIAS));
    let (dbirth, held) = b.device_birth(1, 1000);
    assert!(held.is_empty());
    assert_eq!(dbirth.seq, Some(1));
    let expected: Vec<(String, u64)> = [
        "Machine/State",
        "Machine/Fault Type",
        "Machine/Fault Element",
        "Production/Parts Produced",
        "Tags/spindle_temperature",
        "Alarms/ese/Active",
        "Alarms/ese/Acknowledged",
        "Alarms/ese/Priority",
        "Alarms/ese/Shelved",
    ]
    .iter()
    .enumerate()
    .map(|(i, n)| ((*n).to_string(), 16 + i as u64))
    .collect();
    assert_eq!(names(&dbirth), expected);
    // Unknown until told: null. Declared alarms: normal.
    assert_eq!(dbirth.metrics[0].is_null, Some(true));
    assert_eq!(dbirth.metrics[5].value, Some(Value::BooleanValue(false)));
    assert_eq!(
        dbirth.metrics[7].value,
        Some(Value::StringValue("critical".into()))
    );
    let props = dbirth.metrics[5].properties.as_ref().unwrap();
    assert_eq!(props.keys, ["kind", "faultType"]);
    // The payload is the Tahu message on the wire.
    let bytes = dbirth.encode_to_vec();
    assert_eq!(Payload::decode(bytes.as_slice()).unwrap(), dbirth);
    assert!(!b.grown());
}

#[test]
fn changes_are_held_in_order_and_sent_by_alias() {
    let mut b = book(100);
    let engine = EngineStep {
        events: vec![
            EngineEvent::State {
                state: MachineState::Fault {
                    fault_type: "ESE".into(),
                    element: Some("X0.06".into()),
                },
                kind: HistoryKind::Fault,
                at: 10,
            },
            EngineEvent::Alarm {
                alarm: alarm("ese", true, false),
                transition: Transition::Raised,
                at: 10,
            },
        ],
        parts: vec![(11, 2)],
        exported: vec![(4, Some(81.5)), (9, Some(1.0))],
        ..EngineStep::default()
    };
    assert!(b.apply(&step(12, engine)));
    let changes = b.take_changes(100);
    let data = b.data(changes, 5, 20, false);
    let got: Vec<(u64, Option<Value>)> = data
        .metrics
        .iter()
        .map(|m| (m.alias.unwrap(), m.value.clone()))
        .collect();
    assert_eq!(
        got,
        vec![
            (16, Some(Value::StringValue("fault".into()))),
            (17, Some(Value::StringValue("ESE".into()))),
            (18, Some(Value::StringValue("X0.06".into()))),
            (19, Some(Value::LongValue(2))),
            (20, Some(Value::DoubleValue(81.5))),
            (21, Some(Value::BooleanValue(true))),
            (22, Some(Value::BooleanValue(false))),
        ]
    );
    assert!(data.metrics.iter().all(|m| m.name.is_none()));
    assert_eq!(data.seq, Some(5));
    // The same again changes nothing.
    let again = EngineStep {
        exported: vec![(4, Some(81.5))],
        ..EngineStep::default()
    };
    assert!(!b.apply(&step(13, again)));
}

#[test]
fn held_changes_are_bounded_the_oldest_dropped_and_a_birth_hands_them_back() {
    let mut b = book(3);
    for i in 0..5u64 {
        let engine = EngineStep {
            exported: vec![(4, Some(i as f64))],
            ..EngineStep::default()
        };
        assert!(b.apply(&step(100 + i, engine)));
    }
    assert_eq!(b.held(), 3);
    assert_eq!(b.take_dropped(), 2);
    let (birth, held) = b.device_birth(1, 200);
    // The birth carries the latest value; what was held comes back as
    // history, oldest first.
    assert_eq!(birth.metrics[4].value, Some(Value::DoubleValue(4.0)));
    assert_eq!(
        held.iter().map(|c| c.at).collect::<Vec<_>>(),
        [102, 103, 104]
    );
    let history = b.data(held, 2, 200, true);
    assert!(history
        .metrics
        .iter()
        .all(|m| m.is_historical == Some(true)));
    assert_eq!(b.held(), 0);
}

#[test]
fn an_alarm_not_declared_grows_the_device() {
    let mut b = book(10);
    let engine = EngineStep {
        events: vec![EngineEvent::Alarm {
            alarm: alarm("plc-door-open", true, false),
            transition: Transition::Raised,
            at: 5,
        }],
        ..EngineStep::default()
    };
    assert!(b.apply(&step(5, engine)));
    assert!(b.grown());
    let (birth, _) = b.device_birth(1, 6);
    assert!(birth
        .metrics
        .iter()
        .any(|m| m.name.as_deref() == Some("Alarms/plc-door-open/Active")
            && m.value == Some(Value::BooleanValue(true))));
    assert!(!b.grown());
}

#[test]
fn only_a_rebirth_set_true_asks_for_one() {
    let rebirth = |name: Option<&str>, alias: Option<u64>, v: bool| Payload {
        metrics: vec![Metric {
            name: name.map(str::to_string),
            alias,
            value: Some(Value::BooleanValue(v)),
            ..Metric::default()
        }],
        ..Payload::default()
    };
    assert!(asks_rebirth(&rebirth(Some(REBIRTH), None, true)));
    assert!(asks_rebirth(&rebirth(None, Some(REBIRTH_ALIAS), true)));
    assert!(!asks_rebirth(&rebirth(Some(REBIRTH), None, false)));
    assert!(!asks_rebirth(&rebirth(
        Some("Node Control/Reboot"),
        None,
        true
    )));
    let death = node_death(3, 9);
    assert_eq!(death.seq, None);
    assert_eq!(death.metrics[0].value, Some(Value::LongValue(3)));
}

#[test]
fn held_changes_go_to_the_store_by_name_and_come_back_to_the_next_run() {
    let mut b = book(10);
    for i in 0..2u64 {
        let engine = EngineStep {
            exported: vec![(4, Some(i as f64))],
            ..EngineStep::default()
        };
        b.apply(&step(100 + i, engine));
    }
    let taken = b.take_changes(10);
    let rows = b.to_rows(taken);
    assert_eq!(
        rows.iter()
            .map(|r| (r.metric.as_str(), r.at))
            .collect::<Vec<_>>(),
        [
            ("Tags/spindle_temperature", 100),
            ("Tags/spindle_temperature", 101)
        ]
    );
    // The next run declares the tag at another place: found by its name.
    let next = MetricBook::new(&[], &[(4, "spindle_temperature".into())], false, false, 10);
    let mut gone = rows[0].clone();
    gone.metric = "Tags/removed".into();
    let (changes, unknown) = next.changes_of(vec![rows[0].clone(), gone, rows[1].clone()]);
    assert_eq!(unknown, 1);
    let data = next.data(changes, 2, 200, true);
    assert_eq!(
        data.metrics
            .iter()
            .map(|m| (m.alias, m.value.clone(), m.timestamp))
            .collect::<Vec<_>>(),
        [
            (Some(19), Some(Value::DoubleValue(0.0)), Some(100)),
            (Some(19), Some(Value::DoubleValue(1.0)), Some(101)),
        ]
    );
}

#[test]
fn changes_not_published_are_held_again_first() {
    let mut b = book(10);
    for i in 0..3u64 {
        let engine = EngineStep {
            exported: vec![(4, Some(i as f64))],
            ..EngineStep::default()
        };
        b.apply(&step(100 + i, engine));
    }
    let first = b.take_changes(2);
    b.hold_again(first);
    assert_eq!(
        b.take_changes(10).iter().map(|c| c.at).collect::<Vec<_>>(),
        [100, 101, 102]
    );
}

/// A step of the PLC link going `up` or down, the tag `4` read as `value`
/// with it.
fn link(at: u64, up: bool, value: f64) -> CellStep {
    CellStep {
        input: Input::Connection {
            up,
            detail: String::new(),
        },
        ..step(
            at,
            EngineStep {
                exported: vec![(4, Some(value))],
                ..EngineStep::default()
            },
        )
    }
}

fn exported(at: u64, value: f64) -> CellStep {
    step(
        at,
        EngineStep {
            exported: vec![(4, Some(value))],
            ..EngineStep::default()
        },
    )
}

#[test]
fn the_device_dies_with_its_link_after_the_changes_before() {
    let mut b = book(3);
    assert!(b.device_up() && !b.died());
    assert!(b.apply(&exported(100, 1.0)));
    // The link lost, with a change; then a change while dead.
    assert!(b.apply(&link(101, false, 2.0)));
    assert!(b.apply(&exported(102, 3.0)));
    assert!(!b.device_up() && b.died());
    // Data stops at the death: the first change only, then none.
    assert_eq!(
        b.take_changes(1).iter().map(|c| c.at).collect::<Vec<_>>(),
        [100]
    );
    let before = b.take_before_death();
    assert_eq!(before.iter().map(|c| c.at).collect::<Vec<_>>(), [101]);
    assert!(!b.died());
    assert!(b.take_changes(10).iter().all(|c| c.at == 102));
    // Changes taken and put back before the death stay before it; the
    // oldest dropped past the bound leave it sooner.
    let mut b = book(3);
    b.apply(&exported(100, 1.0));
    b.apply(&exported(101, 2.0));
    b.apply(&link(102, false, 3.0));
    let taken = b.take_changes(10);
    assert_eq!(taken.len(), 3, "all before the death");
    b.hold_again(taken);
    b.apply(&exported(103, 4.0));
    assert_eq!(b.take_dropped(), 1);
    let before = b.take_before_death();
    assert_eq!(before.iter().map(|c| c.at).collect::<Vec<_>>(), [101, 102]);
    // The link back: a birth with the current values, what came while
    // dead handed back as history.
    assert!(b.apply(&link(104, true, 5.0)));
    assert!(b.device_up() && !b.died());
    let (birth, held) = b.device_birth(7, 200);
    assert_eq!(birth.metrics[4].value, Some(Value::DoubleValue(5.0)));
    assert_eq!(held.iter().map(|c| c.at).collect::<Vec<_>>(), [103, 104]);
    let death = device_death(6, 150);
    assert_eq!((death.seq, death.metrics.len()), (Some(6), 0));
}

#[test]
fn a_node_birth_or_a_spill_forgets_a_death_not_yet_told() {
    let mut b = book(10);
    b.apply(&link(100, false, 1.0));
    b.apply(&exported(101, 2.0));
    assert!(b.died());
    assert_eq!(b.take_all().len(), 2);
    assert!(!b.died());
    b.apply(&link(102, true, 3.0));
    b.apply(&link(103, false, 4.0));
    assert!(b.died());
    b.node_birth(1, 200);
    assert!(!b.died() && !b.device_up());
}
