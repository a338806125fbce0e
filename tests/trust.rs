//! Only a cell's agent speaks for its cell, whatever the topology: agents
//! relay nothing for anyone, every payload is sealed by the agent's own key
//! and the CLI believes nothing else, no session listens or links on plain
//! TCP unless asked, and plant-wide views work through the shipped router.

use std::path::Path;
use std::time::Duration;

use cellwatch::agent;
use cellwatch::bus::envelope::{AgentKey, Kind};
use cellwatch::sim::cnc::{SimOptions, SimulatedCnc};

use crate::agent::{config, Fixture};

/// The simulated CNC and the demo cell's configuration for it, their
/// certificates trusted both ways, files under `dir`.
async fn cnc(dir: &Path) -> (SimulatedCnc, cellwatch::config::CellConfig) {
    let sim = SimulatedCnc::start(&SimOptions {
        listen: "127.0.0.1:0".parse().unwrap(),
        pki_dir: dir.join("sim-pki"),
        insecure: false,
        decoy: None,
    })
    .await
    .unwrap();
    let c = config(dir, &sim.endpoint());
    crate::util::trust_sim(&c, &dir.join("sim-pki"));
    (sim, c)
}

/// The ports `pid` listens on (TCP, IPv4 and IPv6), from its socket
/// descriptors and the kernel's socket tables.
fn listening_ports(pid: u32) -> Vec<u16> {
    let inodes = socket_inodes(pid);
    let mut ports = Vec::new();
    for table in ["/proc/net/tcp", "/proc/net/tcp6"] {
        for line in std::fs::read_to_string(table).unwrap().lines().skip(1) {
            let f: Vec<&str> = line.split_whitespace().collect();
            // local_address, state (0A: LISTEN), inode.
            if f.len() > 9 && f[3] == "0A" && inodes.iter().any(|i| i == f[9]) {
                let port = f[1].rsplit(':').next().unwrap();
                ports.push(u16::from_str_radix(port, 16).unwrap());
            }
        }
    }
    ports
}

/// The UDP ports process `pid` has sockets bound to.
fn udp_ports(pid: u32) -> Vec<u16> {
    let inodes = socket_inodes(pid);
    let mut ports = Vec::new();
    for table in ["/proc/net/udp", "/proc/net/udp6"] {
        for line in std::fs::read_to_string(table).unwrap().lines().skip(1) {
            let f: Vec<&str> = line.split_whitespace().collect();
            if f.len() > 9 && inodes.iter().any(|i| i == f[9]) {
                let port = f[1].rsplit(':').next().unwrap();
                ports.push(u16::from_str_radix(port, 16).unwrap());
            }
        }
    }
    ports
}

/// The inodes of process `pid`'s sockets.
fn socket_inodes(pid: u32) -> Vec<String> {
    std::fs::read_dir(format!("/proc/{pid}/fd"))
        .unwrap()
        .map_while(Result::ok)
        .filter_map(|fd| std::fs::read_link(fd.path()).ok())
        .filter_map(|l| {
            let l = l.to_string_lossy().to_string();
            Some(l.strip_prefix("socket:[")?.strip_suffix(']')?.to_string())
        })
        .collect()
}

