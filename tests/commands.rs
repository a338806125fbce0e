//! Operator commands that cannot be bent, replayed or used to flood or
//! forge the journal: refusals before a signature is verified summarised
//! per source, reason and minute; text with control characters refused by
//! the CLI and the agent and escaped by every printer; a write's nonce on
//! disk before the PLC is written (a `kill -9` in between makes no replay
//! possible); the command rows' hash chain checked by `cellwatch audit
//! verify`; operator names and ids that fit keys and files. Real agents
//! (in process or the binary), real Zenoh on loopback, real SQLite files.

use std::path::Path;
use std::time::Duration;

use cellwatch::operator::{Action, Command, OperatorKey};
use cellwatch::sim::moulding::MouldingBus;
use cellwatch_models::at_bus::{Decoded, Decoder};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

use crate::spawned::{kim, query};
use crate::util::cellwatch;

const CELL: &str = "moulding-bus1";

/// Kim's command for the moulding bus, signed unless `key` is `None`.
fn command(
    action: Action,
    alarm: &str,
    tag: Option<&str>,
    value: Option<&str>,
    key: Option<&OperatorKey>,
) -> Command {
    let mut c = Command {
        action,
        alarm: alarm.into(),
        tag: tag.map(str::to_string),
        value: value.map(str::to_string),
        reason: None,
        operator: "kim".into(),
        nonce: cellwatch::operator::nonce(),
        issued_at: cellwatch::clock::now_ms(),
        signature: String::new(),
    };
    if let Some(key) = key {
        c.sign(CELL, key);
    }
    c
}

/// (accepted, detail) of a command's answer.
fn outcome(answer: &str) -> (bool, String) {
    let v: serde_json::Value = serde_json::from_str(answer).unwrap();
    (
        v["accepted"].as_bool().unwrap(),
        v["detail"].as_str().unwrap().to_string(),
    )
}

