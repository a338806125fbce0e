//! The whole engine (`CellEngine::on_readings`), one change per call, on the
//! generated cell of 10,000 contacts and 1,000 switching checks, plus 1,000
//! numeric tags: each check is armed by a comparison of one of them
//! (`D<c> > 5`), and each has a limit check (H 90, L 10, deadband 1).
//!
//! - **boolean** (baseline): every change toggles a contact.
//! - **half_numeric**: every other change is a new value of a numeric tag
//!   (comparison contact and limit levels follow).
//!
//! The flight recorder, on the same cell grown to 100,000 tags (the 10,000
//! contacts and 90,000 numeric tags, each with its limit check), every
//! other change a contact toggle and every other a new value (0..100) of a
//! random numeric tag, so that alarms raise all the time:
//!
//! - **recorder_off** (baseline): the recorder not configured.
//! - **recorder_on**: the recorder with its default configuration.
//!
//! After them it prints what the recorder kept: the ring's bytes at
//! capacity, and per alarm recorded its JSON size and its memory.
//!
//! The flight recorder in a flood on one check (`flight_recorder_flood`):
//! 1,000 contacts, one switching check over 32 of them (`X0.00` AND any of
//! 31 others), 100 changes a millisecond, each a toggle of a random
//! contact, and `X0.00` toggled every 450 changes, so that the check raises
//! and clears about 110 times a second while its 32 signals fill the ring:
//!
//! - **recorder_off** (baseline), **recorder_on**, as above.
//!
//! Run: `cargo bench -p cellwatch-models --bench engine`

#![allow(missing_docs)] // criterion_group! generates undocumented items

mod common;

use std::hint::black_box;

use cellwatch_models::alarm::Severity;
use cellwatch_models::comments::CommentDb;
use cellwatch_models::engine::{
    CellEngine, CheckSet, Reading, RecorderConfig, Recording, StateRules, SwitchingCheck,
    SwitchingChecks, Tag, TagReading,
};
use cellwatch_models::explain::Polarity;
use cellwatch_models::expr::Expr;
use cellwatch_models::limit::{Level, LimitCheck, LimitChecks, LimitLevel};
use cellwatch_models::program::Program;
use cellwatch_models::signal::{Observability, Signal};
use cellwatch_models::switching::SwitchingFunction;
use cellwatch_models::value::Num;
use criterion::{criterion_group, criterion_main, Criterion, Throughput};

const NUMBERS: usize = common::CHECKS;

/// The numeric tags of the 100,000-tag cell.
const MANY_NUMBERS: usize = 100_000 - common::SIGNALS;

fn engine() -> (CellEngine, usize, common::Rng) {
    engine_of(NUMBERS, None)
}

