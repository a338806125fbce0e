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
        async move { crate::spawned::cell_snapshot_until(&client, "moulding-bus1", what, ready).await }
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
pub(crate) async fn moulding_agent(
    dir: &std::path::Path,
    operators: &str,
    serial: bool,
) -> (
    MouldingBus,
    Option<tokio::task::JoinHandle<()>>,
    cellwatch::agent::Agent,
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
    c.zenoh.listen = vec!["quic/127.0.0.1:0".into()];
    crate::util::bus_pki(dir, &["agent-moulding-bus1"]);
    c.zenoh.tls = Some(crate::util::bus_tls(dir, "agent-moulding-bus1"));
    c.journal.path = dir.join("journal.sqlite");
    c.zenoh.signing_key = Some(c.journal.path.with_extension("agent.key"));
    c.metrics = Some("127.0.0.1:0".parse().unwrap());
    let operators_file = dir.join("operators.toml");
    std::fs::write(&operators_file, operators).unwrap();
    c.operators_file = Some(operators_file);
    let agent = cellwatch::agent::start(c, None).await.unwrap();
    let port = crate::util::agent_port(&agent).await;
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
    let write = |operator: &str, value: &str| Command {
        action: Action::Write,
        alarm: String::new(),
        tag: Some("T2".into()),
        value: Some(value.into()),
        reason: None,
        operator: operator.into(),
        nonce: cellwatch::operator::nonce(),
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
    let mut by_lee = write("lee", "1500");
    by_lee.sign("moulding-bus1", &lee);
    let (ok, why) = send(by_lee).await;
    assert_eq!((ok, why.as_str()), (false, "operator 'lee' may not write"));
    assert_eq!(
        send(write("kim", "1500")).await,
        (false, "unsigned command".to_string())
    );
    let mut forged = write("kim", "1500");
    forged.sign("moulding-bus1", &OperatorKey::generate("kim"));
    assert_eq!(send(forged).await, (false, "bad signature".to_string()));
    let mut too_big = write("kim", "1234567");
    too_big.sign("moulding-bus1", &crate::spawned::kim());
    let (ok, why) = send(too_big).await;
    assert!(!ok && why.contains("is not a quantity"), "{why}");
    assert!(
        bus.log().iter().all(|e| !e.what.starts_with("write")),
        "nothing refused reached the bus: {:?}",
        bus.log()
    );

    let mut good = write("kim", "1500");
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

    // Every command is in the journal with its outcome: a write as its
    // request (committed before the unit is written) and its result; a
    // refusal before the signature was verified in a row of its own (the
    // first of its kind this minute).
    let page: serde_json::Value = serde_json::from_str(
        &query(
            "cellwatch/moulding-bus1/history?kind=command;since=1h".into(),
            None,
        )
        .await,
    )
    .unwrap();
    let rows: Vec<(String, String, String, bool)> = page["rows"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| {
            (
                r["fields"]["operator"].as_str().unwrap().to_string(),
                r["fields"]["alarm"].as_str().unwrap().to_string(),
                r["fields"]["stage"].as_str().unwrap().to_string(),
                r["fields"]["accepted"]
                    .as_bool()
                    .unwrap_or(r["fields"]["accepted"] == 1),
            )
        })
        .collect();
    let row = |who: &str, tag: &str, stage: &str, ok| (who.into(), tag.into(), stage.into(), ok);
    assert_eq!(
        rows,
        [
            row("lee", "T2", "command", false),
            row("kim", "T2", "refused", false),
            row("kim", "T2", "refused", false),
            row("kim", "T2", "request", true),
            row("kim", "T2", "result", false),
            row("kim", "T2", "request", true),
            row("kim", "T2", "result", true),
            row("kim", "J2", "request", true),
            row("kim", "J2", "result", true),
        ],
        "{page}"
    );
    agent.stop().await;
    if let Some(server) = server {
        server.abort();
    }
}

/// What the simulator's log says of one unit's day, computed here from
/// the log alone: minutes running / idle / fault per hour, stops per
/// cause code, parts, and parts per order.
struct Logged {
    hours: Vec<[f64; 3]>,
    causes: std::collections::BTreeMap<String, (u64, f64)>,
    parts: u64,
    orders: Vec<(String, u64, u64)>,
}

fn logged(log: &[cellwatch::sim::moulding::LogEntry], unit: u8, start: u64) -> Logged {
    let end = start + 86_400_000;
    let mut out = Logged {
        hours: vec![[0.0; 3]; 24],
        causes: Default::default(),
        parts: 0,
        orders: vec![("ITEM-01".into(), 1000, 0)],
    };
    // (since, 0 running / 1 idle / 2 fault, cause)
    let mut state = (start, 0usize, String::new());
    let close = |from: u64, to: u64, s: usize, cause: &str, out: &mut Logged| {
        let mut t = from;
        while t < to {
            let h = ((t - start) / 3_600_000) as usize;
            let slot_end = (start + (h as u64 + 1) * 3_600_000).min(to);
            out.hours[h][s] += (slot_end - t) as f64 / 60_000.0;
            t = slot_end;
        }
        if s > 0 {
            let c = out.causes.entry(cause.to_string()).or_default();
            c.0 += 1;
            c.1 += (to - from) as f64 / 60_000.0;
        }
    };
    for e in log.iter().filter(|e| e.unit == unit) {
        let words: Vec<&str> = e.what.split(' ').collect();
        match words[..] {
            ["stop", code] => {
                close(state.0, e.at, state.1, &state.2, &mut out);
                state = (e.at, if code == "05" { 1 } else { 2 }, code.to_string());
            }
            ["run"] => {
                close(state.0, e.at, state.1, &state.2, &mut out);
                state = (e.at, 0, String::new());
            }
            ["cycle", k] => {
                let k: u64 = k.trim_start_matches('+').parse().unwrap();
                out.parts += k;
                out.orders.last_mut().unwrap().2 += k;
            }
            ["order", item, "target", target] => {
                out.orders
                    .push((item.to_string(), target.parse().unwrap(), 0));
            }
            _ => panic!("unexpected log entry {e:?}"),
        }
    }
    close(state.0, end, state.1, &state.2, &mut out);
    out
}

/// Each unit of a bus a cell of its own (the shipped `imm-0N.toml`), three
/// agents sharing one poller on one simulated bus; a scripted day in
/// virtual time (stops with causes, a mould change, cycles); then each
/// unit's `report daily` gives the hourly slots, availability, stop
/// causes, production and orders that the simulator's own log says.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn each_unit_a_cell_of_its_own_reports_its_day_as_the_simulator_logged_it() {
    use cellwatch::clock::Clock;
    let dir = tempfile::tempdir().unwrap();
    let start: u64 = chrono::NaiveDate::from_ymd_opt(2021, 3, 2)
        .unwrap()
        .and_hms_opt(0, 0, 0)
        .unwrap()
        .and_utc()
        .timestamp_millis() as u64;
    let min = |m: u64| start + m * 60_000;
    let clock = Clock::manual(start);
    let bus = MouldingBus::new(3).timed_by(clock.clone());
    let (addr, server) = bus
        .listen_tcp("127.0.0.1:0".parse().unwrap())
        .await
        .unwrap();
    let names = ["imm-01", "imm-02", "imm-03"];
    crate::util::bus_pki(
        dir.path(),
        &names
            .map(|n| format!("agent-{n}"))
            .each_ref()
            .map(|s| s.as_str()),
    );
    let mut configs = Vec::new();
    for (i, name) in names.iter().enumerate() {
        let path = crate::util::root().join(format!("config/moulding/{name}.toml"));
        let mut c = cellwatch::config::load(&path).unwrap();
        assert_eq!(c.cell, *name);
        let l = c.legacy.as_mut().unwrap();
        l.transport = Transport::Tcp(addr.to_string());
        l.poll_interval = Duration::from_millis(20);
        c.zenoh.listen = vec!["quic/127.0.0.1:0".into()];
        c.zenoh.tls = Some(crate::util::bus_tls(dir.path(), &format!("agent-{name}")));
        c.journal.path = dir.path().join(format!("{name}.sqlite"));
        c.zenoh.signing_key = Some(c.journal.path.with_extension("agent.key"));
        c.metrics = None;
        assert!(c
            .tags
            .iter()
            .all(|t| t.node_id.starts_with(&format!("@{:02X}/", i + 1))));
        configs.push(c);
    }
    let cells: Vec<_> = configs
        .iter()
        .map(|c| (c.cell.clone(), c.legacy.clone(), c.tags.clone()))
        .collect();
    let (shares, buses) = legacy::share_buses(&cells).unwrap();
    assert_eq!(buses.len(), 1, "one poller for the three cells");
    let mut agents = Vec::new();
    for (c, share) in configs.into_iter().zip(shares) {
        let options = cellwatch::agent::Options {
            source: Some(Box::new(share.expect("a share of the bus"))),
            clock: clock.clone(),
            ..Default::default()
        };
        agents.push(cellwatch::agent::start_with(c, options).await.unwrap());
    }
    let (stop_bus, mut stopped) = tokio::sync::watch::channel(false);
    let bus_poller = buses.into_iter().next().unwrap().timed_by(clock.clone());
    let poller = tokio::spawn(bus_poller.run(async move {
        let _ = stopped.wait_for(|s| *s).await;
    }));
    let db = |u: usize| dir.path().join(format!("{}.sqlite", names[u]));
    let mut committed: Vec<_> = agents.iter().map(|a| a.committed()).collect();
    for (u, c) in committed.iter_mut().enumerate() {
        crate::util::row_at(c, &db(u), "orders", start).await;
        crate::util::row_at(c, &db(u), "state_history", start).await;
    }
    // The day's script, minutes after midnight: (unit, what).
    enum Do {
        Stop(u16),
        Run,
        Order(&'static str, u32),
    }
    let mut script: Vec<(u64, u8, Do)> = vec![
        (150, 2, Do::Stop(Status::FRONT_DOOR_OPEN)),
        (190, 2, Do::Run),
        (375, 1, Do::Stop(Status::MOULD_CLAMP_ABNORMAL)),
        (380, 1, Do::Run),
        (585, 2, Do::Stop(Status::MOULD_CHANGE)),
        (620, 2, Do::Order("B-200", 400)),
        (640, 2, Do::Run),
        (720, 3, Do::Order("C-300", 250)),
        (845, 2, Do::Stop(Status::STOPPED)),
        (900, 2, Do::Run),
        (1370, 2, Do::Stop(Status::ROBOT_ABNORMAL)),
    ];
    script.sort_by_key(|(m, _, _)| *m);
    let mut cycle_at = 5;
    let mut next = script.into_iter().peekable();
    loop {
        let event = next.peek().map(|(m, _, _)| *m);
        if cycle_at >= 24 * 60 && event.is_none() {
            break;
        }
        if event.is_some_and(|m| m <= cycle_at) {
            let (m, unit, what) = next.next().unwrap();
            clock.set(min(m));
            let u = usize::from(unit - 1);
            match what {
                Do::Stop(bit) => bus.stop(unit, Some(bit)),
                Do::Run => bus.stop(unit, None),
                Do::Order(item, target) => bus.set_order(unit, item, target),
            }
            let table = if matches!(what, Do::Order(..)) {
                "orders"
            } else {
                "state_history"
            };
            crate::util::row_at(&mut committed[u], &db(u), table, min(m)).await;
        } else {
            clock.set(min(cycle_at));
            let running: Vec<usize> = (1..=3u8)
                .filter(|&n| bus.unit(n).unwrap().bits & Status::RUNNING != 0)
                .map(|n| usize::from(n - 1))
                .collect();
            bus.cycle();
            for u in running {
                crate::util::row_at(&mut committed[u], &db(u), "production", min(cycle_at)).await;
            }
            cycle_at += 37;
        }
    }
    clock.set(min(24 * 60));
    let _ = stop_bus.send(true);
    for a in agents {
        a.stop().await;
    }
    poller.await.unwrap().unwrap();
    server.abort();
    let log = bus.log();
    for u in 0..3u8 {
        let expected = logged(&log, u + 1, start);
        let r = crate::util::daily_report(&db(usize::from(u)), "2021-03-02");
        let close = |a: f64, b: f64| (a - b).abs() < 1e-6;
        for (h, [run, idle, fault]) in expected.hours.iter().enumerate() {
            let got = &r["hours"][h];
            assert!(
                close(got["running"].as_f64().unwrap(), *run)
                    && close(got["idle"].as_f64().unwrap(), *idle)
                    && close(got["fault"].as_f64().unwrap(), *fault)
                    && close(got["offline"].as_f64().unwrap(), 0.0),
                "unit {} hour {h}: report {got}, log {run} / {idle} / {fault}",
                u + 1
            );
        }
        let run: f64 = expected.hours.iter().map(|h| h[0]).sum();
        let availability = 100.0 * run / (24.0 * 60.0);
        assert!(
            close(r["availability"].as_f64().unwrap(), availability),
            "{r}"
        );
        let causes: std::collections::BTreeMap<String, (u64, f64)> = r["stop_causes"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| {
                (
                    c["code"].as_str().unwrap().to_string(),
                    (c["count"].as_u64().unwrap(), c["minutes"].as_f64().unwrap()),
                )
            })
            .collect();
        assert_eq!(
            causes.keys().collect::<Vec<_>>(),
            expected.causes.keys().collect::<Vec<_>>()
        );
        for (code, (count, minutes)) in &expected.causes {
            assert_eq!(causes[code].0, *count, "unit {} cause {code}", u + 1);
            assert!(
                close(causes[code].1, *minutes),
                "unit {} cause {code}: {r}",
                u + 1
            );
        }
        assert_eq!(r["production"], expected.parts, "unit {}", u + 1);
        let orders: Vec<(String, u64, u64)> = r["orders"]
            .as_array()
            .unwrap()
            .iter()
            .map(|o| {
                (
                    o["item"].as_str().unwrap().to_string(),
                    o["target"].as_u64().unwrap(),
                    o["parts"].as_u64().unwrap(),
                )
            })
            .collect();
        assert_eq!(orders, expected.orders, "unit {}", u + 1);
    }
    // The script did what it says: unit 2 stopped for four causes, unit 1
    // for one, unit 3 never; unit 2 still stopped at midnight.
    let stops = |u: u8| logged(&log, u, start).causes.len();
    assert_eq!((stops(1), stops(2), stops(3)), (1, 4, 0));
}

/// `cellwatch run` with several cells: two on one journal or id are
/// refused naming both files; two on one bus polling it differently are
/// refused naming what differs; nothing is started.
#[test]
fn cells_run_together_must_be_distinct_and_agree_on_their_bus() {
    let dir = tempfile::tempdir().unwrap();
    let unit = |n: u32| crate::util::root().join(format!("config/moulding/imm-0{n}.toml"));
    let one = unit(1);
    let r = crate::util::cellwatch(&["run", one.to_str().unwrap(), one.to_str().unwrap()]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(
        r.stderr.contains("have the same cell id 'imm-01'"),
        "{}",
        r.stderr
    );
    // Unit 2 polled every 2 s beside unit 1's default: refused.
    let text = std::fs::read_to_string(unit(2))
        .unwrap()
        .replace("# poll_interval = \"1s\"", "poll_interval = \"2s\"")
        .replace(
            "\"unit.il\"",
            &format!("{:?}", crate::util::root().join("config/moulding/unit.il")),
        );
    let two = dir.path().join("imm-02.toml");
    std::fs::write(&two, text).unwrap();
    let r = crate::util::cellwatch(&["run", one.to_str().unwrap(), two.to_str().unwrap()]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(
        r.stderr
            .contains("share 127.0.0.1:4001 but poll it differently")
            && r.stderr.contains("poll every 1s")
            && r.stderr.contains("poll every 2s"),
        "{}",
        r.stderr
    );
}
