//! `cellwatch plant`: a plant made from its inventory as an engineer does
//! it (the built binary, in an empty folder), made again without a change,
//! a hand edit never overwritten; and `plant check` against a running
//! plant: a router started from the configuration the plant made, agents
//! started from the cells' configurations it made, each fault said for
//! its cell.

mod archive;
mod check;
mod failover;
mod inventory;
mod revocation;
mod rotation;
mod starting;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use cellwatch::archive::router::PlantRouter;
use cellwatch::sim::cnc::{SimOptions, SimulatedCnc};

use crate::util::root;

struct Ran {
    code: i32,
    stdout: String,
    stderr: String,
}

/// `cellwatch plant ARGS` run in `dir`.
fn plant(dir: &Path, args: &[&str]) -> Ran {
    let out = Command::new(env!("CARGO_BIN_EXE_cellwatch"))
        .arg("plant")
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap();
    Ran {
        code: out.status.code().unwrap_or(-1),
        stdout: String::from_utf8(out.stdout).unwrap(),
        stderr: String::from_utf8(out.stderr).unwrap(),
    }
}

/// The engraving machine's configuration as cell `id`'s, with its files,
/// under `dir/cells`.
fn cell_config(dir: &Path, id: &str) -> String {
    let cells = dir.join("cells");
    std::fs::create_dir_all(cells.join("cnc")).unwrap();
    for f in std::fs::read_dir(root().join("config/cnc")).unwrap() {
        let f = f.unwrap().path();
        std::fs::copy(&f, cells.join("cnc").join(f.file_name().unwrap())).unwrap();
    }
    let text = std::fs::read_to_string(root().join("config/demo.toml"))
        .unwrap()
        .replace("id = \"m01ps0004\"", &format!("id = \"{id}\""));
    std::fs::write(cells.join(format!("{id}.toml")), text).unwrap();
    format!("cells/{id}.toml")
}

/// The generated configuration of `id` on `host` with its host paths
/// under the plant's tree, the bus through `router_port`.
fn as_on_host(dir: &Path, host: &str, id: &str, router_port: u16) -> cellwatch::config::CellConfig {
    let tree = dir.join("hosts").join(host);
    let etc = tree.join("etc/cellwatch");
    let text = std::fs::read_to_string(etc.join(format!("{id}.toml")))
        .unwrap()
        .replace("/etc/cellwatch", &etc.display().to_string())
        .replace(
            "/var/lib/cellwatch",
            &tree.join("var/lib/cellwatch").display().to_string(),
        )
        .replace(
            "quic/127.0.0.1:7447",
            &format!("quic/127.0.0.1:{router_port}"),
        );
    let mut c = cellwatch::config::parse(id, &text, &etc, &cellwatch::config::Disk).unwrap();
    // Port 0 would not be the inventory's: the test's free port is.
    c.metrics = Some(
        format!("127.0.0.1:{}", c.metrics.unwrap().port())
            .parse()
            .unwrap(),
    );
    // What the agent runs is the deployed file (its hash).
    let deployed = std::fs::read(etc.join(format!("{id}.toml"))).unwrap();
    c.source_sha256 = {
        use sha2::Digest;
        hex::encode(sha2::Sha256::digest(&deployed))
    };
    c
}

/// `cellwatch plant ARGS` in `dir`, off the test's runtime.
async fn plant_async(dir: PathBuf, args: Vec<String>) -> Ran {
    tokio::task::spawn_blocking(move || {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        plant(&dir, &args)
    })
    .await
    .unwrap()
}

/// Router `router-1` of the plant in `dir`, from the configuration the
/// plant made (its files under the plant's tree, listening on a port of
/// its own), and that port.
async fn plant_router(dir: &Path) -> (PlantRouter, u16) {
    plant_router_with(dir, true).await
}

/// [`plant_router`], its access control on or (a router misconfigured)
/// off.
async fn plant_router_with(dir: &Path, access_control: bool) -> (PlantRouter, u16) {
    let cfg = router_config(dir, access_control);
    let router = PlantRouter::start(cfg, Path::new("router.json5"))
        .await
        .unwrap();
    let port = crate::util::tls_port(&router.locators());
    (router, port)
}

/// Router `router-1`'s configuration as the plant made it, with its files
/// and its archive under the plant's tree, listening on a port of its own.
fn router_config(dir: &Path, access_control: bool) -> zenoh::Config {
    router_config_of(dir, "router-1", access_control)
}

