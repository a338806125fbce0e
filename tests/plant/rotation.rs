//! An agent's signing key rotated with an overlap, and its bus certificate
//! renewed: every step said by `plant check` against the running agent.

use std::time::Duration;

use super::{agent_config, plant_async, plant_router};

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_signing_key_is_rotated_with_an_overlap_and_a_certificate_renewed() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path().to_path_buf();
    let sim = super::one_cell_plant(&dir).await;
    let run =
        |args: &[&str]| plant_async(dir.clone(), args.iter().map(|a| a.to_string()).collect());
    let (router, port) = plant_router(&dir).await;
    let connect = format!("quic/127.0.0.1:{port}");
    let start = || async {
        let c = agent_config(&dir, "m01", port);
        crate::util::trust_sim(&c, &dir.join("sim-pki"));
        cellwatch::agent::start(c, None).await.unwrap()
    };
    // The plant's check, until m01's agent answers and is ready.
    let check = || async {
        let deadline = std::time::Instant::now() + Duration::from_secs(180);
        loop {
            let r = run(&["check", "--connect", &connect, "--timeout", "10"]).await;
            if r.stdout.contains("does not answer") || r.stdout.contains("its /readyz") {
                assert!(
                    std::time::Instant::now() < deadline,
                    "never up: {}",
                    r.stdout
                );
                continue;
            }
            return r;
        }
    };
    let agent = start().await;
    let r = check().await;
    assert!(r.stdout.contains("cell m01: ok"), "{}", r.stdout);

    // Rotation begun: the trust file believes the old key and the new; the
    // agent still signs with the old one.
    let r = run(&["rotate-key", "--cell", "m01"]).await;
    assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    assert!(
        r.stdout
            .contains("the trust file holds cell m01's old and new keys"),
        "{}",
        r.stdout
    );
    assert!(std::fs::read_to_string(dir.join("trust.toml"))
        .unwrap()
        .contains("previous_keys = ["));
    let r = check().await;
    assert_eq!(r.code, 1, "{}", r.stdout);
    assert!(
        r.stdout
            .contains("its agent still signs with the key it is being rotated from"),
        "{}",
        r.stdout
    );
    assert!(
        r.stdout
            .contains("the rotation of its signing key is under way"),
        "{}",
        r.stdout
    );

    // The new key deployed: believed, the rotation still to end.
    agent.stop().await;
    let agent = start().await;
    let r = check().await;
    assert!(
        !r.stdout.contains("still signs with the key"),
        "{}",
        r.stdout
    );
    assert!(
        r.stdout
            .contains("the rotation of its signing key is under way"),
        "{}",
        r.stdout
    );
    let r = run(&["rotate-key", "--cell", "m01", "--done"]).await;
    assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    assert!(!std::fs::read_to_string(dir.join("trust.toml"))
        .unwrap()
        .contains("previous_keys"));
    let r = check().await;
    assert!(r.stdout.contains("cell m01: ok"), "{}", r.stdout);

    // The certificate renewed: the agent runs with the old one until
    // restarted.
    let r = run(&["renew", "--cell", "m01"]).await;
    assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    let r = check().await;
    assert!(r.stdout.contains("its agent runs with another bus certificate than hosts/127.0.0.1/etc/cellwatch/agent-m01.pem"), "{}", r.stdout);
    agent.stop().await;
    let agent = start().await;
    let r = check().await;
    assert!(r.stdout.contains("cell m01: ok"), "{}", r.stdout);
    assert_eq!(r.code, 0, "{}", r.stdout);
    agent.stop().await;
    router.close().await;
    drop(sim);
}
