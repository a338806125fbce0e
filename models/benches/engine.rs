//! The whole engine (`CellEngine::on_readings`), one change per call, on the
//! generated cell of 10,000 contacts and 1,000 switching checks, plus 1,000
//! numeric tags: each check is armed by a comparison of one of them
//! (`D<c> > 5`), and each has a limit check (H 90, L 10, deadband 1).
//!
//! - **boolean** (baseline): every change toggles a contact.
//! - **half_numeric**: every other change is a new value of a numeric tag
//!   (comparison contact and limit levels follow).
//!
//! Run: `cargo bench -p cellwatch-models --bench engine`

#![allow(missing_docs)] // criterion_group! generates undocumented items

mod common;

use std::hint::black_box;

use cellwatch_models::alarm::Severity;
use cellwatch_models::comments::CommentDb;
use cellwatch_models::engine::{
    CellEngine, CheckSet, Reading, StateRules, SwitchingCheck, SwitchingChecks, Tag, TagReading,
};
use cellwatch_models::explain::Polarity;
use cellwatch_models::expr::Expr;
use cellwatch_models::limit::{Level, LimitCheck, LimitChecks, LimitLevel};
use cellwatch_models::signal::Signal;
use cellwatch_models::switching::SwitchingFunction;
use cellwatch_models::value::Num;
use criterion::{criterion_group, criterion_main, Criterion, Throughput};

const NUMBERS: usize = common::CHECKS;

fn engine() -> (CellEngine, usize, common::Rng) {
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
    for i in 0..NUMBERS {
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
    let limits = (0..NUMBERS)
        .map(|i| LimitCheck {
            comment: None,
            id: format!("d{i}"),
            tag: Signal::new(&format!("D{i}")),
            label: String::new(),
            unit: String::new(),
            deadband: 1.0,
            on_delay: 0,
            off_delay: 0,
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
        },
    )
    .expect("engine");
    e.on_connection(true, 0);
    // Normal state: every contact closed, every number mid-range.
    let mut normal: Vec<TagReading> = (0..n)
        .map(|t| TagReading {
            tag: t,
            reading: Reading::Good(true),
            source_time: 1,
        })
        .collect();
    normal.extend((0..NUMBERS).map(|i| TagReading {
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

criterion_group!(benches, changes_per_second);
criterion_main!(benches);
