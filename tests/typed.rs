//! Typed tags through a real OPC UA server (the simulated CNC with data
//! registers): every scalar type arrives as itself, bits of a byte are
//! contacts, a value of the wrong type is bad; and through the whole
//! agent: a limit alarm, a parts counter that wraps and resets, counted
//! exactly in the metrics and in `cellwatch report`, an exported gauge.

use std::sync::Arc;

use cellwatch::config::TagConfig;
use cellwatch::sim::cnc::{NAMESPACE, PART_COUNTER};
use cellwatch::sources::SourceEvent;
use cellwatch_models::alarm::Transition;
use cellwatch_models::engine::Reading;
use cellwatch_models::signal::Signal;
use cellwatch_models::value::{Num, ValueType};
use opcua::types::{UAString, Variant};
use zenoh_ext::{AdvancedSubscriberBuilderExt, HistoryConfig, RecoveryConfig};

use crate::liveness::{insecure_behind, Running};
use crate::opcua::next;
use crate::util::{cellwatch, root};

fn typed(address: &str, value_type: ValueType, bit: Option<u8>) -> TagConfig {
    let node = address.split('.').next().unwrap();
    TagConfig {
        value_type,
        bit,
        ..TagConfig::boolean(
            &address.to_lowercase(),
            &format!("nsu={NAMESPACE};s={node}"),
            Signal::new(address),
        )
    }
}

