//! `cellwatch plant`: a plant made from its inventory as an engineer does
//! it (the built binary, in an empty folder), made again without a change,
//! a hand edit never overwritten; and `plant check` against a running
//! plant: a router started from the configuration the plant made, agents
//! started from the cells' configurations it made, each fault said for
//! its cell.

mod archive;
mod failover;
mod rotation;
mod starting;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, SystemTime};

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

/// Every file under `dir` with its bytes and modification time.
fn every_file(dir: &Path) -> BTreeMap<PathBuf, (Vec<u8>, SystemTime)> {
    let mut files = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            let meta = p.symlink_metadata().unwrap();
            if meta.is_dir() {
                stack.push(p);
            } else {
                let bytes = if meta.file_type().is_symlink() {
                    std::fs::read_link(&p)
                        .unwrap()
                        .display()
                        .to_string()
                        .into_bytes()
                } else {
                    std::fs::read(&p).unwrap()
                };
                files.insert(p, (bytes, meta.modified().unwrap()));
            }
        }
    }
    files
}

fn mode(path: &Path) -> u32 {
    use std::os::unix::fs::PermissionsExt;
    std::fs::metadata(path).unwrap().permissions().mode() & 0o777
}

const KIM: &str = "2b2a3f1e0d9c8b7a69584736251403f2e1d0c9b8a79685746352413f2e1d0c9b";

