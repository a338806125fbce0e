//! The `@` bus source against the simulated moulding units, over TCP (a
//! serial device server's raw socket) and over a pseudo-terminal (a serial
//! port at 9600 7E2): status contacts and production per unit, a stop with
//! its cause, line noise retried without a trace, a silent unit reported
//! once and nothing else.

use std::time::Duration;

use cellwatch::config::TagConfig;
use cellwatch::sim::moulding::MouldingBus;
use cellwatch::sources::legacy::{self, LegacyConfig, Parity, SerialLine, Transport};
use cellwatch::sources::SourceEvent;
use cellwatch_models::engine::Reading;
use cellwatch_models::legacy::Status;
use cellwatch_models::signal::Signal;
use cellwatch_models::value::{Num, ValueType};
use tokio::sync::mpsc;

use crate::opcua::next;

/// Per unit 1..=3: running (bit 0), front door open (bit 1), production.
fn tags() -> Vec<TagConfig> {
    let mut out = Vec::new();
    for u in 1..=3u8 {
        for (bit, what) in [(0u8, "running"), (1, "front_door_open")] {
            out.push(TagConfig {
                value_type: ValueType::UInt16,
                bit: Some(bit),
                ..TagConfig::boolean(
                    &format!("u{u}_{what}"),
                    &format!("@{u:02X}/status"),
                    Signal::new(&format!("U{u}.{bit:02X}")),
                )
            });
        }
        out.push(TagConfig {
            value_type: ValueType::UInt32,
            ..TagConfig::boolean(
                &format!("u{u}_production"),
                &format!("@{u:02X}/production"),
                Signal::new(&format!("P{u}")),
            )
        });
    }
    out
}

const RUNNING: fn(u8) -> usize = |u| 3 * (usize::from(u) - 1);
const DOOR: fn(u8) -> usize = |u| 3 * (usize::from(u) - 1) + 1;
const PRODUCTION: fn(u8) -> usize = |u| 3 * (usize::from(u) - 1) + 2;

struct Polling {
    rx: mpsc::Receiver<SourceEvent>,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    task: tokio::task::JoinHandle<()>,
}

impl Polling {
    fn start(transport: Transport) -> Polling {
        let config = LegacyConfig {
            transport,
            poll_interval: Duration::from_millis(50),
            response_timeout: Duration::from_millis(200),
            retries: 2,
        };
        let (tx, rx) = mpsc::channel(cellwatch::sources::QUEUE_CAPACITY);
        let (stop, stop_rx) = tokio::sync::oneshot::channel::<()>();
        let task = tokio::spawn(async move {
            legacy::run(&config, &tags(), tx, None, async {
                let _ = stop_rx.await;
            })
            .await
            .unwrap();
        });
        Polling {
            rx,
            stop: Some(stop),
            task,
        }
    }

    async fn stop(mut self) {
        let _ = self.stop.take().unwrap().send(());
        self.task.await.unwrap();
    }
}

/// Waits for readings until tag `tag` is `reading`; returns every event
/// seen on the way.
async fn until(p: &mut Polling, what: &str, tag: usize, reading: Reading) -> Vec<SourceEvent> {
    let mut seen = Vec::new();
    loop {
        let e = next(&mut p.rx, what, |_| true).await;
        let done = matches!(&e, SourceEvent::Readings(rs) if rs.iter().any(|r| r.tag == tag && r.reading == reading));
        seen.push(e);
        if done {
            return seen;
        }
    }
}

fn problems(events: &[SourceEvent]) -> Vec<(String, bool)> {
    events
        .iter()
        .filter_map(|e| match e {
            SourceEvent::Problem { id, problem } => Some((id.clone(), problem.is_some())),
            _ => None,
        })
        .collect()
}

