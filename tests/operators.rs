//! Operators sign with their own Ed25519 keys (`cellwatch keygen`); the
//! agent holds public keys and permissions only. Real binary, real Zenoh.

use crate::spawned::{alarm, snapshot_until, start, KEY};
use crate::util::cellwatch;

/// Operator lee's key pair, made with `cellwatch keygen` in `dir`, allowed
/// to acknowledge in the cell's operators file: the key file and the
/// entry added.
fn allowed_to_ack(dir: &std::path::Path) -> (std::path::PathBuf, String) {
    let key = dir.join("lee.key");
    let made = cellwatch(&[
        "keygen",
        "--operator",
        "lee",
        "--out",
        key.to_str().unwrap(),
        "--allow",
        "ack",
    ]);
    assert_eq!(made.code, 0, "{}", made.stderr);
    let entry: String = made
        .stdout
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| format!("{l}\n"))
        .collect();
    let operators = dir.join("operators.toml");
    let all = format!("{}\n{entry}", std::fs::read_to_string(&operators).unwrap());
    std::fs::write(&operators, all).unwrap();
    (key, entry)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn operators_act_within_their_permissions_and_agents_hold_no_private_key() {
    let d = tempfile::tempdir().unwrap();
    let (sim, mut cell) = start(d.path()).await;
    // lee may acknowledge, not reset; a stranger's key is in no file.
    let (lee_key, entry) = allowed_to_ack(d.path());
    assert!(entry.contains("allow = [\"ack\"]"), "{entry}");
    let stranger_key = d.path().join("stranger.key");
    assert_eq!(
        cellwatch(&[
            "keygen",
            "--operator",
            "lee",
            "--out",
            stranger_key.to_str().unwrap()
        ])
        .code,
        0
    );
    // The key file is never overwritten.
    let again = cellwatch(&[
        "keygen",
        "--operator",
        "lee",
        "--out",
        lee_key.to_str().unwrap(),
    ]);
    assert_eq!(again.code, 2);
    assert!(
        again.stderr.contains("exists; not overwritten"),
        "{}",
        again.stderr
    );

    let mut child = cell.spawn("agent.log").await;
    let client = cell.client().await;
    sim.set("X0.06", false).unwrap();
    snapshot_until(&client, "ESE raised", |s| alarm(s, "ese").is_some()).await;
    let bus = cell.bus_args();
    let send = |action: &str, key: &std::path::Path| {
        let mut args = vec![
            action,
            "--cell",
            "m01ps0004",
            "--alarm",
            "ese",
            "--key-file",
            key.to_str().unwrap(),
        ];
        args.extend(bus.iter().map(String::as_str));
        cellwatch(&args)
    };
    let reset = send("reset", &lee_key);
    assert_eq!(
        (reset.code, reset.stderr.as_str()),
        (1, "error: refused: operator 'lee' may not reset\n")
    );
    let forged = send("ack", &stranger_key);
    assert_eq!(
        (forged.code, forged.stderr.as_str()),
        (1, "error: refused: bad signature\n")
    );
    let ack = send("ack", &lee_key);
    assert_eq!(
        (ack.code, ack.stdout.as_str()),
        (0, "accepted: ack ese by lee\n"),
        "{}",
        ack.stderr
    );
    snapshot_until(&client, "ESE acknowledged by lee", |s| {
        alarm(s, "ese").is_some_and(|a| a["acked_by"] == "lee")
    })
    .await;
    child.kill().unwrap();
    child.wait().unwrap();
    // Nothing the agent has (configuration, operators file, journal)
    // holds a private key.
    let lee_private = std::fs::read_to_string(&lee_key).unwrap();
    let lee_private = lee_private
        .lines()
        .find_map(|l| l.strip_prefix("private_key = \""))
        .unwrap()
        .trim_end_matches('"')
        .to_string();
    for file in [
        "cell.toml",
        "operators.toml",
        "journal.sqlite",
        "journal.sqlite-wal",
    ] {
        let Ok(bytes) = std::fs::read(d.path().join(file)) else {
            assert!(file.ends_with("-wal"), "{file} missing");
            continue;
        };
        let text = String::from_utf8_lossy(&bytes);
        for secret in [lee_private.as_str(), KEY] {
            assert!(!text.contains(secret), "{file} holds a private key");
        }
    }
    sim.stop();
}

/// A command sent right after the agent (re)started is answered: the CLI
/// waits for the agent's queryable and asks again while there is no
/// answer yet, instead of saying the agent did not answer. Three restarts,
/// an acknowledgement sent the moment the agent says it runs.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_command_sent_as_the_agent_restarts_is_answered() {
    let d = tempfile::tempdir().unwrap();
    let (sim, mut cell) = start(d.path()).await;
    let (key, _) = allowed_to_ack(d.path());
    for round in 0..3 {
        let mut child = cell.spawn(&format!("agent-{round}.log")).await;
        let client = cell.client().await;
        // A new occurrence to acknowledge.
        sim.set("X0.06", true).unwrap();
        snapshot_until(&client, "ESE cleared", |s| alarm(s, "ese").is_none()).await;
        sim.set("X0.06", false).unwrap();
        snapshot_until(&client, "ESE raised", |s| {
            alarm(s, "ese").is_some_and(|a| a["state"] == "active_unacknowledged")
        })
        .await;
        client.close().await.unwrap();
        // The agent is killed and started again; the moment it says it
        // runs, the acknowledgement goes out.
        child.kill().unwrap();
        child.wait().unwrap();
        let mut child = cell.spawn(&format!("agent-{round}-again.log")).await;
        let mut args = vec![
            "ack",
            "--cell",
            "m01ps0004",
            "--alarm",
            "ese",
            "--key-file",
            key.to_str().unwrap(),
        ];
        let bus = cell.bus_args();
        args.extend(bus.iter().map(String::as_str));
        let ack = cellwatch(&args);
        assert_eq!(
            (ack.code, ack.stdout.as_str()),
            (0, "accepted: ack ese by lee\n"),
            "round {round}: {}\n{}",
            ack.stderr,
            cell.log(&format!("agent-{round}-again.log"))
        );
        child.kill().unwrap();
        child.wait().unwrap();
    }
    sim.stop();
}
