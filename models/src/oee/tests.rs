//! A hand-made shift with every loss, worked out by hand.

use super::*;
use crate::report::StopCause;

const MIN: u64 = 60_000;
const H: u64 = 60 * MIN;
/// 2026-03-02, a Monday, 00:00 UTC.
const MONDAY: u64 = 1_772_409_600_000;

fn at(h: u64, m: u64) -> u64 {
    MONDAY + h * H + m * MIN
}

fn rules() -> OeeRules {
    OeeRules {
        calendar: Calendar {
            shifts: vec![
                Shift {
                    name: "early".into(),
                    days: [true; 7],
                    start: 6 * 60,
                    end: 14 * 60,
                    breaks: vec![(10 * 60, 10 * 60 + 30)],
                },
                Shift {
                    name: "late".into(),
                    days: [true; 7],
                    start: 14 * 60,
                    end: 22 * 60,
                    breaks: vec![],
                },
            ],
            utc_offset_ms: 0,
        },
        planned_stops: vec!["maintenance".into()],
        setup: vec!["setup".into()],
        small_stop_ms: 5 * MIN,
        startup_ms: 10 * MIN,
        ideal_cycle_ms: MIN,
        items: [("B".to_string(), 30_000)].into(),
    }
}

fn causes() -> StopCauses {
    StopCauses {
        causes: vec![
            StopCause {
                code: "03".into(),
                name: "mould-clamp abnormal".into(),
                fault_type: Some("CLAMP".into()),
                state: None,
            },
            StopCause {
                code: "05".into(),
                name: "stopped".into(),
                fault_type: None,
                state: Some("idle".into()),
            },
        ],
    }
}

fn state(t: u64, s: &str, fault: Option<&str>) -> StateChange {
    StateChange {
        at: t,
        state: s.into(),
        fault_type: fault.map(str::to_string),
    }
}

fn mode(t: u64, m: &str, entered: bool) -> ModeChange {
    ModeChange {
        at: t,
        mode: m.into(),
        entered,
    }
}

fn order(t: u64, item: &str) -> OrderChange {
    OrderChange {
        at: t,
        item: Some(item.into()),
        target: None,
    }
}

struct History {
    changes: Vec<StateChange>,
    modes: Vec<ModeChange>,
    parts: Vec<(u64, u64)>,
    rejects: Vec<(u64, u64)>,
    orders: Vec<OrderChange>,
}

impl History {
    fn facts(&self) -> Facts<'_> {
        Facts {
            changes: &self.changes,
            modes: &self.modes,
            parts: &self.parts,
            rejects: &self.rejects,
            orders: &self.orders,
            earlier_start: None,
        }
    }
}

/// The early shift: a CLAMP fault 07:00-07:20, a 3-minute idle stop at
/// 08:00 (small), a 12-minute one at 08:30, setup 09:00-09:30 (idle), the
/// break 10:00-10:30 (running through it), maintenance 12:00-12:30, the
/// agent away 13:00-13:10. Item A (ideal 60 s) until 10:30, then B (30
/// s); 100 parts at 07:30, 200 at 11:00; 5 rejects at 07:25 (5 min after
/// the start at 07:20), 10 at 11:30.
fn early_shift() -> History {
    History {
        changes: vec![
            state(at(5, 0), "running", None),
            state(at(7, 0), "fault", Some("CLAMP")),
            state(at(7, 20), "running", None),
            state(at(8, 0), "idle", None),
            state(at(8, 3), "running", None),
            state(at(8, 30), "idle", None),
            state(at(8, 42), "running", None),
            state(at(9, 0), "idle", None),
            state(at(9, 30), "running", None),
            state(at(13, 0), "offline", None),
            state(at(13, 10), "running", None),
        ],
        modes: vec![
            mode(at(9, 0), "setup", true),
            mode(at(9, 30), "setup", false),
            mode(at(12, 0), "maintenance", true),
            mode(at(12, 30), "maintenance", false),
        ],
        parts: vec![(at(7, 30), 100), (at(11, 0), 200)],
        rejects: vec![(at(7, 25), 5), (at(11, 30), 10)],
        orders: vec![order(at(4, 0), "A"), order(at(10, 30), "B")],
    }
}

