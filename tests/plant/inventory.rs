//! A plant made from its inventory, made again without a change and a hand
//! edit never overwritten; a bad inventory refused at its line and column.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::SystemTime;

use super::{cell_config, plant};

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
