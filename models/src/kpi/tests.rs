//! The figures live and for a period: the sliding window, floods over
//! every raise and over first-outs, a plant's own rules on both sides,
//! chatter, stale occurrences and a report's acknowledgements and shelves.

use super::*;
use crate::alarm::{Severity, Transition};

const MIN: u64 = 60_000;

#[test]
fn the_live_window_forgets_what_is_older_than_10_minutes() {
    let mut k = LiveKpis::new();
    for i in 0..11 {
        k.on_transition(
            &format!("a{i}"),
            Transition::Raised,
            (i * 1000, false, false, false),
            i * 1000,
        );
    }
    assert_eq!(k.snapshot(10_000).raised_last_10m, 11);
    assert!(k.snapshot(10_000).in_flood);
    k.advance(10 * MIN - 1);
    assert_eq!(k.snapshot(10 * MIN - 1).raised_last_10m, 11);
    // The first raise (second 0) leaves the window at 600 s: 10 left,
    // still a flood until fewer than 5 are (ISA-18.2), at 606 s.
    k.advance(10 * MIN);
    let s = k.snapshot(10 * MIN);
    assert_eq!((s.raised_last_10m, s.in_flood), (10, true));
    k.advance(10 * MIN + 5_999);
    assert!(k.snapshot(10 * MIN + 5_999).in_flood);
    k.advance(10 * MIN + 6_000);
    let s = k.snapshot(10 * MIN + 6_000);
    assert_eq!((s.raised_last_10m, s.in_flood), (4, false));
    assert_eq!(s.flood_ms, 10 * MIN + 6_000 - 10_000);
    // A long gap empties it.
    k.advance(60 * MIN);
    assert_eq!(k.snapshot(60 * MIN).raised_last_10m, 0);
}

#[test]
fn a_cascade_is_a_flood_of_raises_and_no_flood_of_first_outs() {
    // One emergency stop and ten alarms that follow from it.
    let mut k = LiveKpis::new();
    let mut events = Vec::new();
    for i in 0..11u64 {
        let consequence = i > 0;
        k.on_transition(
            &format!("a{i}"),
            Transition::Raised,
            (i, true, consequence, false),
            i,
        );
        events.push(AlarmEvent {
            consequence,
            ..ev(i, &format!("a{i}"), Transition::Raised, i, true)
        });
    }
    let s = k.snapshot(11);
    assert_eq!((s.raised_last_10m, s.in_flood), (11, true));
    assert_eq!((s.first_outs_last_10m, s.first_outs_in_flood), (1, false));
    k.advance(MIN);
    let s = k.snapshot(MIN);
    assert_eq!((s.flood_ms, s.first_outs_flood_ms), (MIN - 10, 0));
    let r = alarm_report(
        &events,
        &[],
        0,
        INTERVAL_MS,
        INTERVAL_MS,
        &KpiRules::default(),
    );
    assert_eq!((r.raised, r.flood_intervals), (11, 1));
    assert_eq!((r.first_outs, r.first_out_flood_intervals), (1, 0));
    let line = r
        .benchmarks()
        .into_iter()
        .find(|b| b.metric.contains("first-outs only"))
        .unwrap();
    assert_eq!(line.value, "0.00 % (1 of 11 raises first-outs)");
}

#[test]
fn a_plant_sets_its_own_flood_chatter_and_stale_rules() {
    // A flood above 3, ended at once below 4 (no hysteresis); two
    // raises in 5 min chatter; stale after 1 h.
    let rules = KpiRules {
        flood_raises: 3,
        flood_ends_below: 4,
        chatter_raises: 2,
        chatter_window_ms: 5 * MIN,
        stale_ms: 3_600_000,
    };
    let mut k = LiveKpis::with_rules(rules);
    for i in 0..4 {
        k.on_transition(
            "a",
            Transition::Raised,
            (i * MIN, i == 3, false, false),
            i * MIN,
        );
    }
    let s = k.snapshot(3 * MIN);
    assert_eq!((s.in_flood, s.chattering), (true, 1));
    k.advance(10 * MIN);
    let s = k.snapshot(10 * MIN);
    assert_eq!((s.raised_last_10m, s.in_flood), (3, false));
    assert_eq!(s.flood_ms, 7 * MIN);
    assert_eq!(k.snapshot(3 * MIN + 3_600_001).stale, 1);
    // The report judges by the same rules, and says them.
    let events: Vec<AlarmEvent> = (0..4)
        .map(|i| AlarmEvent {
            at: i * MIN,
            id: "a".into(),
            transition: Transition::Raised,
            severity: Severity::High,
            raised_at: i * MIN,
            active: false,
            consequence: false,
            by_design: false,
        })
        .collect();
    let r = alarm_report(&events, &[], 0, 20 * MIN, 20 * MIN, &rules);
    assert_eq!(r.flood_intervals, 1);
    assert_eq!(r.chattering[0].raises_in_window, 4);
    let b = r.benchmarks();
    assert_eq!(b[1].target, "<= 3");
    assert_eq!(b[2].metric, "10-min intervals in flood (> 3, until < 4)");
    assert_eq!(b[5].metric, "chattering alarms (2+ raises in 5 min)");
    assert_eq!(b[6].metric, "stale alarms (active > 1 h)");
}