/// The generated cell with `numbers` numeric tags (the first
/// `common::CHECKS` arming the checks), recording by `recorder`.
fn engine_of(numbers: usize, recorder: Option<RecorderConfig>) -> (CellEngine, usize, common::Rng) {
    let (sfs, rng) = common::generated_sfs();
    let mut contacts: Vec<Signal> = sfs.iter().flat_map(|sf| sf.leaves()).collect();
    contacts.sort();
    contacts.dedup();
    let n = contacts.len();
    let mut tags: Vec<Tag> = contacts
        .into_iter()
        .map(|s| Tag {
            name: s.to_string(),
            address: s,
        })
        .collect();
    for i in 0..numbers {
        let s = Signal::new(&format!("D{i}"));
        tags.push(Tag {
            name: s.to_string(),
            address: s,
        });
    }
    let checks = sfs
        .into_iter()
        .enumerate()
        .map(|(c, sf)| SwitchingCheck {
            forces: Vec::new(),
            text: None,
            id: format!("c{c}"),
            sf,
            polarity: Polarity::On,
            severity: Severity::High,
            fault_type: format!("C{c}"),
            comments: CommentDb::default(),
            armed_when: Some(SwitchingFunction::from_expr(
                Signal::new(&format!("c{c}.armed")),
                &Expr::parse(&format!("D{c} > 5")).expect("comparison"),
            )),
        })
        .collect();
    let limits = (0..numbers)
        .map(|i| LimitCheck {
            comment: None,
            id: format!("d{i}"),
            tag: Signal::new(&format!("D{i}")),
            label: String::new(),
            unit: String::new(),
            deadband: 1.0,
            on_delay: 0,
            off_delay: 0,
            rates: Vec::new(),
            levels: vec![
                LimitLevel {
                    level: Level::H,
                    limit: 90.0,
                    severity: Severity::High,
                },
                LimitLevel {
                    level: Level::L,
                    limit: 10.0,
                    severity: Severity::Low,
                },
            ],
        })
        .collect();
    let sets: Vec<Box<dyn CheckSet>> = vec![
        Box::new(SwitchingChecks::new(checks)),
        Box::new(LimitChecks::new(limits)),
    ];
    let mut e = CellEngine::new(
        "bench",
        tags,
        sets,
        StateRules {
            running: None,
            fault_severity: Severity::High,
            modes: Vec::new(),
        },
    )
    .expect("engine");
    if let Some(config) = recorder {
        e = e.recording(config);
    }
    e.on_connection(true, 0);
    // Normal state: every contact closed, every number mid-range.
    let mut normal: Vec<TagReading> = (0..n)
        .map(|t| TagReading {
            tag: t,
            reading: Reading::Good(true),
            source_time: 1,
        })
        .collect();
    normal.extend((0..numbers).map(|i| TagReading {
        tag: n + i,
        reading: Reading::Number(Num::Float(50.0)),
        source_time: 1,
    }));
    e.on_readings(&normal, 1);
    (e, n, rng)
}

fn changes_per_second(c: &mut Criterion) {
    let (mut boolean, contacts, mut rng) = engine();
    let (mut mixed, _, _) = engine();
    let toggles: Vec<usize> = (0..4096).map(|_| rng.below(contacts)).collect();
    let numbers: Vec<(usize, f64)> = (0..4096)
        .map(|_| (contacts + rng.below(NUMBERS), rng.below(101) as f64))
        .collect();
    let mut group = c.benchmark_group("engine_changes");
    group.throughput(Throughput::Elements(1));

    let e = &mut boolean;
    let mut values = vec![true; contacts];
    let mut k = 0usize;
    let mut t = 2u64;
    group.bench_function("boolean", |b| {
        b.iter(|| {
            let tag = toggles[k % toggles.len()];
            k += 1;
            t += 1;
            values[tag] = !values[tag];
            let step = e.on_readings(
                &[TagReading {
                    tag,
                    reading: Reading::Good(values[tag]),
                    source_time: t,
                }],
                t,
            );
            black_box(step.events.len())
        })
    });

    let e = &mut mixed;
    let mut values = vec![true; contacts];
    let mut k = 0usize;
    let mut t = 2u64;
    group.bench_function("half_numeric", |b| {
        b.iter(|| {
            k += 1;
            t += 1;
            let reading = if k % 2 == 0 {
                let tag = toggles[k % toggles.len()];
                values[tag] = !values[tag];
                TagReading {
                    tag,
                    reading: Reading::Good(values[tag]),
                    source_time: t,
                }
            } else {
                let (tag, v) = numbers[k % numbers.len()];
                TagReading {
                    tag,
                    reading: Reading::Number(Num::Float(v)),
                    source_time: t,
                }
            };
            let step = e.on_readings(&[reading], t);
            black_box(step.events.len())
        })
    });
    group.finish();
}

/// Every other change a contact toggle, every other a new value of one of
/// the many numeric tags.
fn flood(contacts: usize, rng: &mut common::Rng) -> Vec<(usize, Reading)> {
    let mut values = vec![true; contacts];
    (0..65_536)
        .map(|k| {
            if k % 2 == 0 {
                let tag = rng.below(contacts);
                values[tag] = !values[tag];
                (tag, Reading::Good(values[tag]))
            } else {
                let tag = contacts + rng.below(MANY_NUMBERS);
                (tag, Reading::Number(Num::Float(rng.below(101) as f64)))
            }
        })
        .collect()
}

