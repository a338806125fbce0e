//! Consequence alarms and first-out on paper 000's engraving machine:
//! ESE (emergency stop error, coil G8.02) and CSD (cycle start disability,
//! coil G9.00), once as the paper writes them (independent) and once with
//! the emergency-stop coil a contact of the cycle-start logic, as on real
//! machines (`tests/data/paper000/csd-ese.il`): there an emergency stop
//! also trips CSD, which is ESE's consequence. A transition timer waiting
//! for what a stuck step waits for follows from the step. The press of
//! `tests/data/press/`, in three languages, is in `press.rs`.

#![allow(clippy::unwrap_used)] // test helpers fail loudly by design

use std::collections::{BTreeSet, HashMap};

use cellwatch_models::alarm::Severity;
use cellwatch_models::comments::CommentDb;
use cellwatch_models::engine::{CellEngine, CheckSet, EngineStep, SwitchingCheck, SwitchingChecks};
use cellwatch_models::expr::Expr;
use cellwatch_models::program::Program;
use cellwatch_models::signal::{Observability, Signal};
use cellwatch_models::switching::SwitchingFunction;
use proptest::prelude::*;

mod press;

#[path = "../kit/mod.rs"]
mod kit;
use kit::{raised, set, CSD, CSD_ESE, CSD_NORMAL, ESE, ESE_NORMAL};

fn check(id: &str, source: &str, coil: &str, armed_when: Option<&str>) -> SwitchingCheck {
    let sf = kit::switching_function(&format!("{id}.il"), source, coil);
    SwitchingCheck {
        armed_when: armed_when.map(|a| {
            SwitchingFunction::from_expr(
                Signal::new(&format!("{id}.armed")),
                &Expr::parse(a).unwrap(),
            )
        }),
        ..kit::switching_check(id, sf, Severity::High)
    }
}

/// ESE and CSD (armed while cycle start is pressed) over `csd`, every
/// contact they read a tag, with G8.02 a tag too (the PLC's coil, as the
/// server publishes it).
fn engine(csd: &str, suppress: bool) -> CellEngine {
    let checks = vec![
        check("ese", ESE, "G8.02", None),
        check("csd", csd, "G9.00", Some("X200.01")),
    ];
    let mut signals = BTreeSet::new();
    for c in &checks {
        signals.extend(c.sf.leaves());
        signals.extend(c.armed_when.iter().flat_map(SwitchingFunction::leaves));
    }
    signals.insert(Signal::new("G8.02"));
    let sets: Vec<Box<dyn CheckSet>> = vec![Box::new(SwitchingChecks::new(checks))];
    kit::related(kit::cell("m01", kit::tags(signals), sets), suppress)
}

/// Both machines' normal values, cycle start released, G8.02 off.
fn normal(e: &mut CellEngine) {
    e.on_connection(true, 1);
    first_values(e, 1);
    assert!(
        e.alarms().all(|a| !a.active),
        "the normal values raise nothing"
    );
}

/// Every tag's normal value at `at`, as a new subscription's first values.
fn first_values(e: &mut CellEngine, at: u64) {
    for values in [ESE_NORMAL, CSD_NORMAL] {
        kit::load(e, values, at);
    }
    set(e, "G8.02", false, at);
}

/// An alarm raised, and its (cause, first-out, suppressed) if it is a
/// consequence.
type Mark = (String, Option<(String, String, bool)>);

/// The mark of each alarm raised.
fn marks(step: &EngineStep) -> Vec<Mark> {
    raised(step)
        .into_iter()
        .map(|a| {
            let c = a
                .consequence
                .map(|c| (c.cause.clone(), c.first_out.clone(), c.suppressed));
            (a.id, c)
        })
        .collect()
}

#[test]
fn the_relation_is_derived_from_the_programs_and_printed_for_review() {
    let independent = engine(CSD, false);
    assert!(independent.relation().is_empty());
    assert_eq!(
        independent.relation().render(),
        "no alarm of the cell's checks follows from another\n\
         communication -> every alarm raised while the link is down\n\
         tag-quality -> an alarm whose culprits are all tags of bad quality\n"
    );
    let related = engine(CSD_ESE, false);
    assert_eq!(
        related.relation().render(),
        "ese -> csd   csd reads G8.02, which ese's fault holds\n\
         communication -> every alarm raised while the link is down\n\
         tag-quality -> an alarm whose culprits are all tags of bad quality\n"
    );
}

