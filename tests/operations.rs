//! Running the agent like plant infrastructure:
//! - `/healthz` and `/readyz` on the metrics port tell the truth across a
//!   PLC outage, a journal another process holds, and a cell loop stuck in
//!   a step;
//! - `cellwatch run` speaks systemd's notify protocol (`READY=1`,
//!   `WATCHDOG=1`, `STOPPING=1`) to a real datagram socket, as systemd
//!   would hear it;
//! - the Debian package (cargo-deb, `deploy/build-deb`) installs into a
//!   root of its own, user and man pages included, and its systemd unit
//!   passes `systemd-analyze verify` there;
//! - `cellwatch journal backup` copies a journal its agent is writing.

use std::sync::Arc;
use std::time::Duration;

use cellwatch::cell::CellStep;
use cellwatch::sinks::Sink;
use cellwatch::sources::scripted::ScriptedSource;
use cellwatch::sources::SourceEvent;
use futures_util::future::BoxFuture;
use futures_util::FutureExt;
use tokio::sync::watch;

use crate::util::{http_get, root};

/// Asks `path` until its status is `status` and its body contains each of
/// `says`; the last answer.
async fn answers(addr: std::net::SocketAddr, path: &str, status: u16, says: &[&str]) -> String {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(60);
    loop {
        let (got, body) = http_get(addr, path).await;
        if got == status && says.iter().all(|s| body.contains(s)) {
            return body;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "{path} never answered {status} with {says:?}; last: {got} {body}"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn health_and_readiness_tell_the_truth_across_a_plc_outage_and_a_held_journal() {
    let mut fx = crate::agent::Fixture::start().await;
    let addr = fx.agent().metrics_addr().unwrap();
    fx.settled().await;
    let ready = answers(addr, "/readyz", 200, &["ready\n"]).await;
    assert!(
        ready.contains("cell m01ps0004: source connected (opc.tcp://")
            && ready.contains("journal writable")
            && ready.contains("bus session up"),
        "{ready}"
    );
    let alive = answers(addr, "/healthz", 200, &["ok\n"]).await;
    assert!(
        alive.contains("cell m01ps0004: the cell loop went round"),
        "{alive}"
    );

    // The PLC goes away: not ready, saying why; still alive.
    fx.sim.stop();
    answers(
        addr,
        "/readyz",
        503,
        &["not ready\n", "cell m01ps0004: source not connected"],
    )
    .await;
    answers(addr, "/healthz", 200, &["ok\n"]).await;
    fx.restart_sim().await;
    answers(addr, "/readyz", 200, &["ready\n", "source connected"]).await;

    // Another process holds the journal's write lock: the next rows
    // cannot be written, and readiness says so; released, ready again.
    fx.settled().await;
    let lock = rusqlite::Connection::open(fx.journal_path()).unwrap();
    lock.execute_batch("BEGIN EXCLUSIVE").unwrap();
    fx.sim.set("X0.06", false).unwrap();
    let held = answers(
        addr,
        "/readyz",
        503,
        &["not ready\n", "journal cannot write: "],
    )
    .await;
    assert!(held.contains("locked"), "{held}");
    answers(addr, "/healthz", 200, &["ok\n"]).await;
    lock.execute_batch("ROLLBACK").unwrap();
    drop(lock);
    answers(addr, "/readyz", 200, &["ready\n", "journal writable"]).await;
    fx.stop().await;
    fx.sim.stop();
}

/// A sink of the test's own that, once told, holds the cell loop inside a
/// step until told again: a loop stuck in a step.
struct Holds(watch::Receiver<bool>);

impl Sink for Holds {
    fn name(&self) -> &'static str {
        "holds"
    }

    fn handle<'a>(&'a mut self, _step: &'a CellStep) -> BoxFuture<'a, ()> {
        async move {
            let _ = self.0.wait_for(|hold| !*hold).await;
        }
        .boxed()
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_cell_loop_stuck_in_a_step_fails_healthz_and_its_source_says_not_ready() {
    let d = tempfile::tempdir().unwrap();
    let config = crate::agent::config(d.path(), "opc.tcp://127.0.0.1:1");
    let (source, script) = ScriptedSource::new();
    let (hold, held) = watch::channel(false);
    let agent = cellwatch::agent::start_with(
        config,
        cellwatch::agent::Options {
            source: Some(Box::new(source)),
            sinks: vec![Box::new(Holds(held))],
            ..Default::default()
        },
    )
    .await
    .unwrap();
    let addr = agent.metrics_addr().unwrap();
    // Before the source has said anything, the cell is not ready.
    answers(
        addr,
        "/readyz",
        503,
        &["cell m01ps0004: source not connected yet"],
    )
    .await;
    script
        .send(SourceEvent::Connected("scripted".into()))
        .await
        .unwrap();
    answers(addr, "/readyz", 200, &["source connected (scripted)"]).await;
    answers(addr, "/healthz", 200, &["ok\n"]).await;
    // The next step holds the loop.
    hold.send(true).unwrap();
    script
        .send(SourceEvent::Disconnected("cable pulled".into()))
        .await
        .unwrap();
    let stuck = answers(
        addr,
        "/healthz",
        503,
        &[
            "not ok\n",
            "cell m01ps0004: the cell loop has made no progress for ",
        ],
    )
    .await;
    assert!(!stuck.contains("went round"), "{stuck}");
    // Let go: it goes round again.
    hold.send(false).unwrap();
    answers(addr, "/healthz", 200, &["ok\n"]).await;
    answers(
        addr,
        "/readyz",
        503,
        &["source not connected: cable pulled"],
    )
    .await;
    agent.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn run_tells_systemd_it_is_ready_feeds_the_watchdog_and_says_it_stops() {
    let d = tempfile::tempdir().unwrap();
    let (sim, mut cell) = crate::spawned::start(d.path()).await;
    // systemd's side: a datagram socket named by NOTIFY_SOCKET.
    let socket_path = d.path().join("notify.sock");
    let socket = Arc::new(tokio::net::UnixDatagram::bind(&socket_path).unwrap());
    cell.env = vec![
        ("NOTIFY_SOCKET".into(), socket_path.to_str().unwrap().into()),
        ("WATCHDOG_USEC".into(), "2000000".into()),
    ];
    cell.watchdog_pid = true;
    let child = cell.spawn("agent.log").await;
    let mut heard = Vec::new();
    let next = async |heard: &mut Vec<String>| {
        let mut buf = vec![0; 4096];
        let n = tokio::time::timeout(Duration::from_secs(30), socket.recv(&mut buf))
            .await
            .unwrap_or_else(|_| panic!("systemd heard nothing more after {heard:?}"))
            .unwrap();
        let message = String::from_utf8_lossy(&buf[..n]).to_string();
        heard.push(message.clone());
        message
    };
    let first = next(&mut heard).await;
    assert!(
        first.lines().any(|l| l == "READY=1")
            && first.lines().any(|l| l == "STATUS=watching m01ps0004"),
        "{first:?}"
    );
    // Fed while the loop goes round (every half second for a 2 s watchdog).
    for _ in 0..3 {
        assert_eq!(next(&mut heard).await.trim_end(), "WATCHDOG=1", "{heard:?}");
    }
    let metrics: std::net::SocketAddr = ([127, 0, 0, 1], cell.metrics_port).into();
    answers(
        metrics,
        "/healthz",
        200,
        &["cell m01ps0004: the cell loop went round"],
    )
    .await;
    crate::robust::sigterm(&child);
    loop {
        if next(&mut heard).await.trim_end() == "STOPPING=1" {
            break;
        }
    }
    assert_eq!(
        crate::robust::exit_code(child).await,
        Some(0),
        "{}",
        cell.log("agent.log")
    );
    assert!(
        cell.log("agent.log")
            .contains("feeding systemd's watchdog while every cell loop goes round"),
        "{}",
        cell.log("agent.log")
    );
    sim.stop();
}

/// cargo-deb at the version `deploy/build-deb` names, installed unless
/// there.
fn cargo_deb() {
    use std::process::Command;
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let there = Command::new("cargo")
            .args(["deb", "--version"])
            .output()
            .is_ok_and(|o| {
                o.status.success() && String::from_utf8_lossy(&o.stdout).contains("3.8.0")
            });
        if !there {
            let out = Command::new("cargo")
                .args(["install", "cargo-deb", "--locked", "--version", "3.8.0"])
                .output()
                .unwrap();
            assert!(
                out.status.success(),
                "installing cargo-deb failed:\n{}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
    });
}

#[test]
fn the_deb_installs_and_its_unit_passes_systemd_analyze_verify() {
    use std::process::Command;
    cargo_deb();
    let d = tempfile::tempdir().unwrap();
    let deb = d.path().join("cellwatch.deb");
    // The dev build the tests run, packaged as the release one is.
    let build = Command::new(root().join("deploy/build-deb"))
        .args(["--dev", "--no-build", "--fast", "--output"])
        .arg(&deb)
        .output()
        .unwrap();
    assert!(
        build.status.success(),
        "{}",
        String::from_utf8_lossy(&build.stderr)
    );
    // Installed into a root of its own, its scripts run as dpkg runs them
    // there (DPKG_ROOT).
    let r = d.path().join("root");
    for dir in [
        "var/lib/dpkg/info",
        "var/lib/dpkg/updates",
        "var/lib/dpkg/triggers",
        "etc",
    ] {
        std::fs::create_dir_all(r.join(dir)).unwrap();
    }
    std::fs::write(r.join("var/lib/dpkg/status"), "").unwrap();
    let install = Command::new("dpkg")
        .arg(format!("--root={}", r.display()))
        .args([
            "--force-script-chrootless",
            "--force-depends",
            "--log=/dev/null",
            "-i",
        ])
        .arg(&deb)
        .output()
        .unwrap();
    assert!(
        install.status.success(),
        "{}{}",
        String::from_utf8_lossy(&install.stdout),
        String::from_utf8_lossy(&install.stderr)
    );
    for file in [
        "usr/bin/cellwatch",
        "usr/lib/systemd/system/cellwatch@.service",
        "usr/lib/systemd/system/cellwatch-router.service",
        "usr/lib/sysusers.d/cellwatch.conf",
        "usr/share/man/man1/cellwatch-router.1.gz",
        "usr/share/man/man1/cellwatch.1.gz",
        "usr/share/man/man1/cellwatch-run.1.gz",
        "usr/share/man/man1/cellwatch-journal-backup.1.gz",
        "usr/share/doc/cellwatch/examples/demo.toml",
        "usr/share/doc/cellwatch/examples/cnc/ese.il",
        "usr/share/doc/cellwatch/examples/alertmanager.yml",
        "etc/cellwatch",
    ] {
        assert!(r.join(file).exists(), "{file} not installed");
    }
    let passwd = std::fs::read_to_string(r.join("etc/passwd")).unwrap();
    assert!(
        passwd
            .lines()
            .any(|l| l.starts_with("cellwatch:")
                && l.ends_with(":/var/lib/cellwatch:/usr/sbin/nologin")),
        "{passwd}"
    );
    let version = Command::new(r.join("usr/bin/cellwatch"))
        .arg("--version")
        .output()
        .unwrap();
    assert!(
        String::from_utf8_lossy(&version.stdout).starts_with("cellwatch "),
        "{version:?}"
    );
    // The unit as installed, against the system's own units, with a
    // cell's configuration where it looks for one.
    if Command::new("systemd-analyze")
        .arg("--version")
        .output()
        .is_err()
    {
        eprintln!("systemd-analyze is not on this machine: the unit is not verified here");
        return;
    }
    let units = r.join("usr/lib/systemd/system");
    for dir in ["/usr/lib/systemd/system", "/lib/systemd/system"] {
        let Ok(entries) = std::fs::read_dir(dir) else {
            continue;
        };
        for e in entries.flatten() {
            if e.file_type().is_ok_and(|t| t.is_file()) && !units.join(e.file_name()).exists() {
                let _ = std::fs::copy(e.path(), units.join(e.file_name()));
            }
        }
    }
    std::fs::write(r.join("etc/cellwatch/press-4.toml"), "").unwrap();
    // What the unit runs besides the agent: kill(1), as on the system.
    let kill = std::fs::canonicalize("/bin/kill").unwrap();
    std::fs::copy(&kill, r.join("usr/bin/kill")).unwrap();
    if !r.join("bin").exists() {
        std::os::unix::fs::symlink("usr/bin", r.join("bin")).unwrap();
    }
    // The router's unit too, with a router's configuration.
    std::fs::create_dir_all(r.join("etc/cellwatch/router")).unwrap();
    std::fs::write(r.join("etc/cellwatch/router/router.json5"), "").unwrap();
    for unit in ["cellwatch@press-4.service", "cellwatch-router.service"] {
        let out = Command::new("systemd-analyze")
            .args(["verify", "--man=no"])
            .arg(format!("--root={}", r.display()))
            .arg(unit)
            .output()
            .unwrap();
        let said = String::from_utf8_lossy(&out.stderr);
        assert!(
            out.status.success() && said.trim().is_empty(),
            "{unit}: {said}"
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_journal_backed_up_while_the_agent_writes_is_whole_and_verifies() {
    use crate::spawned::{send, signed};
    use crate::util::cellwatch;
    let fx = crate::agent::Fixture::start().await;
    fx.settled().await;
    let journal = fx.journal_path();
    // Alarms and a signed command, committed before the backup starts.
    for k in 0..6 {
        fx.sim.set("X0.06", k % 2 == 1).unwrap();
        fx.tag_value_is("X0.06", serde_json::json!(k % 2 == 1))
            .await;
    }
    let (ok, detail) = send(
        fx.client(),
        &signed(cellwatch::operator::Action::Ack, "ese"),
    )
    .await;
    assert!(ok, "{detail}");
    let count = |db: &std::path::Path, table: &str| -> i64 {
        let c = rusqlite::Connection::open(db).unwrap();
        c.query_row(&format!("SELECT count(*) FROM {table}"), [], |r| r.get(0))
            .unwrap()
    };
    let events_before = count(&journal, "alarm_events");
    let commands_before = count(&journal, "commands");
    assert!(events_before >= 6 && commands_before >= 1);
    // The agent goes on writing while the copy is made.
    let writing = {
        let sim = fx.sim.clone();
        std::thread::spawn(move || {
            for k in 0..40 {
                sim.set("X0.04", k % 2 == 1).unwrap();
                std::thread::sleep(Duration::from_millis(5));
            }
        })
    };
    let dest = fx.dir().join("backup.sqlite");
    let run = cellwatch(&[
        "journal",
        "backup",
        journal.to_str().unwrap(),
        dest.to_str().unwrap(),
    ]);
    writing.join().unwrap();
    assert_eq!(run.code, 0, "{}", run.stderr);
    assert!(run.stdout.contains("integrity ok"), "{}", run.stdout);
    assert!(count(&dest, "alarm_events") >= events_before);
    assert!(count(&dest, "commands") >= commands_before);
    assert!(!fx.dir().join("backup.sqlite.partial").exists());
    // The copy is a journal: its command rows' chain holds.
    let audit = cellwatch(&["audit", "verify", dest.to_str().unwrap()]);
    assert_eq!(audit.code, 0, "{}{}", audit.stdout, audit.stderr);
    // Never over an existing file.
    let again = cellwatch(&[
        "journal",
        "backup",
        journal.to_str().unwrap(),
        dest.to_str().unwrap(),
    ]);
    assert_eq!(again.code, 2, "{}", again.stderr);
    assert!(again.stderr.contains("exists already"), "{}", again.stderr);
    let mut fx = fx;
    fx.stop().await;
    fx.sim.stop();
}

fn sighup(child: &std::process::Child) {
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(child.id() as i32),
        nix::sys::signal::Signal::SIGHUP,
    )
    .unwrap();
}

/// Waits until the agent's log (`agent.log`) has said `what` `times` times.
async fn logged(cell: &crate::spawned::Cell, what: &str, times: usize) -> String {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(60);
    loop {
        let log = cell.log("agent.log");
        if log.matches(what).count() >= times {
            return log;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "never logged {what:?} {times} times:\n{log}"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// A spawned agent on the simulated CNC (`cellwatch run`, its log in
/// `agent.log`), a client following its alarms, and its emergency stop
/// raised and acknowledged by kim.
struct Acknowledged {
    sim: cellwatch::sim::cnc::SimulatedCnc,
    cell: crate::spawned::Cell,
    child: std::process::Child,
    client: zenoh::Session,
    sub: crate::robust::AlarmSubscriber,
    seen: Vec<cellwatch::payload::AlarmPayload>,
}

impl Acknowledged {
    async fn start(dir: &std::path::Path) -> Acknowledged {
        let (sim, mut cell) = crate::spawned::start(dir).await;
        let child = cell.spawn("agent.log").await;
        let client = cell.client().await;
        let sub = crate::robust::alarms(&client, "m01ps0004").await;
        crate::spawned::snapshot_until(&client, "connected and running", |s| {
            s["connected"] == true && s["state"] == "running"
        })
        .await;
        let mut a = Acknowledged {
            sim,
            cell,
            child,
            client,
            sub,
            seen: Vec::new(),
        };
        a.sim.set("X0.06", false).unwrap();
        a.until("ESE raised", "ese", "raised").await;
        a.ack("ese").await;
        a
    }

    /// Waits for `transition` of alarm `id`.
    async fn until(
        &mut self,
        what: &str,
        id: &str,
        transition: &str,
    ) -> cellwatch::payload::AlarmPayload {
        crate::agent::alarm_until(&self.sub, what, &mut self.seen, |a| {
            a.id == id && a.transition.as_str() == transition
        })
        .await
    }

    /// Kim acknowledges `id`; waits until the bus says so.
    async fn ack(&mut self, id: &str) {
        let (ok, detail) = crate::spawned::send(
            &self.client,
            &crate::spawned::signed(cellwatch::operator::Action::Ack, id),
        )
        .await;
        assert!(ok, "{detail}");
        self.until("acknowledged", id, "acknowledged").await;
    }

    /// SIGTERM: a clean stop.
    async fn stop(self) {
        crate::robust::sigterm(&self.child);
        assert_eq!(
            crate::robust::exit_code(self.child).await,
            Some(0),
            "{}",
            self.cell.log("agent.log")
        );
        self.sim.stop();
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn sighup_takes_a_changed_limit_keeps_acknowledgements_and_refuses_a_bad_file() {
    let d = tempfile::tempdir().unwrap();
    let mut a = Acknowledged::start(d.path()).await;
    // The spindle above its H limit (85 °C), acknowledged too.
    a.sim.set_temperature(90.0).unwrap();
    a.until("the spindle hot", "spindle-temp-h", "raised").await;
    a.ack("spindle-temp-h").await;
    let before_reload = a.seen.len();

    // The limit raised to 95 °C, read again on SIGHUP: the spindle alarm
    // is carried and cleared by the new limit; the emergency stop is
    // carried, still acknowledged by kim.
    let text = std::fs::read_to_string(&a.cell.config).unwrap();
    let raised_limit = text.replace(
        "h = { limit = 85.0, severity = \"high\" }",
        "h = { limit = 95.0, severity = \"high\" }",
    );
    assert_ne!(text, raised_limit);
    std::fs::write(&a.cell.config, &raised_limit).unwrap();
    sighup(&a.child);
    a.until(
        "the spindle alarm cleared by the new limit",
        "spindle-temp-h",
        "cleared",
    )
    .await;
    let log = logged(&a.cell, "configuration read again and taken", 1).await;
    assert!(!log.contains("taken only by a restart"), "{log}");
    let ese = match a.seen[before_reload..]
        .iter()
        .find(|p| p.id == "ese" && p.transition.as_str() == "restored")
    {
        Some(p) => p.clone(),
        None => {
            a.until("the emergency stop carried", "ese", "restored")
                .await
        }
    };
    assert_eq!(ese.state.as_str(), "active_acknowledged");
    assert_eq!(ese.acked_by.as_deref(), Some("kim"));
    // No gap: the source never went away, and nothing was raised anew.
    let snap =
        crate::spawned::snapshot_until(&a.client, "connected", |s| s["connected"] == true).await;
    assert_eq!(
        crate::spawned::alarm(&snap, "ese").unwrap()["acked_by"],
        "kim"
    );
    assert!(
        a.seen[before_reload..]
            .iter()
            .all(|p| p.transition.as_str() != "raised" && p.id != "communication"),
        "{:#?}",
        &a.seen[before_reload..]
    );

    // A file that does not validate: refused with where and why; the
    // running configuration (H at 95 °C) goes on.
    std::fs::write(
        &a.cell.config,
        raised_limit.replace("h = { limit = 95.0,", "h = { limit = \"hot\","),
    )
    .unwrap();
    sighup(&a.child);
    let log = logged(
        &a.cell,
        "the configuration read again is refused, the running one goes on",
        1,
    )
    .await;
    assert!(
        log.contains("cell.toml:") && log.contains("invalid type: string \"hot\", expected f64"),
        "{log}"
    );
    a.sim.set_temperature(97.0).unwrap();
    let again = a
        .until("raised above the running limit", "spindle-temp-h", "raised")
        .await;
    assert!(
        again.message.contains("above the H limit 95 °C"),
        "{}",
        again.message
    );

    // What only a restart changes is said, the rest taken.
    std::fs::write(
        &a.cell.config,
        raised_limit
            .replace("# publish_interval = \"10s\"", "publish_interval = \"7s\"")
            .replace("h = { limit = 95.0,", "h = { limit = 110.0,")
            .replace("hh = { limit = 100.0,", "hh = { limit = 120.0,"),
    )
    .unwrap();
    sighup(&a.child);
    let log = logged(&a.cell, "configuration read again and taken", 2).await;
    a.until("cleared by the 110 °C limit", "spindle-temp-h", "cleared")
        .await;
    assert!(
        log.contains(
            "changed, but taken only by a restart (the running values go on): state.publish_interval"
        ),
        "{log}"
    );
    // Remotely: `cellwatch reload`, signed by an operator allowed
    // `configure`, is answered with what came of it and journaled.
    std::fs::write(
        &a.cell.config,
        raised_limit
            .replace("# publish_interval = \"10s\"", "publish_interval = \"7s\"")
            .replace("h = { limit = 95.0,", "h = { limit = 90.0,"),
    )
    .unwrap();
    let key = d.path().join("kim.key");
    std::fs::write(&key, crate::spawned::kim().to_file()).unwrap();
    let mut args: Vec<String> = [
        "reload",
        "--cell",
        "m01ps0004",
        "--key-file",
        key.to_str().unwrap(),
    ]
    .map(String::from)
    .to_vec();
    args.extend(a.cell.bus_args());
    let run = tokio::task::spawn_blocking(move || {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        crate::util::cellwatch(&args)
    })
    .await
    .unwrap();
    assert_eq!(run.code, 0, "{}{}", run.stdout, run.stderr);
    assert!(
        run.stdout.contains("read again and taken (")
            && run
                .stdout
                .contains("taken only by a restart: state.publish_interval"),
        "{}",
        run.stdout
    );
    // 97 °C is above the 90 °C limit read remotely: raised again.
    a.until(
        "raised above the limit read remotely",
        "spindle-temp-h",
        "raised",
    )
    .await;
    let journal = rusqlite::Connection::open(a.cell.dir.join("journal.sqlite")).unwrap();
    let rows: Vec<(String, String, bool)> = journal
        .prepare(
            "SELECT action, stage, accepted FROM commands WHERE action = 'configure' ORDER BY seq",
        )
        .unwrap()
        .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)))
        .unwrap()
        .map(Result::unwrap)
        .collect();
    assert_eq!(
        rows,
        [
            ("configure".to_string(), "request".to_string(), true),
            ("configure".to_string(), "result".to_string(), true),
        ]
    );
    a.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn sighup_with_a_new_tag_starts_a_source_of_its_own_and_keeps_every_alarm() {
    let d = tempfile::tempdir().unwrap();
    let mut a = Acknowledged::start(d.path()).await;
    a.sim.set_temperature(82.0).unwrap();
    let at = |address: &'static str| {
        move |s: &serde_json::Value| {
            s["tags"]
                .as_array()
                .unwrap()
                .iter()
                .any(|t| t["address"] == address && t["value"] == 82.0)
        }
    };
    crate::spawned::snapshot_until(&a.client, "the spindle at 82 °C", at("D100")).await;
    // A second view of the spindle's temperature, with a limit of its own.
    let text = std::fs::read_to_string(&a.cell.config).unwrap();
    std::fs::write(
        &a.cell.config,
        format!(
            "{text}\n[[tags]]\nname = \"spindle_temperature_2\"\nnode_id = \"ns=2;s=D100\"\naddress = \"D900\"\ntype = \"Double\"\n\n[[checks.limit]]\nid = \"spindle-2\"\ntag = \"D900\"\nunit = \"°C\"\nh = {{ limit = 80.0 }}\n"
        ),
    )
    .unwrap();
    sighup(&a.child);
    let raised = a
        .until("the new tag's limit raised", "spindle-2-h", "raised")
        .await;
    assert!(raised.message.contains("= 82 °C"), "{}", raised.message);
    let log = logged(&a.cell, "configuration read again and taken", 1).await;
    assert!(
        log.contains("starting a source for the configuration read again"),
        "{log}"
    );
    let snap = crate::spawned::snapshot_until(&a.client, "the new tag known", at("D900")).await;
    assert_eq!(snap["connected"], true);
    let ese = crate::spawned::alarm(&snap, "ese").unwrap();
    assert_eq!(ese["state"], "active_acknowledged", "{ese}");
    assert_eq!(ese["acked_by"], "kim");
    // The new source reads: the contacts still move the alarms, the new
    // tag follows the PLC.
    a.sim.set("X0.06", true).unwrap();
    a.until("ESE cleared through the new source", "ese", "cleared")
        .await;
    a.sim.set_temperature(60.0).unwrap();
    a.until("the new tag's limit cleared", "spindle-2-h", "cleared")
        .await;
    // No communication alarm, no raise of ESE again: no gap.
    assert!(
        !a.seen.iter().any(|p| p.id == "communication"
            || (p.id == "ese" && p.transition.as_str() == "raised" && p.at != a.seen[0].at)),
        "{:#?}",
        a.seen
    );
    a.stop().await;
}
