//! Changes per second on a generated cell of 10,000 signals and 1,000
//! switching functions: incremental re-evaluation of the checks a change
//! touches, against re-evaluating every check (the baseline).
//!
//! Run: `cargo bench -p cellwatch-models --bench evaluation`

#![allow(missing_docs)] // criterion_group! generates undocumented items

use std::hint::black_box;

use cellwatch_models::compiled::CompiledCell;
use criterion::{criterion_group, criterion_main, Criterion, Throughput};

mod common;

fn generated_cell() -> (CompiledCell, Vec<u32>) {
    let (sfs, mut rng) = common::generated_sfs();
    let mut cell = CompiledCell::new(&sfs);
    // Normal state: every contact closed, so no check is faulted.
    let mut changed = Vec::new();
    for i in 0..cell.signals().len() as u32 {
        cell.set(i, true, &mut changed);
    }
    let n = cell.signals().len();
    let changes = (0..4096).map(|_| rng.below(n) as u32).collect();
    (cell, changes)
}

fn changes_per_second(c: &mut Criterion) {
    let (cell, changes) = generated_cell();
    let mut group = c.benchmark_group("sf_changes");
    group.throughput(Throughput::Elements(1));

    let mut incremental = cell.clone();
    let mut k = 0;
    let mut changed = Vec::new();
    group.bench_function("incremental", |b| {
        b.iter(|| {
            let s = changes[k % changes.len()];
            k += 1;
            let v = !incremental.value(s);
            changed.clear();
            incremental.set(black_box(s), v, &mut changed);
            black_box(changed.len())
        })
    });

    let mut full = cell;
    let mut k = 0;
    group.bench_function("full_reevaluation", |b| {
        b.iter(|| {
            let s = changes[k % changes.len()];
            k += 1;
            let v = !full.value(s);
            changed.clear();
            full.write_bit(black_box(s), v);
            full.evaluate_all(&mut changed);
            black_box(changed.len())
        })
    });
    group.finish();
}

criterion_group!(benches, changes_per_second);
criterion_main!(benches);
