//! Numbers in the engine: comparisons used as contacts (in the running rule
//! and in `armed_when`), a value of the wrong type, a parts counter that
//! wraps and resets, limit checks with delays in virtual time, exported
//! values.

#![allow(clippy::unwrap_used)] // test helpers fail loudly by design

use cellwatch_models::alarm::{AlarmKind, Severity, Transition};
use cellwatch_models::comments::CommentDb;
use cellwatch_models::engine::{
    CellEngine, CheckSet, EngineStep, HistoryKind, MachineState, Order, PartCounting, Reading,
    StateRules, SwitchingCheck, SwitchingChecks, TagReading,
};
use cellwatch_models::expr::Expr;
use cellwatch_models::limit::{Level, LimitCheck, LimitChecks, LimitLevel};
use cellwatch_models::signal::Signal;
use cellwatch_models::switching::SwitchingFunction;
use cellwatch_models::value::{Counter, Num, ValueType};

mod kit;
use kit::{set, tag};

/// The ESE machine's contacts, then `MODE` (the mode word), `TEMP` and
/// `COUNT`; ESE armed only in AUTO (`MODE == 1`); running while
/// `G0.00 * TEMP < 90`.
fn engine(limits: Vec<LimitCheck>) -> CellEngine {
    let (mut tags, mut check) = kit::ese();
    tags.extend(kit::tags_at(&["ITEM", "TARGET", "MODE", "TEMP", "COUNT"]));
    check.armed_when = Some(SwitchingFunction::from_expr(
        Signal::new("ese.armed"),
        &Expr::parse("MODE == 1").unwrap(),
    ));
    let rules = StateRules {
        running: Some(Expr::parse("G0.00 * TEMP < 90").unwrap()),
        fault_severity: Severity::High,
        modes: Vec::new(),
    };
    let mut sets: Vec<Box<dyn CheckSet>> = vec![Box::new(SwitchingChecks::new(vec![check]))];
    if !limits.is_empty() {
        sets.push(Box::new(LimitChecks::new(limits)));
    }
    let count = tags.len() - 1;
    CellEngine::new("m01", tags, sets, rules)
        .unwrap()
        .counting(PartCounting::Counters(vec![(
            count,
            Counter::new(ValueType::UInt16.max().unwrap()),
        )]))
        .exporting([count - 1])
        .ordering(Some(count - 4), Some(count - 3))
}

fn number(e: &mut CellEngine, a: &str, v: Num, at: u64) -> EngineStep {
    kit::read(e, a, Reading::Number(v), at)
}

fn load_normal(e: &mut CellEngine, at: u64) {
    e.on_connection(true, at);
    kit::load(e, kit::ESE_NORMAL, at);
}

fn raised(step: &EngineStep) -> Vec<String> {
    kit::raised(step).into_iter().map(|a| a.id).collect()
}

#[test]
fn a_comparison_in_the_running_rule_decides_the_state() {
    let mut e = engine(Vec::new());
    load_normal(&mut e, 1);
    assert_eq!(*e.state(), MachineState::Idle, "TEMP unknown: not running");
    number(&mut e, "TEMP", Num::Float(40.0), 2);
    assert_eq!(*e.state(), MachineState::Running);
    let step = number(&mut e, "TEMP", Num::Float(90.5), 3);
    assert_eq!(*e.state(), MachineState::Idle, "TEMP < 90 no longer holds");
    assert_eq!(step.states().count(), 1);
    number(&mut e, "TEMP", Num::Float(89.9), 4);
    assert_eq!(*e.state(), MachineState::Running);
}

#[test]
fn a_comparison_in_armed_when_arms_the_check() {
    let mut e = engine(Vec::new());
    load_normal(&mut e, 1);
    number(&mut e, "MODE", Num::Int(2), 2);
    // JOG: the over-travel switch opens, the check is not armed.
    assert!(raised(&set(&mut e, "X0.06", false, 3)).is_empty());
    set(&mut e, "X0.06", true, 4);
    number(&mut e, "MODE", Num::Int(1), 5);
    // AUTO: the same fault raises.
    assert_eq!(raised(&set(&mut e, "X0.06", false, 6)), ["ese"]);
}

