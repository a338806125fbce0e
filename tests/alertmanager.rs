//! Alarms to people through a real Prometheus Alertmanager (Debian's
//! `prometheus-alertmanager`, installed on first use), run with the
//! shipped `deploy/alertmanager.yml`: a fault appears in
//! `/api/v2/alerts` with its labels and culprits, clearing and shelving
//! end it, an Alertmanager restarted with nothing stored gets every active
//! alert back, alarms go on reaching the bus while it is down, and the
//! shipped inhibition rule holds back a cell's process alarms while its
//! PLC cannot be reached; an alarm nobody acknowledges escalates step by
//! step and stops at its acknowledgement, as the shipped routes expect.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use cellwatch::config::AlertmanagerConfig;
use cellwatch::operator::Action;

use crate::agent::{alarm_until, Fixture};
use crate::spawned::{send, signed, signed_with};
use crate::util::{http_get, root};

const ALERTMANAGER: &str = "/usr/bin/prometheus-alertmanager";

/// A real Alertmanager on loopback; killed when dropped.
struct Alertmanager {
    child: Child,
    port: u16,
    dir: PathBuf,
}

impl Drop for Alertmanager {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Alertmanager {
    /// Starts one with the shipped configuration on `port`, its storage
    /// (silences, notification log) under `dir`, clustering off; returns
    /// once it says it is ready.
    async fn start(dir: &Path, port: u16) -> Alertmanager {
        Alertmanager::start_with(dir, port, None).await
    }

