//! Every answer to a command is bound to that command: the agent's sealed
//! answer names the payload it answers (`command`, SHA-256), and the bus
//! client (the CLI's commands, the console's forwarding, the demo's
//! operator) believes only the answer naming its own. A command sent again
//! is answered as a replay, never as accepted, before a restart and after:
//! the journal keeps each command's digest with its nonce.

use std::time::Duration;

use cellwatch::bus::envelope::Kind;
use cellwatch::client::BusClient;
use cellwatch::operator::{Action, Command};

use crate::agent::Fixture;

const KEY: &str = "cellwatch/m01ps0004/command";

/// Kim's signed command.
fn signed(action: Action, alarm: &str, reason: Option<&str>) -> Command {
    let mut c = Command {
        action,
        alarm: alarm.into(),
        tag: None,
        value: None,
        reason: reason.map(str::to_string),
        operator: "kim".into(),
        nonce: cellwatch::operator::nonce(),
        issued_at: cellwatch::clock::now_ms(),
        signature: String::new(),
    };
    c.sign("m01ps0004", &crate::spawned::kim());
    c
}

/// Mallory stands between kim and the agent (a router, or any certificate
/// holder kim's session goes through). To kim's command query she first
/// asks the agent the same selector — kim's nonce — with a garbled payload,
/// with kim's command badly signed, and with an earlier command of kim's
/// the agent accepted, and hands kim those answers, genuinely sealed by the
/// agent for kim's query, before the answer to kim's own payload. Kim's
/// client believes only that last one.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn an_answer_to_another_payload_with_the_same_query_is_never_believed() {
    let fx = Fixture::start().await;
    let dir = fx.dir();
    fx.settled().await;
    let earlier =
        serde_json::to_string(&signed(Action::OutOfService, "csd", Some("sensor swap"))).unwrap();
    let (accepted, detail) = crate::spawned::send(fx.client(), &earlier).await;
    assert!(accepted, "{detail}");
    // Mallory: connected to the agent, listening for kim.
    crate::util::bus_pki(dir, &["operator-mallory"]);
    let mut config = crate::util::client_config(dir, "operator-mallory", fx.zenoh_port());
    config.listen = vec!["quic/127.0.0.1:0".into()];
    let mallory = cellwatch::bus::open(&config).await.unwrap();
    let mallory_port = crate::util::session_port(&mallory).await;
    let (handed_tx, handed) = std::sync::mpsc::channel::<(String, String, Vec<u8>)>();
    let relay = mallory.clone();
    let _queryable = mallory
        .declare_queryable(KEY)
        .callback(move |q| {
            let (relay, handed, earlier) = (relay.clone(), handed_tx.clone(), earlier.clone());
            tokio::spawn(async move {
                let params = q.parameters().as_str().to_string();
                let own = q
                    .payload()
                    .map(|p| p.to_bytes().to_vec())
                    .unwrap_or_default();
                let text = String::from_utf8(own.clone()).unwrap();
                let mut badly_signed: serde_json::Value = serde_json::from_str(&text).unwrap();
                badly_signed["signature"] = "00".repeat(64).into();
                let payloads = [
                    ("garbled", b"{\"action\":\"in-serv".to_vec()),
                    ("badly signed", badly_signed.to_string().into_bytes()),
                    ("earlier", earlier.into_bytes()),
                    ("own", own),
                ];
                for (what, payload) in payloads {
                    let replies = relay
                        .get(format!("{KEY}?{params}"))
                        .payload(payload)
                        .allowed_destination(zenoh::sample::Locality::Remote)
                        .await
                        .unwrap();
                    let reply = replies.recv_async().await.unwrap();
                    let bytes = reply.result().unwrap().payload().to_bytes().to_vec();
                    q.reply(KEY, bytes.clone()).await.unwrap();
                    handed.send((what.into(), params.clone(), bytes)).unwrap();
                }
            });
        })
        .await
        .unwrap();
    let kim = crate::util::operator_session(dir, "operator-kim", mallory_port).await;
    let bus = BusClient::on(kim, crate::util::trust(dir), "cellwatch");
    let cmd = signed(Action::InService, "csd", None);
    let answer = bus
        .command("m01ps0004", &cmd, Duration::from_secs(30))
        .await
        .unwrap();
    assert_eq!(answer, (true, "in-service csd by kim".to_string()));
    // What Mallory handed kim first was the agent's own, sealed for kim's
    // query: refused, not carried out, a replay.
    let trust = crate::util::trust(dir);
    let mut seen = Vec::new();
    for _ in 0..4 {
        let (what, params, bytes) = handed.recv_timeout(Duration::from_secs(30)).unwrap();
        let opened = trust.open(&bytes, Kind::Reply, KEY, &params).unwrap();
        let v: serde_json::Value = serde_json::from_str(&opened.body).unwrap();
        assert_eq!(v["accepted"], (what == "own"), "{what}: {v}");
        seen.push((what, v));
    }
    let digest = |payload: &[u8]| cellwatch::step::command_digest([payload]);
    let own = serde_json::to_string(&cmd).unwrap();
    assert_eq!(seen[3].1["command"], digest(own.as_bytes()));
    assert_eq!(seen[0].1["command"], digest(b"{\"action\":\"in-serv"));
    assert!(
        seen[2].1["detail"]
            .as_str()
            .unwrap()
            .starts_with("replayed command: sent before (accepted: "),
        "{}",
        seen[2].1
    );
    assert_eq!(seen[2].1["replayed"]["accepted"], true);
}

