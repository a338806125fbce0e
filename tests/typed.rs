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
    let v = crate::util::todays_report(&journal);
    assert_eq!(v["production"], expected, "{v}");
}

/// The per-tag deadband goes to the server as the data-change filter: a
/// change smaller than it is never sent.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_tags_deadband_filters_small_changes_at_the_server() {
    let dir = tempfile::tempdir().unwrap();
    let (sim, config) = insecure_behind(dir.path(), |addr| async move { addr }).await;
    sim.add_register("D300", Variant::Double(10.0)).unwrap();
    let mut tag = typed("D300", ValueType::Double, None);
    tag.deadband = Some(cellwatch::config::Deadband::Absolute(5.0));
    tag.sampling_interval = Some(std::time::Duration::ZERO);
    let mut source = Running::start(config, vec![tag]);
    assert_eq!(
        readings(&mut source, 1).await,
        [Reading::Number(Num::Float(10.0))]
    );
    for v in [12.0, 14.5, 20.0] {
        sim.set_registers(&[("D300".into(), Variant::Double(v))])
            .unwrap();
    }
    // 12 and 14.5 are within 5 of 10: the only value sent is 20.
    let mut sent = Vec::new();
    while sent.last() != Some(&Reading::Number(Num::Float(20.0))) {
        if let SourceEvent::Readings(rs) = next(&mut source.rx, "20", |e| {
            matches!(e, SourceEvent::Readings(_))
        })
        .await
        {
            sent.extend(rs.into_iter().map(|r| r.reading));
        }
    }
    assert_eq!(sent, [Reading::Number(Num::Float(20.0))]);
    source.stop().await;
    sim.stop();
}

