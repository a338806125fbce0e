//! Transition timers: learning from about 1,000,000 events, and monitor
//! throughput in events per second, each against a baseline measured in the
//! same run: one plain pass that applies the same events to a value vector
//! (the cost of reading the logs at all).
//!
//! Run: `cargo bench -p cellwatch-models --bench timers`

#![allow(missing_docs)] // criterion_group! generates undocumented items

use std::hint::black_box;

use cellwatch_models::timer::learn::{self, LearnOptions, Tau, TimerModel};
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

/// The line's timer model, learned from four short runs.
fn line_model() -> TimerModel {
    let training: Vec<RunLog> = (1..=4).map(|s| line::run(s, 6, None).0).collect();
    learn::common(
        &training,
        &LearnOptions {
            delta_min: 2000,
            tau: Tau::Auto,
            min_support: None,
        },
    )
    .model
}

/// Plays every run on `m`, each signal of a run on the monitor's signals
/// `names` gives for it (one, or one per copy); the outcomes counted.
fn play(m: &mut TimerMonitor, data: &[RunLog], names: &dyn Fn(&str) -> Vec<String>) -> usize {
    let mut n = 0;
    for r in data {
        let index: Vec<Vec<usize>> = r
            .signals
            .iter()
            .map(|s| names(s).iter().filter_map(|x| m.signal(x)).collect())
            .collect();
        for (k, &v) in r.initial.iter().enumerate() {
            for &s in &index[k] {
                n += m.set(s, Some(v), 0).len();
            }
        }
        for ch in &r.changes {
            for &s in &index[ch.signal] {
                n += m.set(s, Some(ch.value), ch.at).len();
            }
        }
    }
    n
}

fn monitoring(c: &mut Criterion) {
    let model = line_model();
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
            |mut m| black_box(play(&mut m, &data, &|s| vec![s.to_string()])),
            BatchSize::LargeInput,
        )
    });
    g.finish();
}

/// `k` copies of `model`, each on its own signals (`name@i`): a cell
/// with `k` times the stations.
fn replicated(model: &TimerModel, k: usize) -> TimerModel {
    let rename = |s: &str, i: usize| match s.strip_prefix('-') {
        Some(r) => format!("-{r}@{i}"),
        None => format!("{s}@{i}"),
    };
    let mut out = model.clone();
    out.signals = (0..k)
        .flat_map(|i| model.signals.iter().map(move |s| format!("{s}@{i}")))
        .collect();
    out.transitions = (0..k)
        .flat_map(|i| {
            model.transitions.iter().map(move |t| {
                let mut t = t.clone();
                t.id += (i * model.transitions.len()) as u32;
                t.from = t.from.iter().map(|l| rename(l, i)).collect();
                t.to = t.to.iter().map(|l| rename(l, i)).collect();
                t.event.tag = rename(&t.event.tag, i);
                if let Some(e) = &mut t.trigger {
                    e.tag = rename(&e.tag, i);
                }
                t.from_numbered = None;
                t
            })
        })
        .collect();
    out
}

/// The monitor with about 1,000 transitions armed at once: the line
/// replicated until that many wait for their events together, each run
/// played on every copy in step. The baseline pass applies the same
/// events to value vectors.
fn monitoring_many_armed(c: &mut Criterion) {
    let one = line_model();
    let data = runs(20_000);
    // How many are armed on one copy, on average over a run's changes.
    let mut probe = TimerMonitor::new(&one).expect("model compiles");
    let (mut armed, mut samples) = (0usize, 0usize);
    for r in &data {
        let index: Vec<Option<usize>> = r.signals.iter().map(|s| probe.signal(s)).collect();
        for ch in &r.changes {
            if let Some(s) = index[ch.signal] {
                probe.set(s, Some(ch.value), ch.at);
                armed += probe.armed();
                samples += 1;
            }
        }
    }
    let per_copy = (armed as f64 / samples.max(1) as f64).max(0.1);
    let copies = (1000.0 / per_copy).ceil() as usize;
    let model = replicated(&one, copies);
    let events: usize = data.iter().map(|r| r.changes.len()).sum::<usize>() * copies;
    let mut g = c.benchmark_group("timers_monitor_1000_armed");
    g.sample_size(10);
    g.throughput(Throughput::Elements(events as u64));
    g.bench_function("baseline_pass", |b| {
        b.iter(|| {
            let mut n = 0;
            for _ in 0..copies {
                n += baseline(black_box(&data));
            }
            black_box(n)
        })
    });
    g.bench_function("monitor", |b| {
        b.iter_batched(
            || TimerMonitor::new(&model).expect("model compiles"),
            |mut m| {
                let copy = |s: &str| (0..copies).map(|i| format!("{s}@{i}")).collect();
                black_box(play(&mut m, &data, &copy))
            },
            BatchSize::LargeInput,
        )
    });
    g.finish();
    println!(
        "timers_monitor_1000_armed: {copies} copies of the line, {} transitions, {events} events, {per_copy:.1} armed per copy on average ({:.0} in all)",
        model.transitions.len(),
        per_copy * copies as f64
    );
}

criterion_group!(benches, learning, monitoring, monitoring_many_armed);
criterion_main!(benches);