    /// [`Alertmanager::start`] with a web configuration (TLS): ready once
    /// it says it listens.
    async fn start_with(dir: &Path, port: u16, web: Option<&Path>) -> Alertmanager {
        crate::util::debian_packages(&[(ALERTMANAGER, "prometheus-alertmanager")]);
        std::fs::create_dir_all(dir).unwrap();
        let log = std::fs::File::create(dir.join("alertmanager.log")).unwrap();
        let child = Command::new(ALERTMANAGER)
            .arg(format!(
                "--config.file={}",
                root().join("deploy/alertmanager.yml").display()
            ))
            .arg(format!("--storage.path={}", dir.display()))
            .arg(format!("--web.listen-address=127.0.0.1:{port}"))
            .arg("--cluster.listen-address=")
            .args(web.map(|w| format!("--web.config.file={}", w.display())))
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .unwrap();
        let mut am = Alertmanager {
            child,
            port,
            dir: dir.to_path_buf(),
        };
        let deadline = tokio::time::Instant::now() + Duration::from_secs(60);
        loop {
            if let Some(status) = am.child.try_wait().unwrap() {
                panic!("Alertmanager ended ({status}):\n{}", am.log());
            }
            if web.is_some() {
                if am.log().contains("TLS is enabled") && am.log().contains("Listening on") {
                    return am;
                }
            } else if let Ok(Ok(s)) = tokio::time::timeout(
                Duration::from_secs(5),
                tokio::net::TcpStream::connect(am.addr()),
            )
            .await
            {
                drop(s);
                if http_get(am.addr(), "/-/ready").await.0 == 200 {
                    return am;
                }
            }
            assert!(
                tokio::time::Instant::now() < deadline,
                "Alertmanager never got ready:\n{}",
                am.log()
            );
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    }

    fn addr(&self) -> std::net::SocketAddr {
        ([127, 0, 0, 1], self.port).into()
    }

    fn url(&self) -> String {
        format!("http://127.0.0.1:{}", self.port)
    }

    fn log(&self) -> String {
        std::fs::read_to_string(self.dir.join("alertmanager.log")).unwrap_or_default()
    }

    /// The alerts it holds now, unresolved, of alarm `id`.
    async fn alerts_of(&self, id: &str) -> Vec<serde_json::Value> {
        let (status, body) = http_get(self.addr(), "/api/v2/alerts").await;
        assert_eq!(status, 200, "{body}");
        let all: Vec<serde_json::Value> = serde_json::from_str(&body).unwrap();
        all.into_iter()
            .filter(|a| a["labels"]["alarm"] == id && a["status"]["state"] != "resolved")
            .collect()
    }

    /// Waits until alarm `id` is an alert that `ok` accepts; the alert.
    async fn until(
        &self,
        id: &str,
        what: &str,
        ok: impl Fn(&serde_json::Value) -> bool,
    ) -> serde_json::Value {
        let deadline = tokio::time::Instant::now() + Duration::from_secs(60);
        loop {
            if let Some(a) = self.alerts_of(id).await.into_iter().find(|a| ok(a)) {
                return a;
            }
            assert!(
                tokio::time::Instant::now() < deadline,
                "{what}: {:#?}\n{}",
                self.alerts_of(id).await,
                self.log()
            );
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    }

    /// Waits until alarm `id` is no alert.
    async fn gone(&self, id: &str, what: &str) {
        let deadline = tokio::time::Instant::now() + Duration::from_secs(60);
        while !self.alerts_of(id).await.is_empty() {
            assert!(
                tokio::time::Instant::now() < deadline,
                "{what}: {:#?}",
                self.alerts_of(id).await
            );
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    }
}

/// The value of a metric line starting with `prefix`.
fn metric(body: &str, prefix: &str) -> f64 {
    body.lines()
        .find(|l| l.starts_with(prefix))
        .and_then(|l| l.rsplit(' ').next()?.parse().ok())
        .unwrap_or_else(|| panic!("no {prefix} in {body}"))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn alarms_reach_a_real_alertmanager_end_there_and_survive_its_restart() {
    let d = tempfile::tempdir().unwrap();
    let port = crate::util::restartable_port();
    let am = Alertmanager::start(&d.path().join("am-1"), port).await;
    let url = am.url();
    let mut fx = Fixture::start_with(|c| {
        c.alertmanager = Some(AlertmanagerConfig {
            urls: vec![url],
            area: Some("press shop".into()),
            console: Some("https://console.plant.example:8470".into()),
            resend: Duration::from_secs(2),
            tls: None,
            escalation: cellwatch::config::default_escalation(),
        });
    })
    .await;
    let sub = crate::robust::alarms(fx.client(), "m01ps0004").await;
    fx.settled().await;
    let mut seen = Vec::new();

    // A fault: an alert with the cell's labels and the culprit.
    fx.sim.set("X0.06", false).unwrap();
    alarm_until(&sub, "ESE raised", &mut seen, |a| {
        a.id == "ese" && a.transition.as_str() == "raised"
    })
    .await;
    let alert = am
        .until("ese", "ESE never reached Alertmanager", |_| true)
        .await;
    let labels = &alert["labels"];
    assert_eq!(labels["alertname"], "ese", "{alert:#}");
    assert_eq!(labels["cell"], "m01ps0004", "{alert:#}");
    assert_eq!(labels["area"], "press shop", "{alert:#}");
    assert_eq!(labels["kind"], "switching", "{alert:#}");
    assert!(
        ["low", "medium", "high", "critical"].contains(&labels["priority"].as_str().unwrap()),
        "{alert:#}"
    );
    let culprits = alert["annotations"]["culprits"].as_str().unwrap();
    assert!(
        culprits.starts_with("X0.06 = 0 (expected 1): "),
        "{alert:#}"
    );
    assert!(culprits.contains("<- trigger"), "{alert:#}");
    assert_eq!(
        alert["generatorURL"],
        "https://console.plant.example:8470/#/alarm/m01ps0004/ese"
    );
    assert!(!alert["annotations"]["summary"].as_str().unwrap().is_empty());

    // Cleared: it ends.
    fx.sim.set("X0.06", true).unwrap();
    alarm_until(&sub, "ESE cleared", &mut seen, |a| {
        a.id == "ese" && a.transition.as_str() == "cleared"
    })
    .await;
    am.gone("ese", "a cleared alarm still alerts").await;

    // Raised again and shelved: it ends; unshelved, it is back.
    fx.sim.set("X0.06", false).unwrap();
    am.until("ese", "ESE raised again", |_| true).await;
    let shelve = signed_with(Action::Shelve, "ese", Some("30m"), Some("sensor cable"));
    let (ok, detail) = send(fx.client(), &shelve).await;
    assert!(ok, "{detail}");
    am.gone("ese", "a shelved alarm still alerts").await;
    let (ok, detail) = send(fx.client(), &signed(Action::Unshelve, "ese")).await;
    assert!(ok, "{detail}");
    am.until("ese", "ESE back after the shelf", |_| true).await;

    // Alertmanager goes away: sends fail and are counted; alarms still
    // reach the bus.
    drop(am);
    let failed = "cellwatch_alertmanager_sends_total{cell=\"m01ps0004\",result=\"failed\"}";
    let deadline = tokio::time::Instant::now() + Duration::from_secs(60);
    while metric(&fx.scrape().await, failed) < 1.0 {
        assert!(
            tokio::time::Instant::now() < deadline,
            "no failed send counted"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let (ok, detail) = send(fx.client(), &signed(Action::Ack, "ese")).await;
    assert!(ok, "{detail}");
    alarm_until(
        &sub,
        "ESE acknowledged while Alertmanager is down",
        &mut seen,
        |a| a.id == "ese" && a.transition.as_str() == "acknowledged",
    )
    .await;

    // Back with nothing stored: every active alert is sent again, with
    // what changed meanwhile.
    let am = Alertmanager::start(&d.path().join("am-2"), port).await;
    let back = am
        .until("ese", "ESE lost across Alertmanager's restart", |a| {
            a["annotations"]["acknowledged"] == "by kim"
        })
        .await;
    assert_eq!(back["labels"]["cell"], "m01ps0004");

    // The PLC goes away: the communication alarm alerts, and the shipped
    // inhibition rule holds back the cell's process alarm.
    fx.sim.stop();
    am.until("communication", "the communication alarm", |_| true)
        .await;
    am.until("ese", "ESE not inhibited by the communication alarm", |a| {
        a["status"]["inhibitedBy"]
            .as_array()
            .is_some_and(|by| !by.is_empty())
    })
    .await;
    fx.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn an_alarm_nobody_acknowledges_escalates_and_stops_at_its_acknowledgement() {
    let d = tempfile::tempdir().unwrap();
    let am = Alertmanager::start(&d.path().join("am"), crate::util::restartable_port()).await;
    let url = am.url();
    let mut fx = Fixture::start_with(|c| {
        c.alertmanager = Some(AlertmanagerConfig {
            urls: vec![url],
            area: None,
            console: None,
            // Nothing is sent again before the steps: each step is sent
            // when it is reached.
            resend: Duration::from_secs(600),
            tls: None,
            escalation: vec![
                ("1s".into(), Duration::from_secs(1)),
                ("3s".into(), Duration::from_secs(3)),
            ],
        });
    })
    .await;
    let sub = crate::robust::alarms(fx.client(), "m01ps0004").await;
    fx.settled().await;
    let mut seen = Vec::new();
    fx.sim.set("X0.06", false).unwrap();
    alarm_until(&sub, "ESE raised", &mut seen, |a| {
        a.id == "ese" && a.transition.as_str() == "raised"
    })
    .await;
    let step = |a: &serde_json::Value| {
        a["labels"]["unacknowledged_for"]
            .as_str()
            .map(str::to_string)
    };
    let first = am
        .until("ese", "ESE never alerted unacknowledged", |a| {
            a["labels"]["acknowledged"] == "false"
        })
        .await;
    assert_ne!(step(&first).as_deref(), Some("3s"), "{first:#}");
    // Each step in turn, and the alert under the step before ends.
    am.until("ese", "ESE never reached its last step", |a| {
        step(a).as_deref() == Some("3s")
    })
    .await;
    let deadline = tokio::time::Instant::now() + Duration::from_secs(60);
    while am.alerts_of("ese").await.len() > 1 {
        assert!(
            tokio::time::Instant::now() < deadline,
            "an earlier step still alerts: {:#?}",
            am.alerts_of("ese").await
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }

    // Acknowledged: one alert, acknowledged, no step; the escalated one
    // ended, so a route on the step stops notifying.
    let (ok, detail) = send(fx.client(), &signed(Action::Ack, "ese")).await;
    assert!(ok, "{detail}");
    am.until("ese", "ESE never alerted acknowledged", |a| {
        a["labels"]["acknowledged"] == "true" && step(a).is_none()
    })
    .await;
    let deadline = tokio::time::Instant::now() + Duration::from_secs(60);
    while am
        .alerts_of("ese")
        .await
        .iter()
        .any(|a| a["labels"]["acknowledged"] != "true")
    {
        assert!(
            tokio::time::Instant::now() < deadline,
            "the unacknowledged alert outlived the acknowledgement: {:#?}",
            am.alerts_of("ese").await
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }

    // The shipped routes: a critical alarm unacknowledged for 5 minutes
    // pages the shift supervisor; acknowledged, it does not.
    let routed = |labels: &[&str]| {
        let out = Command::new("/usr/bin/amtool")
            .args(["config", "routes", "test", "--config.file"])
            .arg(root().join("deploy/alertmanager.yml"))
            .args(labels)
            .output()
            .unwrap();
        assert!(out.status.success(), "{out:?}");
        String::from_utf8(out.stdout).unwrap().trim().to_string()
    };
    let base = ["cell=m01ps0004", "alarm=ese", "priority=critical"];
    let escalated = routed(&[&base[..], &["acknowledged=false", "unacknowledged_for=5m"]].concat());
    assert!(
        escalated.split(',').any(|r| r == "shift-supervisor"),
        "{escalated}"
    );
    for later in ["15m", "1h"] {
        let step = format!("unacknowledged_for={later}");
        let r = routed(&[&base[..], &["acknowledged=false", step.as_str()]].concat());
        assert!(r.split(',').any(|r| r == "shift-supervisor"), "{r}");
    }
    let acked = routed(&[&base[..], &["acknowledged=true"]].concat());
    assert!(!acked.contains("shift-supervisor"), "{acked}");
    let fresh = routed(&[&base[..], &["acknowledged=false"]].concat());
    assert!(!fresh.contains("shift-supervisor"), "{fresh}");
    fx.stop().await;
}

/// `GET path` over HTTPS to 127.0.0.1:`port` as `localhost`, trusting
/// `ca` and presenting `cert`/`key`: the status and the body.
async fn https_get(port: u16, path: &str, ca: &Path, cert: &Path, key: &Path) -> (u16, String) {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    use tokio_rustls::rustls;
    use tokio_rustls::rustls::pki_types::pem::PemObject;
    use tokio_rustls::rustls::pki_types::{CertificateDer, PrivateKeyDer, ServerName};
    let mut roots = rustls::RootCertStore::empty();
    for c in CertificateDer::pem_file_iter(ca).unwrap() {
        roots.add(c.unwrap()).unwrap();
    }
    let chain: Vec<CertificateDer<'static>> = CertificateDer::pem_file_iter(cert)
        .unwrap()
        .map(Result::unwrap)
        .collect();
    let config = rustls::ClientConfig::builder_with_provider(std::sync::Arc::new(
        rustls::crypto::ring::default_provider(),
    ))
    .with_safe_default_protocol_versions()
    .unwrap()
    .with_root_certificates(roots)
    .with_client_auth_cert(chain, PrivateKeyDer::from_pem_file(key).unwrap())
    .unwrap();
    let tcp = tokio::net::TcpStream::connect(("127.0.0.1", port))
        .await
        .unwrap();
    let mut tls = tokio_rustls::TlsConnector::from(std::sync::Arc::new(config))
        .connect(ServerName::try_from("localhost").unwrap(), tcp)
        .await
        .unwrap();
    tls.write_all(
        format!("GET {path} HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n").as_bytes(),
    )
    .await
    .unwrap();
    let mut answer = Vec::new();
    let _ = tls.read_to_end(&mut answer).await;
    crate::util::http_answer(&String::from_utf8_lossy(&answer))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn an_https_alertmanager_asking_for_a_client_certificate_gets_the_alerts() {
    let port = crate::util::restartable_port();
    let mut pki = None;
    let fx = Fixture::start_with(|c| {
        // The agent's own bus certificate from the plant CA is its client
        // certificate; Alertmanager's is issued by the same CA.
        let bus = c.zenoh.tls.clone().unwrap();
        pki = Some(bus.clone());
        c.alertmanager = Some(AlertmanagerConfig {
            urls: vec![format!("https://localhost:{port}")],
            area: None,
            console: None,
            resend: Duration::from_secs(2),
            tls: Some(cellwatch::config::AlertmanagerTls {
                ca: bus.ca,
                client: Some((bus.cert, bus.key)),
            }),
            escalation: cellwatch::config::default_escalation(),
        });
    })
    .await;
    let bus = pki.unwrap();
    let dir = bus.ca.parent().unwrap().to_path_buf();
    let (am_cert, am_key) = cellwatch::bus::certs::issue(
        &dir,
        "alertmanager",
        &["localhost".into(), "127.0.0.1".into()],
    )
    .unwrap();
    let web = fx.dir().join("web.yml");
    std::fs::write(
        &web,
        format!(
            "tls_server_config:\n  cert_file: {}\n  key_file: {}\n  client_auth_type: RequireAndVerifyClientCert\n  client_ca_file: {}\n",
            am_cert.display(),
            am_key.display(),
            bus.ca.display()
        ),
    )
    .unwrap();
    let am = Alertmanager::start_with(&fx.dir().join("am"), port, Some(&web)).await;
    fx.settled().await;
    fx.sim.set("X0.06", false).unwrap();
    let deadline = tokio::time::Instant::now() + Duration::from_secs(60);
    loop {
        let (status, body) = https_get(port, "/api/v2/alerts", &bus.ca, &bus.cert, &bus.key).await;
        assert_eq!(status, 200, "{body}");
        let alerts: Vec<serde_json::Value> = serde_json::from_str(&body).unwrap();
        if alerts
            .iter()
            .any(|a| a["labels"]["alarm"] == "ese" && a["labels"]["cell"] == "m01ps0004")
        {
            break;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "ESE never reached the HTTPS Alertmanager: {body}\n{}",
            am.log()
        );
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    let metrics = fx.scrape().await;
    assert!(
        metrics.contains("cellwatch_alertmanager_sends_total{cell=\"m01ps0004\",result=\"ok\"}"),
        "{metrics}"
    );
    let mut fx = fx;
    fx.stop().await;
    fx.sim.stop();
}