/// An operator's session to an agent in peer mode tries to speak for
/// another cell (and for the agent's own) through it: a put, a queryable,
/// a liveliness token. Another client of the same agent sees none of it:
/// the agent routes for nobody.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn an_agent_in_peer_mode_relays_no_impostor() {
    let fx = Fixture::start().await;
    let dir = fx.dir();
    let port = fx.zenoh_port();
    let kim = fx.client().clone();
    // In client mode: a peer routes for its clients.
    crate::util::bus_pki(dir, &["operator-mallory"]);
    let mut as_client = crate::util::client_config(dir, "operator-mallory", port);
    as_client.mode = cellwatch::config::ZenohMode::Client;
    let mallory = cellwatch::bus::open(&as_client).await.unwrap();
    let seen = kim.declare_subscriber("cellwatch/**").await.unwrap();
    let tokens = kim
        .liveliness()
        .declare_subscriber("cellwatch/**")
        .await
        .unwrap();
    fx.settled().await;
    // Mallory: an impostor queryable and token for cell m02, forged alarms
    // for m02 and for the agent's own cell.
    let _queryable = mallory
        .declare_queryable("cellwatch/m02/snapshot")
        .callback(|q| {
            tokio::spawn(async move {
                let _ = q
                    .reply(q.key_expr().clone(), r#"{"cell":"m02","forged":true}"#)
                    .await;
            });
        })
        .await
        .unwrap();
    let _token = mallory
        .liveliness()
        .declare_token("cellwatch/m02/agent/impostor")
        .await
        .unwrap();
    for key in ["cellwatch/m02/alarms/ese", "cellwatch/m01ps0004/alarms/ese"] {
        mallory.put(key, r#"{"forged":true}"#).await.unwrap();
    }
    // Mallory's query follows all that on her link: once the agent has
    // answered it, it has judged everything before it.
    let mine = mallory.get("cellwatch/m01ps0004/snapshot").await.unwrap();
    assert!(mine.recv_async().await.unwrap().result().is_ok());
    // Kim asks m02 and the agent: the agent's answer comes after anything
    // it would have relayed to kim before it.
    let replies = kim.get("cellwatch/*/snapshot").await.unwrap();
    let mut cells = Vec::new();
    while let Ok(reply) = replies.recv_async().await {
        let text = crate::util::opened(reply.result().unwrap().payload());
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        cells.push(v["cell"].as_str().unwrap().to_string());
    }
    assert_eq!(cells, ["m01ps0004"]);
    while let Ok(Some(sample)) = seen.try_recv() {
        let text = String::from_utf8_lossy(&sample.payload().to_bytes()).to_string();
        assert!(
            !text.contains("forged"),
            "{} relayed: {text}",
            sample.key_expr()
        );
    }
    while let Ok(Some(token)) = tokens.try_recv() {
        assert!(
            !token.key_expr().as_str().contains("impostor"),
            "a token relayed: {}",
            token.key_expr()
        );
    }
}

/// Everything the agent puts or answers is sealed with its own key, on the
/// key it travels on; nothing else opens.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn alarms_and_answers_are_sealed_by_the_cells_agent() {
    let fx = Fixture::start().await;
    let trust = crate::util::trust(fx.dir());
    let sub = fx
        .client()
        .declare_subscriber("cellwatch/m01ps0004/alarms/**")
        .await
        .unwrap();
    fx.settled().await;
    fx.sim.set("X0.06", false).unwrap();
    let sample = tokio::time::timeout(Duration::from_secs(30), sub.recv_async())
        .await
        .unwrap()
        .unwrap();
    let key = sample.key_expr().as_str().to_string();
    let bytes = sample.payload().to_bytes();
    let opened = trust.open(&bytes, Kind::Put, &key, "").unwrap();
    assert_eq!(opened.cell, "m01ps0004");
    assert!(
        opened.body.contains("\"schema\":\"cellwatch.alarm.v1\""),
        "{}",
        opened.body
    );
    // The same envelope on another alarm's key, or as an answer, is refused.
    assert!(trust
        .open(&bytes, Kind::Put, "cellwatch/m01ps0004/alarms/csd", "")
        .is_err());
    assert!(trust.open(&bytes, Kind::Reply, &key, "").is_err());
    // Another agent's key does not open as this cell's.
    let other = AgentKey::generate("m01ps0004");
    let forged = other.seal(Kind::Put, &key, "", 1, opened.body.clone());
    assert!(trust.open(forged.as_bytes(), Kind::Put, &key, "").is_err());
    // An answer is sealed for its query's parameters.
    let replies = fx
        .client()
        .get("cellwatch/m01ps0004/snapshot?nonce=0123456789abcdef")
        .await
        .unwrap();
    let reply = replies.recv_async().await.unwrap();
    let answer = reply.result().unwrap();
    let bytes = answer.payload().to_bytes();
    let snapshot = "cellwatch/m01ps0004/snapshot";
    assert!(trust
        .open(&bytes, Kind::Reply, snapshot, "nonce=0123456789abcdef")
        .is_ok());
    assert!(trust
        .open(&bytes, Kind::Reply, snapshot, "nonce=ffffffffffffffff")
        .is_err());
}

