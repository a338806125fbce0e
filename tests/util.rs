//! Helpers shared by the integration tests: run the binary, make files.

use std::path::{Path, PathBuf};
use std::process::Command;

/// What one run of the binary did.
pub(crate) struct Run {
    pub(crate) code: i32,
    pub(crate) stdout: String,
    pub(crate) stderr: String,
}

/// The repository root, where `config/` is.
pub(crate) fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

/// Runs `cellwatch ARGS` from the repository root.
pub(crate) fn cellwatch(args: &[&str]) -> Run {
    let out = Command::new(env!("CARGO_BIN_EXE_cellwatch"))
        .args(args)
        .current_dir(root())
        .output()
        .unwrap();
    Run {
        code: out.status.code().unwrap_or(-1),
        stdout: String::from_utf8(out.stdout).unwrap(),
        stderr: String::from_utf8(out.stderr).unwrap(),
    }
}

/// A temporary directory holding files written by a test.
pub(crate) struct Dir(tempfile::TempDir);

impl Dir {
    pub(crate) fn new() -> Dir {
        Dir(tempfile::tempdir().unwrap())
    }

    /// The directory.
    pub(crate) fn path(&self) -> &Path {
        self.0.path()
    }

    /// Writes `name` with `bytes` and returns its path as a string.
    pub(crate) fn file(&self, name: &str, bytes: impl AsRef<[u8]>) -> String {
        let p = self.0.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        p.to_str().unwrap().to_string()
    }
}

/// A plant CA and certificates for `names` in `dir/pki-bus`, where the
/// shipped configurations look for them; existing ones are kept.
pub(crate) fn bus_pki(dir: &Path, names: &[&str]) {
    use cellwatch::bus::certs;
    let pki = dir.join("pki-bus");
    certs::make_ca(&pki, "test plant CA").unwrap();
    for name in names {
        if !certs::cert_files(&pki, name).0.exists() {
            certs::issue(&pki, name, &["localhost".into(), "127.0.0.1".into()]).unwrap();
        }
    }
}

/// The TLS files of `name` in `dir/pki-bus`.
pub(crate) fn bus_tls(dir: &Path, name: &str) -> cellwatch::config::ZenohTls {
    let pki = dir.join("pki-bus");
    let (cert, key) = cellwatch::bus::certs::cert_files(&pki, name);
    cellwatch::config::ZenohTls {
        ca: pki.join("ca.pem"),
        cert,
        key,
    }
}

/// A client session (peer) of operator `name`'s certificate to `port`.
pub(crate) async fn operator_session(dir: &Path, name: &str, port: u16) -> zenoh::Session {
    bus_pki(dir, &[name]);
    cellwatch::bus::open(&client_config(dir, name, port))
        .await
        .unwrap()
}

/// A client configuration with `name`'s certificate, to `port`.
pub(crate) fn client_config(dir: &Path, name: &str, port: u16) -> cellwatch::config::ZenohConfig {
    cellwatch::config::ZenohConfig {
        mode: cellwatch::config::ZenohMode::Peer,
        connect: vec![format!("quic/127.0.0.1:{port}")],
        listen: vec![],
        prefix: String::new(),
        multicast_scouting: false,
        tls: Some(bus_tls(dir, name)),
        config_file: None,
        plain: false,
        signing_key: None,
    }
}

/// The CLI flags that reach `port` as operator `name`, trusting the
/// agents whose signing keys are in `dir` ([`trust_file`]).
pub(crate) fn bus_args(dir: &Path, name: &str, port: u16) -> Vec<String> {
    let tls = bus_tls(dir, name);
    vec![
        "--trust".into(),
        trust_file(dir).display().to_string(),
        "--connect".into(),
        format!("quic/127.0.0.1:{port}"),
        "--tls-ca".into(),
        tls.ca.display().to_string(),
        "--tls-cert".into(),
        tls.cert.display().to_string(),
        "--tls-key".into(),
        tls.key.display().to_string(),
    ]
}

