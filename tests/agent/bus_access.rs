//! Who gets onto the bus and who is believed on it: only clients with a plant
//! certificate get in; through the shipped router nobody else publishes or
//! answers for a cell; the CLI believes only the agent.

use std::path::Path;
use std::time::Duration;

use cellwatch::payload::AlarmPayload;
use zenoh_ext::{AdvancedSubscriberBuilderExt, HistoryConfig, RecoveryConfig};

use super::{behind_a_router, Fixture};

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn only_clients_with_a_plant_certificate_get_in() {
    let fx = Fixture::start().await;
    let port = fx.zenoh_port;
    // Plain TCP to a TLS endpoint, and TLS without a client certificate
    // from the plant CA: nothing to talk to.
    let mut plain = crate::util::client_config(&fx.dir, "operator-kim", port);
    plain.connect = vec![format!("tcp/127.0.0.1:{port}")];
    plain.tls = None;
    assert!(cellwatch::bus::open(&plain).await.is_err());
    let elsewhere = fx.dir.join("elsewhere");
    crate::util::bus_pki(&elsewhere, &["operator-kim"]);
    let mut foreign = crate::util::client_config(&elsewhere, "operator-kim", port);
    // Trusting the plant CA is not enough: the certificate must be from it.
    foreign.tls.as_mut().unwrap().ca = fx.dir.join("pki-bus/ca.pem");
    assert!(cellwatch::bus::open(&foreign).await.is_err());
    // A certificate from the plant CA: queries and subscriptions work.
    fx.settled().await;
    fx.agent.unwrap().stop().await;
    fx.sim.stop();
}

/// A client-mode session of `name`'s certificate to the router on `port`.
async fn router_client(dir: &Path, name: &str, port: u16) -> zenoh::Session {
    crate::util::bus_pki(dir, &[name]);
    let mut c = crate::util::client_config(dir, name, port);
    c.mode = cellwatch::config::ZenohMode::Client;
    cellwatch::bus::open(&c).await.unwrap()
}

