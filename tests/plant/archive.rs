//! The plant archive: a cell's alarm events and machine states kept by the
//! plant's router (Zenoh's storage manager with the SQLite volume, as the
//! router configuration the plant made says), read by `cellwatch history
//! --plant` after the cell's agent is stopped for good and its host's files
//! are gone, across a restart of the router as `cellwatch router`; an entry
//! forged in the archive's file is not believed.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use super::{agent_config, plant_async, plant_router, router_config, Ran};

/// `cellwatch ARGS`, off the test's runtime.
async fn cellwatch(args: Vec<String>) -> Ran {
    tokio::task::spawn_blocking(move || {
        let out = Command::new(env!("CARGO_BIN_EXE_cellwatch"))
            .args(&args)
            .output()
            .unwrap();
        Ran {
            code: out.status.code().unwrap_or(-1),
            stdout: String::from_utf8(out.stdout).unwrap(),
            stderr: String::from_utf8(out.stderr).unwrap(),
        }
    })
    .await
    .unwrap()
}

/// `cellwatch history --plant --cell m01` as the plant's administrator,
/// through the router on `port`.
pub(super) async fn archived(dir: &Path, port: u16, more: &[&str]) -> Ran {
    let mut args: Vec<String> = ["history", "--plant", "--cell", "m01", "--since", "1h"]
        .map(String::from)
        .to_vec();
    args.extend(bus_flags(dir, port));
    args.extend(more.iter().map(|a| a.to_string()));
    cellwatch(args).await
}

/// The bus flags of the plant's administrator through the router on `port`.
fn bus_flags(dir: &Path, port: u16) -> Vec<String> {
    let file = |p: &str| dir.join(p).display().to_string();
    [
        "--connect",
        &format!("quic/127.0.0.1:{port}"),
        "--mode",
        "client",
        "--tls-ca",
        &file("ca/ca.pem"),
        "--tls-cert",
        &file("admin/plant-admin.pem"),
        "--tls-key",
        &file("admin/plant-admin.key"),
        "--trust",
        &file("trust.toml"),
        "--timeout",
        "10",
    ]
    .map(String::from)
    .to_vec()
}