/// With `zenoh.config_file` the agent listens on its TLS endpoints only,
/// whatever the file says: Zenoh's default plain listener on every
/// interface is never opened. A file that would make the bus plain is
/// refused at start, and says why.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_zenoh_file_opens_no_plain_listener() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let (sim, mut c) = cnc(dir).await;
    // Nothing about endpoints in the file: Zenoh's default would listen on
    // tcp/[::]:0.
    let file = dir.join("zenoh.json5");
    std::fs::write(&file, "{ transport: { unicast: { max_links: 2 } } }\n").unwrap();
    c.zenoh.config_file = Some(file.clone());
    let agent = agent::start(c.clone(), None).await.unwrap();
    let locators = agent.zenoh_locators().await;
    assert!(
        !locators.is_empty() && locators.iter().all(|l| l.starts_with("quic/")),
        "{locators:?}"
    );
    agent.stop().await;
    // A file asking for a plain listener: the agent's own endpoints win.
    std::fs::write(&file, "{ listen: { endpoints: [\"tcp/127.0.0.1:0\"] } }\n").unwrap();
    let agent = agent::start(c.clone(), None).await.unwrap();
    let locators = agent.zenoh_locators().await;
    assert!(
        locators.iter().all(|l| l.starts_with("quic/")),
        "{locators:?}"
    );
    agent.stop().await;
    // No [zenoh.tls] and a file without TLS: refused, with the reason.
    c.zenoh.tls = None;
    c.zenoh.listen = vec!["tcp/127.0.0.1:0".into()];
    let err = agent::start(c, None).await.err().unwrap();
    assert!(err.is_input());
    assert_eq!(
        err.to_string(),
        "zenoh listen/endpoints = tcp/127.0.0.1:0: not an encrypted endpoint: the bus takes quic/host:port (mutual TLS over QUIC); write zenoh.plain = true (CLI: --plain) to accept a bus without encryption or authentication"
    );
    sim.stop();
}

/// The CLI listens on nothing, whatever its Zenoh file says, and links on
/// plain TCP only when told `--plain`.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn the_cli_listens_on_nothing_and_refuses_plain_tcp() {
    let fx = Fixture::start().await;
    let dir = fx.dir();
    let tls = crate::util::bus_tls(dir, "operator-kim");
    crate::util::bus_pki(dir, &["operator-kim"]);
    let file = dir.join("client.json5");
    let path = |p: &Path| serde_json::to_string(&p.display().to_string()).unwrap();
    std::fs::write(
        &file,
        format!(
            "{{ connect: {{ endpoints: [\"quic/127.0.0.1:{}\"] }},\n  transport: {{ link: {{ tls: {{ root_ca_certificate: {}, connect_certificate: {}, connect_private_key: {}, enable_mtls: true }} }} }} }}\n",
            fx.zenoh_port(),
            path(&tls.ca),
            path(&tls.cert),
            path(&tls.key)
        ),
    )
    .unwrap();
    let trust = crate::util::trust_file(dir);
    let mut follow = std::process::Command::new(env!("CARGO_BIN_EXE_cellwatch"))
        .args(["alarms", "--follow", "--json", "--zenoh-config"])
        .arg(&file)
        .arg("--trust")
        .arg(&trust)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let lines = crate::util::lines_of(&mut follow);
    // Once it prints an alarm, its session is up.
    fx.settled().await;
    fx.sim.set("X0.06", false).unwrap();
    let line = lines.recv_timeout(Duration::from_secs(60)).unwrap();
    assert!(line.contains("\"id\":\"ese\""), "{line}");
    assert_eq!(listening_ports(follow.id()), Vec::<u16>::new());
    // Its QUIC socket (UDP) takes no connection: a session with a plant
    // certificate cannot open one to it.
    let udp = udp_ports(follow.id());
    assert!(!udp.is_empty(), "the CLI has no QUIC socket");
    crate::util::bus_pki(dir, &["operator-mallory"]);
    for port in udp {
        let mut cfg = cellwatch::bus::session_config(&crate::util::client_config(
            dir,
            "operator-mallory",
            port,
        ))
        .unwrap();
        cfg.insert_json5("connect/timeout_ms", "3000").unwrap();
        // Opening connects to the configured endpoint before it returns.
        if let Ok(s) = zenoh::open(cfg).await {
            let peers: Vec<_> = s.info().peers_zid().await.collect();
            assert!(
                peers.is_empty(),
                "{peers:?} took a connection on the CLI's UDP port {port}"
            );
            s.close().await.unwrap();
        }
    }
    follow.kill().unwrap();
    follow.wait().unwrap();
    // Plain TCP: refused unless asked for.
    let trust = trust.display().to_string();
    let run =
        crate::util::cellwatch(&["alarms", "--connect", "tcp/127.0.0.1:9", "--trust", &trust]);
    assert_eq!(run.code, 2, "{}", run.stderr);
    assert_eq!(
        run.stderr.trim_end(),
        "error: zenoh connect/endpoints = tcp/127.0.0.1:9: not an encrypted endpoint: the bus takes quic/host:port (mutual TLS over QUIC); write zenoh.plain = true (CLI: --plain) to accept a bus without encryption or authentication"
    );
    // No trust file: nothing to believe anything with.
    let run = crate::util::cellwatch(&[
        "alarms",
        "--connect",
        &format!("quic/127.0.0.1:{}", fx.zenoh_port()),
    ]);
    assert_eq!(run.code, 2, "{}", run.stderr);
    assert!(run.stderr.contains("give --trust FILE"), "{}", run.stderr);
}