async fn scenario(bus: &MouldingBus, transport: Transport) {
    let mut p = Polling::start(transport);
    next(&mut p.rx, "connected", |e| {
        matches!(e, SourceEvent::Connected(_))
    })
    .await;
    until(
        &mut p,
        "unit 3 production",
        PRODUCTION(3),
        Reading::Number(Num::UInt(0)),
    )
    .await;

    // A door-open stop on unit 2: not running, front door open.
    bus.stop(2, Some(Status::FRONT_DOOR_OPEN));
    let seen = until(&mut p, "unit 2's door open", DOOR(2), Reading::Good(true)).await;
    assert!(seen.iter().any(|e| matches!(e, SourceEvent::Readings(rs)
        if rs.iter().any(|r| r.tag == RUNNING(2) && r.reading == Reading::Good(false)))));

    // Cycles on the running units; noise corrupts two answers in a row,
    // asked again (retries = 2).
    bus.corrupt_next(2);
    for _ in 0..5 {
        bus.cycle();
    }
    let seen = until(
        &mut p,
        "unit 1 at 5 parts",
        PRODUCTION(1),
        Reading::Number(Num::UInt(5)),
    )
    .await;
    assert!(problems(&seen).is_empty(), "noise is retried: {seen:?}");
    assert_eq!(bus.noise_left(), 0);

    // Unit 3 goes silent: its tags unknown, one problem, nothing else.
    bus.set_silent(3, true);
    let seen = until(
        &mut p,
        "unit 3 unreachable",
        PRODUCTION(3),
        Reading::Unreachable,
    )
    .await;
    assert_eq!(problems(&seen), [("legacy-unit-03".to_string(), true)]);
    for e in &seen {
        if let SourceEvent::Readings(rs) = e {
            for r in rs {
                assert!(
                    r.tag >= RUNNING(3) || r.reading != Reading::Unreachable,
                    "only unit 3's tags become unknown: {r:?}"
                );
            }
        }
    }
    bus.cycle();
    let seen = until(
        &mut p,
        "unit 1 at 6 parts",
        PRODUCTION(1),
        Reading::Number(Num::UInt(6)),
    )
    .await;
    assert!(
        problems(&seen).is_empty(),
        "one problem for the silent unit: {seen:?}"
    );
    bus.set_silent(3, false);
    let seen = until(
        &mut p,
        "unit 3 back",
        PRODUCTION(3),
        Reading::Number(Num::UInt(6)),
    )
    .await;
    assert_eq!(problems(&seen), [("legacy-unit-03".to_string(), false)]);
    p.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn three_units_polled_over_tcp() {
    let bus = MouldingBus::new(3);
    let (addr, server) = bus
        .listen_tcp("127.0.0.1:0".parse().unwrap())
        .await
        .unwrap();
    scenario(&bus, Transport::Tcp(addr.to_string())).await;
    server.abort();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn three_units_polled_over_a_serial_line() {
    let bus = MouldingBus::new(3);
    let path = bus.pty().unwrap();
    let line = SerialLine {
        path: path.to_string_lossy().into_owned(),
        baud: 9600,
        data_bits: 7,
        parity: Parity::Even,
        stop_bits: 2,
    };
    scenario(&bus, Transport::Serial(line)).await;
}

/// The paper's reference code (`CheckSum`, and the two `sprintf`s that
/// build a frame), compiled with the machine's C compiler, writes the same
/// bytes as `Frame::encode` for a table of units and texts.
#[test]
fn frames_are_byte_identical_to_the_papers_reference_code() {
    use cellwatch_models::legacy::{Frame, Header};
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("ref.c");
    std::fs::write(
        &src,
        r#"#include <stdio.h>
#include <stdlib.h>
unsigned char CheckSum(char *s) { unsigned char c = 0; while (*s) c ^= *s++; return c; }
int main(int argc, char **argv) {
    char ChkBuf[128], Buf[160];
    for (int i = 1; i + 1 < argc; i += 2) {
        int UnitNo = atoi(argv[i]);
        char *str = argv[i + 1];
        sprintf(ChkBuf, "@%02X%2s", UnitNo, str);
        sprintf(Buf, "%s%02X*\x0D", ChkBuf, CheckSum(ChkBuf));
        fputs(Buf, stdout);
    }
    return 0;
}
"#,
    )
    .unwrap();
    let exe = dir.path().join("ref");
    let cc = std::process::Command::new("cc")
        .arg("-o")
        .arg(&exe)
        .arg(&src)
        .output()
        .expect("a C compiler (cc) is installed");
    assert!(
        cc.status.success(),
        "{}",
        String::from_utf8_lossy(&cc.stderr)
    );
    let table: Vec<Frame> = vec![
        Frame::read(0, Header::ReadStatus),
        Frame::read(1, Header::ReadProduction),
        Frame::new(2, Header::ReadStatus, "0022001234"),
        Frame::new(0x0A, Header::WriteTarget, "001500"),
        Frame::new(0x1F, Header::WriteItem, "AB-12   "),
        Frame::new(0x7F, Header::ReadOutputs, "BEEF"),
        Frame::new(0xFF, Header::Nak, "15"),
        Frame::new(0x10, Header::Ack, "10"),
    ];
    let mut args = Vec::new();
    let mut ours = Vec::new();
    for f in &table {
        args.push(f.unit.to_string());
        args.push(format!("{}{}", f.header.code(), f.text));
        ours.extend(f.encode());
    }
    let out = std::process::Command::new(&exe)
        .args(&args)
        .output()
        .unwrap();
    assert!(out.status.success());
    assert_eq!(
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&ours)
    );
}

/// The shipped `config/moulding.toml` run as an agent against the simulated
/// bus: a door-open stop on unit 2 is an alarm naming the unit's contact
/// and a fault state with stop cause 01; production is the units' parts;
/// line noise is retried and counts nothing twice; a silent unit is one
/// alarm and nothing else; the daily report says what the simulator did.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_legacy_bus_runs_as_a_cell_over_tcp() {
    bus_cell(false).await;
}

