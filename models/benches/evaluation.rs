//! Changes per second on a generated cell of 10,000 signals and 1,000
//! switching functions: incremental re-evaluation of the checks a change
//! touches, against re-evaluating every check (the baseline).
//!
//! Run: `cargo bench -p cellwatch-models --bench evaluation`

#![allow(missing_docs)] // criterion_group! generates undocumented items

use std::hint::black_box;

use cellwatch_models::compiled::CompiledCell;
use cellwatch_models::program::Program;
use cellwatch_models::signal::{Observability, Signal};
use cellwatch_models::switching::SwitchingFunction;
use criterion::{criterion_group, criterion_main, Criterion, Throughput};

const SIGNALS: usize = 10_000;
const CHECKS: usize = 1_000;

/// A small deterministic generator (xorshift64*), so every run measures the
/// same cell.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

fn address(i: usize) -> String {
    format!("X{}.{:02X}", i / 16, i % 16)
}

/// One fault rung like ESE's: OR chains of normally-closed contacts, an AND
/// of an OR group through the stack, about 30 contacts in 4 to 6 blocks.
fn rung(rng: &mut Rng, coil: usize, out: &mut String) {
    let contact = |rng: &mut Rng| address(rng.below(SIGNALS));
    out.push_str(&format!("RD.NOT {}\n", contact(rng)));
    for _ in 0..5 {
        out.push_str(&format!("OR.NOT {}\n", contact(rng)));
    }
    out.push_str(&format!("AND.NOT {}\n", contact(rng)));
    out.push_str(&format!("RD.NOT.STK {}\n", contact(rng)));
    for _ in 0..3 {
        out.push_str(&format!("OR.NOT {}\n", contact(rng)));
    }
    out.push_str("AND.STK\n");
    for _ in 0..2 {
        out.push_str(&format!("AND {}\n", contact(rng)));
    }
    for _ in 0..8 {
        out.push_str(&format!("OR.NOT {}\n", contact(rng)));
    }
    out.push_str(&format!("WRT R{coil}\nRD R{coil}\n"));
    for _ in 0..8 {
        out.push_str(&format!("OR.NOT {}\n", contact(rng)));
    }
    out.push_str(&format!("WRT G{coil}.00\n"));
}

fn generated_cell() -> (CompiledCell, Vec<u32>) {
    let mut rng = Rng(0x00C0_FFEE_1234_5678);
    let mut src = String::new();
    for c in 0..CHECKS {
        rung(&mut rng, c, &mut src);
    }
    let program = Program::compile("generated.il", &src, None).expect("generated program compiles");
    let observable = Observability::default_for(program.dialect());
    let sfs: Vec<SwitchingFunction> = (0..CHECKS)
        .map(|c| {
            SwitchingFunction::expand(&program, &Signal::new(&format!("G{c}.00")), &observable)
                .expect("derivable")
        })
        .collect();
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