/// The journal's command rows: (stage, detail, source, count, accepted,
/// verified).
fn command_rows(db: &Path) -> Vec<(String, String, String, i64, bool, bool)> {
    let c = rusqlite::Connection::open(db).unwrap();
    let mut st = c
        .prepare(
            "SELECT stage, detail, source, count, accepted, verified FROM commands ORDER BY seq",
        )
        .unwrap();
    st.query_map([], |r| {
        Ok((
            r.get(0)?,
            r.get(1)?,
            r.get(2)?,
            r.get(3)?,
            r.get::<_, i64>(4)? != 0,
            r.get::<_, i64>(5)? != 0,
        ))
    })
    .unwrap()
    .map(Result::unwrap)
    .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn refusals_before_the_signature_are_summarised_per_source_reason_and_minute() {
    let dir = tempfile::tempdir().unwrap();
    let (_bus, server, agent, client, _) = crate::at_bus::moulding_agent(
        dir.path(),
        &crate::spawned::operators_file(&[Action::Ack]),
        false,
    )
    .await;
    let metrics = agent.metrics_addr().unwrap();
    let ask = |payload: String| {
        let client = client.clone();
        async move {
            query(&client, &format!("cellwatch/{CELL}/command"), Some(payload))
                .await
                .unwrap()
        }
    };
    // A query that says where it comes from: a publisher's id.
    let claimed = client
        .declare_publisher(format!("cellwatch/{CELL}/probe"))
        .await
        .unwrap();
    let source = claimed.id();
    let first_minute = cellwatch::clock::now_ms() / 60_000;
    const UNSIGNED: usize = 300;
    const FORGED: usize = 100;
    for i in 0..UNSIGNED {
        // Switch commands too: an unsigned force is no request of anyone's.
        let action = [Action::Ack, Action::Force, Action::Stop][i % 3];
        let c = command(action, "", None, Some("F1"), None);
        let (ok, why) = outcome(&ask(serde_json::to_string(&c).unwrap()).await);
        assert_eq!((ok, why.as_str()), (false, "unsigned command"));
    }
    for _ in 0..FORGED {
        let c = command(
            Action::Ack,
            "front-door",
            None,
            None,
            Some(&OperatorKey::generate("kim")),
        );
        let replies = client
            .get(format!("cellwatch/{CELL}/command"))
            .payload(serde_json::to_string(&c).unwrap())
            .source_info(zenoh::sample::SourceInfo::new(source, 0))
            .timeout(Duration::from_secs(10))
            .await
            .unwrap();
        let reply = replies.recv_async().await.unwrap();
        let text = crate::util::opened(reply.result().unwrap().payload());
        assert_eq!(outcome(&text), (false, "bad signature".to_string()));
    }
    let last_minute = cellwatch::clock::now_ms() / 60_000;
    let scrape = crate::util::scrape(metrics).await;
    for (reason, n) in [("unsigned", UNSIGNED), ("bad_signature", FORGED)] {
        let series = format!(
            "cellwatch_requests_refused_total{{cell=\"{CELL}\",reason=\"{reason}\",service=\"command\"}} {n}"
        );
        assert!(scrape.contains(&series), "{series} in\n{scrape}");
    }
    // The agent stops cleanly: the minute's counts are journaled.
    agent.stop().await;
    server.unwrap().abort();
    let rows = command_rows(&dir.path().join("journal.sqlite"));
    // Nothing unauthenticated is stored as accepted, or as verified.
    assert!(rows.iter().all(|r| !r.4 && !r.5), "{rows:#?}");
    assert!(rows.iter().all(|r| r.0 == "refused"), "{rows:#?}");
    let windows = (last_minute - first_minute + 1) as usize;
    let zid = source.zid().to_string();
    for (from, first, more, sent) in [
        (
            "unknown",
            "unsigned command",
            " more unsigned refused from unknown ",
            UNSIGNED,
        ),
        (
            zid.as_str(),
            "bad signature",
            " more bad_signature refused from ",
            FORGED,
        ),
    ] {
        let of: Vec<_> = rows.iter().filter(|r| r.2 == from).collect();
        // The first of each minute as it was, then one count per minute.
        let firsts = of.iter().filter(|r| r.1 == first && r.3 == 1).count();
        let counts: Vec<_> = of.iter().filter(|r| r.1.contains(more)).collect();
        assert!((1..=windows).contains(&firsts), "{of:#?}");
        assert!(
            counts.len() <= windows && of.len() == firsts + counts.len(),
            "{of:#?}"
        );
        let total: i64 = of.iter().map(|r| r.3).sum();
        assert_eq!(total as usize, sent, "{of:#?}");
    }
    assert!(rows.len() <= 4 * windows, "{rows:#?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn control_characters_are_refused_by_the_cli_and_the_agent_and_escaped_in_output() {
    let dir = tempfile::tempdir().unwrap();
    // An older agent journaled a reason with a newline: a fake line.
    let db = dir.path().join("journal.sqlite");
    let fake = "2026-01-01T00:00:00.000Z  command   ack front-door by boss: (accepted)";
    {
        let conn = cellwatch::journal::open(&db).unwrap();
        conn.execute(
            "INSERT INTO commands (at_ms, operator, action, alarm, nonce, accepted, detail) VALUES (?1, 'kim', 'shelve', 'front-door', 'n', 0, ?2)",
            rusqlite::params![
                cellwatch::clock::now_ms() as i64,
                format!("no\n{fake}\u{1b}[2K")
            ],
        )
        .unwrap();
    }
    let (_bus, server, agent, client, port) = crate::at_bus::moulding_agent(
        dir.path(),
        &crate::spawned::operators_file(&Action::ALL),
        false,
    )
    .await;
    // The CLI refuses to sign it, naming the field.
    let key = dir.path().join("kim.key");
    std::fs::write(&key, kim().to_file()).unwrap();
    let mut args: Vec<String> = [
        "shelve",
        "--cell",
        CELL,
        "--alarm",
        "front-door",
        "--for",
        "30m",
        "--reason",
        "2h\nwaiting for parts",
        "--key-file",
        key.to_str().unwrap(),
    ]
    .map(String::from)
    .to_vec();
    args.extend(crate::util::bus_args(dir.path(), "operator-kim", port));
    let run = |args: Vec<String>| {
        tokio::task::spawn_blocking(move || {
            let args: Vec<&str> = args.iter().map(String::as_str).collect();
            cellwatch(&args)
        })
    };
    let r = run(args).await.unwrap();
    assert_eq!(
        (r.code, r.stderr.as_str()),
        (2, "error: reason holds a control character (a newline, tab or escape): write it on one line\n")
    );
    // The agent refuses it too, signed or not.
    let mut shelf = command(Action::Shelve, "front-door", None, Some("30m"), None);
    shelf.reason = Some("2h\nwaiting for parts".into());
    shelf.sign(CELL, &kim());
    let answer = query(
        &client,
        &format!("cellwatch/{CELL}/command"),
        Some(serde_json::to_string(&shelf).unwrap()),
    )
    .await
    .unwrap();
    assert_eq!(
        outcome(&answer),
        (
            false,
            "reason holds a control character (a newline, tab or escape): write it on one line"
                .to_string()
        )
    );
    // `cellwatch history` prints the old row on one line, escaped.
    let mut args: Vec<String> = [
        "history", "--cell", CELL, "--kind", "command", "--since", "1h",
    ]
    .map(String::from)
    .to_vec();
    args.extend(crate::util::bus_args(dir.path(), "operator-kim", port));
    let r = run(args).await.unwrap();
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        !r.stdout.lines().any(|l| l.starts_with("2026-01-01")),
        "{}",
        r.stdout
    );
    assert!(!r.stdout.contains('\u{1b}'), "{}", r.stdout);
    assert!(
        r.stdout
            .contains(&format!("refused (no\\n{fake}\\u{{1b}}[2K)")),
        "{}",
        r.stdout
    );
    agent.stop().await;
    server.unwrap().abort();
}

/// A cable between the agent and the bus that carries everything but
/// writes: a write is held (never passed on, never answered) and
/// announced on `held`.
async fn tap(
    bus: std::net::SocketAddr,
) -> (std::net::SocketAddr, tokio::sync::mpsc::Receiver<String>) {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let (held, writes) = tokio::sync::mpsc::channel(16);
    tokio::spawn(async move {
        while let Ok((agent, _)) = listener.accept().await {
            let Ok(unit) = tokio::net::TcpStream::connect(bus).await else {
                return;
            };
            let (mut from_agent, mut to_agent) = agent.into_split();
            let (mut from_bus, mut to_bus) = unit.into_split();
            tokio::spawn(async move {
                let _ = tokio::io::copy(&mut from_bus, &mut to_agent).await;
            });
            let held = held.clone();
            tokio::spawn(async move {
                let mut decoder = Decoder::requests();
                let mut buf = [0u8; 256];
                let mut frames = Vec::new();
                while let Ok(n) = from_agent.read(&mut buf).await {
                    if n == 0 {
                        break;
                    }
                    decoder.push(&buf[..n], &mut frames);
                    for f in frames.drain(..) {
                        let (Decoded::Frame(f) | Decoded::Duplicate(f)) = f else {
                            continue;
                        };
                        decoder.request_sent();
                        if f.header.is_write() {
                            let _ = held.send(format!("{}{}", f.header, f.text)).await;
                        } else if to_bus.write_all(&f.encode()).await.is_err() {
                            return;
                        }
                    }
                }
            });
        }
    });
    (addr, writes)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_write_killed_before_the_plc_answered_is_a_replay_after_the_restart() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let bus = MouldingBus::new(3);
    let (bus_addr, server) = bus
        .listen_tcp("127.0.0.1:0".parse().unwrap())
        .await
        .unwrap();
    let (cable, mut held) = tap(bus_addr).await;
    crate::util::bus_pki(dir, &["agent-moulding-bus1", "operator-kim"]);
    std::fs::write(
        dir.join("operators.toml"),
        crate::spawned::operators_file(&[Action::Write]),
    )
    .unwrap();
    let moulding =
        std::fs::read_to_string(crate::util::root().join("config/moulding.toml")).unwrap();
    let config = moulding
        .replace(
            "tcp = \"127.0.0.1:4001\"",
            // The write waits long for its answer: long enough to be killed.
            &format!("tcp = \"{cable}\"\npoll_interval = \"100ms\"\nresponse_timeout = \"20s\"\nretries = 0"),
        )
        .replace("quic/127.0.0.1:7449", "quic/127.0.0.1:0")
        .replace("listen = \"127.0.0.1:9466\"", "listen = \"127.0.0.1:0\"")
        .replace(
            "\"moulding/",
            &format!("\"{}/config/moulding/", crate::util::root().display()),
        )
        + "\n[journal]\npath = \"journal.sqlite\"\n\n[commands]\noperators_file = \"operators.toml\"\n";
    let path = dir.join("cell.toml");
    std::fs::write(&path, config).unwrap();
    let mut cell = crate::spawned::Cell {
        dir: dir.to_path_buf(),
        config: path,
        zenoh_port: 0,
        metrics_port: 0,
        env: Vec::new(),
        watchdog_pid: false,
    };
    let mut child = cell.spawn("agent.log").await;
    let client = cell.client().await;
    query(&client, &format!("cellwatch/{CELL}/snapshot"), None)
        .await
        .unwrap();
    let write = command(Action::Write, "", Some("T2"), Some("1500"), Some(&kim()));
    let json = serde_json::to_string(&write).unwrap();
    let asked = tokio::spawn({
        let client = client.clone();
        let json = json.clone();
        async move {
            let _ = client
                .get(format!("cellwatch/{CELL}/command"))
                .payload(json)
                .timeout(Duration::from_secs(60))
                .await;
        }
    });
    // The write is on the line to the unit: the PLC has not answered.
    let frame = tokio::time::timeout(Duration::from_secs(60), held.recv())
        .await
        .unwrap_or_else(|_| panic!("no write reached the bus\n{}", cell.log("agent.log")))
        .unwrap();
    assert_eq!(frame, "WT001500");
    child.kill().unwrap();
    child.wait().unwrap();
    asked.abort();
    // Its nonce was on disk before the write left the agent.
    let rows: Vec<(String, bool)> = {
        let c = rusqlite::Connection::open(dir.join("journal.sqlite")).unwrap();
        let mut st = c
            .prepare("SELECT stage, verified FROM commands WHERE nonce = ?1 ORDER BY seq")
            .unwrap();
        st.query_map([&write.nonce], |r| {
            Ok((r.get(0)?, r.get::<_, i64>(1)? != 0))
        })
        .unwrap()
        .map(Result::unwrap)
        .collect()
    };
    assert_eq!(rows, [("request".to_string(), true)]);
    let mut child = cell.spawn("agent-2.log").await;
    let client = cell.client().await;
    let answer = query(&client, &format!("cellwatch/{CELL}/command"), Some(json))
        .await
        .unwrap();
    // Sent again: a replay, not carried out again, and its first
    // sending's outcome said to be unknown (the agent stopped before the
    // PLC answered).
    assert_eq!(
        outcome(&answer),
        (
            false,
            "replayed command: sent before (not accepted: the agent stopped before this \
             command's outcome was known: see its history); not carried out again"
                .to_string()
        )
    );
    assert!(held.try_recv().is_err(), "the replay reached the bus");
    child.kill().unwrap();
    child.wait().unwrap();
    server.abort();
}

/// A journal with command rows from before the chain, then chained ones
/// written by the journal's writer, interleaved with other rows.
async fn chained_journal(db: &Path) {
    use cellwatch::journal::{Entry, Journal};
    // An older agent's journal: no chain columns yet.
    {
        let c = rusqlite::Connection::open(db).unwrap();
        c.execute_batch(
            "CREATE TABLE commands (seq INTEGER PRIMARY KEY AUTOINCREMENT, at_ms INTEGER NOT NULL, \
             operator TEXT NOT NULL, action TEXT NOT NULL, alarm TEXT NOT NULL, nonce TEXT NOT NULL, \
             accepted INTEGER NOT NULL, detail TEXT NOT NULL);
             INSERT INTO commands (at_ms, operator, action, alarm, nonce, accepted, detail)
             VALUES (strftime('%s','now') * 1000, 'kim', 'ack', 'ese', 'n0', 1, 'ack ese by kim');",
        )
        .unwrap();
    }
    let j = Journal::start(
        db,
        &cellwatch::config::Keep::all(Duration::from_secs(3600)),
        crate::util::NoCommits,
    )
    .unwrap();
    let now = cellwatch::clock::now_ms();
    let mut rows = Vec::new();
    for i in 0..6u64 {
        rows.push(Entry::Command {
            at: now + i,
            operator: "kim".into(),
            action: "ack".into(),
            alarm: "ese".into(),
            nonce: cellwatch::operator::nonce(),
            accepted: true,
            verified: true,
            detail: format!("ack ese by kim ({i})"),
            stage: "command".into(),
            source: String::new(),
            count: 1,
            digest: None,
        });
        rows.push(Entry::Part {
            at: now + i,
            count: 1,
        });
    }
    j.commit(rows).await.unwrap();
    j.close().await;
}

/// `cellwatch audit verify` on a copy of `db` after `tamper`.
fn verify_after(db: &Path, name: &str, tamper: &str) -> crate::util::Run {
    let copy = db.with_file_name(name);
    std::fs::copy(db, &copy).unwrap();
    if !tamper.is_empty() {
        rusqlite::Connection::open(&copy)
            .unwrap()
            .execute_batch(tamper)
            .unwrap();
    }
    cellwatch(&["audit", "verify", copy.to_str().unwrap()])
}

#[tokio::test]
async fn audit_verify_names_the_first_edited_inserted_or_deleted_command_row() {
    let d = tempfile::tempdir().unwrap();
    let db = d.path().join("journal.sqlite");
    chained_journal(&db).await;
    // seq 1 is the old row; the chained ones are 2, 4, 6, 8, 10, 12.
    let seqs: Vec<i64> = {
        let c = rusqlite::Connection::open(&db).unwrap();
        let mut st = c.prepare("SELECT seq FROM commands ORDER BY seq").unwrap();
        st.query_map([], |r| r.get(0))
            .unwrap()
            .map(Result::unwrap)
            .collect()
    };
    assert_eq!(seqs, [1, 2, 4, 6, 8, 10, 12]);
    let ok = verify_after(&db, "same.sqlite", "");
    let name = |n: &str| d.path().join(n).display().to_string();
    assert_eq!(
        (ok.code, ok.stdout.as_str()),
        (
            0,
            format!(
                "{}: 6 command rows intact; 1 row before the chain (not checked)\n",
                name("same.sqlite")
            )
            .as_str()
        ),
        "{}",
        ok.stderr
    );
    let cases = [
        (
            "edited.sqlite",
            "UPDATE commands SET detail = 'reset ese by kim' WHERE seq = 6",
            "seq 6: edited: its fields do not match its hash (2 command rows intact before it)",
        ),
        (
            "accepted.sqlite",
            "UPDATE commands SET accepted = 0 WHERE seq = 10",
            "seq 10: edited: its fields do not match its hash (4 command rows intact before it)",
        ),
        (
            "deleted.sqlite",
            "DELETE FROM commands WHERE seq = 8",
            "seq 10: 1 command row deleted before it (chain position 5 follows 3 at seq 6) (3 command rows intact before it)",
        ),
        (
            "copied.sqlite",
            "INSERT INTO commands (seq, at_ms, operator, action, alarm, nonce, accepted, verified, detail, stage, source, count, chain_index, prev_hash, hash) SELECT 5, at_ms, operator, action, alarm, nonce, accepted, verified, detail, stage, source, count, chain_index, prev_hash, hash FROM commands WHERE seq = 4",
            "seq 5: inserted: chain position 2 comes again after position 2 at seq 4 (2 command rows intact before it)",
        ),
        (
            "inserted.sqlite",
            "INSERT INTO commands (seq, at_ms, operator, action, alarm, nonce, accepted, detail) VALUES (7, 0, 'boss', 'ack', 'ese', 'x', 1, 'ack ese by boss')",
            "seq 7: not in the chain: no hash after the chain began (a row inserted, or its hash removed) (3 command rows intact before it)",
        ),
    ];
    for (file, tamper, found) in cases {
        let r = verify_after(&db, file, tamper);
        assert_eq!(
            (r.code, r.stderr.as_str()),
            (1, format!("error: {}: {found}\n", name(file)).as_str()),
            "{tamper}"
        );
    }
}

#[test]
fn operator_names_fit_the_operators_file() {
    let d = tempfile::tempdir().unwrap();
    let key = d.path().join("ab.key");
    let r = cellwatch(&[
        "keygen",
        "--operator",
        "a.b",
        "--out",
        key.to_str().unwrap(),
    ]);
    assert_eq!(
        (r.code, r.stderr.as_str()),
        (2, "error: --operator \"a.b\": an operator's name is letters, digits, '-' or '_' (a bare key in the operators file)\n")
    );
    assert!(!key.exists());
}