#[test]
fn a_value_of_the_wrong_type_is_bad_quality_naming_what_came() {
    let mut e = engine(Vec::new());
    load_normal(&mut e, 1);
    let t = tag(&e, "X0.06");
    let step = e.on_reading(
        t,
        Reading::WrongType {
            expected: ValueType::Boolean,
            received: Some(ValueType::Double),
        },
        2,
        2,
    );
    let (alarm, transition, _) = step.alarms().next().unwrap();
    assert_eq!(transition, Transition::Raised);
    assert_eq!(alarm.kind, AlarmKind::TagQuality);
    assert_eq!(
        alarm.message,
        "bad or uncertain quality, checks reading them suspended: X0.06 (x0.06): Double received where Boolean is expected"
    );
    assert_eq!(e.values()[t], None, "the contact is unknown");
}

#[test]
fn a_counter_counts_exactly_its_increments_through_wrap_and_reset() {
    let mut e = engine(Vec::new());
    load_normal(&mut e, 1);
    let mut parts = 0;
    let mut at = 10;
    for v in (0..=65535u64).chain([0]).chain(1..=120).chain([0, 1, 2]) {
        at += 1;
        parts += number(&mut e, "COUNT", Num::UInt(v), at)
            .parts
            .iter()
            .map(|&(_, n)| n)
            .sum::<u64>();
    }
    assert_eq!(parts, 65535 + 1 + 120 + 2);
    // Unknown while the connection is down; the value after it counts
    // against the last one seen.
    e.on_connection(false, at + 1);
    e.on_connection(true, at + 2);
    let step = number(&mut e, "COUNT", Num::UInt(7), at + 3);
    assert_eq!(step.parts, [(at + 3, 5)]);
}

#[test]
fn the_work_order_follows_the_item_and_target_tags_and_survives_an_outage() {
    let mut e = engine(Vec::new());
    load_normal(&mut e, 1);
    let item = tag(&e, "ITEM");
    let order = |item: &str, target: Option<u64>| Order {
        item: Some(item.into()),
        target,
    };
    let step = e.on_reading(item, Reading::Text("ITEM-07 ".into()), 2, 2);
    assert_eq!(step.order, Some(order("ITEM-07", None)));
    let step = number(&mut e, "TARGET", Num::UInt(1500), 3);
    assert_eq!(step.order, Some(order("ITEM-07", Some(1500))));
    // The same again, or the unit out of reach and back: no new order.
    assert_eq!(number(&mut e, "TARGET", Num::UInt(1500), 4).order, None);
    e.on_connection(false, 5);
    e.on_connection(true, 6);
    assert_eq!(
        e.on_reading(item, Reading::Text("ITEM-07".into()), 7, 7)
            .order,
        None
    );
    assert_eq!(e.order(), &order("ITEM-07", Some(1500)));
    let step = e.on_reading(item, Reading::Text("ITEM-08".into()), 8, 8);
    assert_eq!(step.order, Some(order("ITEM-08", Some(1500))));
}

#[test]
fn limit_levels_through_the_engine_with_an_on_delay_in_virtual_time() {
    let limit = LimitCheck {
        on_delay: 2000,
        ..temp_limit(85.0)
    };
    let mut e = engine(vec![limit]);
    load_normal(&mut e, 0);
    number(&mut e, "TEMP", Num::Float(40.0), 1_000);
    // A 1 s excursion: nothing.
    assert!(raised(&number(&mut e, "TEMP", Num::Float(86.0), 10_000)).is_empty());
    assert!(raised(&e.advance(10_900)).is_empty());
    number(&mut e, "TEMP", Num::Float(60.0), 11_000);
    assert!(raised(&e.advance(20_000)).is_empty());
    // Above 85 for 2 s: raised once; then hovering around 85 within the
    // deadband: no clear, no second raise.
    let mut seen = Vec::new();
    let values = [86.0, 85.5, 86.5, 85.2, 86.5, 84.0, 86.0, 83.5, 85.5, 84.5];
    for (i, v) in values.into_iter().enumerate() {
        let at = 30_000 + i as u64 * 500;
        let step = number(&mut e, "TEMP", Num::Float(v), at);
        seen.extend(raised(&step));
        assert!(step.alarms().all(|(_, t, _)| t != Transition::Cleared));
        seen.extend(raised(&e.advance(at + 250)));
        if i == 3 {
            assert!(seen.is_empty(), "not before 2 s");
        }
    }
    assert_eq!(seen, ["temp-h"]);
    let a = e.alarms().find(|a| a.id == "temp-h").unwrap();
    assert!(a.active);
    assert_eq!(
        a.message, "TEMP (temp) = 86.5 °C, above the H limit 85 °C for 2.0 s",
        "value, limit, unit and how long"
    );
    let step = number(&mut e, "TEMP", Num::Float(82.9), 40_000);
    assert!(step
        .alarms()
        .any(|(a, t, _)| a.id == "temp-h" && t == Transition::Cleared));
}