/// Writes `dir/trust.toml`, the plant trust file of every agent whose
/// signing key (`*.agent.key`, made by the agent at its first start next to
/// its configuration) is in `dir` or a folder in it, and returns its path.
pub(crate) fn trust_file(dir: &Path) -> PathBuf {
    let mut entries = String::new();
    let mut folders = vec![dir.to_path_buf()];
    while let Some(folder) = folders.pop() {
        for entry in std::fs::read_dir(&folder).unwrap().map_while(Result::ok) {
            let path = entry.path();
            if path.is_dir() {
                folders.push(path);
            } else if path.to_string_lossy().ends_with(".agent.key") {
                let key = cellwatch::bus::envelope::AgentKey::load(&path).unwrap();
                entries += &key.trust_entry();
            }
        }
    }
    let path = dir.join("trust.toml");
    std::fs::write(&path, entries).unwrap();
    path
}

/// The plant trust of the agents whose keys are in `dir` ([`trust_file`]).
pub(crate) fn trust(dir: &Path) -> cellwatch::bus::envelope::Trust {
    cellwatch::bus::envelope::Trust::load(&trust_file(dir)).unwrap()
}

/// The body of a signed envelope as it arrived (a test that checks the
/// signature itself uses [`trust`]).
pub(crate) fn opened(payload: &zenoh::bytes::ZBytes) -> String {
    let env: serde_json::Value = serde_json::from_slice(&payload.to_bytes())
        .unwrap_or_else(|e| panic!("not a signed envelope: {e}"));
    assert!(
        env["schema"] == "cellwatch.signed.v1" || env["schema"] == "cellwatch.signed.v2",
        "{env}"
    );
    env["body"].as_str().unwrap().to_string()
}

/// The body of a signed envelope, or the payload as text when it is not
/// one (Zenoh's own error answers, an impostor's forgeries).
pub(crate) fn opened_or_raw(payload: &zenoh::bytes::ZBytes) -> String {
    let bytes = payload.to_bytes();
    serde_json::from_slice::<serde_json::Value>(&bytes)
        .ok()
        .filter(|env| {
            env["schema"] == "cellwatch.signed.v1" || env["schema"] == "cellwatch.signed.v2"
        })
        .and_then(|env| Some(env["body"].as_str()?.to_string()))
        .unwrap_or_else(|| String::from_utf8_lossy(&bytes).into_owned())
}

/// A loopback port for a server given its port on its command line, which
/// it keeps across a restart (the node-opcua server). It is taken below the
/// system's ephemeral range, which port 0 and outgoing connections draw
/// from, so nothing else in the suite can be handed it while the server is
/// down; distinct within this process; free when chosen.
pub(crate) fn restartable_port() -> u16 {
    use std::sync::atomic::{AtomicU32, Ordering};
    static NEXT: AtomicU32 = AtomicU32::new(0);
    let ephemeral = std::fs::read_to_string("/proc/sys/net/ipv4/ip_local_port_range")
        .ok()
        .and_then(|r| r.split_whitespace().next()?.parse::<u32>().ok())
        .unwrap_or(32768);
    let (low, span) = (10_000, ephemeral.saturating_sub(10_000).max(1_000));
    // Another process running this suite starts elsewhere in the range.
    let start = std::process::id() * 7919 % span;
    loop {
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        assert!(n < span, "no free port below {ephemeral}");
        let port = (low + (start + n) % span) as u16;
        if std::net::TcpListener::bind(("127.0.0.1", port)).is_ok() {
            return port;
        }
    }
}

/// The port of the first `quic/` locator among `locators` (what a session
/// told to listen on port 0 was given).
pub(crate) fn tls_port(locators: &[String]) -> u16 {
    locators
        .iter()
        .find_map(|l| l.strip_prefix("quic/")?.rsplit(':').next()?.parse().ok())
        .unwrap_or_else(|| panic!("no quic/ locator among {locators:?}"))
}

