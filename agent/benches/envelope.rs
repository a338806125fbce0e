//! What sealing costs: every alarm event, state and answer an agent puts on
//! the bus is signed by the cell's agent (`cellwatch.signed.v1`, Ed25519),
//! and every client verifies it. Measured against the baseline of the
//! same payload without the envelope: its JSON serialisation, which every
//! publish does anyway.
//!
//! Run: `cargo bench -p cellwatch --bench envelope`

#![allow(missing_docs)] // criterion_group! generates undocumented items

use std::hint::black_box;

use cellwatch::bus::envelope::{AgentKey, Kind, Trust};
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use serde_json::{json, Value};

/// The README's alarm event (about 500 bytes of JSON).
fn alarm() -> Value {
    json!({"schema": "cellwatch.alarm.v1", "cell": "m01ps0004", "id": "ese", "kind": "switching",
        "severity": "critical", "state": "active_unacknowledged", "transition": "raised",
        "at": "2026-11-21T06:20:50.653Z", "raised_at": "2026-11-21T06:20:50.653Z", "cleared_at": null,
        "acked_by": null, "latched": false, "fault_type": "ESE", "fault_step": 6,
        "culprits": [{"address": "X0.06", "value": false, "expected": true,
                      "comment": "Y Over Travel Limit SW (B)", "trigger": true}],
        "message": "ESE at step 6: X0.06 = 0 (expected 1): Y Over Travel Limit SW (B)",
        "shelved": null, "out_of_service": null})
}

/// A history page of 200 alarm rows (about 130 kB of JSON).
fn history_page() -> Value {
    let rows: Vec<Value> = (0..200)
        .map(|seq| {
            json!({"seq": seq, "table": "alarm", "at": 1_795_000_000_000u64 + seq,
                   "fields": {"alarm": "ese", "kind": "switching", "severity": "critical",
                              "transition": "raised", "payload": alarm().to_string()}})
        })
        .collect();
    json!({"schema": "cellwatch.history.v1", "rows": rows, "more": false, "next": null})
}

fn sealing(c: &mut Criterion) {
    let key = AgentKey::generate("m01ps0004");
    let trust = Trust::parse("trust.toml", &key.trust_entry()).expect("the key's own trust entry");
    for (name, body, kind, on, query) in [
        (
            "alarm",
            alarm(),
            Kind::Put,
            "cellwatch/m01ps0004/alarms/ese",
            "",
        ),
        (
            "history_page",
            history_page(),
            Kind::Reply,
            "cellwatch/m01ps0004/history",
            "since=1h;nonce=00112233445566778899aabbccddeeff",
        ),
    ] {
        let mut group = c.benchmark_group(format!("envelope_{name}"));
        group.throughput(Throughput::Elements(1));
        group.bench_function("serialise (baseline)", |b| {
            b.iter(|| black_box(serde_json::to_string(black_box(&body)).expect("JSON")))
        });
        group.bench_function("serialise and seal", |b| {
            b.iter(|| {
                let text = serde_json::to_string(black_box(&body)).expect("JSON");
                black_box(key.seal(kind, on, query, 1_795_000_000_000, text))
            })
        });
        let sealed = key.seal(
            kind,
            on,
            query,
            1_795_000_000_000,
            serde_json::to_string(&body).expect("JSON"),
        );
        group.bench_function("open (client)", |b| {
            b.iter(|| {
                black_box(
                    trust
                        .open(black_box(sealed.as_bytes()), kind, on, query)
                        .expect("believed"),
                )
            })
        });
        group.finish();
        println!(
            "{name}: body {} bytes, sealed {} bytes",
            serde_json::to_string(&body).expect("JSON").len(),
            sealed.len()
        );
    }
}

criterion_group!(benches, sealing);
criterion_main!(benches);
