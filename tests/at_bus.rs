//! The `@` bus source against the simulated moulding units, over TCP (a
//! serial device server's raw socket) and over a pseudo-terminal (a serial
//! port at 9600 7E2): status contacts and production per unit, a stop with
//! its cause, line noise retried without a trace, a silent unit reported
//! once and nothing else.

mod cells;
mod day;
mod polling;
mod targets;

use std::time::Duration;

use cellwatch::config::TagConfig;
use cellwatch::sim::moulding::MouldingBus;
use cellwatch::sources::at_bus::{Parity, SerialLine, Transport};
use cellwatch_models::signal::Signal;
use cellwatch_models::value::ValueType;

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