/// The bus reference's Python recipe (`docs/reference/bus.md`) opens a
/// real envelope, and refuses one whose body was edited: a third party can
/// verify in a few lines.
#[test]
fn the_readme_python_recipe_verifies_an_envelope() {
    let page = std::fs::read_to_string(crate::util::root().join("docs/reference/bus.md")).unwrap();
    let start = page.find("```python\n").expect("the Python recipe") + "```python\n".len();
    let recipe = &page[start..start + page[start..].find("```").unwrap()];
    let key = AgentKey::generate("m01ps0004");
    let sealed = key.seal(
        Kind::Put,
        "cellwatch/m01ps0004/alarms/ese",
        "",
        1_764_052_850_653,
        r#"{"schema":"cellwatch.alarm.v1","cell":"m01ps0004","id":"ese"}"#.into(),
    );
    let mut edited: serde_json::Value = serde_json::from_str(&sealed).unwrap();
    edited["body"] = r#"{"schema":"cellwatch.alarm.v1","cell":"m01ps0004","id":"csd"}"#.into();
    let d = tempfile::tempdir().unwrap();
    let script = d.path().join("verify.py");
    std::fs::write(
        &script,
        format!(
            "{recipe}\nimport sys\ntrust = {{'m01ps0004': '{}'}}\nfor payload in sys.argv[1:]:\n    try:\n        print(opened(payload.encode(), 'cellwatch/m01ps0004/alarms/ese', trust)['id'])\n    except Exception as e:\n        print('refused', type(e).__name__)\n",
            key.public_hex()
        ),
    )
    .unwrap();
    let out = std::process::Command::new(python_with_cryptography())
        .arg(&script)
        .arg(&sealed)
        .arg(edited.to_string())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        String::from_utf8_lossy(&out.stdout),
        "ese\nrefused InvalidSignature\n"
    );
}

/// A Python 3 that has the `cryptography` package.
fn python_with_cryptography() -> std::path::PathBuf {
    crate::util::python_with("cryptography", "cryptography", &["cryptography"])
}

