//! Consequences among a clamp station's transition timers (paper 001),
//! its stuck steps (paper 004) and the hydraulic fault that drops its
//! clamp valve: the same judgement as for switching checks
//! (`consequences.rs`), on what a timer or a step waits for.
//! The station (`tests/data/station/station.il`) drives its valves from
//! its chart's step flags (`station.sfc.toml`), interlocked by the
//! hydraulic fault G10.00: the clamp valve Y2.00 and the "part clamped"
//! signal to the robot Y3.00 are the fault's forced outputs.

#![allow(clippy::unwrap_used)] // test helpers fail loudly by design

use std::collections::BTreeSet;

use cellwatch_models::alarm::Severity;
use cellwatch_models::comments::CommentDb;
use cellwatch_models::consequence::forced_outputs;
use cellwatch_models::engine::{CellEngine, CheckSet, EngineStep, SwitchingCheck, SwitchingChecks};
use cellwatch_models::signal::{Observability, Signal};
use cellwatch_models::switching::SwitchingFunction;
use cellwatch_models::timer::checks::TimerChecks;
use cellwatch_models::timer::learn::LearnedTransition;

mod kit;
use kit::{raised, set, set_all};

const STATION: &str = include_str!("../../tests/data/station/station.il");
const CHART: &str = include_str!("../../tests/data/station/station.sfc.toml");

/// Every address the station's program, chart and timers name.
const TAGS: [&str; 13] = [
    "X1.00", "X1.01", "X1.02", "X1.03", "X1.04", "X1.05", "R100.00", "R100.01", "R100.02", "Y2.00",
    "Y2.02", "Y3.00", "G10.00",
];

/// `+event after +trigger`, learned with `window`.
fn learned(id: u32, trigger: &str, event: &str, window: [u64; 2]) -> LearnedTransition {
    let [from, to] = window;
    kit::triggered(
        id,
        trigger,
        event,
        (from + to) / 2,
        [from + 50, to - 50],
        window,
    )
}

/// The station's timers, as learned from its commissioning runs:
/// #001 the robot's "part clamped" after it placed the part, #002 the
/// clamp's end switch after its valve, #003 the locating pin's end switch
/// after its valve.
fn timers() -> TimerChecks {
    let model = kit::timer_model(
        "common",
        &["X1.03", "Y3.00", "Y2.00", "X1.02", "Y2.02", "X1.05"],
        vec![
            learned(1, "X1.03", "Y3.00", [900, 1500]),
            learned(2, "Y2.00", "X1.02", [800, 1200]),
            learned(3, "Y2.02", "X1.05", [300, 600]),
        ],
    );
    kit::timer_checks("station", &model)
}

/// The hydraulic fault, a switching check over G10.00 with the outputs
/// the program derives from it.
fn hydraulic() -> SwitchingChecks {
    let p = kit::compile("station.il", STATION);
    let observable = Observability::default_for(p.dialect());
    let coil = Signal::new("G10.00");
    let sf = SwitchingFunction::expand(&p, &coil, &observable).unwrap();
    let forces = forced_outputs(&p, &coil, &observable, |s| TAGS.contains(&s.name()));
    SwitchingChecks::new(vec![SwitchingCheck {
        forces,
        ..kit::switching_check("hydraulic", sf, Severity::High)
    }])
}

/// The chart's step supervision, each step reading the outputs the
/// program drives from its flag.
fn chart() -> Box<dyn CheckSet> {
    let p = kit::compile("station.il", STATION);
    let checks = kit::supervision(kit::charts("station.sfc.toml", CHART), CommentDb::default());
    Box::new(
        checks.driving(&p, &Observability::default_for(p.dialect()), |s| {
            TAGS.contains(&s.name())
        }),
    )
}

fn station(extra: Vec<Box<dyn CheckSet>>) -> CellEngine {
    let mut sets: Vec<Box<dyn CheckSet>> = vec![Box::new(hydraulic()), Box::new(timers())];
    sets.extend(extra);
    kit::related(kit::cell("station", kit::tags_at(&TAGS), sets), false)
}

