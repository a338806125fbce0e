//! A router lost as a crash loses it: the cell's agent, a client of both
//! the plant's routers, moves to the second, and the alarm it raised as the
//! first died, put into a link nobody read any more, is in the second
//! router's archive all the same (its storage recovers it from the agent's
//! publisher cache, as the console does).

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use super::{agent_config, plant_async, router_config_of};

/// Router `name` as `cellwatch router` runs it from the configuration the
/// plant made (listening on a port of its own, linked to the routers on
/// `connect`): the process and its port.
fn router(dir: &Path, name: &str, connect: &[u16]) -> (Child, u16) {
    let mut cfg = router_config_of(dir, name, true);
    let endpoints: Vec<String> = connect
        .iter()
        .map(|p| format!("quic/127.0.0.1:{p}"))
        .collect();
    cfg.insert_json5(
        "connect/endpoints",
        &serde_json::to_string(&endpoints).unwrap(),
    )
    .unwrap();
    let file = dir.join(format!("{name}-test.json5"));
    std::fs::write(&file, cfg.to_string()).unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_cellwatch"))
        .args(["router", "--config"])
        .arg(&file)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap();
    let said = crate::util::lines_of(&mut child)
        .recv_timeout(Duration::from_secs(60))
        .unwrap();
    let port = super::archive::archive_port(&said);
    (child, port)
}

/// Waits until router `port`'s archive (`cellwatch history --plant`)
/// holds `n` events `transition` of cell m01's check `ese`, and no more.
async fn until_kept(dir: &Path, port: u16, transition: &str, n: usize) {
    let line = format!("m01/ese  {transition}");
    let kept = |out: &str| out.lines().filter(|l| l.contains(&line)).count();
    let r = super::archive::until(dir, port, &format!("{n} {transition}"), |o| kept(o) >= n).await;
    assert_eq!(kept(&r.stdout), n, "one event kept twice:\n{}", r.stdout);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn an_alarm_raised_as_a_router_dies_is_in_the_next_routers_archive() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path().to_path_buf();
    let sim = super::one_cell_plant(&dir).await;
    // A second router in the inventory; the plant made again gives the
    // cell's agent both.
    let mut inventory = std::fs::read_to_string(dir.join("plant.toml")).unwrap();
    inventory.push_str("\n[routers.router-2]\nhost = \"127.0.0.1\"\nport = 7448\n");
    std::fs::write(dir.join("plant.toml"), inventory).unwrap();
    let r = plant_async(dir.clone(), vec!["init".into()]).await;
    assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);

    let (mut first, p1) = router(&dir, "router-1", &[]);
    let (mut second, p2) = router(&dir, "router-2", &[p1]);
    let mut c = agent_config(&dir, "m01", p1);
    for endpoint in &mut c.zenoh.connect {
        *endpoint = endpoint.replace("quic/127.0.0.1:7448", &format!("quic/127.0.0.1:{p2}"));
    }
    assert_eq!(
        c.zenoh.connect,
        [
            format!("quic/127.0.0.1:{p1}"),
            format!("quic/127.0.0.1:{p2}")
        ]
    );
    crate::util::trust_sim(&c, &dir.join("sim-pki"));
    let agent = cellwatch::agent::start(c, None).await.unwrap();

    // Through the first router, the second's archive keeps a raise.
    sim.set("X0.06", false).unwrap();
    until_kept(&dir, p2, "raised", 1).await;
    sim.set("X0.06", true).unwrap();
    until_kept(&dir, p2, "cleared", 1).await;

    // The first router killed, and at once the fault again: the agent
    // puts it into the link to the dead router until that link's lease
    // runs out, then moves to the second.
    first.kill().unwrap();
    first.wait().unwrap();
    sim.set("X0.06", false).unwrap();
    until_kept(&dir, p2, "raised", 2).await;

    agent.stop().await;
    let _ = second.kill();
    let _ = second.wait();
}