/// The same over a serial line (a pseudo-terminal at 9600 7E2).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_legacy_bus_runs_as_a_cell_over_a_serial_line() {
    bus_cell(true).await;
}

async fn bus_cell(serial: bool) {
    use cellwatch::payload::AlarmPayload;
    use zenoh_ext::{AdvancedSubscriberBuilderExt, HistoryConfig, RecoveryConfig};

    let dir = tempfile::tempdir().unwrap();
    let (bus, server, agent, client, _) = moulding_agent(
        dir.path(),
        &crate::spawned::operators_file(&cellwatch::operator::Action::ALL),
        serial,
    )
    .await;
    let sub = client
        .declare_subscriber("cellwatch/moulding-bus1/alarms/**")
        .history(HistoryConfig::default().detect_late_publishers())
        .recovery(RecoveryConfig::default().heartbeat())
        .await
        .unwrap();
    let snapshot_until = |what: &'static str, ready: fn(&serde_json::Value) -> bool| {
        let client = client.clone();
        async move {
            let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
            loop {
                let snap: serde_json::Value = serde_json::from_str(
                    &crate::spawned::query(&client, "cellwatch/moulding-bus1/snapshot", None)
                        .await
                        .unwrap(),
                )
                .unwrap();
                if ready(&snap) {
                    return snap;
                }
                assert!(tokio::time::Instant::now() < deadline, "{what}: {snap}");
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
        }
    };
    let value = |snap: &serde_json::Value, address: &str| {
        snap["tags"]
            .as_array()
            .unwrap()
            .iter()
            .find(|t| t["address"] == address)
            .map(|t| t["value"].clone())
            .unwrap()
    };
    snapshot_until("running", |s| s["state"] == "running").await;

    // Five cycles on every unit, two answers corrupted on the way.
    bus.corrupt_next(2);
    for _ in 0..5 {
        bus.cycle();
    }
    let snap = snapshot_until("15 parts", |s| {
        ["P1", "P2", "P3"].iter().all(|a| {
            s["tags"]
                .as_array()
                .unwrap()
                .iter()
                .any(|t| t["address"] == *a && t["value"] == 5)
        })
    })
    .await;
    assert_eq!(value(&snap, "J2"), "ITEM-01");
    assert_eq!(value(&snap, "T2"), 1000);

    // Unit 2's front door opens.
    bus.stop(2, Some(Status::FRONT_DOOR_OPEN));
    let mut seen: Vec<AlarmPayload> = Vec::new();
    let door = crate::agent::alarm_until(&sub, "front-door raised", &mut seen, |a| {
        a.id == "front-door"
    })
    .await;
    assert_eq!(door.fault_type, "DOOR_FRONT");
    assert_eq!(door.culprits[0].address, "U2.01");
    assert_eq!(
        door.culprits[0].comment.as_deref(),
        Some("Unit 2: Front door open (stop cause 01)")
    );
    snapshot_until("fault", |s| s["state"] == "fault").await;
    bus.stop(2, None);
    crate::agent::alarm_until(&sub, "front-door cleared", &mut seen, |a| {
        a.id == "front-door" && a.transition == cellwatch_models::alarm::Transition::Cleared
    })
    .await;

    // Unit 3 goes silent: one alarm, nothing else.
    bus.set_silent(3, true);
    let silent = crate::agent::alarm_until(&sub, "unit 3 out of reach", &mut seen, |a| {
        a.id == "legacy-unit-03"
    })
    .await;
    assert!(
        silent.message.contains("unit 03 does not answer"),
        "{}",
        silent.message
    );
    bus.cycle();
    snapshot_until("unit 1 at 6 parts", |s| {
        s["tags"]
            .as_array()
            .unwrap()
            .iter()
            .any(|t| t["address"] == "P1" && t["value"] == 6)
    })
    .await;
    bus.set_silent(3, false);
    crate::agent::alarm_until(&sub, "unit 3 back", &mut seen, |a| {
        a.id == "legacy-unit-03" && a.transition == cellwatch_models::alarm::Transition::Cleared
    })
    .await;
    let raised: Vec<&str> = seen
        .iter()
        .filter(|a| a.transition == cellwatch_models::alarm::Transition::Raised)
        .map(|a| a.id.as_str())
        .collect();
    assert_eq!(raised, ["front-door", "legacy-unit-03"], "no other alarm");

    // Unit 3 made its sixth part while silent: counted once it answers.
    snapshot_until("unit 3 at 6 parts", |s| {
        s["tags"]
            .as_array()
            .unwrap()
            .iter()
            .any(|t| t["address"] == "P3" && t["value"] == 6)
    })
    .await;
    // Six cycles on every unit (unit 2 ran again before the sixth).
    let made: u64 = 6 + 6 + 6;
    let body = crate::util::scrape(agent.metrics_addr().unwrap()).await;
    assert!(
        body.contains(&format!(
            "cellwatch_parts_produced_total{{cell=\"moulding-bus1\"}} {made}"
        )),
        "{body}"
    );
    agent.stop().await;
    if let Some(server) = server {
        server.abort();
    }

    let v = crate::util::todays_report(&dir.path().join("journal.sqlite"));
    assert_eq!(v["production"], made, "{v}");
    let causes = v["stop_causes"].as_array().unwrap();
    assert!(
        causes.iter().any(|c| c["code"] == "01" && c["count"] == 1),
        "{v}"
    );
}

