//! The quickstart (`docs/quickstart.md`) run end to end, as a plant
//! engineer follows it: its fenced blocks, in order, run by a shell in an
//! empty directory with the built `cellwatch` first on `PATH`, against the
//! simulated CNC in place of the PLC at `opc.tcp://192.168.10.7:4840/` (its
//! own namespace, tags the engineer has never seen).
//!
//! What the test changes, and only that: the PLC's endpoint becomes the
//! simulator's; the bus and metrics listen on port 0 (two runs on one
//! machine never collide), and the bus clients are told where the agent
//! listens (`--connect`); the machine's events are made on the simulator's
//! standard input (`temp 92.5`, `set X0.0D 0`, `set X0.06 0`) where the
//! quickstart says the spindle runs hot, spindle 1 leaves automatic and the
//! Y axis runs onto its limit switch; the engineer's `y` is typed on
//! `trust-server`'s standard input. Everything else — the certificate
//! exchange, `pki`, `keygen`, `discover`, `sf`, the checks, `validate`,
//! `run`, `alarms --follow`, the alarms as printed, `history`, `ack`,
//! `report alarms` — is the page's own text, and a change of the page's
//! blocks fails here until this test follows it.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Output, Stdio};
use std::sync::mpsc::Receiver;
use std::time::Duration;

use crate::util::root;

/// How long any one thing the quickstart waits for may take on a busy
/// machine.
const PATIENCE: Duration = Duration::from_secs(120);

/// The PLC's endpoint as the quickstart writes it.
const PLC: &str = "opc.tcp://192.168.10.7:4840/";

/// One fenced block of the page.
struct Block {
    lang: String,
    text: String,
    /// Its first line's number in the page, for messages.
    line: usize,
}

fn blocks(page: &str) -> Vec<Block> {
    let mut out = Vec::new();
    let mut open: Option<Block> = None;
    for (i, line) in page.lines().enumerate() {
        match (&mut open, line.strip_prefix("```")) {
            (None, Some(lang)) => {
                open = Some(Block {
                    lang: lang.trim().to_string(),
                    text: String::new(),
                    line: i + 1,
                })
            }
            (Some(_), Some(_)) => out.extend(open.take()),
            (Some(b), None) => {
                b.text += line;
                b.text += "\n";
            }
            (None, None) => {}
        }
    }
    out
}

/// A process the test started, killed if the test ends early.
struct Running {
    child: Child,
}

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Waits for the first line of `rx` for which `f` says something.
fn wait_for<T>(rx: &Receiver<String>, what: &str, mut f: impl FnMut(&str) -> Option<T>) -> T {
    let deadline = std::time::Instant::now() + PATIENCE;
    let mut seen = Vec::new();
    loop {
        let left = deadline.saturating_duration_since(std::time::Instant::now());
        match rx.recv_timeout(left) {
            Ok(line) => {
                if let Some(t) = f(&line) {
                    return t;
                }
                seen.push(line);
            }
            Err(e) => panic!("no {what} ({e}); seen:\n{}", seen.join("\n")),
        }
    }
}

/// The quickstart's working directory and shell.
struct Desk {
    dir: PathBuf,
    path: String,
}

impl Desk {
    /// `script` with `input` on its standard input.
    fn sh_with(&self, script: &str, input: &str) -> Output {
        let mut child = Command::new("sh")
            .arg("-c")
            .arg(script)
            .current_dir(&self.dir)
            .env("PATH", &self.path)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let mut stdin = child.stdin.take().unwrap();
        // A command that reads no input may have ended already.
        let _ = stdin.write_all(input.as_bytes());
        drop(stdin);
        child.wait_with_output().unwrap()
    }

    /// Runs `block`'s commands; each must succeed.
    fn run(&self, block: &Block, script: &str) -> String {
        self.run_with(block, script, "")
    }

