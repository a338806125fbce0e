//! The edge node over TLS (`mqtts://`, `[sparkplug.tls]`): mosquitto asks
//! every client of its TLS listener for a certificate of its CA; the node
//! shows its own and is born, and a node whose certificate another CA signed
//! is refused, the agent saying why.

use std::path::Path;
use std::time::Duration;

use cellwatch::bus::certs;

use super::{named, Broker, Host, GROUP, NODE};

/// Waits until the file at `path` has a line containing `text`.
async fn logged(path: &Path, text: &str) -> String {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(90);
    loop {
        let log = std::fs::read_to_string(path).unwrap_or_default();
        if let Some(line) = log.lines().find(|l| l.contains(text)) {
            return line.to_string();
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "no '{text}' in {}:\n{log}",
            path.display()
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn the_node_reaches_a_tls_broker_with_a_certificate_of_its_ca_and_no_other() {
    let d = tempfile::tempdir().unwrap();
    let pki = d.path().join("mqtt-pki");
    certs::make_ca(&pki, "press shop MQTT CA").unwrap();
    let (broker_cert, broker_key) = certs::issue(&pki, "broker", &["localhost".into()]).unwrap();
    let (node_cert, node_key) = certs::issue(&pki, NODE, &[]).unwrap();
    let (ca, _) = certs::ca_files(&pki);
    // The host on the plain listener; the node on the TLS one. Started as
    // root, mosquitto would become its own user, who cannot read the
    // owner-only key in this test's directory: it stays who it is.
    let tls_port = crate::util::restartable_port();
    let broker = Broker::start_with(
        d.path(),
        crate::util::restartable_port(),
        &format!(
            "user root\nlistener {tls_port} 127.0.0.1\ncafile {}\ncertfile {}\nkeyfile {}\nrequire_certificate true\nuse_identity_as_username true\n",
            ca.display(),
            broker_cert.display(),
            broker_key.display()
        ),
    )
    .await;
    let mut host = Host::start(&broker).await;
    let (sim, mut cell) = crate::spawned::start(d.path()).await;
    let plain = std::fs::read_to_string(&cell.config).unwrap();
    let with = |cert: &Path, key: &Path| {
        format!(
            "{plain}\n[sparkplug]\nbroker = \"mqtts://localhost:{tls_port}\"\ngroup_id = \"{GROUP}\"\nedge_node_id = \"{NODE}\"\n\n[sparkplug.tls]\nca = \"{}\"\ncert = \"{}\"\nkey = \"{}\"\n",
            ca.display(),
            cert.display(),
            key.display()
        )
    };
    std::fs::write(&cell.config, with(&node_cert, &node_key)).unwrap();
    let mut agent = cell.spawn("agent-1.log").await;
    let nbirth = host.message("NBIRTH", |_| true).await;
    assert_eq!(named(&nbirth, "Node Control/Rebirth")["value"], false);
    host.message("DBIRTH", |_| true).await;
    agent.kill().unwrap();
    agent.wait().unwrap();

    // A certificate of another CA: refused by the broker, said by the agent.
    let other = d.path().join("other-pki");
    certs::make_ca(&other, "someone else's CA").unwrap();
    let (stray_cert, stray_key) = certs::issue(&other, NODE, &[]).unwrap();
    std::fs::write(&cell.config, with(&stray_cert, &stray_key)).unwrap();
    let mut agent = cell.spawn("agent-2.log").await;
    let said = logged(
        &d.path().join("agent-2.log"),
        "sparkplug: cannot connect to the MQTT broker",
    )
    .await;
    assert!(said.contains("localhost"), "{said}");
    assert_eq!(
        super::scraped(cell.metrics_port, "cellwatch_sparkplug_connected{"),
        0.0
    );
    agent.kill().unwrap();
    agent.wait().unwrap();
    // Nothing of the refused node reached the host.
    let mut since = Vec::new();
    while let Ok(line) = host.lines.try_recv() {
        since.push(line);
    }
    let births: Vec<_> = since
        .iter()
        .filter(|v| v["topic"].as_str().is_some_and(|t| t.contains("/NBIRTH/")))
        .collect();
    assert!(births.is_empty(), "{births:#?}");
    drop(sim);
}
