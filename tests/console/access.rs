//! What the console gives and to whom: its own bus session puts nothing and
//! answers nothing; without a plant identity it serves nothing, and each
//! reader only their cells.

use std::time::Duration;

use super::{plant_with, request, sign_in};

/// The console's own session sends no put and declares no queryable (its
/// access control, egress): it reads the bus and asks, nothing more. A
/// query it sends after its put reaches the other side, the put does not.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_console_session_puts_nothing_and_answers_nothing() {
    let plain = |connect: Vec<String>, listen: Vec<String>| cellwatch::config::ZenohConfig {
        mode: cellwatch::config::ZenohMode::Peer,
        connect,
        listen,
        prefix: String::new(),
        multicast_scouting: false,
        tls: None,
        config_file: None,
        plain: true,
        signing_key: None,
    };
    let bus = cellwatch::bus::open(&plain(vec![], vec!["tcp/127.0.0.1:0".into()]))
        .await
        .unwrap();
    let endpoint = bus.info().locators().await[0].to_string();
    let puts = bus.declare_subscriber("cellwatch/**").await.unwrap();
    let asked = bus
        .declare_queryable("cellwatch/m01/snapshot")
        .await
        .unwrap();
    let console = cellwatch::bus::open_console(&plain(vec![endpoint], vec![]))
        .await
        .unwrap();
    // What a cell's agent would say, said by the console.
    console
        .put("cellwatch/m01/alarms/ese", "forged")
        .await
        .unwrap();
    let queryable = console.declare_queryable("cellwatch/m01/history").await;
    // Then a query, which is allowed: once it has arrived, so would have
    // the put before it on the same link.
    let replies = console
        .get("cellwatch/m01/snapshot")
        .timeout(Duration::from_secs(30))
        .await
        .unwrap();
    let query = asked.recv_async().await.unwrap();
    query
        .reply("cellwatch/m01/snapshot", "answered")
        .await
        .unwrap();
    // The query ends (its final message) when it is dropped.
    drop(query);
    let reply = replies.recv_async().await.unwrap();
    assert!(
        reply.result().is_ok(),
        "{:?}",
        reply
            .result()
            .err()
            .map(|e| e.payload().try_to_string().map(|s| s.to_string()))
    );
    assert!(
        puts.try_recv().unwrap().is_none(),
        "the console's put arrived"
    );
    // Its queryable, if Zenoh declared it locally, is never known outside.
    let mut answers = bus
        .get("cellwatch/m01/history")
        .timeout(Duration::from_secs(2))
        .await
        .unwrap();
    assert!(answers.recv_async().await.is_err(), "the console answered");
    drop((queryable, &mut answers));
}