fn flight_recorder(c: &mut Criterion) {
    let (mut off, contacts, mut rng) = engine_of(MANY_NUMBERS, None);
    let (mut on, _, _) = engine_of(MANY_NUMBERS, Some(RecorderConfig::default()));
    let changes = flood(contacts, &mut rng);
    let mut group = c.benchmark_group("flight_recorder");
    group.throughput(Throughput::Elements(1));
    let mut recordings: Vec<Recording> = Vec::new();
    let mut raised = 0u64;
    let mut kept = std::collections::HashMap::new();
    for (name, e, keep) in [
        ("recorder_off", &mut off, false),
        ("recorder_on", &mut on, true),
    ] {
        // Each engine its own time and its own pass through the same
        // changes; both toggle from the same state.
        let mut k = 0usize;
        let mut t = 2u64;
        group.bench_function(name, |b| {
            b.iter(|| {
                let (tag, reading) = &changes[k % changes.len()];
                k += 1;
                // 100 changes a millisecond: 100,000 a second.
                if k % 100 == 0 {
                    t += 1;
                }
                let step = e.on_readings(
                    &[TagReading {
                        tag: *tag,
                        reading: reading.clone(),
                        source_time: t,
                    }],
                    t,
                );
                if keep {
                    raised += step
                        .alarms()
                        .filter(|(_, tr, _)| *tr == cellwatch_models::alarm::Transition::Raised)
                        .count() as u64;
                    // Up to 1,000 of each: switching alarms (`c…`) and
                    // limit alarms (`d…`), whole or cut short.
                    for r in step.recordings {
                        let count = kept.entry(kind(&r)).or_insert(0usize);
                        if *count < 1_000 {
                            *count += 1;
                            recordings.push(r);
                        }
                    }
                }
                black_box(step.events.len())
            })
        });
    }
    group.finish();
    let fill = on.recorder_fill().expect("recorder on");
    println!(
        "flight recorder: ring {} of {} changes, {} bytes ({:.1} MiB) with its per-tag indices, {} recordings open",
        fill.changes,
        fill.capacity,
        fill.bytes,
        fill.bytes as f64 / (1024.0 * 1024.0),
        fill.open
    );
    println!("flight recorder: {raised} alarms raised");
    let mut kinds: Vec<_> = recordings.iter().map(kind).collect();
    kinds.sort();
    kinds.dedup();
    for k in kinds {
        let of: Vec<&Recording> = recordings.iter().filter(|r| kind(r) == k).collect();
        let n = of.len();
        let json: usize = of
            .iter()
            .map(|r| serde_json::to_vec(r).expect("json").len())
            .sum();
        let memory: usize = of.iter().map(|r| r.bytes()).sum();
        let changes: usize = of.iter().map(|r| r.changes()).sum();
        let signals: usize = of.iter().map(|r| r.signals.len()).sum();
        let largest = of.iter().max_by_key(|r| r.changes()).expect("one");
        println!(
            "flight recorder: {} {}: {n} recordings, each {:.1} signals, {:.1} changes, {} bytes of JSON, {} bytes in memory; the largest {} changes, {} bytes of JSON, {} in memory",
            k.0,
            k.1,
            signals as f64 / n as f64,
            changes as f64 / n as f64,
            json / n,
            memory / n,
            largest.changes(),
            serde_json::to_vec(largest).expect("json").len(),
            largest.bytes()
        );
    }
}

/// A recording's alarm kind (switching or limit) and whether it holds its
/// whole window.
fn kind(r: &Recording) -> (&'static str, &'static str) {
    (
        if r.alarm.starts_with('c') {
            "switching"
        } else {
            "limit"
        },
        if r.truncated.end == Some(cellwatch_models::engine::Cut::Busy) {
            "cut short (busy)"
        } else {
            "whole after"
        },
    )
}

