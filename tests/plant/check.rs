//! `plant check` against a running plant says, per cell, what is wrong.

use std::time::Duration;

use cellwatch::sim::cnc::{SimOptions, SimulatedCnc};

use super::{as_on_host, cell_config, free_tcp_port, plant_async, plant_router, plant_router_with};

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn plant_check_says_per_cell_what_is_wrong_in_the_running_plant() {
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
    let r = run(s(&["init", "--router", "router-1=127.0.0.1"])).await;
    assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    let (m1, m2) = (free_tcp_port(), free_tcp_port());
    for (id, port) in [("m01", m1), ("m02", m2)] {
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
    // The router, from the configuration the plant made (its files under
    // the plant's tree, listening on a port of its own).
    let (router, port) = plant_router(&dir).await;
    let connect = format!("quic/127.0.0.1:{port}");

    // m01 as the plant made it; m02 signing with a key of its own.
    let c1 = as_on_host(&dir, "127.0.0.1", "m01", port);
    crate::util::trust_sim(&c1, &dir.join("sim-pki"));
    let a1 = cellwatch::agent::start(c1, None).await.unwrap();
    let mut c2 = as_on_host(&dir, "127.0.0.1", "m02", port);
    c2.zenoh.signing_key = Some(dir.join("stray.key"));
    crate::util::trust_sim(&c2, &dir.join("sim-pki"));
    let check = || run(s(&["check", "--connect", &connect, "--timeout", "10"]));

    // Checked until both agents are up and m01 is ready (every answer
    // waited for within the timeout; the readiness of a source that is
    // still connecting is said as such and asked again).
    let deadline = std::time::Instant::now() + Duration::from_secs(180);
    let r = loop {
        let r = check().await;
        if !r.stdout.contains("cell m01: ok") {
            assert!(
                std::time::Instant::now() < deadline,
                "never ok: {}{}",
                r.stdout,
                r.stderr
            );
            assert!(
                r.stdout.contains("its /readyz") || r.stdout.contains("does not answer"),
                "{}{}",
                r.stdout,
                r.stderr
            );
            continue;
        }
        break r;
    };
    assert_eq!(r.code, 1, "m02 is not running: {}{}", r.stdout, r.stderr);
    assert!(
        r.stdout
            .contains("cell m01: ok — its bus certificate until 2036-01-01, cellwatch"),
        "{}",
        r.stdout
    );
    assert!(
        r.stdout
            .contains("runs the configuration deployed, operators list v1, ready"),
        "{}",
        r.stdout
    );
    assert!(
        r.stdout
            .contains("cell m02: WRONG\n  - its agent does not answer on the bus"),
        "{}",
        r.stdout
    );
    assert!(
        r.stdout.contains("router router-1: ok — access control as the inventory says, its running access control keeps others from speaking for a cell"),
        "{}",
        r.stdout
    );

    // m02 up, with a key the trust file does not hold.
    let a2 = cellwatch::agent::start(c2, None).await.unwrap();
    let r = loop {
        let r = check().await;
        if r.stdout
            .contains("cell m02: WRONG\n  - its agent does not answer")
        {
            assert!(
                std::time::Instant::now() < deadline,
                "m02 never answered: {}",
                r.stdout
            );
            continue;
        }
        break r;
    };
    assert_eq!(r.code, 1, "{}{}", r.stdout, r.stderr);
    assert!(
        r.stdout.contains(
            "cell m02: WRONG\n  - its agent answers, but is not believed with the trust file's key"
        ),
        "{}",
        r.stdout
    );

    // m01's deployed configuration changed since the agent started.
    let deployed = dir.join("hosts/127.0.0.1/etc/cellwatch/m01.toml");
    let mut text = std::fs::read_to_string(&deployed).unwrap();
    text.push_str("# changed\n");
    std::fs::write(&deployed, text).unwrap();
    let r = check().await;
    assert!(
        r.stdout.contains(
            "its agent runs another configuration than hosts/127.0.0.1/etc/cellwatch/m01.toml"
        ),
        "{}",
        r.stdout
    );
    // A router running without the inventory's access control: the probe
    // comes through it.
    let (open_router, open_port) = plant_router_with(&dir, false).await;
    let r = plant_async(
        dir.clone(),
        vec![
            "check".into(),
            "--connect".into(),
            format!("quic/127.0.0.1:{open_port}"),
            "--timeout".into(),
            "2".into(),
        ],
    )
    .await;
    assert!(
        r.stdout.contains("router router-1: WRONG\n  - it carried a put under cellwatch/m01/_probe from the plant-admin certificate"),
        "{}",
        r.stdout
    );
    open_router.close().await;
    a1.stop().await;
    a2.stop().await;
    router.close().await;
    drop(sim);
}