/// The shipped `config/moulding.toml` as an agent polling a simulated bus
/// of three units over TCP or a serial line (every 100 ms), Zenoh with
/// TLS, the given operators file; an operator's Zenoh session, and the
/// agent's Zenoh port.
async fn moulding_agent(
    dir: &std::path::Path,
    operators: &str,
    serial: bool,
) -> (
    MouldingBus,
    Option<tokio::task::JoinHandle<()>>,
    cellwatch::cell::Agent,
    zenoh::Session,
    u16,
) {
    let bus = MouldingBus::new(3);
    let (transport, server) = if serial {
        let path = bus.pty().unwrap();
        let line = SerialLine {
            path: path.to_string_lossy().into_owned(),
            baud: 9600,
            data_bits: 7,
            parity: Parity::Even,
            stop_bits: 2,
        };
        (Transport::Serial(line), None)
    } else {
        let (addr, server) = bus
            .listen_tcp("127.0.0.1:0".parse().unwrap())
            .await
            .unwrap();
        (Transport::Tcp(addr.to_string()), Some(server))
    };
    let mut c = cellwatch::config::load(&crate::util::root().join("config/moulding.toml")).unwrap();
    let l = c.legacy.as_mut().unwrap();
    l.transport = transport;
    l.poll_interval = Duration::from_millis(100);
    let port = crate::agent::free_port();
    c.zenoh.listen = vec![format!("tls/127.0.0.1:{port}")];
    crate::util::bus_pki(dir, &["agent-moulding-bus1"]);
    c.zenoh.tls = Some(crate::util::bus_tls(dir, "agent-moulding-bus1"));
    c.journal.path = dir.join("journal.sqlite");
    c.metrics = Some("127.0.0.1:0".parse().unwrap());
    let operators_file = dir.join("operators.toml");
    std::fs::write(&operators_file, operators).unwrap();
    c.operators_file = Some(operators_file);
    let agent = cellwatch::cell::start(c, None).await.unwrap();
    let client = crate::util::operator_session(dir, "operator-kim", port).await;
    (bus, server, agent, client, port)
}