#[test]
fn an_emergency_stop_that_trips_cycle_start_is_first_out_and_csd_its_consequence() {
    for suppress in [false, true] {
        let mut e = engine(CSD_ESE, suppress);
        normal(&mut e);
        set(&mut e, "X200.01", true, 2); // cycle start pressed
                                         // The Y over-travel switch opens: ESE, a first-out.
        let s = set(&mut e, "X0.06", false, 3);
        assert_eq!(marks(&s), [("ese".to_string(), None)]);
        // The PLC's emergency-stop coil comes on: CSD follows from ESE.
        let s = set(&mut e, "G8.02", true, 4);
        assert_eq!(
            marks(&s),
            [(
                "csd".to_string(),
                Some(("ese".into(), "ese".into(), suppress))
            )]
        );
        let csd = &raised(&s)[0];
        assert_eq!(csd.culprits.len(), 1);
        assert_eq!(csd.culprits[0].address, Signal::new("G8.02"));
        assert_eq!(csd.is_suppressed(), suppress);
    }
}

#[test]
fn on_the_papers_programs_ese_and_csd_stay_independent() {
    let mut e = engine(CSD, true);
    normal(&mut e);
    set(&mut e, "X200.01", true, 2);
    let s = set(&mut e, "X0.06", false, 3);
    assert_eq!(marks(&s), [("ese".to_string(), None)]);
    // The coil comes on: CSD does not read it.
    assert!(raised(&set(&mut e, "G8.02", true, 4)).is_empty());
    // Cycle start in JOG mode: CSD by its own culprit, a first-out too.
    let s = set(&mut e, "X201.06", true, 5);
    assert_eq!(marks(&s), [("csd".to_string(), None)]);
}

#[test]
fn two_independent_faults_stay_two_first_outs() {
    let mut e = engine(CSD_ESE, true);
    normal(&mut e);
    set(&mut e, "X200.01", true, 2);
    // CSD first, by JOG mode: its own culprit.
    let s = set(&mut e, "X201.06", true, 3);
    assert_eq!(marks(&s), [("csd".to_string(), None)]);
    // Then an emergency stop: ESE does not follow from CSD.
    let s = set(&mut e, "X0.06", false, 4);
    assert_eq!(marks(&s), [("ese".to_string(), None)]);
}

#[test]
fn an_alarm_raised_while_the_link_is_down_follows_from_the_communication_alarm() {
    let mut e = engine(CSD_ESE, false);
    normal(&mut e);
    set(&mut e, "X200.01", true, 2);
    e.on_connection(false, 3);
    assert!(e.alarms().any(|a| a.id == "communication" && a.active));
    // Nothing raises while every tag is unknown; back up, a fault on fresh
    // values is a first-out even while the alarm waits out its off-delay.
    e.on_connection(true, 4);
    first_values(&mut e, 4);
    let s = set(&mut e, "X0.06", false, 5);
    assert_eq!(marks(&s), [("ese".to_string(), None)]);
}

/// Each contact either machine reads, and G8.02.
fn contacts() -> Vec<&'static str> {
    vec![
        "X0.06", "X0.04", "X0.0F", "X200.03", "X200.01", "X201.06", "X201.02", "X201.03", "G0.00",
        "F17.00", "R0.00", "G8.02",
    ]
}

