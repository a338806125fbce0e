//! The real `cellwatch` binary as a child process on the demo cell (plus two
//! transition timers and an operator key), beside a simulated CNC: what the
//! tests that kill it, measure it or flood it share.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use cellwatch::operator::{Action, Command as OperatorCommand, OperatorKey};
use cellwatch::sim::cnc::{SimOptions, SimulatedCnc};

use crate::util::root;

pub(crate) const KEY: &str = "00112233445566778899aabbccddeeff00112233445566778899aabbccddeeff";

/// Operator kim's private key (the operator's side).
pub(crate) fn kim() -> OperatorKey {
    OperatorKey::from_hex("kim", KEY).unwrap()
}

/// An agent's operators file: kim's public key, allowed `allow`.
pub(crate) fn operators_file(allow: &[Action]) -> String {
    kim().operators_entry(allow)
}

/// Two transitions the simulated CNC can be made to take far too early:
/// F17.00 off (all are on normally), then F17.01 off at once (expected 60 s
/// later); same for F18.
const TIMERS: &str = r#"{
  "version": 1,
  "method": "full-state",
  "signals": ["F17.00", "F17.01", "F18.00", "F18.01"],
  "transitions": [
    {"id": 1, "from": ["-F17.00", "F17.01"], "event": {"tag": "F17.01", "edge": "fall"},
     "to": ["-F17.00", "-F17.01"], "delta_ms": 65000, "min_ms": 64000, "max_ms": 66000,
     "support": 4, "window_ms": [60000, 70000]},
    {"id": 2, "from": ["-F18.00", "F18.01"], "event": {"tag": "F18.01", "edge": "fall"},
     "to": ["-F18.00", "-F18.01"], "delta_ms": 65000, "min_ms": 64000, "max_ms": 66000,
     "support": 4, "window_ms": [60000, 70000]}
  ]
}"#;

pub(crate) struct Cell {
    pub(crate) dir: PathBuf,
    pub(crate) config: PathBuf,
    /// Where the running agent's Zenoh session listens (it listens on
    /// port 0: known once [`Cell::spawn`] has returned).
    pub(crate) zenoh_port: u16,
    /// Where the running agent serves `/metrics` (the same).
    pub(crate) metrics_port: u16,
    /// More environment for the agent's process.
    pub(crate) env: Vec<(String, String)>,
    /// Also `WATCHDOG_PID`, the agent's own process id, as systemd sets it
    /// with `WATCHDOG_USEC`.
    pub(crate) watchdog_pid: bool,
}

impl Cell {
    /// Starts `cellwatch run` on the cell, its standard error copied to
    /// `log` in the cell's directory, and returns once the agent has said
    /// where it listens (its "agent running" line), these ports recorded.
    pub(crate) async fn spawn(&mut self, log: &str) -> Child {
        self.spawn_with(log, &[]).await
    }

    /// [`Cell::spawn`] with `args` after the configuration.
    pub(crate) async fn spawn_with(&mut self, log: &str, args: &[&str]) -> Child {
        use std::io::{BufRead, Write};
        let mut command = if self.watchdog_pid {
            // The shell becomes the agent: its process id is the agent's.
            let mut c = Command::new("sh");
            c.args([
                "-c",
                "WATCHDOG_PID=$$; export WATCHDOG_PID; exec \"$0\" \"$@\"",
                env!("CARGO_BIN_EXE_cellwatch"),
            ]);
            c
        } else {
            Command::new(env!("CARGO_BIN_EXE_cellwatch"))
        };
        let mut child = command
            .args(["run", self.config.to_str().unwrap()])
            .args(args)
            .envs(self.env.iter().map(|(k, v)| (k, v)))
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let stderr = child.stderr.take().unwrap();
        let mut file = std::fs::File::create(self.dir.join(log)).unwrap();
        let (tx, running) = tokio::sync::oneshot::channel();
        std::thread::spawn(move || {
            let mut tx = Some(tx);
            for line in std::io::BufReader::new(stderr)
                .lines()
                .map_while(Result::ok)
            {
                let _ = writeln!(file, "{line}");
                if line.contains("agent running") {
                    if let Some(tx) = tx.take() {
                        let _ = tx.send(line);
                    }
                }
            }
        });
        let line = match tokio::time::timeout(Duration::from_secs(60), running).await {
            Ok(Ok(line)) => line,
            _ => panic!("the agent never said it runs:\n{}", self.log(log)),
        };
        let field = |name: &str| -> u16 {
            line.split_whitespace()
                .find_map(|w| w.strip_prefix(name))
                .and_then(|v| v.split(',').next()?.rsplit(':').next()?.parse().ok())
                .unwrap_or_else(|| panic!("no {name} port in: {line}"))
        };
        self.zenoh_port = field("zenoh=");
        self.metrics_port = field("metrics=");
        child
    }

