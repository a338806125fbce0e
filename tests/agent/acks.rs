//! Operators' acknowledgements over the bus: only a correctly signed one is
//! carried out, once, and every one, refused or not, is journaled.

use std::time::Duration;

use cellwatch::operator::Command;

use super::Fixture;

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn only_correctly_signed_acks_are_carried_out_and_all_are_journaled() {
    let fx = Fixture::start().await;
    fx.settled().await;
    fx.sim.set("X0.06", false).unwrap();
    // Wait for the alarm to be active.
    let deadline = tokio::time::Instant::now() + Duration::from_secs(20);
    loop {
        let snap: serde_json::Value = serde_json::from_str(
            &fx.query("cellwatch/m01ps0004/snapshot", None)
                .await
                .unwrap(),
        )
        .unwrap();
        if snap["alarms"]
            .as_array()
            .unwrap()
            .iter()
            .any(|a| a["id"] == "ese")
        {
            assert_eq!(snap["last_fault"]["alarm"], "ese");
            break;
        }
        assert!(tokio::time::Instant::now() < deadline);
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let now = cellwatch::clock::now_ms();
    let cmd = || Command {
        action: cellwatch::operator::Action::Ack,
        alarm: "ese".into(),
        tag: None,
        value: None,
        reason: None,
        operator: "kim".into(),
        nonce: cellwatch::operator::nonce(),
        issued_at: now,
        signature: String::new(),
    };
    let fxr = &fx;
    let send = |c: Command| {
        let json = serde_json::to_string(&c).unwrap();
        async move {
            let r: serde_json::Value = serde_json::from_str(
                &fxr.query("cellwatch/m01ps0004/command", Some(json))
                    .await
                    .unwrap(),
            )
            .unwrap();
            (
                r["accepted"].as_bool().unwrap(),
                r["detail"].as_str().unwrap().to_string(),
            )
        }
    };
    assert_eq!(send(cmd()).await, (false, "unsigned command".to_string()));
    let mut wrong = cmd();
    wrong.sign(
        "m01ps0004",
        &cellwatch::operator::OperatorKey::generate("kim"),
    );
    assert_eq!(send(wrong).await, (false, "bad signature".to_string()));
    let mut good = cmd();
    good.sign("m01ps0004", &crate::spawned::kim());
    assert_eq!(
        send(good.clone()).await,
        (true, "ack ese by kim".to_string())
    );
    // Sent again (an answer lost): a replay with its original outcome,
    // carried out once.
    assert_eq!(
        send(good).await,
        (
            false,
            "replayed command: sent before (accepted: ack ese by kim); not carried out again"
                .to_string()
        )
    );
    let snap: serde_json::Value = serde_json::from_str(
        &fx.query("cellwatch/m01ps0004/snapshot", None)
            .await
            .unwrap(),
    )
    .unwrap();
    let ese = snap["alarms"]
        .as_array()
        .unwrap()
        .iter()
        .find(|a| a["id"] == "ese")
        .unwrap()
        .clone();
    assert_eq!(ese["state"], "active_acknowledged");
    assert_eq!(ese["acked_by"], "kim");
    // Every command, refused or not, is in the journal.
    let deadline = tokio::time::Instant::now() + Duration::from_secs(10);
    loop {
        let rows = fx
            .history_rows("cellwatch/m01ps0004/history?since=1h;kind=command")
            .await;
        let outcomes: Vec<(bool, String)> = rows
            .iter()
            .map(|r| {
                (
                    r["fields"]["accepted"].as_bool().unwrap(),
                    r["fields"]["detail"].as_str().unwrap().to_string(),
                )
            })
            .collect();
        // The same command sent again is not a command of its own.
        if outcomes.len() == 3 {
            assert_eq!(
                outcomes,
                [
                    (false, "unsigned command".to_string()),
                    (false, "bad signature".to_string()),
                    (true, "ack ese by kim".to_string()),
                ]
            );
            break;
        }
        assert!(tokio::time::Instant::now() < deadline, "{outcomes:?}");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let _ = &fx.config;
    fx.agent.unwrap().stop().await;
    fx.sim.stop();
}
