//! A unit's target written over the bus only for an operator allowed to write.

use std::time::Duration;

use super::moulding_agent;

/// Writes to a unit: a target sent by an operator allowed `write` is
/// acknowledged by the unit (`AC10`), read back and journaled; one from an
/// operator without that permission, one unsigned, one with a bad
/// signature and one with a value that does not fit are refused,
/// journaled, and never sent on the bus.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_target_is_written_only_for_an_operator_allowed_to_write() {
    use cellwatch::operator::{Action, Command, OperatorKey};
    let dir = tempfile::tempdir().unwrap();
    let lee = OperatorKey::generate("lee");
    let operators = format!(
        "{}\n{}",
        crate::spawned::operators_file(&[Action::Ack, Action::Write]),
        lee.operators_entry(&[Action::Ack, Action::Reset])
    );
    let (bus, server, agent, client, port) = moulding_agent(dir.path(), &operators, false).await;
    let query = |selector: String, payload: Option<String>| {
        let client = client.clone();
        async move {
            crate::spawned::query(&client, &selector, payload)
                .await
                .unwrap()
        }
    };
    let target_is = |v: u64| {
        let query = &query;
        async move {
            let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
            loop {
                let snap: serde_json::Value = serde_json::from_str(
                    &query("cellwatch/moulding-bus1/snapshot".into(), None).await,
                )
                .unwrap();
                let t2 = snap["tags"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .find(|t| t["address"] == "T2")
                    .map(|t| t["value"].clone());
                if t2 == Some(serde_json::json!(v)) {
                    return;
                }
                assert!(
                    tokio::time::Instant::now() < deadline,
                    "T2 never {v}: {snap}"
                );
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
        }
    };
    target_is(1000).await;
    let write = |operator: &str, value: &str| Command {
        action: Action::Write,
        alarm: String::new(),
        tag: Some("T2".into()),
        value: Some(value.into()),
        reason: None,
        operator: operator.into(),
        nonce: cellwatch::operator::nonce(),
        issued_at: cellwatch::clock::now_ms(),
        signature: String::new(),
    };
    let send = |c: Command| {
        let json = serde_json::to_string(&c).unwrap();
        let query = &query;
        async move {
            let r: serde_json::Value = serde_json::from_str(
                &query("cellwatch/moulding-bus1/command".into(), Some(json)).await,
            )
            .unwrap();
            (
                r["accepted"].as_bool().unwrap(),
                r["detail"].as_str().unwrap().to_string(),
            )
        }
    };
    let mut by_lee = write("lee", "1500");
    by_lee.sign("moulding-bus1", &lee);
    let (ok, why) = send(by_lee).await;
    assert_eq!((ok, why.as_str()), (false, "operator 'lee' may not write"));
    assert_eq!(
        send(write("kim", "1500")).await,
        (false, "unsigned command".to_string())
    );
    let mut forged = write("kim", "1500");
    forged.sign("moulding-bus1", &OperatorKey::generate("kim"));
    assert_eq!(send(forged).await, (false, "bad signature".to_string()));
    let mut too_big = write("kim", "1234567");
    too_big.sign("moulding-bus1", &crate::spawned::kim());
    let (ok, why) = send(too_big).await;
    assert!(!ok && why.contains("is not a quantity"), "{why}");
    assert!(
        bus.log().iter().all(|e| !e.what.starts_with("write")),
        "nothing refused reached the bus: {:?}",
        bus.log()
    );

    let mut good = write("kim", "1500");
    good.sign("moulding-bus1", &crate::spawned::kim());
    assert_eq!(
        send(good).await,
        (true, "WT001500 to unit 02: AC10".to_string())
    );
    assert_eq!(bus.unit(2).unwrap().target, 1500);
    let writes: Vec<String> = bus
        .log()
        .into_iter()
        .filter(|e| e.what.starts_with("write"))
        .map(|e| format!("{} {}", e.unit, e.what))
        .collect();
    assert_eq!(writes, ["2 write WT001500"]);
    target_is(1500).await;

    // The same from the command line: `cellwatch write`.
    let key = dir.path().join("kim.key");
    std::fs::write(&key, crate::spawned::kim().to_file()).unwrap();
    let mut args: Vec<String> = [
        "write",
        "--cell",
        "moulding-bus1",
        "--tag",
        "J2",
        "--value",
        "MOULD-7",
        "--key-file",
        key.to_str().unwrap(),
    ]
    .map(String::from)
    .to_vec();
    args.extend(crate::util::bus_args(dir.path(), "operator-kim", port));
    let r = tokio::task::spawn_blocking(move || {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        crate::util::cellwatch(&args)
    })
    .await
    .unwrap();
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert_eq!(r.stdout, "accepted: WJMOULD-7 to unit 02: AC10\n");
    assert_eq!(bus.unit(2).unwrap().item, "MOULD-7");

    // Every command is in the journal with its outcome: a write as its
    // request (committed before the unit is written) and its result; a
    // refusal before the signature was verified in a row of its own (the
    // first of its kind this minute).
    let page: serde_json::Value = serde_json::from_str(
        &query(
            "cellwatch/moulding-bus1/history?kind=command;since=1h".into(),
            None,
        )
        .await,
    )
    .unwrap();
    let rows: Vec<(String, String, String, bool)> = page["rows"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| {
            (
                r["fields"]["operator"].as_str().unwrap().to_string(),
                r["fields"]["alarm"].as_str().unwrap().to_string(),
                r["fields"]["stage"].as_str().unwrap().to_string(),
                r["fields"]["accepted"]
                    .as_bool()
                    .unwrap_or(r["fields"]["accepted"] == 1),
            )
        })
        .collect();
    let row = |who: &str, tag: &str, stage: &str, ok| (who.into(), tag.into(), stage.into(), ok);
    assert_eq!(
        rows,
        [
            row("lee", "T2", "command", false),
            row("kim", "T2", "refused", false),
            row("kim", "T2", "refused", false),
            row("kim", "T2", "request", true),
            row("kim", "T2", "result", false),
            row("kim", "T2", "request", true),
            row("kim", "T2", "result", true),
            row("kim", "J2", "request", true),
            row("kim", "J2", "result", true),
        ],
        "{page}"
    );
    agent.stop().await;
    if let Some(server) = server {
        server.abort();
    }
}