/// Reads the archive until `seen` holds of its output.
pub(super) async fn until(dir: &Path, port: u16, what: &str, seen: impl Fn(&str) -> bool) -> Ran {
    let deadline = Instant::now() + Duration::from_secs(120);
    loop {
        let r = archived(dir, port, &[]).await;
        if seen(&r.stdout) {
            return r;
        }
        assert!(
            Instant::now() < deadline,
            "never {what}: {}{}",
            r.stdout,
            r.stderr
        );
        tokio::time::sleep(Duration::from_millis(300)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_cells_history_is_read_from_the_plant_archive_after_its_agent_is_gone() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path().to_path_buf();
    let sim = super::one_cell_plant(&dir).await;
    let run =
        |args: &[&str]| plant_async(dir.clone(), args.iter().map(|a| a.to_string()).collect());
    let kim = cellwatch::operator::OperatorKey::generate("kim");
    let r = run(&[
        "add-operator",
        "--name",
        "kim",
        "--public-key",
        &kim.public_hex(),
        "--allow",
        "ack",
    ])
    .await;
    assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    // The router's configuration keeps the archive, as the plant made it.
    let made =
        std::fs::read_to_string(dir.join("routers/router-1/etc/cellwatch/router/router.json5"))
            .unwrap();
    for part in [
        "storage_manager",
        "\"cellwatch/*/alarms/**\"",
        "\"cellwatch/*/state\"",
        "retention: \"90d\"",
        "timestamping",
    ] {
        assert!(made.contains(part), "{part}: {made}");
    }

    let (router, port) = plant_router(&dir).await;
    let mut c = agent_config(&dir, "m01", port);
    c.state_interval = Duration::from_millis(200);
    crate::util::trust_sim(&c, &dir.join("sim-pki"));
    let journal = c.journal.path.clone();
    let agent = cellwatch::agent::start(c, None).await.unwrap();
    // Its state reaches the archive once the PLC answers; then a fault
    // comes and goes.
    until(&dir, port, "a running state", |o| o.contains("m01  state=")).await;
    sim.set("X0.06", false).unwrap();
    until(&dir, port, "the raise", |o| o.contains("m01/ese  raised")).await;
    sim.set("X0.06", true).unwrap();
    let before = until(&dir, port, "the clear", |o| o.contains("m01/ese  cleared")).await;

    // Kim acknowledges: a command row, the chain's end the agent then
    // signs in its state, which the archive keeps.
    let bus = super::admin_client(&dir, port).await;
    let (accepted, detail) = super::kim_acks(&bus, &kim, "m01").await;
    assert!(accepted, "{detail}");
    let deadline = Instant::now() + Duration::from_secs(120);
    let position = loop {
        let r = archived(&dir, port, &["--kind", "state", "--json"]).await;
        let acked = r.stdout.lines().find_map(|l| {
            let v: serde_json::Value = serde_json::from_str(l).ok()?;
            let chain = &v["command_chain"];
            (chain["hash"] != serde_json::Value::Null)
                .then(|| chain["position"].as_i64())
                .flatten()
                .filter(|p| *p >= 1)
        });
        if let Some(p) = acked {
            break p;
        }
        assert!(
            Instant::now() < deadline,
            "no signed chain end archived: {}{}",
            r.stdout,
            r.stderr
        );
        tokio::time::sleep(Duration::from_millis(300)).await;
    };
    drop(bus);

    // The agent stopped for good; its journal kept aside, once whole and
    // once with its last command row cut off (as whoever can write the
    // file while the agent is stopped could); its host's files gone; the
    // router restarted, as `cellwatch router`, from its configuration file.
    agent.stop().await;
    let whole = dir.join("journal-whole.sqlite");
    let cut = dir.join("journal-cut.sqlite");
    for copy in [&whole, &cut] {
        rusqlite::Connection::open(&journal)
            .unwrap()
            .execute("VACUUM INTO ?1", [copy.display().to_string()])
            .unwrap();
    }
    rusqlite::Connection::open(&cut)
        .unwrap()
        .execute(
            "DELETE FROM commands WHERE seq = (SELECT MAX(seq) FROM commands)",
            [],
        )
        .unwrap();
    std::fs::remove_dir_all(dir.join("hosts/127.0.0.1/var/lib/cellwatch/m01")).unwrap();
    std::fs::remove_dir_all(dir.join("state-m01")).unwrap();
    router.close().await;
    let file = dir.join("router-test.json5");
    std::fs::write(&file, router_config(&dir, true).to_string()).unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_cellwatch"))
        .args(["router", "--config"])
        .arg(&file)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap();
    let lines = crate::util::lines_of(&mut child);
    let said = lines.recv_timeout(Duration::from_secs(60)).unwrap();
    let port = archive_port(&said);
    let after = archived(&dir, port, &[]).await;
    assert_eq!(after.code, 0, "{}{}", after.stdout, after.stderr);
    for line in before.stdout.lines().filter(|l| l.contains("m01/ese")) {
        assert!(
            after.stdout.contains(line),
            "{line} lost:\n{}",
            after.stdout
        );
    }
    assert!(
        after.stdout.contains("X0.06"),
        "the culprit: {}",
        after.stdout
    );

    // The console shows the cell's history from the archive: its agent's
    // token is gone, so the routers' storages answer at once.
    std::fs::write(dir.join("kim.key"), kim.to_file()).unwrap();
    std::fs::write(
        dir.join("console-operators.toml"),
        kim.operators_entry(&[cellwatch::operator::Action::Ack]),
    )
    .unwrap();
    std::fs::write(
        dir.join("console.toml"),
        format!(
            "[http]\nlisten = \"127.0.0.1:0\"\n\n[bus]\nconnect = [\"quic/127.0.0.1:{port}\"]\ntrust = {:?}\ntls = {{ ca = {:?}, cert = {:?}, key = {:?} }}\n\n[operators]\nfile = {:?}\n\n[areas]\na = [\"m01\"]\n",
            dir.join("trust.toml"),
            dir.join("ca/ca.pem"),
            dir.join("admin/plant-admin.pem"),
            dir.join("admin/plant-admin.key"),
            dir.join("console-operators.toml"),
        ),
    )
    .unwrap();
    let mut console = Command::new(env!("CARGO_BIN_EXE_cellwatch"))
        .args(["console", "--config"])
        .arg(dir.join("console.toml"))
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap();
    let url = crate::util::lines_of(&mut console)
        .recv_timeout(Duration::from_secs(60))
        .unwrap();
    let addr = url
        .trim()
        .strip_prefix("cellwatch console: http://")
        .unwrap()
        .trim_end_matches('/')
        .to_string();
    let page = {
        let addr = addr.clone();
        let key = dir.join("kim.key");
        tokio::task::spawn_blocking(move || {
            let cookie = crate::console::sign_in(&addr, &key).unwrap();
            crate::console::request(
                &addr,
                &format!(
                    "GET /api/cells/m01/history?kind=alarm&since=1h HTTP/1.1\r\nHost: {addr}\r\n{cookie}"
                ),
                "",
            )
        })
        .await
        .unwrap()
    };
    assert_eq!(page.0, 200, "{page:?}");
    let page: serde_json::Value = serde_json::from_str(&page.2).unwrap();
    assert_eq!(page["from"], "archive", "{page}");
    let transitions: Vec<&str> = page["rows"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|r| r["fields"]["alarm"] == "ese")
        .map(|r| r["fields"]["transition"].as_str().unwrap())
        .collect();
    assert_eq!(transitions, ["raised", "cleared", "acknowledged"], "{page}");
    let _ = console.kill();
    let _ = console.wait();

    // The journal held to the chain ends the archive keeps: whole, it
    // holds; cut, the row is missed though the agent is gone.
    let audit = |journal: &Path| {
        let mut args = vec![
            "audit".to_string(),
            "verify".into(),
            journal.display().to_string(),
            "--against-archive".into(),
            "--cell".into(),
            "m01".into(),
        ];
        args.extend(bus_flags(&dir, port));
        cellwatch(args)
    };
    let r = audit(&whole).await;
    assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    assert!(
        r.stdout
            .contains("every chain end cell m01's agent signed in the plant archive is there"),
        "{}",
        r.stdout
    );
    let r = audit(&cut).await;
    assert_eq!(r.code, 1, "{}{}", r.stdout, r.stderr);
    assert!(
        r.stderr.contains(&format!(
            "1 command row cut off: the plant archive keeps cell m01's agent's signed chain end at position {position}"
        )),
        "{}",
        r.stderr
    );

    // An entry forged in the archive's file: a raise the agent never
    // signed. It is said, not printed as the cell's.
    let db = rusqlite::Connection::open(archive_file(&dir, "alarms")).unwrap();
    let (key, time, id, encoding, payload): (String, i64, Vec<u8>, String, Vec<u8>) = db
        .query_row(
            "SELECT key, time, id, encoding, payload FROM samples ORDER BY time LIMIT 1",
            [],
            |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?, r.get(4)?)),
        )
        .unwrap();
    let forged = String::from_utf8(payload)
        .unwrap()
        .replace("X0.06", "X9.99");
    db.execute(
        "INSERT INTO samples (key, time, id, encoding, payload) VALUES (?1, ?2, ?3, ?4, ?5)",
        rusqlite::params![key, time + 1, id, encoding, forged.as_bytes()],
    )
    .unwrap();
    drop(db);
    let r = archived(&dir, port, &["--kind", "alarm"]).await;
    assert_eq!(r.code, 1, "{}{}", r.stdout, r.stderr);
    assert!(
        r.stderr.contains(
            "not believed: cellwatch/m01/alarms/ese: the signature is not cell m01's agent's"
        ),
        "{}",
        r.stderr
    );
    assert!(!r.stdout.contains("X9.99"), "{}", r.stdout);
    assert!(r.stdout.contains("m01/ese  raised"), "{}", r.stdout);
    let _ = child.kill();
    let _ = child.wait();
    drop(sim);
}

/// A storage's SQLite file in the router's archive.
fn archive_file(dir: &Path, storage: &str) -> PathBuf {
    dir.join(format!("routers/router-1/archive/{storage}.sqlite"))
}

/// The TLS port a `cellwatch router` keeping the plant archive said it
/// listens on (its first line).
pub(super) fn archive_port(said: &str) -> u16 {
    assert!(said.contains("keeping the plant archive"), "{said}");
    crate::util::tls_port(
        &said
            .split(": listening on ")
            .nth(1)
            .unwrap()
            .split([',', ';'])
            .map(|s| s.trim().to_string())
            .collect::<Vec<_>>(),
    )
}