/// The port `agent`'s Zenoh session listens on.
pub(crate) async fn agent_port(agent: &cellwatch::agent::Agent) -> u16 {
    tls_port(&agent.zenoh_locators().await)
}

/// The port a Zenoh `session` listens on (a router's).
pub(crate) async fn session_port(session: &zenoh::Session) -> u16 {
    let locators: Vec<String> = session
        .info()
        .locators()
        .await
        .iter()
        .map(ToString::to_string)
        .collect();
    tls_port(&locators)
}

/// The lines a child writes on its piped standard output, as they come.
pub(crate) fn lines_of(child: &mut std::process::Child) -> std::sync::mpsc::Receiver<String> {
    use std::io::BufRead;
    let (tx, lines) = std::sync::mpsc::channel();
    let stdout = child.stdout.take().expect("stdout piped");
    std::thread::spawn(move || {
        // Read to the end even once nobody listens: a child whose standard
        // output stopped being read dies of a broken pipe at its next line
        // (the simulator did, once its endpoint had been read and the
        // receiver dropped, when it said a fault was set).
        for line in std::io::BufReader::new(stdout)
            .lines()
            .map_while(Result::ok)
        {
            let _ = tx.send(line);
        }
    });
    lines
}

/// A `/metrics` scrape over HTTP.
pub(crate) async fn scrape(addr: std::net::SocketAddr) -> String {
    let (status, body) = http_get(addr, "/metrics").await;
    assert_eq!(status, 200, "{body}");
    body
}

/// `GET path` over plain HTTP/1.1: the status and the body.
pub(crate) async fn http_get(addr: std::net::SocketAddr, path: &str) -> (u16, String) {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
    s.write_all(
        format!("GET {path} HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n").as_bytes(),
    )
    .await
    .unwrap();
    let mut answer = String::new();
    s.read_to_string(&mut answer).await.unwrap();
    http_answer(&answer)
}

/// An HTTP/1.1 answer read to its end: the status and the body.
pub(crate) fn http_answer(answer: &str) -> (u16, String) {
    let status = answer
        .strip_prefix("HTTP/1.1 ")
        .and_then(|r| r.get(..3)?.parse().ok())
        .unwrap_or_else(|| panic!("not an HTTP answer: {answer}"));
    let body = answer
        .split_once("\r\n\r\n")
        .map_or("", |(_, b)| b)
        .to_string();
    (status, body)
}

/// `cellwatch report daily --json` for today (UTC) over `journal`, with
/// the shipped stop causes.
pub(crate) fn todays_report(journal: &Path) -> serde_json::Value {
    daily_report(journal, &chrono::Utc::now().format("%Y-%m-%d").to_string())
}

