//! The PLC's own alarms (OPC UA Alarms & Conditions) as the cell's: a
//! node-opcua server's conditions on its `Press` object, read by the whole
//! agent (SignAndEncrypt, Zenoh with TLS, SQLite), acknowledged by an
//! operator through cellwatch (the condition's `Acknowledge` at the PLC
//! first) and at the PLC (an HMI's).

use cellwatch::config::{self, CellConfig};
use cellwatch::operator::Action;
use cellwatch::payload::AlarmPayload;
use cellwatch::sources::pki;
use serde_json::json;
use zenoh_ext::{AdvancedSubscriberBuilderExt, HistoryConfig, RecoveryConfig};

use crate::agent::alarm_until;
use crate::alarm_server::ScadaProgram;
use crate::interop::{trusted_by_server, URI};
use crate::spawned::{send, signed};
use crate::stacks::StackServer;

/// A cell of two node-opcua tags, one discrete alarm of its own, and the
/// server's conditions as alarms `plc-…`.
fn cell(dir: &std::path::Path, port: u16) -> CellConfig {
    crate::util::bus_pki(dir, &["agent-m01ps0004"]);
    let tls = crate::util::bus_tls(dir, "agent-m01ps0004");
    let text = format!(
        r#"
[cell]
id = "m01ps0004"

[opcua]
endpoint = "opc.tcp://127.0.0.1:{port}/"
pki_dir = "agent-pki"
publishing_interval = "100ms"

[[opcua.events]]
# The Server object: every condition the server reports.
min_severity = 100

[[tags]]
name = "door"
node_id = "nsu={URI};s=T0"
address = "T0"

[[checks.discrete]]
id = "door-open"
tag = "door"
fault_when = "off"

[journal]
path = "journal.sqlite"

[zenoh]
listen = ["quic/127.0.0.1:0"]
signing_key = "agent.key"
tls = {{ ca = "{}", cert = "{}", key = "{}" }}
"#,
        tls.ca.display(),
        tls.cert.display(),
        tls.key.display()
    );
    let mut c = config::parse("cell.toml", &text, dir, &config::Disk).unwrap();
    let secrets = dir.join("operators.toml");
    std::fs::write(&secrets, crate::spawned::operators_file(&Action::ALL)).unwrap();
    c.operators_file = Some(secrets);
    c.metrics = Some("127.0.0.1:0".parse().unwrap());
    c
}

async fn said(server: StackServer, command: String) -> StackServer {
    server.said(&command).await
}

/// A node-opcua server trusting the agent of `dir` (its certificate names
/// the cell), on a port of its own.
async fn plc(dir: &std::path::Path) -> (StackServer, u16) {
    let server_pki = dir.join("server-pki");
    let port = crate::util::restartable_port();
    let made = crate::opcua::opcua_config("opc.tcp://127.0.0.1:1/", &dir.join("agent-pki"));
    drop(cellwatch::sources::opcua::client("m01ps0004", &made).unwrap());
    trusted_by_server(&dir.join("agent-pki"), &server_pki);
    let server = tokio::task::spawn_blocking(move || StackServer::node_opcua(port, &server_pki, 1))
        .await
        .unwrap();
    (server, port)
}

/// The journal's command rows of the last hour, as the bus answers.
async fn command_page(client: &zenoh::Session) -> serde_json::Value {
    let answer = crate::spawned::query(
        client,
        "cellwatch/m01ps0004/history?kind=command;since=1h",
        None,
    )
    .await
    .unwrap();
    serde_json::from_str(&answer).unwrap()
}

type Alarms =
    zenoh_ext::AdvancedSubscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>;

/// The agent of `config` started, and its alarms subscribed to.
async fn agent_of(
    dir: &std::path::Path,
    config: &CellConfig,
) -> (cellwatch::agent::Agent, zenoh::Session, Alarms) {
    let agent = cellwatch::agent::start(config.clone(), None).await.unwrap();
    let zenoh_port = crate::util::agent_port(&agent).await;
    let client = crate::util::operator_session(dir, "operator-kim", zenoh_port).await;
    let sub = client
        .declare_subscriber("cellwatch/m01ps0004/alarms/*")
        .history(HistoryConfig::default().detect_late_publishers())
        .recovery(RecoveryConfig::default().heartbeat())
        .await
        .unwrap();
    (agent, client, sub)
}