/// Waits until every tag has delivered and returns the last reading of
/// each.
async fn readings(source: &mut Running, tags: usize) -> Vec<Reading> {
    let mut last: Vec<Option<Reading>> = vec![None; tags];
    while last.iter().any(Option::is_none) {
        if let SourceEvent::Readings(rs) = next(&mut source.rx, "values of every tag", |e| {
            matches!(e, SourceEvent::Readings(_))
        })
        .await
        {
            for r in rs {
                last[r.tag] = Some(r.reading);
            }
        }
    }
    last.into_iter().map(Option::unwrap).collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_scalar_type_arrives_as_itself_and_bits_are_contacts() {
    let dir = tempfile::tempdir().unwrap();
    let (sim, config) = insecure_behind(dir.path(), |addr| async move { addr }).await;
    for (name, value) in [
        ("D200", Variant::Int16(-1234)),
        ("D202", Variant::UInt32(4_000_000_000)),
        ("D204", Variant::Int64(-9_000_000_000_000)),
        ("D208", Variant::Float(1.5)),
        ("D212", Variant::Double(85.25)),
        ("D220", Variant::String(UAString::from("ABC-123"))),
        ("X30", Variant::Byte(0b1000_0001)),
    ] {
        sim.add_register(name, value).unwrap();
    }
    let tags = vec![
        typed("D200", ValueType::Int16, None),
        typed("D202", ValueType::UInt32, None),
        typed("D204", ValueType::Int64, None),
        typed("D208", ValueType::Float, None),
        typed("D212", ValueType::Double, None),
        typed("D220", ValueType::String, None),
        typed("X30.00", ValueType::Byte, Some(0)),
        typed("X30.01", ValueType::Byte, Some(1)),
        typed("X30.07", ValueType::Byte, Some(7)),
        // A Double where a contact is expected.
        TagConfig::boolean(
            "wrong",
            &format!("nsu={NAMESPACE};s=D212"),
            Signal::new("Y9.00"),
        ),
    ];
    let n = tags.len();
    let mut source = Running::start(config, tags);
    let got = readings(&mut source, n).await;
    assert_eq!(
        got,
        [
            Reading::Number(Num::Int(-1234)),
            Reading::Number(Num::UInt(4_000_000_000)),
            Reading::Number(Num::Int(-9_000_000_000_000)),
            Reading::Number(Num::Float(1.5)),
            Reading::Number(Num::Float(85.25)),
            Reading::Text(Arc::from("ABC-123")),
            Reading::Good(true),
            Reading::Good(false),
            Reading::Good(true),
            Reading::WrongType {
                expected: ValueType::Boolean,
                received: Some(ValueType::Double),
            },
        ]
    );
    // One write of the byte moves all its contacts.
    sim.set_registers(&[("X30".into(), Variant::Byte(0b0000_0010))])
        .unwrap();
    let mut bits: [Option<Reading>; 3] = Default::default();
    while bits.iter().any(Option::is_none) {
        if let SourceEvent::Readings(rs) = next(&mut source.rx, "the byte's new bits", |e| {
            matches!(e, SourceEvent::Readings(_))
        })
        .await
        {
            for r in rs.into_iter().filter(|r| (6..9).contains(&r.tag)) {
                bits[r.tag - 6] = Some(r.reading);
            }
        }
    }
    assert_eq!(
        bits,
        [
            Some(Reading::Good(false)),
            Some(Reading::Good(true)),
            Some(Reading::Good(false))
        ]
    );
    source.stop().await;
    sim.stop();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_agent_raises_a_limit_alarm_and_counts_parts_through_wrap_and_reset() {
    let mut fx = crate::agent::Fixture::start().await;
    let sub = fx
        .client()
        .declare_subscriber("cellwatch/m01ps0004/alarms/**")
        .history(HistoryConfig::default().detect_late_publishers())
        .recovery(RecoveryConfig::default().heartbeat())
        .await
        .unwrap();
    fx.settled().await;
    let mut seen = Vec::new();

    // The spindle runs hot: the H limit (85 °C, on-delay 2 s) raises with
    // value, limit, unit and how long.
    fx.sim.set_temperature(90.5).unwrap();
    let hot = crate::agent::alarm_until(&sub, "spindle-temp-h raised", &mut seen, |a| {
        a.id == "spindle-temp-h" && a.transition == Transition::Raised
    })
    .await;
    assert!(
        hot.message
            .starts_with("D100 (spindle_temperature) = 90.5 °C, above the H limit 85 °C for 2."),
        "{}",
        hot.message
    );
    assert_eq!(hot.kind, cellwatch_models::alarm::AlarmKind::Limit);
    let body = fx.scrape().await;
    assert!(
        body.contains(r#"cellwatch_tag_value{cell="m01ps0004",tag="spindle_temperature"} 90.5"#),
        "{body}"
    );
    fx.sim.set_temperature(40.0).unwrap();
    crate::agent::alarm_until(&sub, "spindle-temp-h cleared", &mut seen, |a| {
        a.id == "spindle-temp-h" && a.transition == Transition::Cleared
    })
    .await;

    // The parts counter: up, over the top, reset after 120. Each value is
    // seen by the agent before the next is written.
    let mut expected = 0u64;
    let mut last = 0u64;
    for v in [100u16, 30_000, 65_535, 0, 120, 0, 5] {
        fx.sim.set_part_counter(v).unwrap();
        fx.tag_value_is(PART_COUNTER, serde_json::json!(v)).await;
        let v = u64::from(v);
        expected += match (last, v) {
            (65_535, 0) => 1,
            (l, v) if v >= l => v - l,
            (_, v) => v,
        };
        last = v;
    }
    assert_eq!(expected, 100 + 29_900 + 35_535 + 1 + 120 + 5);
    let body = fx.scrape().await;
    assert!(
        body.contains(&format!(
            "cellwatch_parts_produced_total{{cell=\"m01ps0004\"}} {expected}"
        )),
        "{body}"
    );
    let journal = fx.journal_path();
    fx.stop().await;
    let day = chrono::Utc::now().format("%Y-%m-%d").to_string();
    let r = cellwatch(&[
        "report",
        "daily",
        "--date",
        &day,
        "--db",
        journal.to_str().unwrap(),
        "--causes",
        root().join("config/stop-causes.toml").to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let v: serde_json::Value = serde_json::from_str(&r.stdout).unwrap();
    assert_eq!(v["production"], expected, "{v}");
}
