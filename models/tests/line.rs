//! Transition timers on the simulated body-shop line (paper 001's case):
//! learned from 4 runs with Δmin = 2 s, for a fixed τ and for the learned
//! τ rule: one transition per end-of-motion sensor, random loading waits
//! never learned, no false alarm on 50 held-out normal runs, and at least
//! 99 % of 200 injected timing faults detected with the right transition.
//! Drift: a weld slowing by 1 % an hour is warned of before it falls late,
//! and long held-out normal runs warn of nothing.

#![allow(clippy::unwrap_used)] // test helpers fail loudly by design

use cellwatch_models::alarm::Transition;
use cellwatch_models::engine::{EngineStep, Reading};
use cellwatch_models::signal::Signal;
use cellwatch_models::timer::checks::drift_alarm;
use cellwatch_models::timer::drift::DriftRules;
use cellwatch_models::timer::learn::{self, LearnOptions, SignalEdge, Tau, TimerModel};
use cellwatch_models::timer::line::{self, Fault, FaultKind, Slowdown};
use cellwatch_models::timer::log::RunLog;
use cellwatch_models::timer::monitor::{replay, Outcome};

mod kit;

const CYCLES: usize = 6;

fn end_of_motion_sensors() -> Vec<(String, SignalEdge)> {
    let mut s = vec![("CV_IN_POS".to_string(), SignalEdge::Rise)];
    for k in 0..4 {
        for (name, edge) in [
            ("TR{k}_AT_STATION", SignalEdge::Rise),
            ("ST{k}_CLAMPED", SignalEdge::Rise),
            ("ST{k}_CLAMPED", SignalEdge::Fall),
            ("TR{k}_HOME", SignalEdge::Rise),
        ] {
            s.push((name.replace("{k}", &k.to_string()), edge));
        }
        for w in ["A", "B"] {
            s.push((format!("WR{k}{w}_DONE"), SignalEdge::Rise));
        }
    }
    s
}

fn learned(tau: Tau) -> TimerModel {
    let training: Vec<_> = (1..=4).map(|s| line::run(s, CYCLES, None).0).collect();
    learn::common(
        &training,
        &LearnOptions {
            delta_min: 2000,
            tau,
            min_support: None,
        },
    )
    .model
}

fn check(model: &TimerModel) {
    // One transition per end-of-motion sensor.
    for (sensor, edge) in end_of_motion_sensors() {
        let n = model
            .transitions
            .iter()
            .filter(|t| t.event.tag == sensor && t.event.edge == edge)
            .count();
        assert_eq!(n, 1, "{sensor} {edge:?}: {n} transitions");
    }
    assert!(model.transitions.len() >= 16);
    // The operator's random loading waits are no timing invariant.
    assert!(
        model
            .transitions
            .iter()
            .all(|t| !t.event.tag.ends_with("_LOADED")),
        "a loading wait was learned"
    );
    // No false alarm on held-out normal runs.
    for seed in 100..150 {
        let alarms: Vec<Outcome> = replay(model, &line::run(seed, CYCLES, None).0)
            .unwrap()
            .into_iter()
            .filter(|o| !matches!(o, Outcome::Normal { .. }))
            .collect();
        assert!(
            alarms.is_empty(),
            "false alarms on normal run {seed}: {alarms:?}"
        );
    }
    // Injected timing faults, detected on the faulty motion's transition.
    let kinds = [
        FaultKind::SensorMissing,
        FaultKind::TooFast,
        FaultKind::TooSlow,
        FaultKind::Stuck,
    ];
    let mut detected = 0;
    for i in 0..200u64 {
        let (run, f) = line::run(
            1000 + i,
            CYCLES,
            Some(Fault {
                kind: kinds[(i % 4) as usize],
                step: (i * 7 % 90) as usize,
            }),
        );
        let f = f.unwrap();
        let hit = replay(model, &run).unwrap().iter().any(|o| match o {
            Outcome::Early {
                transition, at_ms, ..
            }
            | Outcome::Late { transition, at_ms } => {
                *at_ms >= f.command_at
                    && model
                        .transitions
                        .iter()
                        .any(|t| t.id == *transition && t.event.tag == f.sensor)
            }
            Outcome::Normal { .. } => false,
        });
        detected += usize::from(hit);
    }
    assert!(
        detected >= 198,
        "detected {detected} of 200 injected faults"
    );
}

#[test]
fn fixed_tau() {
    check(&learned(Tau::Fixed(300)));
}

#[test]
fn learned_tau() {
    check(&learned(Tau::Auto));
}

#[test]
fn the_full_state_method_breaks_on_parallel_stations() {
    // The paper's method on the same runs: the parallel stations scatter each
    // motion over many states, so almost nothing is seen in every run.
    let training: Vec<_> = (1..=4).map(|s| line::run(s, CYCLES, None).0).collect();
    let l = learn::full_state(
        &training,
        &LearnOptions {
            delta_min: 2000,
            tau: Tau::Fixed(300),
            min_support: None,
        },
    );
    assert!(
        l.model.transitions.len() < 5,
        "{} transitions",
        l.model.transitions.len()
    );
}

/// `config/line/timers.json` is what the commands in `config/line.toml`'s
/// header produce: `simulate line --runs 4 --seed 1 --cycles 6`, then
/// `learn --delta-min 2s --tau-auto`.
#[test]
fn the_shipped_line_model_is_reproducible() {
    let shipped: TimerModel =
        serde_json::from_str(include_str!("../../config/line/timers.json")).unwrap();
    let training: Vec<_> = (1..=4).map(|s| line::run(s, 6, None).0).collect();
    let fresh = learn::common(
        &training,
        &LearnOptions {
            delta_min: 2000,
            tau: Tau::Auto,
            min_support: None,
        },
    )
    .model;
    assert_eq!(
        shipped, fresh,
        "re-learn config/line/timers.json with the commands in config/line.toml"
    );
}