/// `cellwatch report daily --json` for `day` (UTC) over `journal`, with
/// the shipped stop causes.
pub(crate) fn daily_report(journal: &Path, day: &str) -> serde_json::Value {
    let causes = root().join("config/stop-causes.toml");
    let r = cellwatch(&[
        "report",
        "daily",
        "--date",
        day,
        "--db",
        journal.to_str().unwrap(),
        "--causes",
        causes.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    serde_json::from_str(&r.stdout).unwrap()
}

/// Waits until the journal at `db` has a row of `table` stamped `at`
/// (each scripted change of a simulated day leaves one).
pub(crate) async fn row_at(
    committed: &mut tokio::sync::watch::Receiver<u64>,
    db: &std::path::Path,
    table: &str,
    at: u64,
) {
    loop {
        let n: i64 = rusqlite::Connection::open(db)
            .unwrap()
            .query_row(
                &format!("SELECT count(*) FROM {table} WHERE at_ms = ?1"),
                [at as i64],
                |r| r.get(0),
            )
            .unwrap();
        if n > 0 {
            return;
        }
        tokio::time::timeout(std::time::Duration::from_secs(60), committed.changed())
            .await
            .unwrap_or_else(|_| {
                let c = rusqlite::Connection::open(db).unwrap();
                let mut st = c.prepare(&format!("SELECT * FROM {table}")).unwrap();
                let n = st.column_count();
                let rows: Vec<String> = st
                    .query_map([], |r| {
                        Ok((0..n)
                            .map(|i| format!("{:?}", r.get_ref(i).unwrap()))
                            .collect::<Vec<_>>()
                            .join(","))
                    })
                    .unwrap()
                    .map(|r| r.unwrap())
                    .collect();
                panic!("no {table} row at {at} in {}: {rows:?}", db.display())
            })
            .unwrap();
    }
}

/// The agent of `config` (its key pair made now) and the simulated PLC
/// whose PKI is `sim_pki` trust each other, certificate by certificate.
pub(crate) fn trust_sim(config: &cellwatch::config::CellConfig, sim_pki: &Path) {
    use cellwatch::sources::{opcua, pki};
    let ua = config.opcua.as_ref().unwrap();
    drop(opcua::client(&config.cell, ua).unwrap());
    pki::trust(&pki::own_cert(&ua.pki_dir), sim_pki).unwrap();
    pki::trust(&pki::own_cert(sim_pki), &ua.pki_dir).unwrap();
}

/// Installs the Debian packages whose files are missing (`(file,
/// package)`), with apt-get (root needed), once per process at a time;
/// apt-get waits for another's lock.
pub(crate) fn debian_packages(wanted: &[(&str, &str)]) {
    use std::process::Command;
    static APT: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _one = APT
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let missing: Vec<&str> = wanted
        .iter()
        .filter(|(file, _)| !Path::new(file).exists())
        .map(|(_, package)| *package)
        .collect();
    if missing.is_empty() {
        return;
    }
    let install = || {
        Command::new("apt-get")
            .args([
                "-o",
                "DPkg::Lock::Timeout=600",
                "install",
                "-y",
                "--no-install-recommends",
            ])
            .args(&missing)
            .env("DEBIAN_FRONTEND", "noninteractive")
            .output()
            .expect("apt-get is needed to install what the tests run")
    };
    let mut out = install();
    if !out.status.success() {
        // A fresh machine's package lists may be missing or stale.
        let update = Command::new("apt-get")
            .args(["-o", "DPkg::Lock::Timeout=600", "update"])
            .output()
            .unwrap();
        assert!(
            update.status.success(),
            "apt-get update failed:\n{}",
            String::from_utf8_lossy(&update.stderr)
        );
        out = install();
    }
    assert!(
        out.status.success(),
        "installing {missing:?} failed (root needed):\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// A journal observer that notes nothing (journals written by tests).
pub(crate) struct NoCommits;

impl cellwatch::journal::CommitObserver for NoCommits {
    fn committed(&self, _: usize, _: std::time::Duration) {}
    fn failed(&self, _: &str) {}
}

/// A Python 3 that can `import module`: the machine's, or one in a virtual
/// environment `target/py-NAME` that this makes once, with `pip install
/// packages` (pinned versions, so every run gets the same stack). One
/// installation at a time in this process.
pub(crate) fn python_with(name: &str, module: &str, packages: &[&str]) -> PathBuf {
    static PIP: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _one = PIP
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let has = |python: &Path| {
        Command::new(python)
            .args(["-c", &format!("import {module}")])
            .output()
            .is_ok_and(|o| o.status.success())
    };
    let venv = root().join("target").join(format!("py-{name}"));
    let python = venv.join("bin/python3");
    if has(&python) {
        return python;
    }
    let run = |cmd: &mut Command| {
        let out = cmd.output().unwrap();
        assert!(
            out.status.success(),
            "{cmd:?} failed:\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
    };
    run(Command::new("python3").args(["-m", "venv"]).arg(&venv));
    run(Command::new(&python)
        .args(["-m", "pip", "install", "--quiet"])
        .args(packages));
    python
}