#[test]
fn exported_tags_report_their_changes() {
    let mut e = engine(Vec::new());
    load_normal(&mut e, 1);
    let temp = tag(&e, "TEMP");
    let step = number(&mut e, "TEMP", Num::Float(41.5), 2);
    assert_eq!(step.exported, [(temp, Some(41.5))]);
    assert!(number(&mut e, "MODE", Num::Int(1), 3).exported.is_empty());
    let step = e.on_connection(false, 4);
    assert_eq!(step.exported, [(temp, None)]);
}

/// ISA-18.2 delays on a switching check, in virtual time: with a 5 s
/// on-delay a 3 s fault raises nothing and a 6 s one raises once; with a
/// 5 s off-delay a 3 s return clears nothing and a 6 s one clears once.
#[test]
fn on_and_off_delays_announce_only_conditions_that_last() {
    let mut e = engine(Vec::new()).delaying("ese", 5000, 5000);
    load_normal(&mut e, 0);
    number(&mut e, "MODE", Num::Int(1), 0);
    number(&mut e, "TEMP", Num::Float(40.0), 0);
    let mut transitions = Vec::new();
    let mut at = |e: &mut CellEngine, t: u64, open: Option<bool>| {
        let step = match open {
            Some(v) => set(e, "X0.06", !v, t),
            None => e.advance(t),
        };
        transitions.extend(step.alarms().map(|(a, tr, at)| (a.id.clone(), tr, at)));
    };
    // A 3 s fault: nothing.
    at(&mut e, 10_000, Some(true));
    at(&mut e, 12_000, None);
    at(&mut e, 13_000, Some(false));
    at(&mut e, 20_000, None);
    // A 6 s fault: raised once, 5 s after it began.
    at(&mut e, 30_000, Some(true));
    at(&mut e, 34_999, None);
    at(&mut e, 35_000, None);
    at(&mut e, 36_000, None);
    // A 3 s return: still active (the fault's return updates its
    // explanation).
    at(&mut e, 40_000, Some(false));
    at(&mut e, 43_000, Some(true));
    at(&mut e, 50_000, None);
    // A 6 s return: cleared once, 5 s after it began.
    at(&mut e, 60_000, Some(false));
    at(&mut e, 65_000, None);
    at(&mut e, 66_000, None);
    assert_eq!(
        transitions,
        [
            ("ese".to_string(), Transition::Raised, 35_000),
            ("ese".to_string(), Transition::Updated, 43_000),
            ("ese".to_string(), Transition::Cleared, 65_000),
        ]
    );
}

/// A high limit `h` on `TEMP` (°C, deadband 2), without delays or rates.
fn temp_limit(h: f64) -> LimitCheck {
    LimitCheck {
        comment: None,
        id: "temp".into(),
        tag: Signal::new("TEMP"),
        label: "temp".into(),
        unit: "°C".into(),
        deadband: 2.0,
        on_delay: 0,
        off_delay: 0,
        rates: Vec::new(),
        levels: vec![LimitLevel {
            level: Level::H,
            limit: h,
            severity: Severity::High,
        }],
    }
}

fn transitions(steps: &[EngineStep]) -> Vec<(String, Transition)> {
    steps
        .iter()
        .flat_map(|s| s.alarms().map(|(a, t, _)| (a.id.clone(), t)))
        .collect()
}