/// Through the shipped router, an intruder with a valid plant certificate
/// (an operator's) can neither publish an alarm for a cell nor answer for
/// it; the operator sees the agent's alarms and answers only.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn through_the_router_nobody_else_publishes_or_answers_for_the_cell() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let (_router, port, sim, agent) = behind_a_router(dir, true).await;
    let kim = router_client(dir, "operator-kim", port).await;
    let mallory = router_client(dir, "operator-mallory", port).await;
    let snapshot = |s: zenoh::Session| async move {
        let replies = s
            .get("cellwatch/m01ps0004/snapshot")
            .consolidation(zenoh::query::ConsolidationMode::None)
            .await
            .unwrap();
        let mut answers = Vec::new();
        while let Ok(r) = replies.recv_async().await {
            if let Ok(sample) = r.result() {
                answers.push(crate::util::opened_or_raw(sample.payload()));
            }
        }
        answers
    };
    // The agent is reachable through the router, for kim and for mallory.
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    while snapshot(kim.clone()).await.is_empty() {
        assert!(
            tokio::time::Instant::now() < deadline,
            "the agent never answered through the router"
        );
    }
    // Mallory declares an impostor queryable, then queries: her query
    // follows the declaration on the same link, so when it is answered the
    // router has judged the declaration too.
    let impostor = mallory
        .declare_queryable("cellwatch/m01ps0004/snapshot")
        .await
        .unwrap();
    let impostor_task = tokio::spawn(async move {
        while let Ok(q) = impostor.recv_async().await {
            let _ = q.reply(q.key_expr().clone(), r#"{"forged":true}"#).await;
        }
    });
    let command_impostor = mallory
        .declare_queryable("cellwatch/m01ps0004/command")
        .await
        .unwrap();
    let command_task = tokio::spawn(async move {
        while let Ok(q) = command_impostor.recv_async().await {
            let _ = q.reply(q.key_expr().clone(), r#"{"accepted":true}"#).await;
        }
    });
    assert!(!snapshot(mallory.clone()).await.is_empty());
    let answers = snapshot(kim.clone()).await;
    assert_eq!(answers.len(), 1, "{answers:?}");
    assert!(answers[0].contains("\"cell\":\"m01ps0004\""), "{answers:?}");
    // History and commands: the agent's answers only.
    let ask = |selector: &'static str, payload: Option<&'static str>| {
        let kim = kim.clone();
        async move {
            let mut get = kim
                .get(selector)
                .consolidation(zenoh::query::ConsolidationMode::None);
            if let Some(p) = payload {
                get = get.payload(p);
            }
            let replies = get.await.unwrap();
            let mut answers = Vec::new();
            while let Ok(r) = replies.recv_async().await {
                answers.push(match r.result() {
                    Ok(s) => crate::util::opened_or_raw(s.payload()),
                    Err(e) => crate::util::opened_or_raw(e.payload()),
                });
            }
            answers
        }
    };
    let history = ask("cellwatch/m01ps0004/history?since=1h", None).await;
    assert_eq!(history.len(), 1, "{history:?}");
    assert!(history[0].contains("cellwatch.history.v1"), "{history:?}");
    let command = ask("cellwatch/m01ps0004/command", Some("{}")).await;
    assert_eq!(command.len(), 1, "{command:?}");
    assert!(command[0].contains("\"accepted\":false"), "{command:?}");
    command_task.abort();
    // Mallory publishes forged alarms all along, before and after a real fault.
    // Kim subscribes as `cellwatch alarms --follow` does: an alarm put
    // before the router told the agent of the subscription is fetched from
    // the agent's cache.
    let sub = kim
        .declare_subscriber("cellwatch/m01ps0004/alarms/**")
        .history(HistoryConfig::default().detect_late_publishers())
        .recovery(RecoveryConfig::default().heartbeat())
        .await
        .unwrap();
    let forging = {
        let mallory = mallory.clone();
        tokio::spawn(async move {
            loop {
                let _ = mallory
                    .put(
                        "cellwatch/m01ps0004/alarms/ese",
                        r#"{"cell":"m01ps0004","id":"ese","forged":true}"#,
                    )
                    .await;
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
        })
    };
    sim.set("X0.06", false).unwrap();
    let mut transitions = Vec::new();
    while !transitions.iter().any(|t: &String| t == "cleared") {
        let sample = tokio::time::timeout_at(deadline, sub.recv_async())
            .await
            .unwrap_or_else(|_| panic!("ESE raised and cleared; saw {transitions:?}"))
            .unwrap();
        let text = crate::util::opened_or_raw(sample.payload());
        assert!(
            !text.contains("forged"),
            "a forged event got through: {text}"
        );
        let a: AlarmPayload = serde_json::from_str(&text).unwrap();
        if a.id == "ese" && a.transition.as_str() == "raised" {
            sim.set("X0.06", true).unwrap();
        }
        transitions.push(a.transition.as_str().to_string());
    }
    assert!(transitions.iter().any(|t| t == "raised"), "{transitions:?}");
    forging.abort();
    impostor_task.abort();
    agent.stop().await;
    sim.stop();
}

/// With a router whose access control is off, an impostor can answer the
/// `command` queryable: the CLI believes the agent's answer only.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn the_cli_believes_only_the_agent() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let (_router, port, sim, agent) = behind_a_router(dir, false).await;
    crate::util::bus_pki(dir, &["operator-kim"]);
    let mallory = router_client(dir, "operator-mallory", port).await;
    let impostor = mallory
        .declare_queryable("cellwatch/m01ps0004/command")
        .await
        .unwrap();
    let answered = std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let impostor_task = {
        let answered = answered.clone();
        tokio::spawn(async move {
            while let Ok(q) = impostor.recv_async().await {
                let _ = q
                    .reply(
                        q.key_expr().clone(),
                        r#"{"accepted":true,"detail":"ack no-such-alarm by kim"}"#,
                    )
                    .await;
                answered.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
            }
        })
    };
    let key_file = dir.join("kim.key");
    std::fs::write(&key_file, crate::spawned::kim().to_file()).unwrap();
    let mut args: Vec<String> = [
        "ack",
        "--cell",
        "m01ps0004",
        "--alarm",
        "no-such-alarm",
        "--mode",
        "client",
        "--key-file",
    ]
    .map(String::from)
    .to_vec();
    args.push(key_file.display().to_string());
    args.extend(crate::util::bus_args(dir, "operator-kim", port));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    for _ in 0..3 {
        let run = tokio::task::spawn_blocking({
            let args: Vec<String> = args.iter().map(|s| s.to_string()).collect();
            move || crate::util::cellwatch(&args.iter().map(String::as_str).collect::<Vec<_>>())
        })
        .await
        .unwrap();
        assert_eq!(run.code, 1, "{}{}", run.stdout, run.stderr);
        assert!(run.stdout.is_empty(), "{}", run.stdout);
        // The agent's refusal is what counts; the impostor's "accepted" is
        // named as ignored when it arrived first.
        assert!(
            run.stderr
                .ends_with("error: refused: no alarm 'no-such-alarm'\n"),
            "{}",
            run.stderr
        );
        // Plain text on a pipe: no terminal colour codes.
        assert!(!run.stderr.contains('\u{1b}'), "{}", run.stderr);
    }
    // The impostor did answer, and was not believed.
    assert!(answered.load(std::sync::atomic::Ordering::SeqCst) >= 1);
    // Mallory replays every real alarm event, altered: `alarms --follow`
    // prints the agent's events only.
    let mut follow: Vec<String> = [
        "alarms",
        "--cell",
        "m01ps0004",
        "--follow",
        "--json",
        "--mode",
        "client",
    ]
    .map(String::from)
    .to_vec();
    follow.extend(crate::util::bus_args(dir, "operator-kim", port));
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_cellwatch"))
        .args(&follow)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let lines = crate::util::lines_of(&mut child);
    let copier = mallory
        .declare_subscriber("cellwatch/m01ps0004/alarms/**")
        .await
        .unwrap();
    let replayed = std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let replaying = {
        let (mallory, replayed) = (mallory.clone(), replayed.clone());
        tokio::spawn(async move {
            while let Ok(sample) = copier.recv_async().await {
                let Ok(mut envelope) =
                    serde_json::from_slice::<serde_json::Value>(&sample.payload().to_bytes())
                else {
                    continue;
                };
                let body = envelope["body"].as_str().unwrap_or_default().to_string();
                // Not what she put herself.
                if body.contains("FORGED")
                    || body.is_empty()
                    || sample.key_expr().as_str().ends_with("/csd")
                {
                    continue;
                }
                // The agent's envelope, its text edited; and the agent's
                // envelope as it is, put on another alarm's key.
                envelope["body"] = body
                    .replace("\"message\":\"", "\"message\":\"FORGED ")
                    .into();
                let _ = mallory
                    .put(sample.key_expr().clone(), envelope.to_string())
                    .await;
                let _ = mallory
                    .put("cellwatch/m01ps0004/alarms/csd", sample.payload().clone())
                    .await;
                replayed.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
            }
        })
    };
    // Two faults, raised and cleared: the second comes after mallory has
    // replayed the first's events, so her copies travel while the follower
    // prints the second's.
    let mut printed: Vec<String> = Vec::new();
    let count = |printed: &[String], t: &str| {
        printed
            .iter()
            .filter(|l| l.contains(&format!("\"transition\":\"{t}\"")) && !l.contains("FORGED"))
            .count()
    };
    // Mallory's subscription may reach the agent after the first fault on
    // a loaded machine: faults go on until she has replayed one, then one
    // more.
    let mut replayed_in = None;
    for round in 1.. {
        for (value, transition) in [(false, "raised"), (true, "cleared")] {
            sim.set("X0.06", value).unwrap();
            while count(&printed, transition) < round {
                printed.push(
                    lines
                        .recv_timeout(Duration::from_secs(30))
                        .unwrap_or_else(|_| {
                            panic!("no ESE {transition} from alarms --follow: {printed:#?}")
                        }),
                );
            }
        }
        if replayed_in.is_some_and(|r| round > r) {
            break;
        }
        let deadline = tokio::time::Instant::now() + Duration::from_secs(5);
        while replayed.load(std::sync::atomic::Ordering::SeqCst) < 2
            && tokio::time::Instant::now() < deadline
        {
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        if replayed_in.is_none() && replayed.load(std::sync::atomic::Ordering::SeqCst) >= 2 {
            replayed_in = Some(round);
        }
        assert!(round < 10, "mallory never replayed in {round} faults");
    }
    assert!(replayed.load(std::sync::atomic::Ordering::SeqCst) >= 1);
    child.kill().unwrap();
    child.wait().unwrap();
    while let Ok(line) = lines.try_recv() {
        printed.push(line);
    }
    assert!(
        !printed
            .iter()
            .any(|l| l.contains("FORGED") || l.contains("\"id\":\"csd\"")),
        "{printed:#?}"
    );
    replaying.abort();
    impostor_task.abort();
    agent.stop().await;
    sim.stop();
}
