//! The units polled over TCP and over a serial line: status contacts and
//! production per unit, a stop with its cause, line noise retried, a silent
//! unit reported once; frames byte for byte as the paper's reference code.

use std::time::Duration;

use cellwatch::sim::moulding::MouldingBus;
use cellwatch::sources::at_bus::{self, AtBusConfig, Parity, SerialLine, Transport};
use cellwatch::sources::SourceEvent;
use cellwatch_models::at_bus::Status;
use cellwatch_models::engine::Reading;
use cellwatch_models::value::Num;
use tokio::sync::mpsc;

use crate::opcua::next;

use super::tags;

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
        let config = AtBusConfig {
            transport,
            poll_interval: Duration::from_millis(50),
            response_timeout: Duration::from_millis(200),
            retries: 2,
        };
        let (tx, rx) = mpsc::channel(cellwatch::sources::QUEUE_CAPACITY);
        let (stop, stop_rx) = tokio::sync::oneshot::channel::<()>();
        let task = tokio::spawn(async move {
            at_bus::run(&config, &tags(), tx, None, async {
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
    use cellwatch_models::at_bus::{Frame, Header};
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