#[test]
fn a_reload_keeps_what_holds_and_judges_the_rest_by_the_new_checks() {
    let mut old = engine(vec![temp_limit(85.0)]);
    load_normal(&mut old, 0);
    assert_eq!(
        raised(&number(&mut old, "TEMP", Num::Float(90.0), 1_000)),
        ["temp-h"]
    );
    old.acknowledge("temp-h", "kim", None, 2_000).unwrap();

    // The same limit: the alarm is carried, still acknowledged, and the
    // value as it was changes nothing.
    let mut same = engine(vec![temp_limit(85.0)]);
    let steps = same.take_over(old.carry_over(), 3_000);
    assert_eq!(
        transitions(&steps),
        [("temp-h".to_string(), Transition::Restored)]
    );
    let a = same.alarms().find(|a| a.id == "temp-h").unwrap();
    assert!(a.active && a.acknowledged && a.acked_by.as_deref() == Some("kim"));
    assert!(same.connected());
    assert_eq!(
        same.value(tag(&same, "TEMP")),
        Some(cellwatch_models::engine::Value::Num(Num::Float(90.0)))
    );
    assert_eq!(same.state(), old.state());

    // The limit raised above the value: carried, then cleared by the new
    // check on the value as it was.
    let mut higher = engine(vec![temp_limit(95.0)]);
    let steps = higher.take_over(old.carry_over(), 3_000);
    assert_eq!(
        transitions(&steps),
        [
            ("temp-h".to_string(), Transition::Restored),
            ("temp-h".to_string(), Transition::Cleared),
        ]
    );
    // A check removed: its alarm is not carried.
    let mut without = engine(Vec::new());
    let steps = without.take_over(old.carry_over(), 3_000);
    assert!(transitions(&steps).is_empty(), "{:?}", transitions(&steps));
    // A new check whose condition holds on the values as they were: raised.
    let mut calm = engine(Vec::new());
    load_normal(&mut calm, 0);
    number(&mut calm, "TEMP", Num::Float(90.0), 1_000);
    let mut added = engine(vec![temp_limit(85.0)]);
    let steps = added.take_over(calm.carry_over(), 3_000);
    assert_eq!(
        transitions(&steps),
        [("temp-h".to_string(), Transition::Raised)]
    );
}

#[test]
fn a_number_that_is_not_one_is_bad_quality_never_a_limit_violation() {
    let mut e = engine(vec![temp_limit(85.0)]);
    load_normal(&mut e, 0);
    number(&mut e, "TEMP", Num::Float(40.0), 1_000);
    let t = tag(&e, "TEMP");
    for (i, (x, name)) in [
        (f64::INFINITY, "+inf"),
        (f64::NAN, "NaN"),
        (f64::NEG_INFINITY, "-inf"),
    ]
    .into_iter()
    .enumerate()
    {
        let at = 2_000 + i as u64 * 20_000;
        let step = number(&mut e, "TEMP", Num::Float(x), at);
        assert!(
            raised(&step).iter().all(|id| id == "tag-quality"),
            "{:?}",
            raised(&step)
        );
        // The text names the new reason once the last one has stood 10 s.
        assert!(raised(&e.advance(at + 10_000)).is_empty());
        let quality = e.alarms().find(|a| a.id == "tag-quality").unwrap();
        assert!(quality.active);
        assert!(
            quality
                .message
                .ends_with(&format!("TEMP (temp): {name} received, not a number")),
            "{}",
            quality.message
        );
        assert_eq!(e.value(t), None, "unknown while not a number");
        assert!(e.bad_tags().any(|b| b == t));
    }
    // A number again: the quality clears, and the limit is judged on it.
    let step = number(&mut e, "TEMP", Num::Float(90.0), 62_000);
    assert_eq!(raised(&step), ["temp-h"]);
    assert!(!e.alarms().find(|a| a.id == "tag-quality").unwrap().active);
    // While a limit alarm is active, NaN suspends the check: the alarm
    // holds, and the tag-quality alarm says why nothing is judged.
    let step = number(&mut e, "TEMP", Num::Float(f64::NAN), 63_000);
    assert_eq!(raised(&step), ["tag-quality"]);
    assert!(e.alarms().find(|a| a.id == "temp-h").unwrap().active);
}