/// The same signed command sent again by someone else is answered as a
/// replay, what it first came to beside, and is not carried out again;
/// another command with a used nonce gets nobody's outcome.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_command_sent_again_is_answered_as_a_replay() {
    let fx = Fixture::start().await;
    fx.settled().await;
    let cmd = signed(Action::OutOfService, "csd", Some("sensor swap"));
    let payload = serde_json::to_string(&cmd).unwrap();
    let first = crate::spawned::send(fx.client(), &payload).await;
    assert_eq!(first, (true, "out-of-service csd by kim".to_string()));
    let again = crate::spawned::send(fx.client(), &payload).await;
    assert_eq!(
        again,
        (
            false,
            "replayed command: sent before (accepted: out-of-service csd by kim); \
             not carried out again"
                .to_string()
        )
    );
    // Kim's client, sending its own command again (its first answer lost),
    // gets what it came to, said to be the first sending's.
    let bus = BusClient::on(
        fx.client().clone(),
        crate::util::trust(fx.dir()),
        "cellwatch",
    );
    let (accepted, detail) = bus
        .command("m01ps0004", &cmd, Duration::from_secs(30))
        .await
        .unwrap();
    assert!(accepted);
    assert_eq!(
        detail,
        "out-of-service csd by kim (sent before: the outcome of its first sending; \
         not carried out again)"
    );
    // The same nonce on another command, signed: a plain replay refusal.
    let mut other = Command {
        action: Action::InService,
        reason: None,
        signature: String::new(),
        ..cmd.clone()
    };
    other.sign("m01ps0004", &crate::spawned::kim());
    let (accepted, detail) =
        crate::spawned::send(fx.client(), &serde_json::to_string(&other).unwrap()).await;
    assert!(!accepted);
    assert_eq!(detail, "replayed command (nonce already used)");
    // Carried out once; the other command's refusal journaled beside.
    let rows = fx
        .history_rows("cellwatch/m01ps0004/history?kind=command")
        .await;
    let of_nonce = rows
        .iter()
        .filter(|r| r["fields"]["nonce"] == cmd.nonce.as_str())
        .count();
    assert_eq!(of_nonce, 2, "{rows:#?}");
}

/// After a restart, a command sent again is known by its digest, kept in
/// the journal with its nonce: the same signed command gets its own first
/// outcome, and another command of the same operator and action with the
/// same nonce (kim's earlier out-of-service of csd, its reason changed and
/// signed again) gets nobody's, as before the restart.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn after_a_restart_a_replay_is_matched_by_its_digest() {
    let mut fx = Fixture::start().await;
    fx.settled().await;
    let cmd = signed(Action::OutOfService, "csd", Some("sensor swap"));
    let payload = serde_json::to_string(&cmd).unwrap();
    let first = crate::spawned::send(fx.client(), &payload).await;
    assert_eq!(first, (true, "out-of-service csd by kim".to_string()));
    let mut other = Command {
        reason: Some("cable cut".into()),
        signature: String::new(),
        ..cmd.clone()
    };
    other.sign("m01ps0004", &crate::spawned::kim());
    let other = serde_json::to_string(&other).unwrap();
    let refused = (false, "replayed command (nonce already used)".to_string());
    assert_eq!(crate::spawned::send(fx.client(), &other).await, refused);

    fx.restart().await;
    let replayed = (
        false,
        "replayed command: sent before (accepted: out-of-service csd by kim); \
         not carried out again"
            .to_string(),
    );
    // Its JSON spaced otherwise: the same signed command.
    let spaced = serde_json::to_string_pretty(&cmd).unwrap();
    assert_eq!(crate::spawned::send(fx.client(), &spaced).await, replayed);
    assert_eq!(crate::spawned::send(fx.client(), &other).await, refused);
    assert_eq!(crate::spawned::send(fx.client(), &payload).await, replayed);
    // Carried out once; each command's rows keep its digest.
    let journal = rusqlite::Connection::open(fx.journal_path()).unwrap();
    let rows: Vec<(bool, bool, Option<String>)> = journal
        .prepare("SELECT accepted, verified, digest FROM commands WHERE nonce = ?1 ORDER BY seq")
        .unwrap()
        .query_map([&cmd.nonce], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    let own = Some(hex::encode(cmd.digest()));
    assert_eq!(rows[0], (true, true, own.clone()), "{rows:?}");
    assert_eq!(rows.iter().filter(|r| r.0).count(), 1, "{rows:?}");
    assert!(rows.iter().all(|r| r.2.is_some()), "{rows:?}");
    fx.stop().await;
}