/// Plant-wide views through the shipped router and its access control: the
/// alarms of every cell (a query on `cellwatch/*/snapshot`, answered on
/// each cell's own key), the alarm events as they happen, a cell's history.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn plant_wide_views_work_through_the_shipped_router() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let (_router, port, sim, agent) = crate::agent::behind_a_router(dir, true).await;
    crate::util::bus_pki(dir, &["operator-kim"]);
    let mut bus = crate::util::bus_args(dir, "operator-kim", port);
    bus.extend([
        "--mode".into(),
        "client".into(),
        "--timeout".into(),
        "30".into(),
    ]);
    let cli = |args: &[&str]| {
        let mut all: Vec<String> = args.iter().map(|a| a.to_string()).collect();
        all.extend(bus.iter().cloned());
        let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_cellwatch"));
        cmd.args(all);
        cmd
    };
    let mut follow = cli(&["alarms", "--follow", "--json"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let lines = crate::util::lines_of(&mut follow);
    // Once the whole-plant query sees the agent, the follower's
    // subscription went through the same router before it.
    let deadline = std::time::Instant::now() + Duration::from_secs(60);
    loop {
        let out = tokio::task::spawn_blocking({
            let mut cmd = cli(&["alarms"]);
            move || cmd.output().unwrap()
        })
        .await
        .unwrap();
        if out.status.success() {
            break;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "alarms over cellwatch/*/snapshot through the router: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    sim.set("X0.06", false).unwrap();
    let line = lines.recv_timeout(Duration::from_secs(60)).unwrap();
    assert!(
        line.contains("\"id\":\"ese\"") && line.contains("\"raised\""),
        "{line}"
    );
    let out = cli(&["alarms"]).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("m01ps0004/ese") && text.contains("active_unacknowledged"),
        "{text}"
    );
    let out = cli(&["history", "--cell", "m01ps0004", "--kind", "alarm"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("alarm     ese raised"));
    follow.kill().unwrap();
    follow.wait().unwrap();
    agent.stop().await;
    sim.stop();
}

/// A client that sends the same signed command again (its answer lost,
/// or the agent restarted meanwhile) is told it is a replay and what the
/// first sending came to: the command is carried out once.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn the_same_signed_command_sent_again_gets_its_original_outcome() {
    use cellwatch::operator::{Action, Command};
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let (sim, c) = cnc(dir).await;
    let agent = agent::start(c.clone(), None).await.unwrap();
    let port = crate::util::agent_port(&agent).await;
    let kim = crate::util::operator_session(dir, "operator-kim", port).await;
    let alarms = kim
        .declare_subscriber("cellwatch/m01ps0004/alarms/ese")
        .await
        .unwrap();
    // The subscription is known to the agent once a query has crossed.
    send_until_answered(&kim, "{}").await;
    sim.set("X0.06", false).unwrap();
    loop {
        let sample = tokio::time::timeout(Duration::from_secs(30), alarms.recv_async())
            .await
            .unwrap()
            .unwrap();
        if crate::util::opened(sample.payload()).contains("\"transition\":\"raised\"") {
            break;
        }
    }
    let mut ack = Command {
        action: Action::Ack,
        alarm: "ese".into(),
        tag: None,
        value: None,
        reason: None,
        operator: "kim".into(),
        nonce: cellwatch::operator::nonce(),
        issued_at: cellwatch::clock::now_ms(),
        signature: String::new(),
    };
    ack.sign("m01ps0004", &crate::spawned::kim());
    let ack = serde_json::to_string(&ack).unwrap();
    let digest = cellwatch::step::command_digest([ack.as_bytes()]);
    let first = send_until_answered(&kim, &ack).await;
    assert_eq!(
        first,
        format!(r#"{{"accepted":true,"detail":"ack ese by kim","command":"{digest}"}}"#)
    );
    let replayed = format!(
        r#"{{"accepted":false,"detail":"replayed command: sent before (accepted: ack ese by kim); not carried out again","command":"{digest}","replayed":{{"accepted":true,"detail":"ack ese by kim"}}}}"#
    );
    assert_eq!(send_until_answered(&kim, &ack).await, replayed);
    // After a restart: the outcome read back from the journal.
    agent.stop().await;
    let agent = agent::start(c, None).await.unwrap();
    let port = crate::util::agent_port(&agent).await;
    let kim = crate::util::operator_session(dir, "operator-kim", port).await;
    assert_eq!(send_until_answered(&kim, &ack).await, replayed);
    // Carried out once: one accepted row for its nonce in the journal.
    let journal = rusqlite::Connection::open(dir.join("journal.sqlite")).unwrap();
    let nonce = serde_json::from_str::<serde_json::Value>(&ack).unwrap()["nonce"]
        .as_str()
        .unwrap()
        .to_string();
    let rows: i64 = journal
        .query_row(
            "SELECT COUNT(*) FROM commands WHERE nonce = ?1",
            [&nonce],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!(rows, 1);
    agent.stop().await;
    sim.stop();
}

/// Sends `payload` to the cell's `command` queryable until an answer comes
/// (a session just opened may not know the queryable yet); its body.
async fn send_until_answered(session: &zenoh::Session, payload: &str) -> String {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    loop {
        let replies = session
            .get("cellwatch/m01ps0004/command")
            .payload(payload.to_string())
            .await
            .unwrap();
        if let Ok(reply) = replies.recv_async().await {
            return match reply.result() {
                Ok(s) => crate::util::opened(s.payload()),
                Err(e) => crate::util::opened_or_raw(e.payload()),
            };
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "the agent never answered"
        );
        // Backoff only: the answer itself is the event waited for.
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// Every private key the agent writes is its owner's only, and it refuses
/// to start on one that others may read, naming the file.
#[cfg(unix)]
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn private_keys_are_the_owners_only() {
    use std::os::unix::fs::PermissionsExt;
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let (sim, c) = cnc(dir).await;
    let agent = agent::start(c.clone(), None).await.unwrap();
    agent.stop().await;
    let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
    let tls_key = c.zenoh.tls.as_ref().unwrap().key.clone();
    for key in [
        dir.join("agent-pki/private/private.pem"),
        dir.join("sim-pki/private/private.pem"),
        c.zenoh.signing_key.clone().unwrap(),
        tls_key.clone(),
    ] {
        assert_eq!(mode(&key), 0o600, "{}", key.display());
    }
    std::fs::set_permissions(&tls_key, std::fs::Permissions::from_mode(0o644)).unwrap();
    let err = agent::start(c, None).await.err().unwrap();
    assert!(err.is_input());
    assert_eq!(
        err.to_string(),
        format!(
            "{0}: a private key readable by others (mode 644); make it the owner's only: chmod 600 {0}",
            tls_key.display()
        )
    );
    sim.stop();
}