/// Values sampled over a while and delivered together (one publish, a
/// republish after a cut, a late batch) are judged at their source times:
/// an excursion of 1.5 s with an on-delay of 1 s raises at 1 s into it and
/// clears at its end, though both values arrive in one call at one moment.
#[test]
fn a_batch_sampled_over_a_while_is_judged_at_its_source_times() {
    let mut limit = temp_limit(85.0);
    limit.on_delay = 1000;
    let mut e = engine(vec![limit]);
    load_normal(&mut e, 0);
    number(&mut e, "TEMP", Num::Float(40.0), 1_000);
    let temp = tag(&e, "TEMP");
    let at = |t: u64, v: f64| TagReading {
        tag: temp,
        reading: Reading::Number(Num::Float(v)),
        source_time: t,
    };
    let step = e.on_readings(&[at(10_000, 90.0), at(11_500, 60.0)], 20_000);
    let seen: Vec<(String, Transition)> =
        step.alarms().map(|(a, t, _)| (a.id.clone(), t)).collect();
    assert_eq!(
        seen,
        [
            ("temp-h".to_string(), Transition::Raised),
            ("temp-h".to_string(), Transition::Cleared)
        ]
    );
    let raised = step.alarms().next().unwrap().0;
    assert!(
        raised
            .message
            .contains("= 90 °C, above the H limit 85 °C for 1.0 s"),
        "{}",
        raised.message
    );
    // Shorter than the delay, together: nothing.
    let step = e.on_readings(&[at(30_000, 90.0), at(30_900, 60.0)], 40_000);
    assert_eq!(step.alarms().count(), 0);
}

/// Trusting the source's clock, the alarms of a batch are stamped with the
/// times the conditions changed at the source, not when the batch came; a
/// source time further back than the trust, or ahead of the agent, is not
/// believed.
#[test]
fn alarms_judged_in_a_late_batch_carry_the_source_times_the_agent_trusts() {
    let mut limit = temp_limit(85.0);
    limit.on_delay = 1000;
    let mut e = engine(vec![limit])
        .delaying("ese", 1000, 0)
        .trusting_source_time(60_000);
    load_normal(&mut e, 0);
    number(&mut e, "MODE", Num::Int(1), 0);
    number(&mut e, "TEMP", Num::Float(40.0), 1_000);
    let temp = tag(&e, "TEMP");
    let x006 = tag(&e, "X0.06");
    let num = |t: u64, v: f64| TagReading {
        tag: temp,
        reading: Reading::Number(Num::Float(v)),
        source_time: t,
    };
    let bit = |t: u64, v: bool| TagReading {
        tag: x006,
        reading: Reading::Good(v),
        source_time: t,
    };
    let times = |step: &EngineStep, id: &str| -> Vec<(Transition, u64)> {
        step.alarms()
            .filter(|(a, _, _)| a.id == id)
            .map(|(_, t, at)| (t, at))
            .collect()
    };
    // Both excursions arrive 8 s late, together.
    let step = e.on_readings(
        &[
            num(10_000, 90.0),
            bit(10_200, false),
            num(11_500, 60.0),
            bit(11_700, true),
        ],
        20_000,
    );
    assert_eq!(
        times(&step, "temp-h"),
        [(Transition::Raised, 11_000), (Transition::Cleared, 11_500)]
    );
    assert_eq!(
        times(&step, "ese"),
        [(Transition::Raised, 11_200), (Transition::Cleared, 11_700)]
    );
    // The machine-state history rows too, not when the batch came: idle
    // when the spindle got hot (the running rule), the fault when ESE was
    // raised, the recovery when it cleared.
    let states: Vec<(HistoryKind, u64)> = step.states().map(|(_, k, at)| (k, at)).collect();
    assert_eq!(
        states,
        [
            (HistoryKind::Normal, 10_000),
            (HistoryKind::Fault, 11_200),
            (HistoryKind::Recovery, 11_700)
        ]
    );
    // Further back than trusted (a source clock 2 min behind): the agent's
    // clock.
    let step = e.on_readings(&[bit(100_000, false), bit(101_500, true)], 220_000);
    assert_eq!(
        times(&step, "ese"),
        [
            (Transition::Raised, 220_000),
            (Transition::Cleared, 220_000)
        ]
    );
    // Ahead of the agent: the agent's clock.
    let step = e.on_readings(&[bit(300_000, false), bit(301_500, true)], 250_000);
    assert_eq!(
        times(&step, "ese"),
        [
            (Transition::Raised, 250_000),
            (Transition::Cleared, 250_000)
        ]
    );
}