/// The agent stopped while the PLC's alarms go on: back, it restores them
/// from the journal, and the server's refresh says which it still holds —
/// the one that ended and was acknowledged at the PLC meanwhile clears,
/// the one still active is not raised a second time.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_plcs_alarms_survive_a_restart_and_what_ended_meanwhile_clears() {
    crate::network_cut::logs();
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let (server, port) = plc(dir).await;
    let config = cell(dir, port);
    pki::trust(&server.cert, &config.opcua.as_ref().unwrap().pki_dir).unwrap();
    let server = said(server, "alarm Guard 300 Guard door open".into()).await;
    let server = said(server, "alarm Oil 600 Oil temperature high".into()).await;
    let (agent, _client, sub) = agent_of(dir, &config).await;
    let mut seen = Vec::new();
    for id in ["plc-Press-Guard", "plc-Press-Oil"] {
        alarm_until(&sub, id, &mut seen, |a| {
            a.id == id && a.transition.as_str() == "raised"
        })
        .await;
    }
    agent.stop().await;
    let server = said(server, "hmi-ack Oil anna cooled down".into()).await;
    let server = said(server, "normal Oil".into()).await;

    let (agent, _client, sub) = agent_of(dir, &config).await;
    let mut seen = Vec::new();
    let oil = alarm_until(&sub, "oil cleared after the restart", &mut seen, |a| {
        a.id == "plc-Press-Oil" && a.transition.as_str() == "acknowledged"
    })
    .await;
    assert_eq!(oil.state.as_str(), "normal", "{seen:#?}");
    assert_eq!(oil.acked_by.as_deref(), Some("plc"));
    assert!(
        oil.message.ends_with("(no longer held by the PLC)"),
        "{}",
        oil.message
    );
    // The guard came back from the journal and stays, raised once.
    let guard: Vec<&str> = seen
        .iter()
        .filter(|a| a.id == "plc-Press-Guard")
        .map(|a| a.transition.as_str())
        .collect();
    assert!(
        guard.contains(&"restored") && !guard.contains(&"raised"),
        "{seen:#?}"
    );
    agent.stop().await;
    tokio::task::spawn_blocking(move || server.stop())
        .await
        .unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_plcs_own_alarms_are_the_cells_acknowledged_at_the_plc_first() {
    crate::network_cut::logs();
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let (server, port) = plc(dir).await;
    // Active before the agent subscribes: found by the refresh.
    let server = said(
        server,
        "alarm Overpressure 700 Hydraulic pressure above 210 bar".into(),
    )
    .await;
    let config = cell(dir, port);
    pki::trust(&server.cert, &config.opcua.as_ref().unwrap().pki_dir).unwrap();
    let (agent, client, sub) = agent_of(dir, &config).await;
    let mut seen: Vec<AlarmPayload> = Vec::new();
    let over = "plc-Press-Overpressure";
    let raised = alarm_until(&sub, "the PLC's overpressure raised", &mut seen, |a| {
        a.id == over && a.transition.as_str() == "raised"
    })
    .await;
    assert_eq!(raised.kind.as_str(), "plc");
    assert_eq!(raised.severity.as_str(), "high");
    assert_eq!(raised.message, "Hydraulic pressure above 210 bar");
    assert_eq!(raised.state.as_str(), "active_unacknowledged");

    // Raised while the agent watches; below min_severity: not an alarm.
    let server = said(server, "alarm Lube 50 Lubrication due".into()).await;
    let server = said(server, "alarm Guard 300 Guard door open".into()).await;
    let guard = "plc-Press-Guard";
    let g = alarm_until(&sub, "the guard raised", &mut seen, |a| a.id == guard).await;
    assert_eq!(
        (
            g.transition.as_str(),
            g.severity.as_str(),
            g.message.as_str()
        ),
        ("raised", "medium", "Guard door open")
    );

    // Kim acknowledges the overpressure in cellwatch: at the PLC first,
    // with her name and her comment in the condition's comment.
    let (ok, detail) = send(
        &client,
        &crate::spawned::signed_with(Action::Ack, over, None, Some("relief valve checked")),
    )
    .await;
    assert!(ok, "{detail}");
    let server = tokio::task::spawn_blocking(move || {
        let mut server = server;
        let line = server.wait_for("acknowledged Overpressure");
        assert_eq!(
            line,
            "acknowledged Overpressure acknowledged in cellwatch by kim: relief valve checked"
        );
        server
    })
    .await
    .unwrap();
    let acked = alarm_until(&sub, "the overpressure acknowledged", &mut seen, |a| {
        a.id == over && a.transition.as_str() == "acknowledged"
    })
    .await;
    assert_eq!(
        (acked.acked_by.as_deref(), acked.ack_comment.as_deref()),
        (Some("kim"), Some("relief valve checked"))
    );
    // Once, not again when the PLC's event says so.
    let (ok, detail) = send(&client, &signed(Action::Ack, over)).await;
    assert!(!ok && detail.contains("already acknowledged"), "{detail}");

    // Anna acknowledges the guard at the HMI; it returns to normal.
    let server = said(server, "hmi-ack Guard anna door checked".into()).await;
    let acked = alarm_until(&sub, "the guard acknowledged at the HMI", &mut seen, |a| {
        a.id == guard && a.transition.as_str() == "acknowledged"
    })
    .await;
    assert_eq!(acked.acked_by.as_deref(), Some("plc: anna"));
    let server = said(server, "normal Guard".into()).await;
    let cleared = alarm_until(&sub, "the guard cleared", &mut seen, |a| {
        a.id == guard && a.transition.as_str() == "cleared"
    })
    .await;
    assert_eq!(cleared.state.as_str(), "normal");

    assert!(!seen.iter().any(|a| a.id.contains("Lube")), "{seen:#?}");
    // Journaled as any command: the request, committed before the PLC was
    // asked, and what the PLC answered.
    let page = command_page(&client).await;
    let rows: Vec<(String, String, String)> = page["rows"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|r| r["fields"]["alarm"] == over)
        .map(|r| {
            let f = |k: &str| r["fields"][k].as_str().unwrap_or_default().to_string();
            (f("operator"), f("stage"), f("detail"))
        })
        .collect();
    let row =
        |stage: &str, detail: &str| ("kim".to_string(), stage.to_string(), detail.to_string());
    assert_eq!(
        rows,
        [
            row(
                "request",
                "acknowledge plc-Press-Overpressure at the PLC, asked by kim: relief valve checked"
            ),
            row("result", "plc-Press-Overpressure acknowledged at the PLC"),
            row("command", "plc-Press-Overpressure is already acknowledged"),
        ],
        "{page:#}"
    );
    // An alarm the PLC does not hold cannot be acknowledged at it.
    let (ok, detail) = send(&client, &signed(Action::Ack, "plc-Press-Nothing")).await;
    assert!(!ok && detail.contains("unknown alarm"), "{detail}");

    agent.stop().await;
    tokio::task::spawn_blocking(move || server.stop())
        .await
        .unwrap();
}