/// Router `name`'s configuration as the plant made it, as
/// [`router_config`] makes router-1's.
fn router_config_of(dir: &Path, name: &str, access_control: bool) -> zenoh::Config {
    let router_dir = dir.join(format!("routers/{name}/etc/cellwatch/router"));
    let mut cfg = zenoh::Config::from_file(router_dir.join("router.json5")).unwrap();
    let file = |f: &str| serde_json::to_string(&router_dir.join(f).display().to_string()).unwrap();
    for (key, value) in [
        ("listen/endpoints", "[\"quic/127.0.0.1:0\"]".to_string()),
        ("transport/link/tls/root_ca_certificate", file("ca.pem")),
        (
            "transport/link/tls/listen_certificate",
            file(&format!("{name}.pem")),
        ),
        (
            "transport/link/tls/listen_private_key",
            file(&format!("{name}.key")),
        ),
        (
            "transport/link/tls/connect_certificate",
            file(&format!("{name}.pem")),
        ),
        (
            "transport/link/tls/connect_private_key",
            file(&format!("{name}.key")),
        ),
        ("access_control/enabled", access_control.to_string()),
        (
            "plugins/storage_manager/volumes/sqlite/dir",
            serde_json::to_string(
                &dir.join(format!("routers/{name}/archive"))
                    .display()
                    .to_string(),
            )
            .unwrap(),
        ),
    ] {
        cfg.insert_json5(key, &value).unwrap();
    }
    cfg
}

fn free_tcp_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// Kim's signed acknowledgement of `ese` on `cell`, as the agent answers
/// it (accepted, detail).
/// A bus client as the plant's administrator, through the router on
/// `port`, believing what the plant's trust file does.
async fn admin_client(dir: &Path, port: u16) -> cellwatch::client::BusClient {
    let trust = cellwatch::bus::envelope::Trust::load(&dir.join("trust.toml")).unwrap();
    cellwatch::client::BusClient::open(
        &cellwatch::config::ZenohConfig {
            mode: cellwatch::config::ZenohMode::Client,
            connect: vec![format!("quic/127.0.0.1:{port}")],
            listen: vec![],
            prefix: String::new(),
            multicast_scouting: false,
            tls: Some(cellwatch::config::ZenohTls {
                ca: dir.join("ca/ca.pem"),
                cert: dir.join("admin/plant-admin.pem"),
                key: dir.join("admin/plant-admin.key"),
            }),
            config_file: None,
            plain: false,
            signing_key: None,
        },
        trust,
        "cellwatch",
    )
    .await
    .unwrap()
}

async fn kim_acks(
    bus: &cellwatch::client::BusClient,
    kim: &cellwatch::operator::OperatorKey,
    cell: &str,
) -> (bool, String) {
    let mut c = cellwatch::operator::Command {
        action: cellwatch::operator::Action::Ack,
        alarm: "ese".into(),
        tag: None,
        value: None,
        reason: None,
        operator: kim.operator.clone(),
        nonce: cellwatch::operator::nonce(),
        issued_at: cellwatch::clock::now_ms(),
        signature: String::new(),
    };
    c.sign(cell, kim);
    bus.command(cell, &c, Duration::from_secs(20))
        .await
        .unwrap()
}

/// The simulated CNC, and a plant made in `dir` around it: router
/// `router-1` on loopback and cell `m01` of area `a` watching the CNC,
/// its `/metrics` on a free port.
async fn one_cell_plant(dir: &Path) -> SimulatedCnc {
    let sim = SimulatedCnc::start(&SimOptions {
        listen: "127.0.0.1:0".parse().unwrap(),
        pki_dir: dir.join("sim-pki"),
        insecure: false,
        decoy: None,
    })
    .await
    .unwrap();
    let run = |args: &[&str]| {
        plant_async(
            dir.to_path_buf(),
            args.iter().map(|a| a.to_string()).collect(),
        )
    };
    let r = run(&["init", "--router", "router-1=127.0.0.1"]).await;
    assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    let config = cell_config(dir, "m01");
    let metrics = free_tcp_port().to_string();
    let r = run(&[
        "add-cell",
        "--cell",
        "m01",
        "--area",
        "a",
        "--host",
        "127.0.0.1",
        "--plc",
        &sim.endpoint(),
        "--config",
        &config,
        "--metrics",
        &metrics,
    ])
    .await;
    assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    sim
}

/// Cell `id`'s agent as the plant made it, keeping its operators list
/// where the host would (`dir/state-<id>`, seeded from the plant's tree
/// at first start).
fn agent_config(dir: &Path, id: &str, router_port: u16) -> cellwatch::config::CellConfig {
    let mut c = as_on_host(dir, "127.0.0.1", id, router_port);
    let state = dir.join(format!("state-{id}"));
    let list = state.join("plant-operators.json");
    if !list.exists() {
        std::fs::create_dir_all(&state).unwrap();
        let seeded = dir.join(format!(
            "hosts/127.0.0.1/var/lib/cellwatch/{id}/plant-operators.json"
        ));
        std::fs::copy(seeded, &list).unwrap();
    }
    c.plant_operators.as_mut().unwrap().list = list;
    c
}