/// A verdict waiting out its delay while changes of what it reads were
/// lost for good (a queue that overflowed, a publish the server could not
/// send again) says so when it comes: the excursion may have ended and
/// begun again unseen. A gap elsewhere, or none, says nothing.
#[test]
fn a_delay_run_across_a_gap_says_its_trigger_is_uncertain() {
    let mut limit = temp_limit(85.0);
    limit.on_delay = 1000;
    let mut e = engine(vec![limit]).delaying("ese", 1000, 0);
    load_normal(&mut e, 0);
    number(&mut e, "MODE", Num::Int(1), 0);
    number(&mut e, "TEMP", Num::Float(40.0), 1_000);
    let (temp, x006, count) = (tag(&e, "TEMP"), tag(&e, "X0.06"), tag(&e, "COUNT"));
    let message = |step: &EngineStep, id: &str| {
        step.alarms()
            .find(|(a, t, _)| a.id == id && *t == Transition::Raised)
            .map(|(a, _, _)| a.message.clone())
    };
    // The spindle runs hot and the Y switch opens, both waiting out 1 s;
    // a value of TEMP and one of X0.06 are lost meanwhile, then values
    // come again (which end the tags' own marks).
    number(&mut e, "TEMP", Num::Float(90.0), 10_000);
    set(&mut e, "X0.06", false, 10_000);
    e.on_gap(Some(&[temp, x006]), 2, "2 values lost in a full queue");
    number(&mut e, "TEMP", Num::Float(91.0), 10_500);
    set(&mut e, "X0.06", false, 10_500);
    let step = e.advance(11_100);
    let temp_h = message(&step, "temp-h").unwrap();
    assert!(
        temp_h.ends_with("(trigger uncertain: 2 values lost in a full queue)"),
        "{temp_h}"
    );
    let ese = message(&step, "ese").unwrap();
    assert!(
        ese.ends_with("(trigger uncertain: 2 values lost in a full queue)"),
        "{ese}"
    );
    // Both back; again, with a gap on a tag neither reads (the parts
    // counter): nothing said.
    number(&mut e, "TEMP", Num::Float(40.0), 20_000);
    set(&mut e, "X0.06", true, 20_000);
    e.advance(21_100);
    number(&mut e, "TEMP", Num::Float(90.0), 30_000);
    set(&mut e, "X0.06", false, 30_000);
    e.on_gap(Some(&[count]), 1, "1 value lost in a full queue");
    let step = e.advance(31_100);
    assert!(!message(&step, "temp-h").unwrap().contains("uncertain"));
    assert!(!message(&step, "ese").unwrap().contains("uncertain"));
}

/// The same for an alarm delay of a contact check (switching or discrete):
/// the fault lasted 1.5 s at the source, the delay is 1 s.
#[test]
fn a_contact_fault_in_a_batch_outlasting_its_delay_is_raised_and_cleared() {
    let mut e = engine(Vec::new()).delaying("ese", 1000, 0);
    load_normal(&mut e, 0);
    number(&mut e, "MODE", Num::Int(1), 0);
    number(&mut e, "TEMP", Num::Float(40.0), 0);
    let x006 = tag(&e, "X0.06");
    let at = |t: u64, v: bool| TagReading {
        tag: x006,
        reading: Reading::Good(v),
        source_time: t,
    };
    let step = e.on_readings(&[at(10_000, false), at(11_500, true)], 12_000);
    let seen: Vec<Transition> = step
        .alarms()
        .filter(|(a, _, _)| a.id == "ese")
        .map(|(_, t, _)| t)
        .collect();
    assert_eq!(seen, [Transition::Raised, Transition::Cleared]);
    // 0.9 s: nothing, together or not.
    let step = e.on_readings(&[at(20_000, false), at(20_900, true)], 21_000);
    assert_eq!(step.alarms().filter(|(a, _, _)| a.id == "ese").count(), 0);
}

