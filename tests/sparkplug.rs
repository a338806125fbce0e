//! The cell as a Sparkplug B edge node against a real broker (Debian's
//! mosquitto, installed on first use) and an independent host: Eclipse
//! Tahu's JavaScript payload library, run by node (`tests/interop/sparkplug`,
//! installed with `npm ci` from the committed lock file), decodes every
//! message. The real agent binary watches the simulated CNC over OPC UA:
//! its births declare every metric, an alarm's raise arrives as DDATA, the
//! sequence has no gap, a host's rebirth request is taken and a device
//! command is not, and the broker says the node's death when the agent is
//! killed. With a primary host, nothing is published while its `STATE` says
//! offline; once online, the births carry the current values and what was
//! held follows, flagged historical; offline again, the node says NDEATH
//! and waits on a new session, a stale `STATE` changing nothing
//! (`sparkplug/host.rs`). Held changes survive a broker restart and an
//! agent killed while holding them (`sparkplug/outage.rs`). Over TLS the
//! node shows a client certificate of the broker's CA and is born; one of
//! another CA is refused, and the agent says so (`sparkplug/tls.rs`). A
//! cell fed by a script in virtual time, in process: with `[oee]` its
//! births and data carry the shift's OEE figures computed here by hand
//! (`sparkplug/oee.rs`); its PLC link lost, the device says DDEATH and is
//! born again when the link is back (`sparkplug/plc_link.rs`).

