//! Evaluation of transition timers on the simulated body-shop line:
//! learn from 4 runs, count false alarms on held-out normal runs, and
//! detections of injected faults, for several τ rules.
//!
//! Run: `cargo run --release -p cellwatch-models --example line_eval`

use cellwatch_models::timer::learn::{self, LearnOptions, Tau, TimerModel};
use cellwatch_models::timer::line::{self, Fault, FaultKind, InjectedFault};
use cellwatch_models::timer::log::RunLog;
use cellwatch_models::timer::monitor::{self, Outcome};

const CYCLES: usize = 6;

fn replay(model: &TimerModel, run: &RunLog) -> Vec<Outcome> {
    monitor::replay(model, run).expect("model compiles")
}

fn alarms(o: &[Outcome]) -> Vec<Outcome> {
    o.iter()
        .copied()
        .filter(|o| !matches!(o, Outcome::Normal { .. }))
        .collect()
}

fn detected(model: &TimerModel, outcomes: &[Outcome], f: &InjectedFault) -> bool {
    outcomes.iter().any(|o| match o {
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
    })
}

fn main() {
    let training: Vec<RunLog> = (1..=4).map(|s| line::run(s, CYCLES, None).0).collect();
    for (name, tau) in [
        ("fixed 300 ms", Tau::Fixed(300)),
        ("fixed 500 ms", Tau::Fixed(500)),
        ("auto", Tau::Auto),
    ] {
        let l = learn::common(
            &training,
            &LearnOptions {
                delta_min: 2000,
                tau,
                min_support: None,
            },
        );
        let model = &l.model;
        let sensors: Vec<String> = model
            .transitions
            .iter()
            .map(|t| {
                format!(
                    "{}{}",
                    if t.event.edge == learn::SignalEdge::Rise {
                        "+"
                    } else {
                        "-"
                    },
                    t.event.tag
                )
            })
            .collect();
        let mut false_alarms = 0;
        for seed in 100..150 {
            false_alarms += alarms(&replay(model, &line::run(seed, CYCLES, None).0)).len();
        }
        let kinds = [
            FaultKind::SensorMissing,
            FaultKind::TooFast,
            FaultKind::TooSlow,
            FaultKind::Stuck,
        ];
        let mut hit = 0;
        let mut total = 0;
        for i in 0..200u64 {
            let kind = kinds[(i % 4) as usize];
            let (run, f) = line::run(
                1000 + i,
                CYCLES,
                Some(Fault {
                    kind,
                    step: (i * 7 % 90) as usize,
                }),
            );
            let f = f.expect("fault injected");
            total += 1;
            if detected(model, &replay(model, &run), &f) {
                hit += 1;
            } else if std::env::var("VERBOSE").is_ok() {
                println!("  missed {:?} on {}", f.kind, f.sensor);
            }
        }
        println!(
            "τ {name:<13} transitions {:>2}  false alarms on 50 normal runs {:>3}  detected {hit}/{total} ({:.1} %)",
            model.transitions.len(),
            false_alarms,
            100.0 * hit as f64 / total as f64
        );
        if std::env::var("VERBOSE").is_ok() {
            println!("  learned: {}", sensors.join(" "));
            for d in &l.dropped {
                if !matches!(d.reason, learn::DropReason::TooShort { .. }) {
                    println!("  dropped {}: {}", d.transition, d.reason);
                }
            }
        }
    }
}
