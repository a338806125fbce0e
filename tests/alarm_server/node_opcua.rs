//! node-opcua's SCADA acknowledges and shelves ESE, and finds it again after
//! a restart.

use cellwatch::operator::Action;

use super::{commands_journaled, kim_says, serving, ScadaProgram};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_node_opcua_scada_acknowledges_and_shelves_ese_and_finds_it_after_a_restart() {
    let fx = serving().await;
    let addr = fx.agent().alarm_server_addr().unwrap();
    let url = format!("opc.tcp://127.0.0.1:{}", addr.port());
    let mut scada = ScadaProgram::connected(
        &url,
        &fx.dir().join("node-scada-pki"),
        &fx.dir().join("alarm-server-pki"),
        "scada-kim",
    );

    // The SCADA's session is counted.
    let line = "cellwatch_alarm_server_sessions{cell=\"m01ps0004\"} ";
    let scraped = fx.scrape().await;
    assert!(
        scraped.lines().any(|l| l == format!("{line}1")),
        "{scraped}"
    );
    fx.settled().await;
    fx.sim.set("X0.06", false).unwrap();
    let raised = scada.event("ESE raised", |e| {
        e["conditionName"] == "ese" && e["active"] == true
    });
    assert_eq!(raised["sourceName"], "m01ps0004");
    assert_eq!(raised["acked"], false);
    assert_eq!(raised["retain"], true);
    assert!(
        raised["message"].as_str().unwrap().contains("X0.06"),
        "{raised}"
    );
    assert!(
        raised["culprits"]
            .as_str()
            .unwrap()
            .contains("X0.06 = 0 (expected 1)"),
        "{raised}"
    );
    assert!(
        raised["eventType"]
            .as_str()
            .unwrap()
            .ends_with(";s=CellAlarmType"),
        "{raised}"
    );
    let severity = raised["severity"].as_u64().unwrap();
    assert!([250, 500, 750, 1000].contains(&severity), "{raised}");
    let condition = raised["conditionId"].as_str().unwrap().to_string();
    let event_id = raised["eventId"].as_str().unwrap().to_string();

    // An old event id is refused; the latest is taken, with the comment.
    assert_eq!(
        scada.ask(&format!("ack {condition} 00ff nothing"), "ack "),
        "BadEventIdUnknown"
    );
    assert_eq!(
        scada.ask(
            &format!("ack {condition} {event_id} seen on WinCC, tool changed"),
            "ack "
        ),
        "Good"
    );
    let acked = scada.event("ESE acknowledged", |e| {
        e["conditionName"] == "ese" && e["acked"] == true
    });
    assert_eq!(acked["clientUserId"], "kim");
    assert_eq!(acked["comment"], "seen on WinCC, tool changed");
    assert_eq!(acked["active"], true);
    assert_eq!(acked["suppressedOrShelved"], false);
    assert_eq!(
        scada.ask(
            &format!(
                "ack {condition} {} again",
                acked["eventId"].as_str().unwrap()
            ),
            "ack "
        ),
        "BadConditionBranchAlreadyAcked"
    );

    // A refresh: ESE between the refresh's start (i=2787) and end (i=2788).
    assert_eq!(scada.ask("refresh", "refresh "), "Good");
    let is = |e: &serde_json::Value, id: &str| {
        e["eventType"] == format!("ns=0;{id}") || e["eventType"] == id
    };
    scada.event("the refresh's start", |e| is(e, "i=2787"));
    let mut retained = Vec::new();
    loop {
        let e = scada.event("the refresh's end", |_| true);
        if is(&e, "i=2788") {
            break;
        }
        retained.push((
            e["conditionName"].clone(),
            e["active"].clone(),
            e["acked"].clone(),
        ));
    }
    assert_eq!(
        retained,
        [(
            serde_json::json!("ese"),
            serde_json::json!(true),
            serde_json::json!(true)
        )]
    );
    // Journaled with kim's comment, before the answer.
    commands_journaled(
        &fx,
        &[(
            true,
            "kim",
            "ack ese by kim: seen on WinCC, tool changed",
            "opcua user scada-kim",
        )],
    )
    .await;

    // Shelved by an operator on the bus: the SCADA sees it shelved, then
    // back.
    let (ok, detail) = kim_says(&fx, Action::Shelve).await;
    assert!(ok, "{detail}");
    scada.event("ESE shelved", |e| {
        e["conditionName"] == "ese" && e["suppressedOrShelved"] == true
    });
    let (ok, detail) = kim_says(&fx, Action::Unshelve).await;
    assert!(ok, "{detail}");
    scada.event("ESE unshelved", |e| {
        e["conditionName"] == "ese" && e["suppressedOrShelved"] == false
    });

    // Shelved from the SCADA, through its ShelvingState's methods, as kim.
    let shelving = format!("{condition}.ShelvingState");
    let call = |method: &str, ms: Option<u64>| {
        let ms = ms.map_or(String::new(), |ms| format!(" {ms}"));
        format!("call {shelving} {method}{ms}")
    };
    let (timed, one_shot, unshelve) = ("i=2949", "i=2948", "i=2947");
    // 30 days: longer than commands.max_shelve (8 h unless set).
    assert_eq!(
        scada.ask(&call(timed, Some(30 * 24 * 3_600_000)), "call "),
        "BadShelvingTimeOutOfRange"
    );
    assert_eq!(scada.ask(&call(timed, Some(600_000)), "call "), "Good");
    let shelved = scada.event("ESE shelved from the SCADA", |e| {
        e["conditionName"] == "ese" && e["shelving"] == "ns=0;i=2932"
    });
    assert_eq!(shelved["suppressedOrShelved"], true);
    assert_eq!(
        scada.ask(&call(one_shot, None), "call "),
        "BadConditionAlreadyShelved"
    );
    assert_eq!(scada.ask(&call(unshelve, None), "call "), "Good");
    scada.event("ESE unshelved from the SCADA", |e| {
        e["conditionName"] == "ese" && e["shelving"] == "ns=0;i=2930"
    });
    assert_eq!(
        scada.ask(&call(unshelve, None), "call "),
        "BadConditionNotShelved"
    );
    assert_eq!(scada.ask(&call(one_shot, None), "call "), "Good");
    scada.event("ESE shelved once from the SCADA", |e| {
        e["conditionName"] == "ese" && e["shelving"] == "ns=0;i=2933"
    });
    let shelves: Vec<(String, String)> = fx
        .history_rows("cellwatch/m01ps0004/history?since=1h;kind=command")
        .await
        .iter()
        .filter(|r| r["fields"]["source"] == "opcua user scada-kim")
        .map(|r| {
            let f = |k: &str| r["fields"][k].as_str().unwrap_or_default().to_string();
            (f("action"), f("detail"))
        })
        .collect();
    assert_eq!(
        shelves[1..],
        [
            (
                "shelve".into(),
                "shelve for 2592000000ms: at most 8h on this cell".into()
            ),
            ("shelve".into(), "shelve ese by kim".into()),
            ("unshelve".into(), "unshelve ese by kim".into()),
            ("shelve".into(), "shelve ese by kim".into()),
        ]
    );

    // The agent restarts: ESE, restored from the journal, is on its alarm
    // server again for a SCADA that refreshes, active and acknowledged by
    // kim, with her comment.
    drop(scada);
    let config = fx.config().clone();
    let mut fx = fx;
    fx.stop().await;
    let again = cellwatch::agent::start(config, None).await.unwrap();
    let url = format!("opc.tcp://{}", again.alarm_server_addr().unwrap());
    let (scada_pki, server_pki) = (
        fx.dir().join("node-scada-pki"),
        fx.dir().join("alarm-server-pki"),
    );
    let mut scada = tokio::task::spawn_blocking(move || {
        ScadaProgram::connected(&url, &scada_pki, &server_pki, "scada-kim")
    })
    .await
    .unwrap();
    assert_eq!(scada.ask("refresh", "refresh "), "Good");
    let restored = scada.event("ESE after the restart", |e| e["conditionName"] == "ese");
    assert_eq!(
        (
            &restored["active"],
            &restored["acked"],
            &restored["clientUserId"],
            &restored["comment"]
        ),
        (
            &serde_json::json!(true),
            &serde_json::json!(true),
            &serde_json::json!("kim"),
            &serde_json::json!("seen on WinCC, tool changed")
        )
    );
    drop(scada);
    again.stop().await;
}
