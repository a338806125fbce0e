//! Transition timers on the simulated body-shop line (paper 001's case):
//! learned from 4 runs with Δmin = 2 s, for a fixed τ and for the learned
//! τ rule: one transition per end-of-motion sensor, random loading waits
//! never learned, no false alarm on 50 held-out normal runs, and at least
//! 99 % of 200 injected timing faults detected with the right transition.

#![allow(clippy::unwrap_used)] // test helpers fail loudly by design

use cellwatch_models::timer::learn::{self, Edge, LearnOptions, Tau, TimerModel};
use cellwatch_models::timer::line::{self, Fault, FaultKind};
use cellwatch_models::timer::monitor::{replay, Outcome};

const CYCLES: usize = 6;

fn end_of_motion_sensors() -> Vec<(String, Edge)> {
    let mut s = vec![("CV_IN_POS".to_string(), Edge::Rise)];
    for k in 0..4 {
        for (name, edge) in [
            ("TR{k}_AT_STATION", Edge::Rise),
            ("ST{k}_CLAMPED", Edge::Rise),
            ("ST{k}_CLAMPED", Edge::Fall),
            ("TR{k}_HOME", Edge::Rise),
        ] {
            s.push((name.replace("{k}", &k.to_string()), edge));
        }
        for w in ["A", "B"] {
            s.push((format!("WR{k}{w}_DONE"), Edge::Rise));
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
