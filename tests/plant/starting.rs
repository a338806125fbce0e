//! An agent starting on a starved host, as fifty start at once: its first
//! router answers after the client's open timeout, or not at all for a
//! while; the agent's session opens all the same, through whichever
//! router answers, rather than the agent exiting at start.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Duration;

use cellwatch::config::{ZenohConfig, ZenohMode};
use tokio::net::{TcpListener, TcpStream};

/// What the relay in front of a router does to the connections it takes.
#[derive(Clone, Copy)]
enum Fault {
    /// The first `n` connections are closed as soon as taken.
    Refuse(usize),
    /// The router's answers on the first connection are held this long.
    HoldFirst(Duration),
}

/// A TCP relay to `target` with `fault`: its port, and how many
/// connections it took.
async fn relay(target: u16, fault: Fault) -> (u16, Arc<AtomicUsize>) {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let port = listener.local_addr().unwrap().port();
    let taken = Arc::new(AtomicUsize::new(0));
    let count = taken.clone();
    tokio::spawn(async move {
        while let Ok((client, _)) = listener.accept().await {
            let n = count.fetch_add(1, Ordering::SeqCst);
            let hold = match fault {
                Fault::Refuse(first) if n < first => {
                    drop(client);
                    continue;
                }
                Fault::HoldFirst(hold) if n == 0 => hold,
                _ => Duration::ZERO,
            };
            tokio::spawn(forward(client, target, hold));
        }
    });
    (port, taken)
}

async fn forward(client: TcpStream, target: u16, hold: Duration) {
    let Ok(server) = TcpStream::connect(("127.0.0.1", target)).await else {
        return;
    };
    let (mut client_rx, mut client_tx) = client.into_split();
    let (mut server_rx, mut server_tx) = server.into_split();
    tokio::spawn(async move {
        let _ = tokio::io::copy(&mut client_rx, &mut server_tx).await;
    });
    tokio::time::sleep(hold).await;
    let _ = tokio::io::copy(&mut server_rx, &mut client_tx).await;
}

/// A plain Zenoh router on loopback, and its TCP port.
async fn router() -> (zenoh::Session, u16) {
    let mut cfg = zenoh::Config::default();
    for (key, value) in [
        ("mode", "\"router\""),
        ("listen/endpoints", "[\"tcp/127.0.0.1:0\"]"),
        ("scouting/multicast/enabled", "false"),
    ] {
        cfg.insert_json5(key, value).unwrap();
    }
    let session = zenoh::open(cfg).await.unwrap();
    let locator = session.info().locators().await[0].to_string();
    let port = locator.rsplit(':').next().unwrap().parse().unwrap();
    (session, port)
}

/// An agent's bus configuration, a client of the routers on `ports`.
fn agent_bus(ports: &[u16]) -> ZenohConfig {
    ZenohConfig {
        mode: ZenohMode::Client,
        connect: ports.iter().map(|p| format!("tcp/127.0.0.1:{p}")).collect(),
        listen: vec![],
        prefix: "cellwatch/m01".into(),
        multicast_scouting: false,
        tls: None,
        config_file: None,
        plain: true,
        signing_key: None,
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn an_agent_whose_first_router_answers_late_opens_its_session_all_the_same() {
    let (first, p1) = router().await;
    let (second, p2) = router().await;
    let late = Duration::from_millis(cellwatch::bus::CLIENT_OPEN_TIMEOUT_MS + 1_500);
    let (relay, _) = relay(p1, Fault::HoldFirst(late)).await;
    let session = cellwatch::bus::open_agent(&agent_bus(&[relay, p2]))
        .await
        .expect("the session opens through a router that answers");
    let routers: Vec<_> = session.info().routers_zid().await.collect();
    assert_eq!(routers.len(), 1, "{routers:?}");
    assert!(
        [first.zid(), second.zid()].contains(&routers[0]),
        "{routers:?}"
    );
    session.close().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn an_agent_started_before_its_router_answers_opens_once_it_does() {
    let (router, port) = router().await;
    let (relay, taken) = relay(port, Fault::Refuse(2)).await;
    let session = cellwatch::bus::open_agent(&agent_bus(&[relay]))
        .await
        .expect("the session opens once the router answers");
    assert_eq!(
        taken.load(Ordering::SeqCst),
        3,
        "two refused, the third taken"
    );
    let routers: Vec<_> = session.info().routers_zid().await.collect();
    assert_eq!(routers, [router.zid()]);
    session.close().await.unwrap();
}
