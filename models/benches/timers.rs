//! Transition timers: learning from about 1,000,000 events, and monitor
//! throughput in events per second, each against a baseline measured in the
//! same run: one plain pass that applies the same events to a value vector
//! (the cost of reading the logs at all).
//!
//! Run: `cargo bench -p cellwatch-models --bench timers`

#![allow(missing_docs)] // criterion_group! generates undocumented items

use std::hint::black_box;

use cellwatch_models::timer::learn::{self, LearnOptions, Tau};
use cellwatch_models::timer::line;
use cellwatch_models::timer::log::RunLog;
use cellwatch_models::timer::monitor::TimerMonitor;
use criterion::{criterion_group, criterion_main, BatchSize, Criterion, Throughput};

/// Runs of the simulated line totalling at least `events` changes.
fn runs(events: usize) -> Vec<RunLog> {
    let mut out = Vec::new();
    let mut total = 0;
    let mut seed = 1;
    while total < events {
        let (r, _) = line::run(seed, 50, None);
        total += r.changes.len();
        out.push(r);
        seed += 1;
    }
    out
}

fn baseline(runs: &[RunLog]) -> usize {
    let mut n = 0;
    for r in runs {
        let mut v = r.initial.clone();
        for c in &r.changes {
            v[c.signal] = c.value;
            n += usize::from(c.value);
        }
        n += v.len();
    }
    n
}

fn learning(c: &mut Criterion) {
    let data = runs(1_000_000);
    let events: usize = data.iter().map(|r| r.changes.len()).sum();
    let options = LearnOptions {
        delta_min: 2000,
        tau: Tau::Auto,
        min_support: None,
    };
    let mut g = c.benchmark_group("timers_learn");
    g.sample_size(10);
    g.throughput(Throughput::Elements(events as u64));
    g.bench_function("baseline_pass", |b| {
        b.iter(|| black_box(baseline(black_box(&data))))
    });
    g.bench_function("common", |b| {
        b.iter(|| {
            black_box(
                learn::common(black_box(&data), &options)
                    .model
                    .transitions
                    .len(),
            )
        })
    });
    g.finish();
}

fn monitoring(c: &mut Criterion) {
    let training: Vec<RunLog> = (1..=4).map(|s| line::run(s, 6, None).0).collect();
    let model = learn::common(
        &training,
        &LearnOptions {
            delta_min: 2000,
            tau: Tau::Auto,
            min_support: None,
        },
    )
    .model;
    let data = runs(200_000);
    let events: usize = data.iter().map(|r| r.changes.len()).sum();
    let mut g = c.benchmark_group("timers_monitor");
    g.sample_size(10);
    g.throughput(Throughput::Elements(events as u64));
    g.bench_function("baseline_pass", |b| {
        b.iter(|| black_box(baseline(black_box(&data))))
    });
    g.bench_function("monitor", |b| {
        b.iter_batched(
            || TimerMonitor::new(&model).expect("model compiles"),
            |mut m| {
                let mut n = 0;
                for r in &data {
                    let index: Vec<Option<usize>> = r.signals.iter().map(|s| m.signal(s)).collect();
                    for (i, &v) in r.initial.iter().enumerate() {
                        if let Some(s) = index[i] {
                            n += m.set(s, Some(v), 0).len();
                        }
                    }
                    for ch in &r.changes {
                        if let Some(s) = index[ch.signal] {
                            n += m.set(s, Some(ch.value), ch.at).len();
                        }
                    }
                }
                black_box(n)
            },
            BatchSize::LargeInput,
        )
    });
    g.finish();
}

criterion_group!(benches, learning, monitoring);
criterion_main!(benches);