/// Writes to a unit: a target sent by an operator allowed `write` is
/// acknowledged by the unit (`AC10`), read back and journaled; one from an
/// operator without that permission, one unsigned, one with a bad
/// signature and one with a value that does not fit are refused,
/// journaled, and never sent on the bus.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_target_is_written_only_for_an_operator_allowed_to_write() {
    use cellwatch::operator::{Action, Command, OperatorKey};
    let dir = tempfile::tempdir().unwrap();
    let lee = OperatorKey::generate("lee");
    let operators = format!(
        "{}\n{}",
        crate::spawned::operators_file(&[Action::Ack, Action::Write]),
        lee.operators_entry(&[Action::Ack, Action::Reset])
    );
    let (bus, server, agent, client, port) = moulding_agent(dir.path(), &operators, false).await;
    let query = |selector: String, payload: Option<String>| {
        let client = client.clone();
        async move {
            crate::spawned::query(&client, &selector, payload)
                .await
                .unwrap()
        }
    };
    let target_is = |v: u64| {
        let query = &query;
        async move {
            let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
            loop {
                let snap: serde_json::Value = serde_json::from_str(
                    &query("cellwatch/moulding-bus1/snapshot".into(), None).await,
                )
                .unwrap();
                let t2 = snap["tags"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .find(|t| t["address"] == "T2")
                    .map(|t| t["value"].clone());
                if t2 == Some(serde_json::json!(v)) {
                    return;
                }
                assert!(
                    tokio::time::Instant::now() < deadline,
                    "T2 never {v}: {snap}"
                );
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
        }
    };
    target_is(1000).await;
    let write = |operator: &str, value: &str, nonce: &str| Command {
        action: Action::Write,
        alarm: String::new(),
        tag: Some("T2".into()),
        value: Some(value.into()),
        operator: operator.into(),
        nonce: nonce.into(),
        issued_at: cellwatch::clock::now_ms(),
        signature: String::new(),
    };
    let send = |c: Command| {
        let json = serde_json::to_string(&c).unwrap();
        let query = &query;
        async move {
            let r: serde_json::Value = serde_json::from_str(
                &query("cellwatch/moulding-bus1/command".into(), Some(json)).await,
            )
            .unwrap();
            (
                r["accepted"].as_bool().unwrap(),
                r["detail"].as_str().unwrap().to_string(),
            )
        }
    };
    let mut by_lee = write("lee", "1500", "n1");
    by_lee.sign("moulding-bus1", &lee);
    let (ok, why) = send(by_lee).await;
    assert_eq!((ok, why.as_str()), (false, "operator 'lee' may not write"));
    assert_eq!(
        send(write("kim", "1500", "n2")).await,
        (false, "unsigned command".to_string())
    );
    let mut forged = write("kim", "1500", "n3");
    forged.sign("moulding-bus1", &OperatorKey::generate("kim"));
    assert_eq!(send(forged).await, (false, "bad signature".to_string()));
    let mut too_big = write("kim", "1234567", "n4");
    too_big.sign("moulding-bus1", &crate::spawned::kim());
    let (ok, why) = send(too_big).await;
    assert!(!ok && why.contains("is not a quantity"), "{why}");
    assert!(
        bus.log().iter().all(|e| !e.what.starts_with("write")),
        "nothing refused reached the bus: {:?}",
        bus.log()
    );

    let mut good = write("kim", "1500", "n5");
    good.sign("moulding-bus1", &crate::spawned::kim());
    assert_eq!(
        send(good).await,
        (true, "WT001500 to unit 02: AC10".to_string())
    );
    assert_eq!(bus.unit(2).unwrap().target, 1500);
    let writes: Vec<String> = bus
        .log()
        .into_iter()
        .filter(|e| e.what.starts_with("write"))
        .map(|e| format!("{} {}", e.unit, e.what))
        .collect();
    assert_eq!(writes, ["2 write WT001500"]);
    target_is(1500).await;

    // The same from the command line: `cellwatch write`.
    let key = dir.path().join("kim.key");
    std::fs::write(&key, crate::spawned::kim().to_file()).unwrap();
    let mut args: Vec<String> = [
        "write",
        "--cell",
        "moulding-bus1",
        "--tag",
        "J2",
        "--value",
        "MOULD-7",
        "--key-file",
        key.to_str().unwrap(),
    ]
    .map(String::from)
    .to_vec();
    args.extend(crate::util::bus_args(dir.path(), "operator-kim", port));
    let r = tokio::task::spawn_blocking(move || {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        crate::util::cellwatch(&args)
    })
    .await
    .unwrap();
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert_eq!(r.stdout, "accepted: WJMOULD-7 to unit 02: AC10\n");
    assert_eq!(bus.unit(2).unwrap().item, "MOULD-7");

    // Every command is in the journal with its outcome.
    let page: serde_json::Value = serde_json::from_str(
        &query(
            "cellwatch/moulding-bus1/history?kind=command;since=1h".into(),
            None,
        )
        .await,
    )
    .unwrap();
    let rows: Vec<(String, String, bool)> = page["rows"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| {
            (
                r["fields"]["operator"].as_str().unwrap().to_string(),
                r["fields"]["alarm"].as_str().unwrap().to_string(),
                r["fields"]["accepted"]
                    .as_bool()
                    .unwrap_or(r["fields"]["accepted"] == 1),
            )
        })
        .collect();
    assert_eq!(
        rows,
        [
            ("lee".into(), "T2".into(), false),
            ("kim".into(), "T2".into(), false),
            ("kim".into(), "T2".into(), false),
            ("kim".into(), "T2".into(), false),
            ("kim".into(), "T2".into(), true),
            ("kim".into(), "J2".into(), true),
        ],
        "{page}"
    );
    agent.stop().await;
    if let Some(server) = server {
        server.abort();
    }
}