    /// `cellwatch alarms --follow --since SINCE --json` for this cell, its
    /// output piped.
    pub(crate) fn follow_since(&self, since: &str) -> Child {
        Command::new(env!("CARGO_BIN_EXE_cellwatch"))
            .args([
                "alarms",
                "--cell",
                "m01ps0004",
                "--follow",
                "--json",
                "--since",
                since,
                // A loaded machine may take more than the default 5 s.
                "--timeout",
                "30",
            ])
            .args(self.bus_args())
            .stdout(Stdio::piped())
            .stderr(std::fs::File::create(self.dir.join("follow.log")).unwrap())
            .spawn()
            .unwrap()
    }

    /// A session of operator kim's certificate to the agent.
    pub(crate) async fn client(&self) -> zenoh::Session {
        crate::util::operator_session(&self.dir, "operator-kim", self.zenoh_port).await
    }

    /// The CLI flags that reach the agent as operator kim.
    pub(crate) fn bus_args(&self) -> Vec<String> {
        crate::util::bus_args(&self.dir, "operator-kim", self.zenoh_port)
    }

    pub(crate) fn log(&self, name: &str) -> String {
        std::fs::read_to_string(self.dir.join(name)).unwrap_or_default()
    }
}

/// A simulated CNC and, in `dir`, the configuration of an agent watching it.
pub(crate) async fn start(dir: &Path) -> (SimulatedCnc, Cell) {
    let sim = SimulatedCnc::start(&SimOptions {
        listen: "127.0.0.1:0".parse().unwrap(),
        pki_dir: dir.join("sim-pki"),
        insecure: false,
        decoy: None,
    })
    .await
    .unwrap();
    let cell = cell(dir, &sim);
    (sim, cell)
}

/// The demo cell plus the two timers, its files in `dir`, its ports chosen
/// by the system.
pub(crate) fn cell(dir: &Path, sim: &SimulatedCnc) -> Cell {
    std::fs::write(dir.join("timers.json"), TIMERS).unwrap();
    crate::util::bus_pki(dir, &["agent-m01ps0004", "operator-kim"]);
    std::fs::write(dir.join("operators.toml"), operators_file(&Action::ALL)).unwrap();
    let demo = std::fs::read_to_string(root().join("config/demo.toml")).unwrap();
    let config = demo
        .replace("opc.tcp://127.0.0.1:4845/", &sim.endpoint())
        .replace("quic/127.0.0.1:7447", "quic/127.0.0.1:0")
        .replace("# listen = \"127.0.0.1:9464\"", "listen = \"127.0.0.1:0\"")
        .replace(
            "# path = \"cellwatch-m01ps0004.sqlite\"",
            "path = \"journal.sqlite\"",
        )
        .replace(
            "# operators_file = \"/etc/cellwatch/operators.toml\"",
            "operators_file = \"operators.toml\"",
        )
        .replace(
            "program = \"cnc/",
            &format!("program = \"{}/config/cnc/", root().display()),
        )
        .replace(
            "comments = \"cnc/",
            &format!("comments = \"{}/config/cnc/", root().display()),
        )
        + "\n[[checks.timers]]\nid = \"tmr\"\nmodel = \"timers.json\"\nseverity = \"high\"\n";
    let path = dir.join("cell.toml");
    std::fs::write(&path, config).unwrap();
    // The agent and the simulator trust each other's certificates.
    let parsed = cellwatch::config::load(&path).unwrap();
    crate::util::trust_sim(&parsed, &dir.join("sim-pki"));
    Cell {
        dir: dir.to_path_buf(),
        config: path,
        zenoh_port: 0,
        metrics_port: 0,
        env: Vec::new(),
        watchdog_pid: false,
    }
}