/// Nothing of the plant without a plant identity: every route under
/// `/api/` refuses a client that has not signed in (the page itself holds
/// nothing), a request for another host name (DNS rebinding) or from
/// another site's page is refused, a reader sees only the cells
/// `[readers]` gives it, an operator signs in only with the key the
/// operators file holds, and one client's share of the console is bounded.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_console_serves_nothing_without_a_plant_identity_and_each_reader_its_cells() {
    let d = tempfile::tempdir().unwrap();
    // A second cell in the trust file (its agent not running), which ana
    // alone reads.
    std::fs::create_dir(d.path().join("press7")).unwrap();
    cellwatch::bus::envelope::AgentKey::load_or_create(
        &d.path().join("press7/press7.agent.key"),
        "press7",
    )
    .unwrap();
    let p = plant_with(
        d.path(),
        "",
        &format!(
            "press-shop = [\"press7\"]\n\n[readers]\nkim = [\"*\"]\nana = [\"press-shop\"]\n\n[plant]\ndeployed = {:?}\n",
            d.path().join("plant-deployed.json")
        ),
    )
    .await;
    let addr = p
        .url
        .trim_start_matches("http://")
        .trim_end_matches('/')
        .to_string();
    let host = format!("Host: {addr}");
    let get = |path: &str, extra: &str| {
        let extra = if extra.is_empty() {
            String::new()
        } else {
            format!("\r\n{extra}")
        };
        request(&addr, &format!("GET {path} HTTP/1.1\r\n{host}{extra}"), "")
    };

    // Anonymous: the page, yes; the plant, no.
    assert_eq!(get("/", "").0, 200);
    for path in [
        "/api/plant",
        "/api/operators",
        "/api/kpi?since=24h",
        "/api/cells/m01ps0004/snapshot",
        "/api/cells/m01ps0004/history?kind=command&since=24h",
        "/api/events",
        "/api/agents",
    ] {
        let (status, _, body) = get(path, "");
        assert_eq!(status, 401, "{path}: {body}");
        assert!(body.contains("sign in first"), "{path}: {body}");
    }
    let (status, _, _) = request(
        &addr,
        &format!("POST /api/cells/m01ps0004/command HTTP/1.1\r\n{host}\r\nContent-Type: application/json"),
        "{}",
    );
    assert_eq!(status, 401);

    // Kim signs in with her key: she reads everything.
    let kim = sign_in(&addr, &d.path().join("kim.key")).expect("kim signs in");
    let (status, _, body) = get("/api/plant", &kim);
    assert_eq!(status, 200, "{body}");
    let view: serde_json::Value = serde_json::from_str(&body).unwrap();
    let cells: Vec<&str> = view["cells"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["cell"].as_str().unwrap())
        .collect();
    assert_eq!(cells, ["m01ps0004", "press7"], "{body}");
    assert_eq!(get("/api/cells/m01ps0004/snapshot", &kim).0, 200);
    let (_, _, mine) = get("/api/operators", &kim);
    assert!(
        mine.contains("\"operator\":\"kim\"") && !mine.contains("ana"),
        "{mine}"
    );
    // A window further back than a month is not asked of the agents.
    let (status, _, body) = get("/api/kpi?since=1970-01-01T00:00:00Z", &kim);
    assert_eq!(status, 400, "{body}");

    // The Agents page: each agent's about judged against what the plant
    // deployed. No such file yet: said, and the agent judged without it.
    let agents = |who: &str| {
        let (status, _, body) = get("/api/agents", who);
        assert_eq!(status, 200, "{body}");
        serde_json::from_str::<serde_json::Value>(&body).unwrap()
    };
    let of = |v: &serde_json::Value, cell: &str| {
        v["cells"]
            .as_array()
            .unwrap()
            .iter()
            .find(|c| c["cell"] == cell)
            .cloned()
            .unwrap_or_else(|| panic!("no {cell} in {v}"))
    };
    let v = agents(&kim);
    assert!(
        v["deployed"]["error"]
            .as_str()
            .unwrap()
            .contains("plant-deployed.json"),
        "{v}"
    );
    assert_eq!(
        of(&v, "m01ps0004")["problems"],
        serde_json::json!([]),
        "{v}"
    );
    assert_eq!(
        of(&v, "press7")["problems"],
        serde_json::json!(["its agent is not on the bus"]),
        "{v}"
    );
    // Deployed: another configuration than the one it runs.
    let deployed = |sha: &str| {
        let cell = serde_json::json!({
            "config": "hosts/h1/etc/cellwatch/m01ps0004.toml",
            "config_sha256": { "Ok": sha },
            "bus_certificate": "hosts/h1/etc/cellwatch/agent-m01ps0004.pem",
            "bus_certificate_sha256": null,
            "signing_key": "hosts/h1/var/lib/cellwatch/m01ps0004/signing.key",
            "rotated_from": [],
        });
        std::fs::write(
            d.path().join("plant-deployed.json"),
            serde_json::json!({
                "schema": "cellwatch.plant-deployed.v1",
                "operators_version": null,
                "cells": { "m01ps0004": cell },
            })
            .to_string(),
        )
        .unwrap();
    };
    deployed(&"0".repeat(64));
    let m01 = of(&agents(&kim), "m01ps0004");
    assert!(
        m01["problems"][0]
            .as_str()
            .unwrap()
            .contains("runs another configuration than hosts/h1/etc/cellwatch/m01ps0004.toml"),
        "{m01}"
    );
    // The one it runs, by its own hash, computed here.
    use sha2::Digest;
    let runs = hex::encode(sha2::Sha256::digest(std::fs::read(&p.cell.config).unwrap()));
    deployed(&runs);
    let m01 = of(&agents(&kim), "m01ps0004");
    assert_eq!(m01["problems"], serde_json::json!([]), "{m01}");
    assert!(
        m01["facts"]
            .as_array()
            .unwrap()
            .contains(&serde_json::json!("runs the configuration deployed")),
        "{m01}"
    );
    assert_eq!(m01["about"]["config_sha256"], runs.as_str());

    // The same cookie under another host name, or from another site's
    // page, gets nothing.
    let (status, _, _) = request(
        &addr,
        &format!(
            "GET /api/plant HTTP/1.1\r\nHost: attacker.example:{}\r\n{kim}",
            addr.rsplit(':').next().unwrap()
        ),
        "",
    );
    assert_eq!(status, 421);
    let (status, _, _) = get(
        "/api/plant",
        &format!("{kim}\r\nOrigin: http://attacker.example"),
    );
    assert_eq!(status, 403);

    // Ana reads the press shop only.
    let ana = sign_in(&addr, &d.path().join("ana.key")).expect("ana signs in");
    let (_, _, body) = get("/api/plant", &ana);
    assert!(!body.contains("m01ps0004"), "{body}");
    let (_, _, body) = get("/api/agents", &ana);
    assert!(
        !body.contains("m01ps0004") && body.contains("press7"),
        "{body}"
    );
    let (status, _, body) = get("/api/cells/m01ps0004/snapshot", &ana);
    assert_eq!(status, 403, "{body}");
    // Nor does she forward kim's commands.
    let (status, _, body) = request(
        &addr,
        &format!("POST /api/cells/press7/command HTTP/1.1\r\n{host}\r\n{ana}\r\nContent-Type: application/json"),
        &serde_json::json!({"action": "ack", "alarm": "x", "operator": "kim", "nonce": "00", "issued_at": 0, "signature": "00"}).to_string(),
    );
    assert_eq!(status, 403, "{body}");

    // A key that is not the operators file's signs nobody in.
    let forged = cellwatch::operator::OperatorKey::generate("kim");
    std::fs::write(d.path().join("forged.key"), forged.to_file()).unwrap();
    let (status, body) = sign_in(&addr, &d.path().join("forged.key")).unwrap_err();
    assert_eq!(status, 403);
    assert!(
        body.contains("not the key the operators file holds for 'kim'"),
        "{body}"
    );

    // One identity holds at most 8 live streams.
    let streams: Vec<std::net::TcpStream> = (0..8)
        .map(|_| {
            use std::io::{BufRead, Write};
            let mut s = std::net::TcpStream::connect(&addr).unwrap();
            s.write_all(format!("GET /api/events HTTP/1.1\r\n{host}\r\n{kim}\r\n\r\n").as_bytes())
                .unwrap();
            let mut first = String::new();
            std::io::BufReader::new(s.try_clone().unwrap())
                .read_line(&mut first)
                .unwrap();
            assert!(first.starts_with("HTTP/1.1 200"), "{first}");
            s
        })
        .collect();
    let (status, _, body) = get("/api/events", &kim);
    assert_eq!(status, 429, "{body}");
    drop(streams);

    // One address gets 100 requests at once, then 20 a second.
    let refused = (0..150)
        .map(|_| get("/api/session", &kim).0)
        .filter(|s| *s == 429)
        .count();
    assert!(refused > 0, "no request of 150 was refused");
}