/// Idle: the pump runs with its pressure, no part, step S0.
fn idle(e: &mut CellEngine) {
    e.on_connection(true, 0);
    let mut values: Vec<(&str, bool)> = TAGS.iter().map(|&a| (a, false)).collect();
    for (a, v) in &mut values {
        *v = matches!(*a, "X1.00" | "X1.01" | "R100.00");
    }
    set_all(e, &values, 0);
    assert!(e.alarms().all(|a| !a.active), "idle raises nothing");
}

/// The robot places a part at `at`: the chart goes to S1 (clamp), the
/// program drives the clamp and the locating pin.
fn place(e: &mut CellEngine, at: u64) {
    let values = [
        ("X1.03", true),
        ("R100.00", false),
        ("R100.01", true),
        ("Y2.00", true),
        ("Y2.02", true),
    ];
    for s in set_all(e, &values, at) {
        assert!(raised(&s).is_empty());
    }
}

/// The part placed, the locating pin goes in (0.5 s) and the clamp closes
/// (1.1 s): "part clamped" to the robot, the chart on to S2 (weld), the
/// pin's valve off.
fn clamp(e: &mut CellEngine) {
    let values = [
        (500, "X1.05", true),
        (1_100, "X1.02", true),
        (1_100, "Y3.00", true),
        (1_100, "R100.01", false),
        (1_100, "R100.02", true),
        (1_100, "Y2.02", false),
    ];
    for (at, a, v) in values {
        assert!(raised(&set(e, a, v, at)).is_empty(), "{a} at {at}");
    }
}

/// The pressure falls at `at`: the PLC's fault coil and the valve it
/// drops are read back with it.
fn pressure_falls(e: &mut CellEngine, at: u64) -> Vec<Mark> {
    let steps = set_all(
        e,
        &[("X1.01", false), ("G10.00", true), ("Y2.00", false)],
        at,
    );
    steps.iter().flat_map(marks).collect()
}

/// An alarm raised, and its cause and first-out if it is a consequence.
type Mark = (String, Option<(String, String)>);

fn marks(step: &EngineStep) -> Vec<Mark> {
    raised(step)
        .into_iter()
        .map(|a| {
            let c = a.consequence.map(|c| (c.cause, c.first_out));
            (a.id, c)
        })
        .collect()
}

fn first_out(id: &str) -> Mark {
    (id.into(), None)
}

fn hydraulics(id: &str) -> Mark {
    (id.into(), Some(("hydraulic".into(), "hydraulic".into())))
}

/// What alarm `id`'s consequence went through.
fn through(e: &CellEngine, id: &str) -> Vec<(Signal, bool)> {
    let a = e.alarms().find(|a| a.id == id).unwrap();
    a.consequence.as_ref().unwrap().through.clone()
}

#[test]
fn a_normal_cycle_raises_nothing() {
    let mut e = station(Vec::new());
    idle(&mut e);
    place(&mut e, 100);
    clamp(&mut e);
    assert!(raised(&e.advance(10_000)).is_empty());
}

#[test]
fn the_timers_follow_from_the_hydraulics_through_their_event_or_their_request() {
    let e = station(Vec::new());
    let edges: BTreeSet<(String, String)> =
        e.relation().edges().map(|x| (x.cause, x.effect)).collect();
    // #001 waits for Y3.00 and #002 is started by Y2.00, both forced by
    // the hydraulic fault; nothing holds the locating pin #003 waits for.
    assert_eq!(
        edges,
        BTreeSet::from([
            ("hydraulic".into(), "station-001".into()),
            ("hydraulic".into(), "station-002".into()),
        ])
    );
}

