//! The quickstart (`docs/quickstart.md`) run end to end, as a plant
//! engineer follows it: its fenced blocks, in order, run by a shell in an
//! empty directory with the built `cellwatch` first on `PATH`, against the
//! simulated CNC in place of the PLC at `opc.tcp://192.168.10.7:4840/`.
//!
//! What the test changes, and only that: the PLC's endpoint becomes the
//! simulator's; the bus and metrics listen on port 0 (two runs on one
//! machine never collide), and the bus clients are told where the agent
//! listens (`--connect`); the fault is made on the simulator's standard
//! input (`set X0.06 0`) where the quickstart says "open the limit switch".
//! Everything else — the certificate exchange, `discover`, `sf`, the
//! check, `pki`, `keygen`, `validate`, `run`, `alarms --follow`, the alarm
//! as printed, `history`, `ack` — is the page's own text, and a change of
//! the page's blocks fails here until this test follows it.

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
    fn sh(&self, script: &str) -> Output {
        Command::new("sh")
            .arg("-c")
            .arg(script)
            .current_dir(&self.dir)
            .env("PATH", &self.path)
            .output()
            .unwrap()
    }

    /// Runs `block`'s commands; each must succeed.
    fn run(&self, block: &Block, script: &str) -> String {
        let out = self.sh(&format!("set -e\n{script}"));
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

fn files_in(dir: &Path) -> Vec<PathBuf> {
    std::fs::read_dir(dir)
        .map(|d| d.map_while(Result::ok).map(|e| e.path()).collect())
        .unwrap_or_default()
}

#[test]
fn the_quickstart_runs_end_to_end() {
    let page = std::fs::read_to_string(root().join("docs/quickstart.md")).unwrap();
    let b = blocks(&page);
    let langs: Vec<&str> = b.iter().map(|b| b.lang.as_str()).collect();
    assert_eq!(
        langs,
        ["sh", "sh", "sh", "sh", "toml", "sh", "toml", "sh", "sh", "text", "sh"],
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

    // 2. OPC UA certificates. The first connection makes the agent's key
    // pair and is refused: the PLC does not know it yet.
    let (sim, _, endpoint) = desk.simulator(&[]);
    let discover = b[1].text.replace(PLC, &endpoint);
    assert!(!desk.sh(&discover).status.success(), "{discover}");
    assert!(desk.dir.join("pki/own/cert.der").exists());
    // "For the simulator: `cellwatch simulate cnc --trust pki/own/cert.der`".
    assert!(page.contains("`cellwatch simulate cnc --trust pki/own/cert.der`"));
    drop(sim);
    let (mut sim, mut plc_input, endpoint) = desk.simulator(&["pki/own/cert.der"]);
    let discover = b[1].text.replace(PLC, &endpoint);
    assert!(!desk.sh(&discover).status.success(), "{discover}");
    // "The PLC's certificate is now in pki/rejected/: ... move it to
    // pki/trusted/."
    let rejected = files_in(&desk.dir.join("pki/rejected"));
    assert_eq!(rejected.len(), 1, "{rejected:?}");
    let name = rejected[0].file_name().unwrap();
    std::fs::rename(&rejected[0], desk.dir.join("pki/trusted").join(name)).unwrap();

    // 3. Discover the tags; set [cell] id = "press7".
    desk.run(&b[2], &b[2].text.replace(PLC, &endpoint));
    let config_path = desk.dir.join("press7.toml");
    let discovered = std::fs::read_to_string(&config_path).unwrap();
    assert!(discovered.contains("id = \"new-cell\""), "{discovered}");
    let mut config = discovered.replace("id = \"new-cell\"", "id = \"press7\"");

    // 4. The program and its I/O list beside the configuration; `sf`; the
    // check added.
    for f in ["ese.il", "ese-comments.csv"] {
        std::fs::copy(root().join("config/cnc").join(f), desk.dir.join(f)).unwrap();
    }
    let sf = desk.run(&b[3], &b[3].text);
    assert!(sf.starts_with("G8.02  (ese.il, 6 step blocks"), "{sf}");
    assert!(sf.contains("X0.06     Y Over Travel Limit SW (B)"), "{sf}");
    config += "\n";
    config += &b[4].text;

    // 5. The bus: certificates, keys and trust; the [zenoh] section that
    // `discover` wrote replaced.
    desk.run(&b[5], &b[5].text);
    let at = config.find("[zenoh]\n").expect("discover writes [zenoh]");
    let end = config[at + 1..]
        .find("\n[")
        .map_or(config.len(), |e| at + 1 + e + 1);
    assert!(
        config[at..end].contains("plain = true"),
        "{}",
        &config[at..end]
    );
    let bus = b[6].text.replace("quic/127.0.0.1:7447", "quic/127.0.0.1:0");
    config = format!(
        "{}{}{bus}\n[metrics]\nlisten = \"127.0.0.1:0\"\n",
        &config[..at],
        &config[end..]
    );
    std::fs::write(&config_path, &config).unwrap();

    // 6. Validate and run.
    let (validate, run) = b[7].text.trim().split_once('\n').unwrap();
    assert_eq!(validate, "cellwatch validate press7.toml");
    let checked = desk.run(&b[7], validate);
    assert!(checked.contains("cell press7"), "{checked}");
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
    // The machine runs before its fault: the agent has read every tag.
    tags_known(&metrics);

    // 7. The first diagnosed alarm: follow, then open the limit switch.
    let with_connect = |script: &str| {
        let script = script.replace(
            "--trust trust.toml\"",
            &format!("--trust trust.toml --connect {locator}\""),
        );
        assert!(script.contains("--connect"), "{script}");
        script
    };
    let follow = with_connect(&b[8].text);
    let (_follow, alarms) = desk.spawn(&follow);
    writeln!(plc_input, "set X0.06 0").unwrap();
    plc_input.flush().unwrap();
    // The alarm as the quickstart prints it, but for its time.
    let expected: Vec<&str> = b[9].text.lines().collect();
    let without_time = |l: &str| l.split_once("  ").map(|(_, r)| r.to_string());
    let raised = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        wait_for(&alarms, "raised ese alarm", |l| {
            l.contains("press7/ese  raised").then(|| l.to_string())
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
    });
    assert_eq!(without_time(&raised), without_time(expected[0]));
    let culprit = alarms.recv_timeout(PATIENCE).unwrap();
    assert_eq!(culprit, expected[1]);

    // Then: history and the signed acknowledgement.
    let bus_line = b[8].text.lines().next().unwrap();
    let (history, ack) = b[10].text.trim().split_once('\n').unwrap();
    let rows = desk.run(&b[10], &with_connect(&format!("{bus_line}\n{history}")));
    assert!(rows.contains("ese"), "{rows}");
    let acked = desk.run(&b[10], &with_connect(&format!("{bus_line}\n{ack}")));
    assert!(acked.starts_with("accepted"), "{acked}");

    writeln!(plc_input, "quit").unwrap();
    let _ = sim.child.wait();
}
