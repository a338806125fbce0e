//! A key revoked in the inventory reaches every agent at once.

use std::path::Path;
use std::time::Duration;

use cellwatch::sim::cnc::{SimOptions, SimulatedCnc};

use super::{
    admin_client, agent_config, cell_config, free_tcp_port, kim_acks, plant_async, plant_router,
};

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_key_revoked_in_the_inventory_reaches_every_agent_at_once() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path().to_path_buf();
    let sim = SimulatedCnc::start(&SimOptions {
        listen: "127.0.0.1:0".parse().unwrap(),
        pki_dir: dir.join("sim-pki"),
        insecure: false,
        decoy: None,
    })
    .await
    .unwrap();
    let run = |args: Vec<String>| plant_async(dir.clone(), args);
    let s = |v: &[&str]| v.iter().map(|a| a.to_string()).collect::<Vec<_>>();
    assert_eq!(
        run(s(&["init", "--router", "router-1=127.0.0.1"]))
            .await
            .code,
        0
    );
    for (id, port) in [("m01", free_tcp_port()), ("m02", free_tcp_port())] {
        let config = cell_config(&dir, id);
        let r = run(s(&[
            "add-cell",
            "--cell",
            id,
            "--area",
            "machining",
            "--host",
            "127.0.0.1",
            "--plc",
            &sim.endpoint(),
            "--config",
            &config,
            "--metrics",
            &port.to_string(),
        ]))
        .await;
        assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    }
    let kim = cellwatch::operator::OperatorKey::generate("kim");
    let lee = cellwatch::operator::OperatorKey::generate("lee");
    for (name, key) in [("kim", &kim), ("lee", &lee)] {
        let r = run(s(&[
            "add-operator",
            "--name",
            name,
            "--public-key",
            &key.public_hex(),
            "--allow",
            "ack",
        ]))
        .await;
        assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    }
    let list_version = |dir: &Path| {
        let v: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.join("operators.signed.json")).unwrap())
                .unwrap();
        let list: serde_json::Value = serde_json::from_str(v["list"].as_str().unwrap()).unwrap();
        list["version"].as_u64().unwrap()
    };
    let v1 = list_version(&dir);
    let first_list = std::fs::read(dir.join("operators.signed.json")).unwrap();

    // The router and both agents, as the plant made them.
    let (router, port) = plant_router(&dir).await;
    let connect = format!("quic/127.0.0.1:{port}");
    let c1 = agent_config(&dir, "m01", port);
    crate::util::trust_sim(&c1, &dir.join("sim-pki"));
    let journal1 = c1.journal.path.clone();
    let a1 = cellwatch::agent::start(c1, None).await.unwrap();
    let c2 = agent_config(&dir, "m02", port);
    crate::util::trust_sim(&c2, &dir.join("sim-pki"));
    let a2 = cellwatch::agent::start(c2, None).await.unwrap();
    let bus = admin_client(&dir, port).await;
    // Kim is known to both agents (the list they started with).
    for cell in ["m01", "m02"] {
        let (_, detail) = kim_acks(&bus, &kim, cell).await;
        assert!(!detail.contains("unknown operator"), "{cell}: {detail}");
    }

    // Kim revoked in the inventory: one edit, the plant made again.
    let inventory = dir.join("plant.toml");
    let mut doc: toml_edit::DocumentMut = std::fs::read_to_string(&inventory)
        .unwrap()
        .parse()
        .unwrap();
    doc["operators"]
        .as_table_mut()
        .unwrap()
        .remove("kim")
        .unwrap();
    std::fs::write(&inventory, doc.to_string()).unwrap();
    let r = run(s(&["init"])).await;
    assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    assert_eq!(list_version(&dir), v1 + 1);

    // m02 is down when the list is published: m01 takes it, m02 is named.
    a2.stop().await;
    let r = run(s(&["publish", "--connect", &connect, "--timeout", "10"])).await;
    assert_eq!(r.code, 1, "{}{}", r.stdout, r.stderr);
    assert!(
        r.stdout
            .contains(&format!("cell m01: judges by operators list v{}", v1 + 1)),
        "{}",
        r.stdout
    );
    assert!(
        r.stderr.contains("not taken by 1 of 2 cells"),
        "{}",
        r.stderr
    );
    let (accepted, detail) = kim_acks(&bus, &kim, "m01").await;
    assert!(
        !accepted && detail.contains("unknown operator 'kim'"),
        "{detail}"
    );
    let (_, detail) = kim_acks(&bus, &lee, "m01").await;
    assert!(!detail.contains("unknown operator"), "lee stays: {detail}");
    // ... journaled as the plant's change.
    let c = rusqlite::Connection::open(&journal1).unwrap();
    let taken: String = c
        .query_row(
            "SELECT detail FROM commands WHERE source = 'plant' ORDER BY seq DESC LIMIT 1",
            [],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!(
        taken,
        format!("plant operators list v{} taken: -kim", v1 + 1)
    );

    // m02 back with the list it kept (v1): it catches up from m01 at start.
    let a2 = cellwatch::agent::start(agent_config(&dir, "m02", port), None)
        .await
        .unwrap();
    let deadline = std::time::Instant::now() + Duration::from_secs(120);
    loop {
        let (_, detail) = kim_acks(&bus, &kim, "m02").await;
        if detail.contains("unknown operator 'kim'") {
            break;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "m02 never took the newer list: {detail}"
        );
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    // Every cell now judges by the newest list, and keeps it.
    let r = run(s(&["publish", "--connect", &connect, "--timeout", "20"])).await;
    assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    let kept = std::fs::read_to_string(dir.join("state-m02/plant-operators.json")).unwrap();
    assert!(
        kept.contains(&format!("\\\"version\\\":{}", v1 + 1)),
        "{kept}"
    );

    // The older list put again (a replay) is not taken: kim stays revoked.
    bus.session()
        .put("cellwatch/_plant/operators", first_list)
        .await
        .unwrap();
    let r = run(s(&["check", "--connect", &connect, "--timeout", "10"])).await;
    assert!(
        !r.stdout.contains("its agent judges commands by"),
        "{}",
        r.stdout
    );
    let (_, detail) = kim_acks(&bus, &kim, "m01").await;
    assert!(detail.contains("unknown operator 'kim'"), "{detail}");
    a1.stop().await;
    a2.stop().await;
    router.close().await;
    drop(sim);
}