#[test]
fn the_pressure_falling_as_the_clamp_closes_makes_the_robot_wait_for_the_hydraulics() {
    let mut e = station(Vec::new());
    idle(&mut e);
    place(&mut e, 100);
    set(&mut e, "X1.05", true, 500);
    // The pressure falls as the clamp reaches its end: the clamp is
    // closed, the hydraulic fault is the first-out and the PLC withholds
    // "part clamped" from the robot.
    assert_eq!(pressure_falls(&mut e, 1_000), [first_out("hydraulic")]);
    let s = set_all(
        &mut e,
        &[("X1.02", true), ("R100.01", false), ("R100.02", true)],
        1_000,
    );
    assert!(s.iter().all(|s| raised(s).is_empty()));
    // #001 falls late: with the hydraulics normal, Y3.00 (the clamp
    // closed and no fault) would have come. A consequence, through Y3.00.
    assert_eq!(marks(&e.advance(1_600)), [hydraulics("station-001")]);
    assert_eq!(through(&e, "station-001"), [(Signal::new("Y3.00"), false)]);
}

#[test]
fn the_valve_dropped_before_the_clamp_closed_late_clamp_follows_the_pin_does_not() {
    let mut e = station(Vec::new());
    idle(&mut e);
    place(&mut e, 100);
    // The pressure falls before the clamp closes: the valve drops, the
    // clamp stops short of its end switch; the locating pin's end switch
    // is broken besides.
    assert_eq!(pressure_falls(&mut e, 300), [first_out("hydraulic")]);
    // The pin's timer: nothing the hydraulics hold is what it waits for
    // or what starts it. A first-out of its own.
    assert_eq!(marks(&e.advance(700)), [first_out("station-003")]);
    // The clamp's timer: its request, the valve, was taken back by the
    // hydraulic fault (on without it): its end switch would have come.
    assert_eq!(marks(&e.advance(1_300)), [hydraulics("station-002")]);
    assert_eq!(through(&e, "station-002"), [(Signal::new("Y2.00"), false)]);
    // The robot's timer waits for Y3.00, which the fault holds off; but
    // with the hydraulics normal Y3.00 is the end switch, still open: by
    // the program alone, the robot's wait is not the hydraulics' (the
    // end switch's absence is not known to follow from the valve here).
    assert_eq!(marks(&e.advance(1_600)), [first_out("station-001")]);
}

#[test]
fn a_broken_end_switch_keeps_the_robots_wait_its_own_though_the_pressure_falls_later() {
    let mut e = station(Vec::new());
    idle(&mut e);
    place(&mut e, 100);
    set(&mut e, "X1.05", true, 500);
    // The clamp's end switch never makes: its timer, with the valve on
    // and nothing in fault, is a first-out.
    assert_eq!(marks(&e.advance(1_300)), [first_out("station-002")]);
    // Then the pressure falls, and the robot's timer falls late with the
    // hydraulic fault active: Y3.00 is held off by it, but without it
    // Y3.00 would still be off (the end switch is open). Not its
    // consequence, though its culprit is a signal the fault holds.
    assert_eq!(pressure_falls(&mut e, 1_400), [first_out("hydraulic")]);
    let s = e.advance(1_600);
    assert_eq!(marks(&s), [first_out("station-001")]);
    let robot = &raised(&s)[0];
    assert_eq!(robot.culprits[0].address, Signal::new("Y3.00"));
}

#[test]
fn a_step_follows_from_the_hydraulics_through_the_valve_it_drives() {
    let e = station(vec![chart()]);
    let edges: BTreeSet<(String, String)> =
        e.relation().edges().map(|x| (x.cause, x.effect)).collect();
    // S1 (clamp) and S2 (weld) read the clamp valve the program drives
    // from their flags; S1 holds the end switch the clamp's timer waits
    // for.
    assert_eq!(
        edges,
        BTreeSet::from([
            ("hydraulic".into(), "sfc-C1-S1".into()),
            ("hydraulic".into(), "sfc-C1-S2".into()),
            ("hydraulic".into(), "station-001".into()),
            ("hydraulic".into(), "station-002".into()),
            ("sfc-C1-S1".into(), "station-002".into()),
        ])
    );
}