/// An alarm raised while replaying a run through the engine.
#[derive(Debug)]
struct Raised {
    id: String,
    at: u64,
    message: String,
}

/// Replays `run` through a cell engine running `model` as the agent does
/// (time advanced to each deadline, every change at its source time), with
/// drift warnings by the default rules: every alarm raised, in order, and
/// the largest |window position| seen once a transition could warn.
fn engine_raises(model: &TimerModel, run: &RunLog) -> (Vec<Raised>, f64) {
    let tags = kit::tags_as_named(run.signals.iter().map(|n| Signal::new(n)));
    let checks = kit::timer_checks("line", model).drifting(Some(DriftRules::default()));
    let mut e = kit::cell("line", tags, vec![Box::new(checks)]);
    let mut raised = Vec::new();
    let mut keep = |step: EngineStep| {
        for (a, tr, at) in step.alarms() {
            if tr == Transition::Raised {
                raised.push(Raised {
                    id: a.id.clone(),
                    at,
                    message: a.message.clone(),
                });
            }
        }
    };
    keep(e.on_connection(true, 0));
    for (i, &v) in run.initial.iter().enumerate() {
        keep(e.on_reading(i, Reading::Good(v), 0, 0));
    }
    let mut furthest: f64 = 0.0;
    let min_samples = u64::from(DriftRules::default().min_samples);
    for (i, c) in run.changes.iter().enumerate() {
        while let Some(d) = e.next_deadline().filter(|&d| d <= c.at) {
            keep(e.advance(d));
        }
        keep(e.on_reading(c.signal, Reading::Good(c.value), c.at, c.at));
        if i % 50 == 0 {
            for p in e.window_positions() {
                if p.samples >= min_samples {
                    furthest = furthest.max(p.position.abs());
                }
            }
        }
    }
    (raised, furthest)
}

/// How many times `sensor` rose in `run` by `at`: the station's cycle.
fn cycle_at(run: &RunLog, sensor: &str, at: u64) -> usize {
    let s = run.signals.iter().position(|n| n == sensor).unwrap();
    run.changes
        .iter()
        .filter(|c| c.signal == s && c.value && c.at <= at)
        .count()
}

fn hours(ms: u64) -> f64 {
    ms as f64 / 3_600_000.0
}

/// Station 2's weld B (4.9 s) slows by 1 % an hour: its drift warning
/// comes before its first late alarm, and nothing else is raised before.
#[test]
fn a_weld_slowing_one_percent_an_hour_is_warned_of_before_it_falls_late() {
    let model = learned(Tau::Auto);
    let t = model
        .transitions
        .iter()
        .find(|t| t.event.tag == "WR2B_DONE" && t.event.edge == SignalEdge::Rise)
        .unwrap();
    let slow = Slowdown {
        sensor: "WR2B_DONE".into(),
        rising: true,
        percent_per_hour: 1.0,
    };
    let (run, _) = line::run_slowing(500, 500, None, Some(&slow));
    let (raised, _) = engine_raises(&model, &run);
    let (drift, late) = (drift_alarm("line", t.id), format!("line-{:03}", t.id));
    let first = |id: &str| raised.iter().find(|r| r.id == id);
    let warning = first(&drift).expect("a drift warning");
    let alarm = first(&late).expect("a late alarm");
    let cycle = |at| cycle_at(&run, "WR2B_DONE", at);
    println!(
        "{} {}: window {:?} ms, learned {} ms",
        late,
        cellwatch_models::timer::checks::label(t),
        t.window_ms,
        t.delta_ms
    );
    println!(
        "drift warning at {:.2} h (cycle {}): {}",
        hours(warning.at),
        cycle(warning.at),
        warning.message
    );
    println!(
        "first late alarm at {:.2} h (cycle {}): {}",
        hours(alarm.at),
        cycle(alarm.at),
        alarm.message
    );
    assert!(warning.at < alarm.at);
    // Nothing else before: no other transition warned of or alarmed.
    let before: Vec<&Raised> = raised
        .iter()
        .take_while(|r| r.at <= alarm.at)
        .filter(|r| r.id != drift && r.id != late)
        .collect();
    assert!(before.is_empty(), "{before:?}");
    assert_eq!(
        warning.message,
        "transition #020 (+WR2B_DONE after +WR2A_START) slowing: \
         mean 4.91 s → 5.03 s over 2.6 h, limit 5.15 s"
    );
}

/// Long held-out normal runs: no drift warning (and no timer alarm).
#[test]
fn long_normal_runs_warn_of_no_drift() {
    let model = learned(Tau::Auto);
    let (mut cycles, mut span, mut warnings, mut alarms) = (0, 0, Vec::new(), Vec::new());
    let mut furthest: f64 = 0.0;
    for seed in 200..210 {
        let (run, _) = line::run(seed, 500, None);
        cycles += 4 * 500;
        span += run.changes.last().map_or(0, |c| c.at);
        let (raised, f) = engine_raises(&model, &run);
        furthest = furthest.max(f);
        for r in raised {
            if r.id.ends_with("-drift") {
                warnings.push((seed, r));
            } else {
                alarms.push((seed, r));
            }
        }
    }
    println!(
        "normal runs (seeds 200-209): {cycles} station cycles over {:.1} h, \
         {} drift warnings, {} timer alarms, furthest window position {furthest:.2} \
         (warning at {})",
        hours(span),
        warnings.len(),
        alarms.len(),
        DriftRules::default().fraction
    );
    assert!(warnings.is_empty(), "{warnings:?}");
    assert!(alarms.is_empty(), "{alarms:?}");
}