/// `cellwatch discover` against the simulated CNC prints a configuration
/// that validates and reads the same nodes, with the same types, as
/// `config/demo.toml`; `--check` names what a configuration gets wrong.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn discover_prints_a_configuration_of_the_demos_tags_and_checks_one() {
    use cellwatch::sim::cnc::{SimOptions, SimulatedCnc};
    use cellwatch::sources::{opcua, pki};
    let dir = tempfile::tempdir().unwrap();
    let sim = SimulatedCnc::start(&SimOptions {
        listen: "127.0.0.1:0".parse().unwrap(),
        pki_dir: dir.path().join("sim-pki"),
        insecure: false,
        decoy: None,
    })
    .await
    .unwrap();
    let pki_dir = dir.path().join("pki");
    let mut ours = crate::opcua::opcua_config(&sim.endpoint(), &pki_dir);
    ours.pki_dir = pki_dir.clone();
    drop(opcua::client("discover", &ours).unwrap());
    pki::trust(&pki::own_cert(&pki_dir), &dir.path().join("sim-pki")).unwrap();
    pki::trust(&pki::own_cert(&dir.path().join("sim-pki")), &pki_dir).unwrap();

    let endpoint = sim.endpoint();
    let pki = pki_dir.to_str().unwrap().to_string();
    let r =
        tokio::task::spawn_blocking(move || cellwatch(&["discover", &endpoint, "--pki-dir", &pki]))
            .await
            .unwrap();
    assert_eq!(r.code, 0, "{}", r.stderr);
    // The cell's id from the server's application name; the bus's files
    // it names are listed, with the commands that make them, until there.
    let cell = "cellwatch-simulated-cnc";
    assert!(
        r.stdout.contains(&format!("[cell]\nid = \"{cell}\"\n")),
        "{}",
        r.stdout
    );
    assert!(
        r.stderr.contains(&format!(
            "cellwatch pki issue --dir pki-bus --name agent-{cell}"
        )),
        "{}",
        r.stderr
    );
    crate::util::bus_pki(dir.path(), &[&format!("agent-{cell}")]);
    let key = dir.path().join(format!("{cell}.agent.key"));
    let made = cellwatch(&[
        "pki",
        "agent-key",
        "--cell",
        cell,
        "--out",
        key.to_str().unwrap(),
    ]);
    assert_eq!(made.code, 0, "{}", made.stderr);
    std::fs::write(
        dir.path().join("operators.toml"),
        crate::spawned::operators_file(&cellwatch::operator::Action::ALL),
    )
    .unwrap();
    // Written as it is, it validates: secure, complete.
    let found = dir.path().join("found.toml");
    std::fs::write(&found, &r.stdout).unwrap();
    let v = cellwatch(&["validate", found.to_str().unwrap()]);
    assert_eq!(v.code, 0, "{}\n{}", v.stderr, r.stdout);

    let discovered = cellwatch::config::load(&found).unwrap();

    // The same tags in a tags file (for servers of thousands of tags): the
    // configuration printed reads it and gets the same tags.
    let csv = dir.path().join("tags.csv");
    std::fs::write(&csv, "stale").unwrap();
    let (endpoint, pki, csv_arg) = (
        sim.endpoint(),
        pki_dir.to_str().unwrap().to_string(),
        csv.to_str().unwrap().to_string(),
    );
    let f = tokio::task::spawn_blocking(move || {
        cellwatch(&[
            "discover",
            &endpoint,
            "--pki-dir",
            &pki,
            "--tags-file",
            &csv_arg,
        ])
    })
    .await
    .unwrap();
    assert_eq!(f.code, 0, "{}", f.stderr);
    assert!(!f.stdout.contains("[[tags]]"), "{}", f.stdout);
    assert!(
        f.stdout
            .contains(&format!("tags_file = \"{}\"", csv.display())),
        "{}",
        f.stdout
    );
    let with_file = dir.path().join("found-file.toml");
    std::fs::write(&with_file, &f.stdout).unwrap();
    let v = cellwatch(&["validate", with_file.to_str().unwrap()]);
    assert_eq!(v.code, 0, "{}\n{}", v.stderr, f.stdout);
    let read = cellwatch::config::load(&with_file).unwrap();
    assert_eq!(read.tags, discovered.tags);
    let rows = std::fs::read_to_string(&csv).unwrap();
    assert!(
        rows.starts_with("name,node_id,address,type,comment\n"),
        "{rows}"
    );
    assert_eq!(rows.lines().count(), discovered.tags.len() + 1, "{rows}");
    let demo = cellwatch::config::load(&root().join("config/demo.toml")).unwrap();
    let node = |t: &TagConfig, uri: Option<&str>| opcua::TagNode::parse(&t.node_id, uri).unwrap();
    let by_address: std::collections::HashMap<_, _> = discovered
        .tags
        .iter()
        .map(|t| (t.address.clone(), t))
        .collect();
    for t in &demo.tags {
        let d = by_address
            .get(&t.address)
            .unwrap_or_else(|| panic!("{} not discovered:\n{}", t.address, r.stdout));
        assert_eq!(
            node(d, None),
            node(t, demo.opcua.as_ref().unwrap().namespace_uri.as_deref()),
            "{}",
            t.address
        );
        assert_eq!(d.value_type, t.value_type, "{}", t.address);
    }
    // Besides the demo's tags, the server has only the fault coils.
    let mut extra: Vec<String> = discovered
        .tags
        .iter()
        .filter(|d| !demo.tags.iter().any(|t| t.address == d.address))
        .map(|d| d.address.to_string())
        .collect();
    extra.sort();
    assert_eq!(extra, ["G8.02", "G9.00"]);
    let temp = by_address[&Signal::new("D100")];
    assert_eq!(
        temp.comment.as_deref(),
        Some("Spindle temperature, degrees C")
    );

    // A configuration with a wrong type and a tag the server lacks.
    let (tags, _) = r.stdout.split_once("\n[zenoh]").unwrap();
    let wrong = tags.replace("type = \"UInt16\"", "type = \"Int32\"")
        + "\n[[tags]]\nname = \"ghost\"\nnode_id = \"nsu=urn:cellwatch:sim:cnc:plc;s=X99.00\"\naddress = \"X99.00\"\n\n[zenoh]\nplain = true\n";
    let checked = dir.path().join("wrong.toml");
    std::fs::write(&checked, wrong).unwrap();
    let checked = checked.to_str().unwrap().to_string();
    let c = tokio::task::spawn_blocking(move || cellwatch(&["discover", "--check", &checked]))
        .await
        .unwrap();
    assert_eq!(c.code, 1, "{}\n{}", c.stdout, c.stderr);
    assert_eq!(
        c.stdout,
        "d108 (D108): typed differently: the configuration says Int32, the server has UInt16\n\
         ghost (X99.00): missing: nsu=urn:cellwatch:sim:cnc:plc;s=X99.00 (no such node)\n"
    );
    assert!(
        c.stderr.contains("2 of 44 tags do not match the server"),
        "{}",
        c.stderr
    );
    sim.stop();
}