#[test]
fn the_clamp_step_stuck_with_its_valve_dropped_is_the_hydraulics_consequence() {
    let mut e = station(vec![chart()]);
    idle(&mut e);
    place(&mut e, 100);
    // The pressure falls before the clamp closes: the valve drops and the
    // clamp stops short of its end switch; the locating pin goes in.
    assert_eq!(pressure_falls(&mut e, 300), [first_out("hydraulic")]);
    set(&mut e, "X1.05", true, 500);
    assert_eq!(marks(&e.advance(1_300)), [hydraulics("station-002")]);
    assert_eq!(marks(&e.advance(1_600)), [first_out("station-001")]);
    // S1 is stuck at 2.1 s waiting for "clamp closed": with the
    // hydraulics normal, the valve it drives would be on. A consequence,
    // through the valve.
    let s = e.advance(2_100);
    assert_eq!(marks(&s), [hydraulics("sfc-C1-S1")]);
    assert_eq!(through(&e, "sfc-C1-S1"), [(Signal::new("Y2.00"), false)]);
    let stuck = &raised(&s)[0];
    assert!(
        stuck
            .message
            .contains("t2 (Clamp closed) waits for X1.02 = 0"),
        "{}",
        stuck.message
    );
}

#[test]
fn the_clamp_step_stuck_with_its_valve_on_and_its_end_switch_broken_is_its_own() {
    let mut e = station(vec![chart()]);
    idle(&mut e);
    place(&mut e, 100);
    set(&mut e, "X1.05", true, 500);
    // The end switch never makes, with the valve on: the clamp's timer and
    // the robot's are first-outs, nothing being in fault.
    assert_eq!(marks(&e.advance(1_300)), [first_out("station-002")]);
    assert_eq!(marks(&e.advance(1_600)), [first_out("station-001")]);
    // The pressure switch drops at 2.05 s; the PLC's fault coil and the
    // valve it drops come in the next publish, after S1's deadline.
    assert_eq!(
        marks(&set(&mut e, "X1.01", false, 2_050)),
        [first_out("hydraulic")]
    );
    // S1 stuck with the hydraulic fault active, but the valve it drives is
    // on and would be on without the fault; "clamp closed" would still be
    // missing. Its own first-out.
    assert_eq!(marks(&e.advance(2_100)), [first_out("sfc-C1-S1")]);
    let later = set_all(&mut e, &[("G10.00", true), ("Y2.00", false)], 2_150);
    assert!(later.iter().all(|s| raised(s).is_empty()));
}

#[test]
fn the_weld_step_stuck_with_the_valve_holding_its_part_dropped_follows_from_the_hydraulics() {
    let mut e = station(vec![chart()]);
    idle(&mut e);
    place(&mut e, 100);
    clamp(&mut e);
    // The weld never finishes; the pressure falls meanwhile and drops the
    // valve S2 holds the part with (and "part clamped" to the robot): S2
    // stuck at 6.1 s follows from it.
    assert_eq!(pressure_falls(&mut e, 3_000), [first_out("hydraulic")]);
    set(&mut e, "Y3.00", false, 3_000);
    assert_eq!(marks(&e.advance(6_100)), [hydraulics("sfc-C1-S2")]);
}

#[test]
fn a_step_stuck_though_its_transition_could_fire_is_not_the_hydraulics_doing() {
    let mut e = station(vec![chart()]);
    idle(&mut e);
    place(&mut e, 100);
    set(&mut e, "X1.05", true, 500);
    assert_eq!(marks(&e.advance(1_300)), [first_out("station-002")]);
    assert_eq!(marks(&e.advance(1_600)), [first_out("station-001")]);
    // The pressure switch drops (the coil and the valve not yet read
    // back); the end switch makes, but the chart does not step on.
    assert_eq!(
        marks(&set(&mut e, "X1.01", false, 2_050)),
        [first_out("hydraulic")]
    );
    set(&mut e, "X1.02", true, 2_060);
    // S1 stuck with t2 able to fire now: the hydraulics keep nothing from
    // it.
    assert_eq!(marks(&e.advance(2_100)), [first_out("sfc-C1-S1")]);
}
