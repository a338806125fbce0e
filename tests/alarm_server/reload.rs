//! A reload reads the alarm server's users and the operators again.

use cellwatch::operator::Action;

use super::{kim_says, serving, ScadaProgram};

/// A reload (SIGHUP, `cellwatch reload`) reads the alarm server's users
/// and the operators again: a session already open acknowledges as the
/// operator its user acts as now, and an operator taken out of the file
/// is refused at once.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_reload_reads_the_users_and_the_operators_again() {
    let mut fx = serving().await;
    let url = format!("opc.tcp://{}", fx.agent().alarm_server_addr().unwrap());
    let mut scada = ScadaProgram::connected(
        &url,
        &fx.dir().join("node-scada-pki"),
        &fx.dir().join("alarm-server-pki"),
        "scada-lee",
    );
    fx.settled().await;
    fx.sim.set("X0.06", false).unwrap();
    let raised = scada.event("ESE raised", |e| {
        e["conditionName"] == "ese" && e["active"] == true
    });
    let ack = format!(
        "ack {} {} seen",
        raised["conditionId"].as_str().unwrap(),
        raised["eventId"].as_str().unwrap()
    );
    // scada-lee acts as lee, whom the operators file does not name.
    assert_eq!(scada.ask(&ack, "ack "), "BadUserAccessDenied");

    // Lee's account now acts as kim: read again, the open session's
    // acknowledgement is kim's.
    let users = fx.dir().join("opcua-users.toml");
    let text = std::fs::read_to_string(&users).unwrap();
    let changed = text.replacen("operator = \"lee\"", "operator = \"kim\"", 1);
    assert_ne!(text, changed);
    std::fs::write(&users, changed).unwrap();
    let config = fx.config().clone();
    fx.agent.as_mut().unwrap().reload(&config).await.unwrap();
    // (The reload carries ESE over to the checks read again: a new event,
    // whose id an acknowledgement names.)
    assert_eq!(scada.ask("refresh", "refresh "), "Good");
    scada.event("the refresh's start", |e| {
        e["eventType"] == "ns=0;i=2787" || e["eventType"] == "i=2787"
    });
    let latest = scada.event("ESE, refreshed", |e| e["conditionName"] == "ese");
    let ack = format!(
        "ack {} {} seen",
        latest["conditionId"].as_str().unwrap(),
        latest["eventId"].as_str().unwrap()
    );
    assert_eq!(scada.ask(&ack, "ack "), "Good");
    let acked = scada.event("ESE acknowledged", |e| {
        e["conditionName"] == "ese" && e["acked"] == true
    });
    assert_eq!(acked["clientUserId"], "kim");

    // Kim taken out of the operators file: read again, her signed
    // command is refused.
    let operators = config.operators_file.clone().unwrap();
    let text = std::fs::read_to_string(&operators).unwrap();
    let without_kim: String = text
        .split_inclusive('\n')
        .scan(false, |in_kim, line| {
            if line.starts_with("[operators.") {
                *in_kim = line.starts_with("[operators.kim]");
            }
            Some(if *in_kim { "" } else { line })
        })
        .collect();
    assert!(!without_kim.contains("[operators.kim]") && without_kim.contains("[operators.ana]"));
    std::fs::write(&operators, without_kim).unwrap();
    let (ok, detail) = kim_says(&fx, Action::Shelve).await;
    assert!(ok, "kim may shelve before the reload: {detail}");
    fx.agent.as_mut().unwrap().reload(&config).await.unwrap();
    let (ok, detail) = kim_says(&fx, Action::Unshelve).await;
    assert!(!ok && detail.contains("unknown operator 'kim'"), "{detail}");
    // A users file that does not read is refused; the running users go on.
    std::fs::write(&users, "[users.x]\n").unwrap();
    let refused = fx
        .agent
        .as_mut()
        .unwrap()
        .reload(&config)
        .await
        .unwrap_err();
    assert!(
        refused
            .to_string()
            .contains("missing field `password_hash`"),
        "{refused}"
    );
}
