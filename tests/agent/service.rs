//! The agent as a service: a stop frees its port and its liveliness token;
//! finished parts are counted in its metrics and its daily report.

use std::time::Duration;

use super::Fixture;

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_stopped_agent_frees_its_port_and_its_liveliness_token() {
    let mut fx = Fixture::start().await;
    fx.settled().await;
    let token = "cellwatch/m01ps0004/agent/*";
    let alive = |client: zenoh::Session| async move {
        let replies = client
            .liveliness()
            .get(token)
            .timeout(Duration::from_secs(3))
            .await
            .unwrap();
        let mut n = 0;
        while replies.recv_async().await.is_ok() {
            n += 1;
        }
        n
    };
    // The client hears the token come and go (its current tokens first).
    let tokens = fx
        .client
        .liveliness()
        .declare_subscriber(token)
        .history(true)
        .await
        .unwrap();
    let next = |kind: zenoh::sample::SampleKind| {
        let tokens = &tokens;
        async move {
            loop {
                let sample = tokio::time::timeout(Duration::from_secs(30), tokens.recv_async())
                    .await
                    .unwrap_or_else(|_| panic!("no {kind:?} of the agent's token"))
                    .unwrap();
                if sample.kind() == kind {
                    break;
                }
            }
        }
    };
    next(zenoh::sample::SampleKind::Put).await;
    assert_eq!(alive(fx.client.clone()).await, 1);
    let agent = fx.agent.take().unwrap();
    let addr = agent.metrics_addr().unwrap();
    agent.stop().await;
    // Stop has returned: the port is free.
    std::net::TcpListener::bind(addr).unwrap();
    // The token is gone, once the client has heard the agent leave.
    next(zenoh::sample::SampleKind::Delete).await;
    assert_eq!(alive(fx.client.clone()).await, 0);
    fx.sim.stop();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn part_done_edges_are_counted_and_reported() {
    let fx = Fixture::start().await;
    fx.settled().await;
    let mut committed = fx.agent().committed();
    let before = *committed.borrow();
    for k in 1..=3 {
        // Each rising edge is one `part` row, committed before the next.
        fx.sim.set("X12.03", true).unwrap();
        committed.wait_for(|n| *n >= before + k).await.unwrap();
        fx.sim.set("X12.03", false).unwrap();
        fx.tag_is("X12.03", false).await;
    }
    let metrics = fx.scrape().await;
    assert!(
        metrics.contains("cellwatch_parts_produced_total{cell=\"m01ps0004\"} 3"),
        "{metrics}"
    );
    let journal = fx.config.journal.path.clone();
    fx.agent.unwrap().stop().await;
    fx.sim.stop();
    let today = cellwatch::clock::rfc3339(cellwatch::clock::now_ms())[..10].to_string();
    let run = crate::util::cellwatch(&[
        "report",
        "daily",
        "--date",
        &today,
        "--db",
        journal.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    let report: serde_json::Value = serde_json::from_str(&run.stdout).unwrap();
    assert_eq!(report["production"], 3, "{report:#}");
}