/// The values `normal` sets, as this test reads them from the same files.
fn normal_values(e: &CellEngine) -> HashMap<Signal, bool> {
    let mut values = HashMap::new();
    for text in [ESE_NORMAL, CSD_NORMAL] {
        for (a, v) in kit::snapshot(text) {
            if e.tag_index(&Signal::new(a)).is_some() {
                values.insert(Signal::new(a), v);
            }
        }
    }
    values.insert(Signal::new("G8.02"), false);
    values
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// An alarm is marked a consequence exactly when, computed here from
    /// the values set and the programs alone, its cause's fault is active
    /// and its own fault would not hold with what the cause holds (ESE's
    /// coil G8.02) at its normal value; ESE, which follows from nothing,
    /// never is.
    #[test]
    fn an_alarm_is_a_consequence_exactly_when_its_fault_would_not_hold_without_the_cause(
        changes in prop::collection::vec((0..12usize, any::<bool>()), 1..60),
    ) {
        let ese = check("ese", ESE, "G8.02", None);
        let csd = check("csd", CSD_ESE, "G9.00", Some("X200.01"));
        let mut e = engine(CSD_ESE, true);
        normal(&mut e);
        let mut values = normal_values(&e);
        for (k, (c, v)) in changes.into_iter().enumerate() {
            let contact = contacts()[c];
            values.insert(Signal::new(contact), v);
            let s = set(&mut e, contact, v, 10 + k as u64);
            for a in raised(&s) {
                let expected = match a.id.as_str() {
                    "csd" => {
                        let cause_active = ese.sf.evaluate(|x| values[x]).0;
                        let without = |x: &Signal| {
                            if *x == Signal::new("G8.02") { false } else { values[x] }
                        };
                        let armed = csd.armed_when.as_ref().unwrap().evaluate(without).0;
                        let would_hold = armed && csd.sf.evaluate(without).0;
                        cause_active && !would_hold
                    }
                    _ => false,
                };
                prop_assert_eq!(
                    a.consequence.is_some(),
                    expected,
                    "{} after {} = {}: {:?} with {:?}",
                    a.id,
                    contact,
                    v,
                    a.consequence,
                    a.culprits
                );
                if let Some(c) = &a.consequence {
                    prop_assert!(c.suppressed);
                    prop_assert_eq!(&c.cause, "ese");
                }
            }
        }
    }
}

/// A clamp cylinder: step S1 drives it out and waits for its end switch
/// (`X1.00`); a learned transition timer waits for the same switch after
/// the valve (`Y1.00`).
const CLAMP: &str = r#"
[[chart]]
name = "C1"
initial = "S0"

[[chart.step]]
name = "S0"
flag = "S0.X"

[[chart.step]]
name = "S1"
flag = "S1.X"
supervision = "1s"

[[chart.transition]]
id = "t1"
from = "S0"
to = "S1"
condition = "X0.00"

[[chart.transition]]
id = "t2"
from = "S1"
to = "S0"
condition = "X1.00"
"#;

#[test]
fn a_timer_waiting_for_what_a_stuck_step_waits_for_follows_from_it() {
    let model = kit::timer_model(
        "common",
        &["Y1.00", "X1.00"],
        vec![kit::triggered(
            2,
            "Y1.00",
            "X1.00",
            1000,
            [950, 1050],
            [800, 4000],
        )],
    );
    let timers = kit::timer_checks("clamp", &model);
    let chart = kit::supervision(kit::charts("clamp.sfc.toml", CLAMP), CommentDb::default());
    let tags = kit::tags_at(&["S0.X", "S1.X", "X0.00", "X1.00", "Y1.00"]);
    let sets: Vec<Box<dyn CheckSet>> = vec![Box::new(chart), Box::new(timers)];
    let e = kit::cell("c", tags, sets);
    assert_eq!(
        e.relation().render(),
        "sfc-C1-S1 -> clamp-002   clamp-002 reads X1.00, which sfc-C1-S1's fault holds\n\
         communication -> every alarm raised while the link is down\n\
         tag-quality -> an alarm whose culprits are all tags of bad quality\n"
    );
    // The clamp sticks: S1 is stuck first (1 s), then the timer is late
    // (4 s), waiting for the same switch: a consequence.
    let mut e = kit::related(e, false);
    e.on_connection(true, 0);
    for (a, v) in [
        ("S0.X", true),
        ("S1.X", false),
        ("X0.00", false),
        ("X1.00", false),
        ("Y1.00", false),
    ] {
        set(&mut e, a, v, 0);
    }
    set(&mut e, "X0.00", true, 100);
    set(&mut e, "S0.X", false, 100);
    set(&mut e, "S1.X", true, 100);
    set(&mut e, "Y1.00", true, 100);
    assert_eq!(marks(&e.advance(1_200)), [("sfc-C1-S1".to_string(), None)]);
    assert_eq!(
        marks(&e.advance(4_200)),
        [(
            "clamp-002".to_string(),
            Some(("sfc-C1-S1".into(), "sfc-C1-S1".into(), false))
        )]
    );
}