#[test]
fn a_report_interval_after_a_flood_stays_in_flood_until_fewer_than_5() {
    let raise = |at: u64| AlarmEvent {
        at,
        id: format!("a{at}"),
        transition: Transition::Raised,
        severity: Severity::Low,
        raised_at: at,
        active: false,
        consequence: false,
        by_design: false,
    };
    // 11, 6, 4, 6 raises in four intervals: flood, flood (6 >= 5),
    // over (4 < 5), not again (6 is no more than 10).
    let mut events = Vec::new();
    for (interval, n) in [11u64, 6, 4, 6].into_iter().enumerate() {
        for k in 0..n {
            events.push(raise(interval as u64 * 10 * MIN + k * 1000));
        }
    }
    let r = alarm_report(&events, &[], 0, 40 * MIN, 40 * MIN, &KpiRules::default());
    assert_eq!((r.intervals, r.flood_intervals), (4, 2));
    assert_eq!(
        r.benchmarks()[2].metric,
        "10-min intervals in flood (> 10, until < 5)"
    );
    assert_eq!(r.benchmarks()[6].metric, "stale alarms (active > 24 h)");
    assert_eq!(
        r.benchmarks()[5].metric,
        "chattering alarms (3+ raises in 60 s)"
    );
}

#[test]
fn three_raises_within_a_minute_chatter_until_the_minute_is_over() {
    let mut k = LiveKpis::new();
    for at in [0, 20_000, 50_000] {
        k.on_transition("x", Transition::Raised, (at, true, false, false), at);
        k.on_transition("x", Transition::Cleared, (at, false, false, false), at + 1);
    }
    assert_eq!(k.snapshot(50_001).chattering, 1);
    k.advance(59_999);
    assert_eq!(k.snapshot(59_999).chattering, 1);
    k.advance(60_000);
    assert_eq!(k.snapshot(60_000).chattering, 0);
    // Three raises spread over more than a minute: no chatter.
    for at in [100_000, 140_000, 170_000] {
        k.on_transition("y", Transition::Raised, (at, false, false, false), at);
    }
    assert_eq!(k.snapshot(170_000).chattering, 0);
}

#[test]
fn an_occurrence_is_stale_after_24_hours() {
    let mut k = LiveKpis::new();
    k.on_transition("x", Transition::Raised, (0, true, false, false), 0);
    k.on_transition("x", Transition::Acknowledged, (0, true, false, false), 5);
    assert_eq!(k.snapshot(STALE_MS).stale, 0);
    assert_eq!(k.snapshot(STALE_MS + 1).stale, 1);
    k.on_transition(
        "x",
        Transition::Cleared,
        (0, false, false, false),
        STALE_MS + 2,
    );
    assert_eq!(k.snapshot(STALE_MS + 3).stale, 0);
}

fn ev(at: u64, id: &str, transition: Transition, raised_at: u64, active: bool) -> AlarmEvent {
    AlarmEvent {
        consequence: false,
        by_design: false,
        at,
        id: id.into(),
        transition,
        severity: Severity::High,
        raised_at,
        active,
    }
}

#[test]
fn a_report_counts_acknowledgements_shelves_and_what_was_active_before() {
    use Transition::*;
    let day = 86_400_000;
    let events = [
        ev(day + 1_000, "a", Raised, day + 1_000, true),
        ev(day + 11_000, "a", Acknowledged, day + 1_000, true),
        ev(day + 20_000, "a", Cleared, day + 1_000, false),
        ev(day + 31_000, "a", Raised, day + 31_000, true),
        ev(day + 40_000, "a", Shelved, day + 31_000, true),
        ev(day + 91_000, "a", Acknowledged, day + 31_000, true),
        ev(day + 95_000, "b", OutOfService, day + 95_000, false),
    ];
    // "old" was raised the day before, at 06:00, and never cleared.
    let before = [ev(6 * 3_600_000, "old", Raised, 6 * 3_600_000, true)];
    let r = alarm_report(
        &events,
        &before,
        day,
        2 * day,
        3 * day,
        &KpiRules::default(),
    );
    assert_eq!((r.raised, r.intervals, r.peak_rate), (2, 144, 2));
    assert_eq!(r.ack.count, 2);
    assert_eq!(r.ack.mean, Some(35.0));
    assert_eq!(r.ack.median, Some(35.0));
    assert_eq!(r.ack.max, Some(60.0));
    assert_eq!((r.shelved, r.alarms_shelved, r.out_of_service), (1, 1, 1));
    assert_eq!(r.stale.len(), 1);
    assert_eq!(r.stale[0].id, "old");
    assert!((r.stale[0].hours - 42.0).abs() < 1e-9);
    // "a" is still active at the end, for less than 24 h: not stale.
    // A day still running ends now.
    let r = alarm_report(
        &events,
        &before,
        day,
        2 * day,
        day + 600_001,
        &KpiRules::default(),
    );
    assert_eq!((r.intervals, r.to), (2, day + 600_001));
}

#[test]
fn raises_suppressed_by_design_are_counted_apart_and_in_no_other_figure() {
    // A setup: twenty door alarms suppressed by design, one real fault.
    let mut k = LiveKpis::new();
    let mut events = Vec::new();
    for i in 0..20u64 {
        k.on_transition("door", Transition::Raised, (i, true, false, true), i);
        events.push(AlarmEvent {
            by_design: true,
            ..ev(i, "door", Transition::Raised, i, true)
        });
    }
    k.on_transition("ese", Transition::Raised, (30, true, false, false), 30);
    events.push(ev(30, "ese", Transition::Raised, 30, true));
    let s = k.snapshot(31);
    assert_eq!(
        (
            s.raised_last_10m,
            s.by_design_last_10m,
            s.in_flood,
            s.chattering,
            s.first_outs_last_10m
        ),
        (1, 20, false, 0, 1)
    );
    let r = alarm_report(&events, &[], 0, 10 * MIN, 10 * MIN, &KpiRules::default());
    assert_eq!(
        (r.raised, r.by_design, r.flood_intervals, r.top.len()),
        (1, 20, 0, 1)
    );
    assert!(r.chattering.is_empty());
}