#[test]
fn a_plant_is_made_from_its_inventory_and_made_again_changes_nothing() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let r = plant(
        dir,
        &[
            "init",
            "--name",
            "Plant A",
            "--router",
            "router-1=router-1.plant",
            "--router",
            "router-2=router-2.plant",
        ],
    );
    assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    for (id, host, area) in [
        ("m01", "cnc-1.plant", "machining"),
        ("m02", "cnc-1.plant", "machining"),
        ("p07", "press-7.plant", "press-shop"),
    ] {
        let config = cell_config(dir, id);
        let metrics = if id == "m02" { "9465" } else { "9464" };
        let r = plant(
            dir,
            &[
                "add-cell",
                "--cell",
                id,
                "--area",
                area,
                "--host",
                host,
                "--plc",
                "opc.tcp://10.0.1.4:4840",
                "--config",
                &config,
                "--metrics",
                metrics,
            ],
        );
        assert_eq!(r.code, 0, "{id}: {}{}", r.stdout, r.stderr);
    }
    let r = plant(
        dir,
        &[
            "add-operator",
            "--name",
            "kim",
            "--public-key",
            KIM,
            "--allow",
            "ack",
            "--area",
            "press-shop=reset,shelve",
            "--on-cell",
            "m01=force",
        ],
    );
    assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);

    // The identities: the CA's key and every agent's keys owner-only, in
    // owner-only folders on their hosts' trees.
    assert_eq!(mode(&dir.join("ca/ca.key")), 0o600);
    assert_eq!(mode(&dir.join("ca")), 0o700);
    for (host, id) in [
        ("cnc-1.plant", "m01"),
        ("cnc-1.plant", "m02"),
        ("press-7.plant", "p07"),
    ] {
        let state = dir.join(format!("hosts/{host}/var/lib/cellwatch/{id}"));
        assert_eq!(mode(&state), 0o700, "{}", state.display());
        assert_eq!(mode(&state.join("signing.key")), 0o600);
        assert_eq!(mode(&state.join(format!("agent-{id}.key"))), 0o600);
        let link = dir.join(format!(
            "hosts/{host}/etc/systemd/system/multi-user.target.wants/cellwatch@{id}.service"
        ));
        assert_eq!(
            std::fs::read_link(&link).unwrap(),
            Path::new("/usr/lib/systemd/system/cellwatch@.service")
        );
    }
    // The trust file holds every agent's own key.
    let trust = cellwatch::bus::envelope::Trust::load(&dir.join("trust.toml")).unwrap();
    for (host, id) in [("cnc-1.plant", "m01"), ("press-7.plant", "p07")] {
        let key = cellwatch::bus::envelope::AgentKey::load(
            &dir.join(format!("hosts/{host}/var/lib/cellwatch/{id}/signing.key")),
        )
        .unwrap();
        assert_eq!(trust.public_hex(id), Some(key.public_hex()));
    }
    // Each cell's operators file: what kim may do on that cell.
    let ops = |host: &str, id: &str| {
        let text = std::fs::read_to_string(
            dir.join(format!("hosts/{host}/etc/cellwatch/{id}.operators.toml")),
        )
        .unwrap();
        let v: toml::Value = toml::from_str(&text).unwrap();
        v["operators"]["kim"]["allow"].clone()
    };
    assert_eq!(
        ops("cnc-1.plant", "m01"),
        toml::Value::try_from(["ack", "force"]).unwrap()
    );
    assert_eq!(
        ops("cnc-1.plant", "m02"),
        toml::Value::try_from(["ack"]).unwrap()
    );
    assert_eq!(
        ops("press-7.plant", "p07"),
        toml::Value::try_from(["ack", "reset", "shelve"]).unwrap()
    );
    // Each cell's configuration for its host validates with its files
    // beside it, and the plant's bus, journal and metrics set.
    let etc = dir.join("hosts/cnc-1.plant/etc/cellwatch");
    let config = cellwatch::config::load(&etc.join("m02.toml")).unwrap();
    assert_eq!(config.cell, "m02");
    assert_eq!(
        config.zenoh.connect,
        ["quic/router-1.plant:7447", "quic/router-2.plant:7447"]
    );
    assert_eq!(
        config.journal.path,
        Path::new("/var/lib/cellwatch/m02/journal.sqlite")
    );
    assert_eq!(config.metrics, Some("0.0.0.0:9465".parse().unwrap()));
    assert!(etc.join("cnc/ese.il").is_file());
    // Each router's configuration is Zenoh's, with an agent's rules per cell.
    for router in ["router-1", "router-2"] {
        let file = dir.join(format!(
            "routers/{router}/etc/cellwatch/router/router.json5"
        ));
        let cfg = zenoh::Config::from_file(&file).unwrap();
        let acl = cfg.get_json("access_control/subjects").unwrap();
        for id in ["m01", "m02", "p07"] {
            assert!(acl.contains(&format!("agent-{id}")), "{router}: {acl}");
        }
        // Its clients take it for gone after 3 s without a word, not 10.
        assert_eq!(
            cfg.get_json("transport/link/tx/lease").unwrap(),
            cellwatch::plant::render::ROUTER_LEASE_MS.to_string()
        );
    }
    let targets = std::fs::read_to_string(dir.join("prometheus/cellwatch.yml")).unwrap();
    assert!(
        targets.contains(
            "targets: [\"press-7.plant:9464\"]\n  labels: { cell: \"p07\", area: \"press-shop\" }"
        ),
        "{targets}"
    );

    // Made again: nothing changes, not a byte nor a time.
    let before = every_file(dir);
    let r = plant(dir, &["init"]);
    assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    assert!(r.stdout.contains("nothing to do"), "{}", r.stdout);
    assert_eq!(every_file(dir), before);
    // The same cell added again changes nothing; another cell of that id
    // is refused, the inventory as it was.
    let r = plant(
        dir,
        &[
            "add-cell",
            "--cell",
            "p07",
            "--area",
            "press-shop",
            "--host",
            "press-7.plant",
            "--plc",
            "opc.tcp://10.0.1.4:4840",
            "--config",
            "cells/p07.toml",
            "--metrics",
            "9464",
        ],
    );
    assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    let r = plant(
        dir,
        &[
            "add-cell",
            "--cell",
            "p07",
            "--area",
            "press-shop",
            "--host",
            "press-8.plant",
            "--config",
            "cells/p07.toml",
        ],
    );
    assert_eq!(r.code, 2, "{}{}", r.stdout, r.stderr);
    assert!(
        r.stderr.contains("cells.p07 exists with other values"),
        "{}",
        r.stderr
    );
    assert_eq!(every_file(dir), before);

    // A console added: its configuration names what was deployed, which
    // holds each agent's configuration by the hash of the file on its host.
    let inventory = dir.join("plant.toml");
    let text =
        std::fs::read_to_string(&inventory).unwrap() + "\n[console]\nhost = \"console.plant\"\n";
    std::fs::write(&inventory, text).unwrap();
    let r = plant(dir, &["init"]);
    assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    let console =
        cellwatch::console::config::load(&dir.join("console/etc/cellwatch/console.toml")).unwrap();
    assert_eq!(
        console.deployed.as_deref(),
        Some(Path::new("/etc/cellwatch/plant-deployed.json"))
    );
    let deployed: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("console/etc/cellwatch/plant-deployed.json")).unwrap(),
    )
    .unwrap();
    use sha2::Digest;
    let m02 = hex::encode(sha2::Sha256::digest(
        std::fs::read(etc.join("m02.toml")).unwrap(),
    ));
    assert_eq!(deployed["schema"], "cellwatch.plant-deployed.v1");
    assert_eq!(
        deployed["cells"]["m02"]["config_sha256"]["Ok"],
        m02.as_str(),
        "{deployed}"
    );
    assert_eq!(
        deployed["cells"]["m02"]["config"],
        "hosts/cnc-1.plant/etc/cellwatch/m02.toml"
    );

    // A router's configuration changed by hand is kept and named; the rest
    // follows the inventory (an operator added).
    let router1 = dir.join("routers/router-1/etc/cellwatch/router/router.json5");
    let edited = std::fs::read_to_string(&router1).unwrap().replace(
        "default_permission: \"deny\"",
        "default_permission: \"allow\"",
    );
    std::fs::write(&router1, &edited).unwrap();
    let r = plant(
        dir,
        &[
            "add-operator",
            "--name",
            "lee",
            "--public-key",
            &"ab".repeat(32),
            "--allow",
            "ack",
        ],
    );
    assert_eq!(r.code, 2, "{}{}", r.stdout, r.stderr);
    assert!(
        r.stderr
            .contains("routers/router-1/etc/cellwatch/router/router.json5"),
        "{}",
        r.stderr
    );
    assert_eq!(std::fs::read_to_string(&router1).unwrap(), edited);
    let ops =
        std::fs::read_to_string(dir.join("hosts/press-7.plant/etc/cellwatch/p07.operators.toml"))
            .unwrap();
    assert!(ops.contains("[operators.lee]"), "{ops}");
    // ... and `plant check --offline` says so.
    let r = plant(dir, &["check", "--offline"]);
    assert_eq!(r.code, 1, "{}{}", r.stdout, r.stderr);
    assert!(r.stdout.contains("router router-1: WRONG\n  - routers/router-1/etc/cellwatch/router/router.json5: its access control is not the inventory's"), "{}", r.stdout);
    assert!(r.stdout.contains("router router-2: ok"), "{}", r.stdout);
    // A cell taken out of the inventory: its agent's instance on its host
    // is named.
    let inventory = dir.join("plant.toml");
    let mut doc: toml_edit::DocumentMut = std::fs::read_to_string(&inventory)
        .unwrap()
        .parse()
        .unwrap();
    doc["cells"].as_table_mut().unwrap().remove("m02").unwrap();
    std::fs::write(&inventory, doc.to_string()).unwrap();
    let r = plant(dir, &["check", "--offline"]);
    assert!(r.stdout.contains("host cnc-1.plant: WRONG\n  - cell m02 is no longer in the inventory on this host: stop and disable cellwatch@m02 there"), "{}", r.stdout);
}

#[test]
fn a_bad_inventory_is_refused_at_its_line_and_column() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    std::fs::write(dir.join("plant.toml"), "[plant]\nname = \"x\"\n\n[cells.m01]\narea = \"a\"\nhost = \"h\"\nconfig = \"cells/none.toml\"\n").unwrap();
    let r = plant(dir, &["init"]);
    assert_eq!(r.code, 2, "{}{}", r.stdout, r.stderr);
    assert!(
        r.stderr.contains("plant.toml:7:10: cells.m01.config:"),
        "{}",
        r.stderr
    );
    assert!(
        r.stderr
            .contains("routers: the plant's agents and clients meet at routers"),
        "{}",
        r.stderr
    );
    assert!(
        !dir.join("ca").exists(),
        "nothing made from a bad inventory"
    );
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