/// One reply to `selector` (retried until the agent answers).
pub(crate) async fn query(
    session: &zenoh::Session,
    selector: &str,
    payload: Option<String>,
) -> Result<String, String> {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    loop {
        let mut get = session.get(selector).timeout(Duration::from_secs(3));
        if let Some(p) = &payload {
            get = get.payload(p.clone());
        }
        let replies = get.await.unwrap();
        if let Ok(reply) = replies.recv_async().await {
            return match reply.result() {
                Ok(s) => Ok(crate::util::opened(s.payload())),
                Err(e) => Err(crate::util::opened(e.payload())),
            };
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "no reply to {selector}"
        );
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
}

/// Polls the snapshot until `ready` holds; returns it.
pub(crate) async fn snapshot_until(
    session: &zenoh::Session,
    what: &str,
    ready: impl Fn(&serde_json::Value) -> bool,
) -> serde_json::Value {
    cell_snapshot_until(session, "m01ps0004", what, ready).await
}

/// Polls `cell`'s snapshot until `ready` holds; returns it.
pub(crate) async fn cell_snapshot_until(
    session: &zenoh::Session,
    cell: &str,
    what: &str,
    ready: impl Fn(&serde_json::Value) -> bool,
) -> serde_json::Value {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(60);
    let selector = format!("cellwatch/{cell}/snapshot");
    loop {
        let snap: serde_json::Value =
            serde_json::from_str(&query(session, &selector, None).await.unwrap()).unwrap();
        if ready(&snap) {
            return snap;
        }
        assert!(tokio::time::Instant::now() < deadline, "{what}: {snap:#}");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

pub(crate) fn alarm<'a>(snap: &'a serde_json::Value, id: &str) -> Option<&'a serde_json::Value> {
    snap["alarms"].as_array()?.iter().find(|a| a["id"] == id)
}

pub(crate) fn signed(action: Action, alarm: &str) -> String {
    signed_with(action, alarm, None, None)
}

/// Kim's signed command with a value and a reason.
pub(crate) fn signed_with(
    action: Action,
    alarm: &str,
    value: Option<&str>,
    reason: Option<&str>,
) -> String {
    let mut c = OperatorCommand {
        action,
        alarm: alarm.into(),
        tag: None,
        value: value.map(str::to_string),
        reason: reason.map(str::to_string),
        operator: "kim".into(),
        nonce: cellwatch::operator::nonce(),
        issued_at: cellwatch::clock::now_ms(),
        signature: String::new(),
    };
    c.sign("m01ps0004", &kim());
    serde_json::to_string(&c).unwrap()
}

pub(crate) async fn send(session: &zenoh::Session, json: &str) -> (bool, String) {
    let r: serde_json::Value = serde_json::from_str(
        &query(
            session,
            "cellwatch/m01ps0004/command",
            Some(json.to_string()),
        )
        .await
        .unwrap(),
    )
    .unwrap();
    (
        r["accepted"].as_bool().unwrap(),
        r["detail"].as_str().unwrap().to_string(),
    )
}

pub(crate) fn scrape(port: u16) -> String {
    use std::io::{Read, Write};
    let mut s = std::net::TcpStream::connect(("127.0.0.1", port)).unwrap();
    s.write_all(b"GET /metrics HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n")
        .unwrap();
    let mut body = String::new();
    s.read_to_string(&mut body).unwrap();
    body
}