/// A coil that is a comparison: its culprit, raised through the engine,
/// names the number compared and what it needs, with the variable's
/// comment.
#[test]
fn a_comparison_culprit_names_the_number_it_compared() {
    let tags = kit::tags_at(&["TEMP", "LIMIT", "X1"]);
    let check = |id: &str, condition: &str| SwitchingCheck {
        comments: [
            (Signal::new("X1"), "Coolant on".to_string()),
            (Signal::new("TEMP"), "Spindle temperature".to_string()),
        ]
        .into_iter()
        .collect(),
        ..kit::switching_check(
            id,
            SwitchingFunction::from_expr(Signal::new(id), &Expr::parse(condition).unwrap()),
            Severity::High,
        )
    };
    let sets: Vec<Box<dyn CheckSet>> = vec![Box::new(SwitchingChecks::new(vec![
        check("hot", "TEMP > 80.5 * X1"),
        check("over", "TEMP >= LIMIT"),
    ]))];
    let mut e = kit::cell("m01", tags, sets);
    e.on_connection(true, 1);
    set(&mut e, "X1", true, 1);
    number(&mut e, "LIMIT", Num::Int(95), 1);
    number(&mut e, "TEMP", Num::Float(70.0), 2);
    let step = number(&mut e, "TEMP", Num::Float(85.25), 3);
    let raised: Vec<(String, String)> = step
        .alarms()
        .filter(|(_, t, _)| *t == Transition::Raised)
        .map(|(a, _, _)| {
            (
                a.message.clone(),
                a.culprits
                    .iter()
                    .map(ToString::to_string)
                    .collect::<Vec<_>>()
                    .join(", "),
            )
        })
        .collect();
    assert_eq!(
        raised,
        [(
            "HOT at step 1: TEMP = 85.25 (needs <= 80.5): Spindle temperature".to_string(),
            "TEMP = 85.25 (needs <= 80.5): Spindle temperature, X1 = 1 (expected 0): Coolant on"
                .to_string()
        )]
    );
    let step = number(&mut e, "TEMP", Num::Float(96.0), 4);
    let (over, _, _) = step
        .alarms()
        .find(|(a, t, _)| a.id == "over" && *t == Transition::Raised)
        .unwrap();
    assert_eq!(
        over.message,
        "OVER: TEMP = 96.0 (needs < LIMIT, LIMIT = 95): Spindle temperature"
    );
    assert_eq!(
        over.culprits[0].to_string(),
        "TEMP = 96.0 (needs < LIMIT, LIMIT = 95): Spindle temperature"
    );
}

/// A check set that raises one alarm blaming a comparison, as a set that
/// reads no numbers does.
struct BlamesHot;

impl CheckSet for BlamesHot {
    fn inputs(&self) -> Vec<Signal> {
        vec![Signal::new("TEMP > 80")]
    }

    fn alarms(&self) -> Vec<cellwatch_models::engine::Declared> {
        Vec::new()
    }

    fn on_change(
        &mut self,
        signal: &Signal,
        value: Option<bool>,
        _before: Option<bool>,
        _now: u64,
        out: &mut Vec<cellwatch_models::engine::Finding>,
    ) {
        out.push(cellwatch_models::engine::Finding {
            id: "hot".into(),
            kind: AlarmKind::Switching,
            severity: Severity::High,
            fault_type: "HOT".into(),
            latched: false,
            active: value == Some(true),
            fault_step: None,
            culprits: vec![cellwatch_models::explain::Culprit {
                address: signal.clone(),
                value: true,
                expected: false,
                comment: None,
                trigger: true,
                compared: None,
            }],
            message: "hot".into(),
            at: None,
        });
    }
}

#[test]
fn the_engine_shows_a_comparison_culprit_a_check_could_not_with_its_numbers() {
    let tags = kit::tags_at(&["TEMP"]);
    let io: CommentDb = [(Signal::new("TEMP"), "Spindle temperature".to_string())]
        .into_iter()
        .collect();
    let mut e = kit::cell("m01", tags, vec![Box::new(BlamesHot)]).commenting(io);
    e.on_connection(true, 1);
    number(&mut e, "TEMP", Num::Int(70), 2);
    let step = number(&mut e, "TEMP", Num::Int(85), 3);
    let (alarm, _, _) = step.alarms().next().unwrap();
    assert_eq!(
        alarm.culprits[0].to_string(),
        "TEMP = 85 (needs <= 80): Spindle temperature"
    );
}
