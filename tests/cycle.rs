//! A publishing cycle the server splits over several publishes is judged
//! in source-time order as a whole: the server (async-opcua's, as any
//! server may) puts a cycle's changes into publishes in its own order of
//! items, so a later change of one contact can come a publish before an
//! earlier change of another. Taken publish by publish, two contacts that
//! were never closed together would be seen closed together for an
//! instant — a fault that never was.
//!
//! The items are sampled at `0` (every change): async-opcua's server
//! re-stamps a change that comes sooner than the sampling interval after
//! the last one to the next sample's time, which can put A's and B's
//! changes in either order when a round follows the last within 50 ms.

use cellwatch::sim::cnc::SimOptions;
use opcua::types::DateTime;

use crate::robust::{bus_metrics_journal, started};
use crate::spawned::snapshot_until;

/// Changes of other tags in each cycle besides the two contacts: more than
/// the 100 a publish may carry, so that every cycle is split.
const NOISE: usize = 160;

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn two_contacts_never_closed_together_raise_nothing_when_the_server_splits_the_cycle() {
    // The agent asks 100 a publish, and the server grants them.
    split_cycles(100, 0).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_server_that_sends_fewer_than_asked_is_found_out_and_its_cycles_judged_whole() {
    // The agent asks the default 10,000; the server sends 100 at most and
    // does not say so.
    split_cycles(10_000, 100).await;
}

/// Rounds of cycles of more than 100 changes in which A and B are never
/// closed together, the agent asking `asked` notifications a publish of
/// a server that sends `server_cap` at most (0: as many as asked).
async fn split_cycles(asked: u32, server_cap: u64) {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let noise = |k: usize| format!("N{k:03}");
    let mut initial = vec![("A".to_string(), false), ("B".to_string(), true)];
    initial.extend((0..NOISE).map(|k| (noise(k), false)));
    let server = cellwatch::sim::server::SimServer::start_sending_at_most(
        &SimOptions {
            listen: "127.0.0.1:0".parse().unwrap(),
            pki_dir: dir.join("sim-pki"),
            insecure: false,
            decoy: None,
        },
        "cnc",
        "cellwatch simulated PLC",
        &initial,
        server_cap,
    )
    .await
    .unwrap();
    // BOTH while A and B are closed together, which never happens: B
    // opens before A closes, A opens before B closes.
    std::fs::write(dir.join("both.il"), "LD A\nAND B\nST BOTH\n").unwrap();
    let tags: String = initial
        .iter()
        .map(|(a, _)| {
            format!(
                "[[tags]]\nname = \"{}\"\nnode_id = \"ns=2;s={a}\"\naddress = \"{a}\"\n\n",
                a.to_lowercase()
            )
        })
        .collect();
    let path = |p: &std::path::Path| format!("{:?}", p.display().to_string());
    let file = dir.join("cell.toml");
    std::fs::write(
        &file,
        format!(
            r#"[cell]
id = "m01ps0004"

[opcua]
endpoint = "{}"
pki_dir = {}
namespace_uri = "urn:cellwatch:sim:cnc:plc"
max_notifications_per_publish = {asked}
sampling_interval = "0"

{tags}[[checks.switching]]
id = "both"
program = "both.il"
dialect = "iec"
coil = "BOTH"
fault_when = "on"
severity = "high"

{}"#,
            server.endpoint(),
            path(&dir.join("agent-pki")),
            bus_metrics_journal(dir),
        ),
    )
    .unwrap();
    let (agent, client, sub) = started(dir, &file).await;
    let seen = |a: bool, b: bool| {
        let client = client.clone();
        async move {
            snapshot_until(&client, &format!("A = {a}, B = {b}"), |s| {
                let value = |address: &str| {
                    s["tags"]
                        .as_array()
                        .unwrap()
                        .iter()
                        .find(|t| t["address"] == address)
                        .map(|t| t["value"].clone())
                };
                s["connected"] == true
                    && value("A") == Some(a.into())
                    && value("B") == Some(b.into())
            })
            .await;
        }
    };
    seen(false, true).await;
    let at = |ms: i64| DateTime::from(chrono::Utc::now() + chrono::Duration::milliseconds(ms));
    // Each round two cycles of more than 100 changes, of varying sizes so
    // that the server's cut falls between A and B in some of them: then,
    // whichever the server's order of the two items, in one of the two
    // kinds of cycle the later change comes a publish before the earlier.
    let mut noise_now = [false; NOISE];
    let mut flip = |count: usize| -> Vec<(String, bool, DateTime)> {
        (0..count)
            .map(|k| {
                noise_now[k] = !noise_now[k];
                (noise(k), noise_now[k], at(-20))
            })
            .collect()
    };
    if server_cap > 0 {
        // A cycle of noise alone, split by the server: its two publishes,
        // stamped alike, the first not full by what the agent asked, tell
        // the agent the server's limit before A and B move.
        server.set_each_at(&flip(NOISE)).unwrap();
        snapshot_until(&client, "every noise tag set", |s| {
            s["tags"]
                .as_array()
                .unwrap()
                .iter()
                .filter(|t| t["address"].as_str().is_some_and(|a| a.starts_with('N')))
                .all(|t| t["value"] == true)
        })
        .await;
    }
    for round in 0..12usize {
        let count = NOISE - 4 * round;
        let mut opening = flip(count);
        opening.extend([
            ("B".to_string(), false, at(0)),
            ("A".to_string(), true, at(5)),
        ]);
        server.set_each_at(&opening).unwrap();
        seen(true, false).await;
        // The others back only in part: each cycle a size of its own.
        let mut closing = flip(NOISE - 3 * round - 1);
        closing.extend([
            ("A".to_string(), false, at(0)),
            ("B".to_string(), true, at(5)),
        ]);
        server.set_each_at(&closing).unwrap();
        seen(false, true).await;
    }
    let mut raised = Vec::new();
    while let Ok(Some(sample)) = sub.try_recv() {
        raised.push(crate::util::opened_or_raw(sample.payload()));
    }
    assert!(
        !raised.iter().any(|p| p.contains("\"both\"")),
        "BOTH raised: {raised:?}"
    );
    let metrics = crate::util::scrape(agent.metrics_addr().unwrap()).await;
    assert!(
        !metrics.contains("cellwatch_alarms_raised_total{cell=\"m01ps0004\",check=\"both\""),
        "{metrics}"
    );
    agent.stop().await;
    server.stop();
}