/// The whole chain across two stacks nobody here wrote: a SCADA (node-opcua's
/// client) acknowledges the PLC's own alarm (node-opcua's server) on
/// cellwatch's alarm server as kim; cellwatch acknowledges it at the PLC
/// first, with kim's name and comment, and only then is it acknowledged —
/// on the bus, on the SCADA and in the journal.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_scada_acknowledges_the_plcs_alarm_through_cellwatch_at_the_plc_first() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let (server, port) = plc(dir).await;
    let server = said(server, "alarm Guard 300 Guard door open".into()).await;
    let mut config = cell(dir, port);
    pki::trust(&server.cert, &config.opcua.as_ref().unwrap().pki_dir).unwrap();
    crate::alarm_server::users_file(&dir.join("opcua-users.toml"));
    config.alarm_server = Some(cellwatch::config::AlarmServerConfig {
        listen: "127.0.0.1:0".parse().unwrap(),
        pki_dir: dir.join("alarm-server-pki"),
        users_file: dir.join("opcua-users.toml"),
    });
    let (agent, client, sub) = agent_of(dir, &config).await;
    let guard = "plc-Press-Guard";
    let mut seen: Vec<AlarmPayload> = Vec::new();
    alarm_until(&sub, "the guard raised", &mut seen, |a| a.id == guard).await;

    let url = format!("opc.tcp://{}", agent.alarm_server_addr().unwrap());
    let (scada_pki, server_pki) = (dir.join("scada-pki"), dir.join("alarm-server-pki"));
    let mut scada = tokio::task::spawn_blocking(move || {
        ScadaProgram::connected(&url, &scada_pki, &server_pki, "scada-kim")
    })
    .await
    .unwrap();
    // Raised before the SCADA came: its refresh finds it.
    assert_eq!(scada.ask("refresh", "refresh "), "Good");
    let shown = scada.event("the guard, refreshed", |e| e["conditionName"] == guard);
    assert_eq!(
        (&shown["active"], &shown["acked"], &shown["message"]),
        (&json!(true), &json!(false), &json!("Guard door open"))
    );
    let ack = format!(
        "ack {} {} door checked on the SCADA",
        shown["conditionId"].as_str().unwrap(),
        shown["eventId"].as_str().unwrap()
    );
    assert_eq!(scada.ask(&ack, "ack "), "Good");
    let server = tokio::task::spawn_blocking(move || {
        let mut server = server;
        let line = server.wait_for("acknowledged Guard");
        assert_eq!(
            line,
            "acknowledged Guard acknowledged in cellwatch by kim: door checked on the SCADA"
        );
        server
    })
    .await
    .unwrap();
    // (The PLC's own acknowledgement may come back first, by "plc".)
    scada.event("the guard acknowledged by kim", |e| {
        e["conditionName"] == guard && e["acked"] == true && e["clientUserId"] == "kim"
    });
    let on_bus = alarm_until(&sub, "the guard acknowledged", &mut seen, |a| {
        a.id == guard && a.transition.as_str() == "acknowledged"
    })
    .await;
    assert_eq!(on_bus.acked_by.as_deref(), Some("kim"));
    let page = command_page(&client).await;
    let rows: Vec<(String, String, String)> = page["rows"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| {
            let f = |k: &str| r["fields"][k].as_str().unwrap_or_default().to_string();
            (f("stage"), f("detail"), f("source"))
        })
        .collect();
    let row = |stage: &str, detail: &str| {
        (
            stage.to_string(),
            detail.to_string(),
            "opcua user scada-kim".to_string(),
        )
    };
    assert_eq!(
        rows,
        [
            row(
                "request",
                "acknowledge plc-Press-Guard at the PLC, asked by kim: door checked on the SCADA"
            ),
            row("result", "plc-Press-Guard acknowledged at the PLC"),
        ],
        "{page:#}"
    );
    drop(scada);
    agent.stop().await;
    tokio::task::spawn_blocking(move || server.stop())
        .await
        .unwrap();
}