use std::collections::HashMap;
use std::io::{BufRead, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::Once;
use std::time::Duration;

use cellwatch::clock::Clock;
use cellwatch::sources::scripted::ScriptedSource;
use cellwatch::sources::SourceEvent;
use cellwatch_models::engine::{Reading, TagReading};
use serde_json::{json, Value};

use crate::util::root;

mod host;
mod oee;
mod outage;
mod plc_link;
mod tls;

const MOSQUITTO: &str = "/usr/sbin/mosquitto";
const GROUP: &str = "press-shop";
const NODE: &str = "m01-agent";
const DEVICE: &str = "m01ps0004";

/// `npm ci` in tests/interop/sparkplug, once per test run, unless already
/// installed.
fn installed() -> PathBuf {
    static ONCE: Once = Once::new();
    let dir = root().join("tests/interop/sparkplug");
    ONCE.call_once(|| {
        let modules = dir.join("node_modules");
        if modules.join("sparkplug-payload").exists() && modules.join("mqtt").exists() {
            return;
        }
        let out = Command::new("npm")
            .args(["ci", "--no-audit", "--no-fund"])
            .current_dir(&dir)
            .output()
            .expect("npm (Node.js) is needed for the Sparkplug tests");
        assert!(
            out.status.success(),
            "npm ci failed:\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
    });
    dir
}

/// A real mosquitto on loopback, anonymous, nothing persisted; killed when
/// dropped.
struct Broker {
    child: Child,
    port: u16,
}

impl Drop for Broker {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Broker {
    /// Starts one on `port` with its configuration in `dir`; returns once
    /// it says it runs.
    async fn start(dir: &Path, port: u16) -> Broker {
        Broker::start_with(dir, port, "").await
    }

    /// [`Broker::start`], `more` added to its configuration (another
    /// listener).
    async fn start_with(dir: &Path, port: u16, more: &str) -> Broker {
        crate::util::debian_packages(&[(MOSQUITTO, "mosquitto")]);
        let conf = dir.join("mosquitto.conf");
        std::fs::write(
            &conf,
            format!(
                "allow_anonymous true\npersistence false\nlog_dest stderr\nlog_type all\nlistener {port} 127.0.0.1\n{more}"
            ),
        )
        .unwrap();
        let mut child = Command::new(MOSQUITTO)
            .arg("-c")
            .arg(&conf)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let stderr = child.stderr.take().unwrap();
        let mut log = std::fs::File::create(dir.join("mosquitto.log")).unwrap();
        let (tx, running) = tokio::sync::oneshot::channel();
        std::thread::spawn(move || {
            let mut tx = Some(tx);
            for line in std::io::BufReader::new(stderr)
                .lines()
                .map_while(Result::ok)
            {
                let _ = writeln!(log, "{line}");
                if line.contains(" running") {
                    if let Some(tx) = tx.take() {
                        let _ = tx.send(());
                    }
                }
            }
        });
        let said = tokio::time::timeout(Duration::from_secs(60), running).await;
        assert!(
            matches!(said, Ok(Ok(()))),
            "mosquitto never said it runs:\n{}",
            std::fs::read_to_string(dir.join("mosquitto.log")).unwrap_or_default()
        );
        Broker { child, port }
    }
}

/// The Tahu host: every message it decoded, in order.
struct Host {
    child: Child,
    stdin: ChildStdin,
    lines: tokio::sync::mpsc::UnboundedReceiver<Value>,
    /// Every message of the node and its device (births, data, deaths).
    seen: Vec<Value>,
}

impl Drop for Host {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Host {
    /// Starts the host on `broker`; returns once it has subscribed.
    async fn start(broker: &Broker) -> Host {
        let dir = installed();
        let mut child = Command::new("node")
            .arg(dir.join("host.js"))
            .arg(format!("mqtt://127.0.0.1:{}", broker.port))
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("node (Node.js) is needed for the Sparkplug tests");
        let stdout = child.stdout.take().unwrap();
        let stdin = child.stdin.take().unwrap();
        let (tx, lines) = tokio::sync::mpsc::unbounded_channel();
        std::thread::spawn(move || {
            for line in std::io::BufReader::new(stdout)
                .lines()
                .map_while(Result::ok)
            {
                let v: Value = serde_json::from_str(&line).unwrap_or(json!({ "raw": line }));
                if tx.send(v).is_err() {
                    break;
                }
            }
        });
        let mut host = Host {
            child,
            stdin,
            lines,
            seen: Vec::new(),
        };
        host.until("the host subscribed", |v| v["subscribed"] == true)
            .await;
        host
    }

    /// Waits for the first line `ok` accepts; `what` names it.
    async fn until(&mut self, what: &str, ok: impl Fn(&Value) -> bool) -> Value {
        let deadline = tokio::time::Instant::now() + Duration::from_secs(90);
        loop {
            let line = tokio::time::timeout_at(deadline, self.lines.recv())
                .await
                .unwrap_or_else(|_| panic!("{what}: not seen; seen {:#?}", self.seen))
                .unwrap_or_else(|| panic!("{what}: the host ended"));
            assert!(line.get("error").is_none(), "the host: {line}");
            if line["topic"]
                .as_str()
                .is_some_and(|t| t.starts_with(&format!("spBv1.0/{GROUP}/")))
            {
                self.seen.push(line.clone());
            }
            if ok(&line) {
                return line;
            }
        }
    }

    /// The next message on the node's topic of `kind` (with the device for
    /// device kinds) that `ok` accepts.
    async fn message(&mut self, kind: &str, ok: impl Fn(&Value) -> bool) -> Value {
        let topic = topic(kind);
        self.until(&format!("{topic} as expected"), |v| {
            v["topic"] == topic.as_str() && ok(&v["payload"])
        })
        .await["payload"]
            .clone()
    }

    /// Publishes `payload` (encoded by Tahu) on `topic`.
    fn publish(&mut self, topic: &str, payload: Value) {
        let line = json!({ "topic": topic, "payload": payload }).to_string();
        writeln!(self.stdin, "{line}").unwrap();
    }
}

/// The topic of `kind` for the node, or its device.
fn topic(kind: &str) -> String {
    match kind {
        "DBIRTH" | "DDATA" | "DCMD" | "DDEATH" => format!("spBv1.0/{GROUP}/{kind}/{NODE}/{DEVICE}"),
        _ => format!("spBv1.0/{GROUP}/{kind}/{NODE}"),
    }
}

/// The metrics of a decoded payload.
fn metrics(payload: &Value) -> &Vec<Value> {
    payload["metrics"].as_array().unwrap()
}

/// The metric named `name` of a birth.
fn named<'a>(payload: &'a Value, name: &str) -> &'a Value {
    metrics(payload)
        .iter()
        .find(|m| m["name"] == name)
        .unwrap_or_else(|| panic!("no {name} in {payload:#}"))
}

/// Every sequence number the node used follows the one before it (0 at
/// each NBIRTH, 255 wrapping to 0).
fn no_gaps(seen: &[Value]) {
    let mut previous: Option<u64> = None;
    for m in seen {
        let t = m["topic"].as_str().unwrap();
        if t.contains("/NDEATH/") || t.contains("/NCMD/") || t.contains("/DCMD/") {
            continue;
        }
        let seq = m["payload"]["seq"]
            .as_u64()
            .unwrap_or_else(|| panic!("no seq: {m}"));
        if t.contains("/NBIRTH/") {
            assert_eq!(seq, 0, "{m}");
        } else {
            let expected = previous.map(|p| (p + 1) % 256);
            assert_eq!(Some(seq), expected, "a gap before {m}");
        }
        previous = Some(seq);
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn births_data_rebirth_and_death_reach_a_tahu_host_through_mosquitto() {
    let d = tempfile::tempdir().unwrap();
    let broker = Broker::start(d.path(), crate::util::restartable_port()).await;
    let mut host = Host::start(&broker).await;
    let (sim, mut cell) = crate::spawned::start(d.path()).await;
    let mut config = std::fs::read_to_string(&cell.config).unwrap();
    config += &format!(
        "\n[sparkplug]\nbroker = \"mqtt://127.0.0.1:{}\"\ngroup_id = \"{GROUP}\"\nedge_node_id = \"{NODE}\"\n",
        broker.port
    );
    std::fs::write(&cell.config, config).unwrap();
    let mut agent = cell.spawn("agent.log").await;

    // NBIRTH: sequence 0, bdSeq, the rebirth control.
    let nbirth = host.message("NBIRTH", |_| true).await;
    assert_eq!(nbirth["seq"], 0, "{nbirth:#}");
    let bd_seq = named(&nbirth, "bdSeq")["value"].as_u64().unwrap();
    assert_eq!(named(&nbirth, "bdSeq")["type"], "Int64");
    let rebirth = named(&nbirth, "Node Control/Rebirth");
    assert_eq!(rebirth["type"], "Boolean");
    assert_eq!(rebirth["value"], false);

    // DBIRTH: every metric the device will send, each with its own alias.
    let dbirth = host.message("DBIRTH", |_| true).await;
    assert_eq!(dbirth["seq"], 1, "{dbirth:#}");
    let mut aliases: HashMap<String, u64> = HashMap::new();
    for m in metrics(&dbirth) {
        let alias = m["alias"]
            .as_u64()
            .unwrap_or_else(|| panic!("no alias: {m}"));
        let name = m["name"].as_str().unwrap().to_string();
        assert!(
            !aliases.values().any(|a| *a == alias),
            "alias {alias} twice"
        );
        aliases.insert(name, alias);
    }
    for (name, kind) in [
        ("Machine/State", "String"),
        ("Machine/Fault Type", "String"),
        ("Machine/Fault Element", "String"),
        ("Production/Parts Produced", "UInt64"),
        ("Tags/spindle_temperature", "Double"),
        ("Tags/mode_word", "Double"),
        ("Alarms/ese/Active", "Boolean"),
        ("Alarms/ese/Acknowledged", "Boolean"),
        ("Alarms/ese/Priority", "String"),
        ("Alarms/ese/Shelved", "Boolean"),
        ("Alarms/csd/Active", "Boolean"),
        ("Alarms/spindle-temp-h/Active", "Boolean"),
        ("Alarms/z2-overtravel/Active", "Boolean"),
    ] {
        assert_eq!(named(&dbirth, name)["type"], kind, "{name}");
    }
    assert_eq!(named(&dbirth, "Alarms/ese/Priority")["value"], "critical");
    let properties = &named(&dbirth, "Alarms/ese/Active")["properties"];
    assert_eq!(properties["kind"]["value"], "switching", "{properties:#}");

    // A fault: ESE raised arrives as live DDATA by alias.
    let active = aliases["Alarms/ese/Active"];
    sim.set("X0.06", false).unwrap();
    let raised = host
        .message("DDATA", |p| {
            metrics(p)
                .iter()
                .any(|m| m["alias"] == active && m["value"] == true && m["isHistorical"] != true)
        })
        .await;
    assert!(
        metrics(&raised).iter().all(|m| m.get("name").is_none()),
        "data names metrics by alias only: {raised:#}"
    );

    // A device command is not taken; a rebirth request is: NBIRTH and
    // DBIRTH again on the same session (same bdSeq), ESE active in it.
    host.publish(
        &topic("DCMD"),
        json!({ "timestamp": 1, "metrics": [
            { "name": "Alarms/ese/Acknowledged", "type": "Boolean", "value": true }
        ] }),
    );
    host.publish(
        &topic("NCMD"),
        json!({ "timestamp": 1, "metrics": [
            { "name": "Node Control/Rebirth", "type": "Boolean", "value": true }
        ] }),
    );
    let again = host.message("NBIRTH", |_| true).await;
    assert_eq!(named(&again, "bdSeq")["value"], bd_seq);
    let reborn = host.message("DBIRTH", |_| true).await;
    assert_eq!(named(&reborn, "Alarms/ese/Active")["value"], true);
    assert_eq!(named(&reborn, "Alarms/ese/Acknowledged")["value"], false);
    let scraped = crate::spawned::scrape(cell.metrics_port);
    assert!(
        scraped.lines().any(
            |l| l.starts_with("cellwatch_sparkplug_commands_ignored_total") && l.ends_with(" 1")
        ),
        "{scraped}"
    );
    no_gaps(&host.seen);

    // Killed: the broker says the node's will, with the session's bdSeq.
    agent.kill().unwrap();
    agent.wait().unwrap();
    let death = host.message("NDEATH", |_| true).await;
    assert_eq!(named(&death, "bdSeq")["value"], bd_seq, "{death:#}");
    drop(sim);
}

/// The value of the metric line starting with `prefix` at the agent's
/// `/metrics`.
fn scraped(port: u16, prefix: &str) -> f64 {
    let body = crate::spawned::scrape(port);
    body.lines()
        .find(|l| l.starts_with(prefix))
        .and_then(|l| l.rsplit(' ').next()?.parse().ok())
        .unwrap_or_else(|| panic!("no {prefix} in {body}"))
}

/// Waits until the agent's metric starting with `prefix` is one `ok`
/// accepts; returns it.
async fn until_scraped(port: u16, prefix: &str, ok: impl Fn(f64) -> bool) -> f64 {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(90);
    loop {
        let now = scraped(port, prefix);
        if ok(now) {
            return now;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "{prefix} stayed at {now}"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// The demo cell beside its simulated CNC, a Sparkplug edge node on
/// `broker` (`more` added to its `[sparkplug]`), not yet running.
async fn edge_node(
    dir: &Path,
    broker: &Broker,
    more: &str,
) -> (cellwatch::sim::cnc::SimulatedCnc, crate::spawned::Cell) {
    let (sim, cell) = crate::spawned::start(dir).await;
    let mut config = std::fs::read_to_string(&cell.config).unwrap();
    config += &format!(
        "\n[sparkplug]\nbroker = \"mqtt://127.0.0.1:{}\"\ngroup_id = \"{GROUP}\"\nedge_node_id = \"{NODE}\"\n{more}",
        broker.port
    );
    std::fs::write(&cell.config, config).unwrap();
    (sim, cell)
}

/// The ESE alarm's metric line (critical, switching) at `/metrics`.
const CRITICAL: &str =
    "cellwatch_alarms_active{cell=\"m01ps0004\",kind=\"switching\",severity=\"critical\"}";

/// The ESE's `Active` values in `messages`' DDATA flagged historical, with
/// their timestamps, in the order they came; `active` its alias.
fn historical(messages: &[Value], active: &Value) -> Vec<(bool, u64)> {
    messages
        .iter()
        .filter(|m| m["topic"] == topic("DDATA").as_str())
        .flat_map(|m| metrics(&m["payload"]).iter())
        .filter(|m| m["isHistorical"] == true && &m["alias"] == active)
        .map(|m| {
            (
                m["value"].as_bool().unwrap(),
                m["timestamp"].as_u64().unwrap(),
            )
        })
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn validate_opens_the_password_and_tls_files() {
    let d = tempfile::tempdir().unwrap();
    let (_sim, cell) = crate::spawned::start(d.path()).await;
    let base = std::fs::read_to_string(&cell.config).unwrap();
    let config = d.path().join("sparkplug.toml");
    let validate = |section: &str| {
        std::fs::write(&config, format!("{base}\n[sparkplug]\n{section}")).unwrap();
        crate::util::cellwatch(&["validate", config.to_str().unwrap()])
    };
    let plain = "broker = \"mqtt://127.0.0.1:1883\"\ngroup_id = \"g\"\nedge_node_id = \"n\"\n";
    let ok = validate(plain);
    assert_eq!(ok.code, 0, "{}", ok.stderr);

    // A password file that is not there: said before the agent runs.
    let missing = d.path().join("mqtt-password");
    let v = validate(&format!(
        "{plain}username = \"agent\"\npassword_file = \"{}\"\n",
        missing.display()
    ));
    assert_eq!(v.code, 2, "{}", v.stdout);
    assert!(v.stderr.contains("mqtt-password"), "{}", v.stderr);

    // A CA that is not a certificate.
    let ca = d.path().join("broker-ca.pem");
    std::fs::write(&ca, "not a certificate\n").unwrap();
    let v = validate(&format!(
        "broker = \"mqtts://127.0.0.1:8883\"\ngroup_id = \"g\"\nedge_node_id = \"n\"\n[sparkplug.tls]\nca = \"{}\"\n",
        ca.display()
    ));
    assert_eq!(v.code, 2, "{}", v.stdout);
    assert!(
        v.stderr.contains("sparkplug.tls") && v.stderr.contains("broker-ca.pem"),
        "{}",
        v.stderr
    );
}

/// The contacts of [`scripted_node`]'s cell, by index: the machine runs
/// while `X0.00` holds; each rising edge of `X0.01` is a part done, of
/// `X0.02` a part rejected.
const RUN: usize = 0;
const PART: usize = 1;
const REJECT: usize = 2;

/// A cell of three contacts ([`RUN`], [`PART`], [`REJECT`]) fed by a
/// script, run in process on `clock`: a Sparkplug edge node on `broker`,
/// `more` added to its configuration (after `[production]`). Its script's
/// sender is returned with it.
async fn scripted_node(
    dir: &Path,
    broker: &Broker,
    more: &str,
    clock: &Clock,
) -> (
    cellwatch::agent::Agent,
    tokio::sync::mpsc::Sender<SourceEvent>,
) {
    crate::util::bus_pki(dir, &[&format!("agent-{DEVICE}")]);
    let mut text = format!(
        r#"[cell]
id = "{DEVICE}"

[opcua]
endpoint = "opc.tcp://127.0.0.1:4840/"
pki_dir = "pki"
namespace_uri = "urn:cellwatch:test"

[zenoh]
listen = ["quic/127.0.0.1:0"]

[zenoh.tls]
ca = "pki-bus/ca.pem"
cert = "pki-bus/agent-{DEVICE}.pem"
key = "pki-bus/agent-{DEVICE}.key"

[journal]
path = "{journal}"

[metrics]
listen = "127.0.0.1:0"

[sparkplug]
broker = "mqtt://127.0.0.1:{port}"
group_id = "{GROUP}"
edge_node_id = "{NODE}"

[state]
running = "X0.00"

[production]
part_done = "X0.01"
"#,
        journal = dir.join("journal.sqlite").display(),
        port = broker.port,
    );
    text += more;
    for (name, address) in [("run", "X0.00"), ("part", "X0.01"), ("reject", "X0.02")] {
        text += &format!(
            "\n[[tags]]\nname = \"{name}\"\nnode_id = \"ns=2;s={address}\"\naddress = \"{address}\"\ntype = \"Boolean\"\n"
        );
    }
    let path = dir.join("cell.toml");
    std::fs::write(&path, text).unwrap();
    let config = cellwatch::config::load(&path).unwrap();
    let (source, script) = ScriptedSource::new();
    let agent = cellwatch::agent::start_with(
        config,
        cellwatch::agent::Options {
            source: Some(Box::new(source)),
            clock: clock.clone(),
            ..Default::default()
        },
    )
    .await
    .unwrap();
    (agent, script)
}

/// Contact `tag` read as `on` at `at`.
fn contact(tag: usize, on: bool, at: u64) -> SourceEvent {
    SourceEvent::Readings(
        vec![TagReading {
            tag,
            reading: Reading::Good(on),
            source_time: at,
        }]
        .into(),
    )
}

/// What a host knows of the device after `messages`: each metric's current
/// value by name, from the last DBIRTH and the live DDATA after it (history
/// is older than the birth's values).
fn current(messages: &[Value]) -> HashMap<String, Value> {
    let mut names: HashMap<u64, String> = HashMap::new();
    let mut values = HashMap::new();
    for m in messages {
        let payload = &m["payload"];
        if m["topic"] == topic("DBIRTH").as_str() {
            names.clear();
            values.clear();
            for x in metrics(payload) {
                let name = x["name"].as_str().unwrap().to_string();
                names.insert(x["alias"].as_u64().unwrap(), name.clone());
                values.insert(name, x["value"].clone());
            }
        } else if m["topic"] == topic("DDATA").as_str() {
            for x in metrics(payload)
                .iter()
                .filter(|x| x["isHistorical"] != true)
            {
                if let Some(name) = x["alias"].as_u64().and_then(|a| names.get(&a)) {
                    values.insert(name.clone(), x["value"].clone());
                }
            }
        }
    }
    values
}