/// 1,000 contacts, all closed but `X0.00`; one check over 32 of them:
/// `X0.00` AND any of `X0.01`..`X1.15`. Recording by `recorder`.
fn flood_engine(recorder: Option<RecorderConfig>) -> CellEngine {
    const CONTACTS: usize = 1_000;
    let mut src = format!("RD {}\nRD.STK {}\n", common::address(0), common::address(1));
    for i in 2..32 {
        src.push_str(&format!("OR {}\n", common::address(i)));
    }
    src.push_str("AND.STK\nWRT G0.00\n");
    let program = Program::compile("flood.il", &src, None).expect("flood program compiles");
    let observable = Observability::default_for(program.dialect());
    let sf =
        SwitchingFunction::expand(&program, &Signal::new("G0.00"), &observable).expect("derivable");
    let tags = (0..CONTACTS)
        .map(|i| {
            let s = Signal::new(&common::address(i));
            Tag {
                name: s.to_string(),
                address: s,
            }
        })
        .collect();
    let check = SwitchingCheck {
        forces: Vec::new(),
        text: None,
        id: "flood".into(),
        sf,
        polarity: Polarity::On,
        severity: Severity::High,
        fault_type: "FLOOD".into(),
        comments: CommentDb::default(),
        armed_when: None,
    };
    let sets: Vec<Box<dyn CheckSet>> = vec![Box::new(SwitchingChecks::new(vec![check]))];
    let mut e = CellEngine::new(
        "flood",
        tags,
        sets,
        StateRules {
            running: None,
            fault_severity: Severity::High,
            modes: Vec::new(),
        },
    )
    .expect("engine");
    if let Some(config) = recorder {
        e = e.recording(config);
    }
    e.on_connection(true, 0);
    let normal: Vec<TagReading> = (0..CONTACTS)
        .map(|t| TagReading {
            tag: t,
            reading: Reading::Good(t != 0),
            source_time: 1,
        })
        .collect();
    e.on_readings(&normal, 1);
    e
}

fn flight_recorder_flood(c: &mut Criterion) {
    let mut rng = common::Rng(0x05EE_D0FF_100D);
    let mut values: Vec<bool> = (0..1_000).map(|t| t != 0).collect();
    let changes: Vec<(usize, bool)> = (0..90_000)
        .map(|k| {
            let tag = if k % 450 == 0 { 0 } else { 1 + rng.below(999) };
            values[tag] = !values[tag];
            (tag, values[tag])
        })
        .collect();
    let mut group = c.benchmark_group("flight_recorder_flood");
    group.throughput(Throughput::Elements(1));
    for (name, recorder) in [
        ("recorder_off", None),
        ("recorder_on", Some(RecorderConfig::default())),
    ] {
        let mut e = flood_engine(recorder);
        let (mut k, mut t, mut raised, mut calls) = (0usize, 2u64, 0u64, 0u64);
        group.bench_function(name, |b| {
            b.iter(|| {
                let (tag, value) = changes[k % changes.len()];
                k += 1;
                // 100 changes a millisecond: 100,000 a second.
                if k % 100 == 0 {
                    t += 1;
                }
                let step = e.on_readings(
                    &[TagReading {
                        tag,
                        reading: Reading::Good(value),
                        source_time: t,
                    }],
                    t,
                );
                calls += 1;
                raised += step
                    .alarms()
                    .filter(|(_, tr, _)| *tr == cellwatch_models::alarm::Transition::Raised)
                    .count() as u64;
                black_box(step.events.len())
            })
        });
        println!(
            "flight recorder flood, {name}: {raised} raises in {calls} changes ({:.0} a second at 100,000 changes a second)",
            raised as f64 * 100_000.0 / calls.max(1) as f64
        );
    }
    group.finish();
}

criterion_group!(
    benches,
    changes_per_second,
    flight_recorder,
    flight_recorder_flood
);
criterion_main!(benches);