    /// [`Desk::run`] with `input` typed on standard input.
    fn run_with(&self, block: &Block, script: &str, input: &str) -> String {
        let out = self.sh_with(&format!("set -e\n{script}"), input);
        assert!(
            out.status.success(),
            "quickstart.md:{}: {script}\nstdout: {}\nstderr: {}",
            block.line,
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8(out.stdout).unwrap()
    }

    /// Starts `script`'s last command in the background (`exec`), its
    /// standard output and error read line by line.
    fn spawn(&self, script: &str) -> (Running, Receiver<String>) {
        let (before, last) = script.trim_end().rsplit_once('\n').unwrap_or(("", script));
        let mut child = Command::new("sh")
            .arg("-c")
            .arg(format!("{before}\nexec {last} 2>&1"))
            .current_dir(&self.dir)
            .env("PATH", &self.path)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .spawn()
            .unwrap();
        let rx = crate::util::lines_of(&mut child);
        (Running { child }, rx)
    }

    /// The simulated CNC, serving on a port of its own, scenario `none`
    /// (faults only on its standard input), trusting `trust`.
    fn simulator(&self, trust: &[&str]) -> (Running, ChildStdin, String) {
        let mut child = Command::new(env!("CARGO_BIN_EXE_cellwatch"))
            .args([
                "simulate",
                "cnc",
                "--listen",
                "127.0.0.1:0",
                "--pki-dir",
                "sim-pki",
                "--scenario",
                "none",
            ])
            .args(trust.iter().flat_map(|t| ["--trust", t]))
            .current_dir(&self.dir)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(std::fs::File::create(self.dir.join("sim.log")).unwrap())
            .spawn()
            .unwrap();
        let stdin = child.stdin.take().unwrap();
        let rx = crate::util::lines_of(&mut child);
        let endpoint = wait_for(&rx, "simulator endpoint", |l| {
            l.strip_prefix("simulated CNC on ")
                .and_then(|r| r.split_whitespace().next())
                .map(str::to_string)
        });
        (Running { child }, stdin, endpoint)
    }
}

/// Waits until the agent whose metrics are at `addr` knows every tag's
/// value (`cellwatch_tags_unknown` 0: connected, first values read).
fn tags_known(addr: &str) {
    use std::io::Read;
    let deadline = std::time::Instant::now() + PATIENCE;
    loop {
        let mut body = String::new();
        if let Ok(mut s) = std::net::TcpStream::connect(addr) {
            let _ = s.write_all(
                b"GET /metrics HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n",
            );
            let _ = s.read_to_string(&mut body);
        }
        if body.contains("\ncellwatch_tags_unknown{cell=\"press7\"} 0\n") {
            return;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "the agent never read every tag:\n{body}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[test]
fn the_quickstart_runs_end_to_end() {
    let page = std::fs::read_to_string(root().join("docs/quickstart.md")).unwrap();
    let b = blocks(&page);
    let langs: Vec<&str> = b.iter().map(|b| b.lang.as_str()).collect();
    assert_eq!(
        langs,
        ["sh", "sh", "sh", "sh", "sh", "toml", "sh", "sh", "text", "sh", "sh"],
        "docs/quickstart.md's blocks changed: make this test follow them"
    );
    let tmp = tempfile::tempdir().unwrap();
    let bin = Path::new(env!("CARGO_BIN_EXE_cellwatch")).parent().unwrap();
    let desk = Desk {
        dir: tmp.path().to_path_buf(),
        path: format!(
            "{}:{}",
            bin.display(),
            std::env::var("PATH").unwrap_or_default()
        ),
    };

    // 1. Install: the test runs the binary just built.
    assert_eq!(b[0].text.trim(), "cargo install --locked --path agent");

    // 2. OPC UA certificates, one command: the engineer answers y; the PLC
    // does not know the agent yet, and the command says so.
    let (sim, _, endpoint) = desk.simulator(&[]);
    let trust = b[1].text.replace(PLC, &endpoint);
    let said = desk.run_with(&b[1], &trust, "y\n");
    for expected in [
        "SHA-256",
        "thumbprint",
        "Trust it?",
        "Trusted: pki/trusted/",
        "This agent's certificate, pki/own/cert.der",
        "The server does not accept this agent yet",
        "the server refused this agent's certificate",
    ] {
        assert!(said.contains(expected), "{expected}\nin:\n{said}");
    }
    // "For the simulator: `cellwatch simulate cnc --trust pki/own/cert.der`";
    // the same command again connects.
    assert!(page.contains("`cellwatch simulate cnc --trust pki/own/cert.der`"));
    drop(sim);
    let (mut sim, mut plc_input, endpoint) = desk.simulator(&["pki/own/cert.der"]);
    let trust = b[1].text.replace(PLC, &endpoint);
    let said = desk.run(&b[1], &trust);
    assert!(
        said.contains("is trusted already")
            && said.contains("Connected: the server accepts this agent"),
        "{said}"
    );

    // 3. The bus: certificates, keys and trust.
    desk.run(&b[2], &b[2].text);

    // 4. Discover: the whole configuration.
    desk.run(&b[3], &b[3].text.replace(PLC, &endpoint));
    let config_path = desk.dir.join("press7.toml");
    let discovered = std::fs::read_to_string(&config_path).unwrap();
    assert!(discovered.contains("id = \"press7\""), "{discovered}");
    assert!(!discovered.contains("plain"), "{discovered}");

    // 5. The program and its I/O list beside the configuration; `sf`; the
    // checks added at its end.
    for f in ["ese.il", "ese-comments.csv"] {
        std::fs::copy(root().join("config/cnc").join(f), desk.dir.join(f)).unwrap();
    }
    let sf = desk.run(&b[4], &b[4].text);
    assert!(sf.starts_with("G8.02  (ese.il, 6 step blocks"), "{sf}");
    assert!(sf.contains("X0.06     Y Over Travel Limit SW (B)"), "{sf}");
    let mut config = discovered + "\n" + &b[5].text;
    std::fs::write(&config_path, &config).unwrap();
    // What discover wrote, with the checks, is valid as it is.
    let (validate, run) = b[6].text.trim().split_once('\n').unwrap();
    assert_eq!(validate, "cellwatch validate press7.toml");
    let checked = desk.run(&b[6], validate);
    assert!(checked.contains("cell press7"), "{checked}");
    // The test's own change: ports of its own.
    let listen = "listen = [\"quic/127.0.0.1:7447\"]";
    assert!(config.contains(listen), "{config}");
    config = config.replace(listen, "listen = [\"quic/127.0.0.1:0\"]")
        + "\n[metrics]\nlisten = \"127.0.0.1:0\"\n";
    std::fs::write(&config_path, &config).unwrap();

    // 6. Validate and run.
    desk.run(&b[6], validate);
    let (_agent, agent_log) = desk.spawn(run);
    let (locator, metrics) = wait_for(&agent_log, "`agent running` line", |l| {
        let field = |name: &str| {
            l.split(name)
                .nth(1)
                .and_then(|r| r.split([' ', ',']).next())
                .map(str::to_string)
        };
        (l.contains("agent running") && l.contains("cell=\"press7\""))
            .then(|| (field("zenoh=").unwrap(), field("metrics=").unwrap()))
    });
    // The machine runs before its faults: the agent has read every tag.
    tags_known(&metrics);

    // 7. The first alarms: follow, then the spindle runs hot, spindle 1
    // leaves automatic, the Y axis runs onto its limit switch.
    let with_connect = |script: &str| {
        let script = script.replace(
            "--trust trust.toml\"",
            &format!("--trust trust.toml --connect {locator}\""),
        );
        assert!(script.contains("--connect"), "{script}");
        script
    };
    let follow = with_connect(&b[7].text);
    let (_follow, alarms) = desk.spawn(&follow);
    // The alarms as the quickstart prints them, but for their time.
    let expected: Vec<&str> = b[8].text.lines().collect();
    assert_eq!(expected.len(), 5, "{expected:?}");
    let without_time = |l: &str| l.split_once("  ").map(|(_, r)| r.to_string());
    let mut raised = |event: &str, alarm: &str| {
        writeln!(plc_input, "{event}").unwrap();
        plc_input.flush().unwrap();
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            wait_for(&alarms, alarm, |l| {
                l.contains(&format!("press7/{alarm}  raised"))
                    .then(|| l.to_string())
            })
        }))
        .unwrap_or_else(|e| {
            // What the agent said meanwhile, to tell why.
            let said: Vec<String> = agent_log.try_iter().collect();
            panic!(
                "{}\nthe agent said:\n{}\nthe simulator: {:?}, its log:\n{}",
                e.downcast_ref::<String>().map_or("", String::as_str),
                said.join("\n"),
                sim.child.try_wait(),
                std::fs::read_to_string(desk.dir.join("sim.log")).unwrap_or_default()
            )
        })
    };
    let limit = raised("temp 92.5", "spindle-temp-h");
    assert_eq!(without_time(&limit), without_time(expected[0]));
    let discrete = raised("set X0.0D 0", "spindle1-auto");
    assert_eq!(without_time(&discrete), without_time(expected[1]));
    assert_eq!(alarms.recv_timeout(PATIENCE).unwrap(), expected[2]);
    let diagnosed = raised("set X0.06 0", "ese");
    assert_eq!(without_time(&diagnosed), without_time(expected[3]));
    assert_eq!(alarms.recv_timeout(PATIENCE).unwrap(), expected[4]);

    // Then: history and the signed acknowledgement.
    let bus_line = b[7].text.lines().next().unwrap();
    let (history, ack) = b[9].text.trim().split_once('\n').unwrap();
    let rows = desk.run(&b[9], &with_connect(&format!("{bus_line}\n{history}")));
    assert!(rows.contains("ese"), "{rows}");
    let acked = desk.run(&b[9], &with_connect(&format!("{bus_line}\n{ack}")));
    assert!(acked.starts_with("accepted"), "{acked}");

    // 8. The alarm system's figures of the day: the three alarms (unless
    // the day ended between them and the report, just after midnight UTC).
    let report = desk.run(&b[10], &b[10].text);
    let same_day = [&limit, &discrete, &diagnosed]
        .iter()
        .all(|l| report.starts_with(&format!("alarm performance {} ", &l[..10])));
    if same_day {
        assert!(report.contains(": 3 alarms in "), "{report}");
        for id in ["ese", "spindle-temp-h", "spindle1-auto"] {
            assert!(report.contains(&format!("\n  {id} ")), "{id}: {report}");
        }
    }
    assert!(
        report.contains("10-min intervals in flood (> 10, until < 5)"),
        "{report}"
    );

    writeln!(plc_input, "quit").unwrap();
    let _ = sim.child.wait();
}