#[test]
fn a_shift_with_every_loss_gives_the_figures_worked_out_by_hand() {
    let h = early_shift();
    let r = rules();
    let d = day(&r, &causes(), &h.facts(), MONDAY, MONDAY + 2 * 24 * H);
    let f = &d.shifts[0].figures;
    assert_eq!(d.shifts[0].shift.name, "early");
    // 480 min less the break (30), maintenance (30) and the agent's
    // absence (10).
    assert_eq!(f.planned_ms, 410 * MIN);
    assert_eq!(f.not_planned_ms, 60 * MIN);
    assert_eq!(f.unobserved_ms, 10 * MIN);
    // Less the breakdowns (20 + 12) and the setup (30).
    assert_eq!(f.run_ms, 348 * MIN);
    assert_eq!(
        f.losses,
        Losses {
            breakdowns_ms: 32 * MIN,
            setup_ms: 30 * MIN,
            small_stops_ms: 3 * MIN,
            reduced_speed_ms: (348 - 3 - 200) * MIN,
            startup_rejects: 5,
            startup_rejects_ms: 5 * MIN,
            production_rejects: 10,
            production_rejects_ms: 5 * MIN,
        }
    );
    assert_eq!(
        f.breakdowns,
        [
            Breakdown {
                code: "03".into(),
                name: "mould-clamp abnormal".into(),
                stops: 1,
                ms: 20 * MIN
            },
            Breakdown {
                code: "05".into(),
                name: "stopped".into(),
                stops: 1,
                ms: 12 * MIN
            }
        ]
    );
    // 100 parts of A at 60 s and 200 of B at 30 s: 200 min ideal.
    assert_eq!((f.ideal_ms, f.parts, f.rejects), (200 * MIN, 300, 15));
    let close = |a: Option<f64>, b: f64| (a.unwrap() - b).abs() < 1e-12;
    assert!(close(f.availability, 348.0 / 410.0));
    assert!(close(f.performance, 200.0 / 348.0));
    assert!(close(f.quality, 285.0 / 300.0));
    assert!(close(f.oee, 348.0 / 410.0 * 200.0 / 348.0 * 0.95));
    // The late shift: running all through, no parts.
    let late = &d.shifts[1].figures;
    assert_eq!((late.planned_ms, late.run_ms), (8 * H, 8 * H));
    assert_eq!((late.performance, late.quality), (Some(0.0), None));
    assert_eq!(late.losses.reduced_speed_ms, 8 * H);
    // The day is their sum.
    assert_eq!(d.total.planned_ms, 410 * MIN + 8 * H);
    assert_eq!(d.total.run_ms, 348 * MIN + 8 * H);
    assert!(close(d.total.quality, 0.95));
    assert_eq!(d.total.breakdowns.len(), 2);
}

#[test]
fn a_shift_under_way_counts_to_now_and_a_stop_growing_stops_being_small() {
    let h = early_shift();
    let r = rules();
    let w = &r.calendar.windows(MONDAY, MONDAY + 24 * H)[0];
    // 08:32: the idle stop begun 08:30 is small so far.
    let f = shift(&r, &causes(), &h.facts(), w, at(8, 32));
    assert_eq!(f.planned_ms, 152 * MIN);
    assert_eq!(f.losses.small_stops_ms, 5 * MIN);
    assert_eq!(f.losses.breakdowns_ms, 20 * MIN);
    // 08:40: ten minutes, a breakdown now.
    let f = shift(&r, &causes(), &h.facts(), w, at(8, 40));
    assert_eq!(f.losses.small_stops_ms, 3 * MIN);
    assert_eq!(f.losses.breakdowns_ms, 30 * MIN);
    // Before the shift: nothing planned yet.
    let f = shift(&r, &causes(), &h.facts(), w, at(5, 0));
    assert_eq!((f.planned_ms, f.availability), (0, None));
}

#[test]
fn a_fault_begun_before_the_shift_is_one_stop_of_the_shift_before() {
    let h = History {
        changes: vec![
            state(at(5, 0), "fault", Some("CLAMP")),
            state(at(6, 30), "running", None),
        ],
        modes: vec![],
        parts: vec![],
        rejects: vec![(at(6, 35), 1), (at(6, 45), 2)],
        orders: vec![],
    };
    let r = rules();
    let w = &r.calendar.windows(MONDAY, MONDAY + 24 * H)[0];
    let f = shift(&r, &causes(), &h.facts(), w, at(7, 0));
    assert_eq!(f.breakdowns[0].stops, 0);
    assert_eq!(f.breakdowns[0].ms, 30 * MIN);
    assert_eq!(
        (f.losses.startup_rejects, f.losses.production_rejects),
        (1, 2)
    );
}
