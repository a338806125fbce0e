//! `cellwatch plant check`: the plant's folder and the running plant
//! against the inventory, cell by cell and router by router. From the
//! folder: each agent's signing key against the trust file, its
//! certificate's end, a router whose access control is not the
//! inventory's. Over the bus, from each agent's signed `about`: whether it
//! answers, is believed with the trust file's key, runs the configuration
//! deployed and this version, its certificate's end; over HTTP its
//! `/readyz`.

use std::collections::BTreeMap;
use std::time::Duration;

use sha2::{Digest, Sha256};

use super::inventory::Inventory;
use super::judge::{judge, DeployedCell, DeployedPlant, Judged};
use super::layout::Layout;
use super::render;
use crate::bus::certs::facts;
use crate::bus::envelope::{AgentKey, Trust};
use crate::bus::keys::Service;
use crate::client::BusClient;
use crate::payload::AboutPayload;

/// What the check found about one part of the plant.
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub(crate) struct Finding {
    /// `cell m01ps0004`, `router router-1`, `plant`.
    pub subject: String,
    /// What is as it should be (shown after `ok`).
    pub facts: Vec<String>,
    /// What is wrong, each with what to do.
    pub problems: Vec<String>,
}

/// Every part's finding, cells first.
#[derive(Debug, Default)]
pub(crate) struct Report {
    /// By subject, in the inventory's order.
    pub findings: Vec<Finding>,
}

impl Report {
    /// Whether anything is wrong.
    pub(crate) fn wrong(&self) -> bool {
        self.findings.iter().any(|f| !f.problems.is_empty())
    }

    /// The report as text, one block per part.
    pub(crate) fn text(&self) -> String {
        let mut out = String::new();
        for f in &self.findings {
            if f.problems.is_empty() {
                out.push_str(&format!("{}: ok — {}\n", f.subject, f.facts.join(", ")));
            } else {
                out.push_str(&format!("{}: WRONG\n", f.subject));
                for p in &f.problems {
                    out.push_str(&format!("  - {p}\n"));
                }
            }
        }
        let wrong = self
            .findings
            .iter()
            .filter(|f| !f.problems.is_empty())
            .count();
        out.push_str(&format!(
            "{} of {} parts wrong\n",
            wrong,
            self.findings.len()
        ));
        out
    }
}

/// Why the plant check could not read a file of the plant's folder, or
/// ask an agent's `/readyz`.
#[derive(Debug, thiserror::Error)]
pub(crate) enum CheckError {
    /// The signed operators list cannot be read.
    #[error("{path}: {source}")]
    ReadList {
        /// The file.
        path: std::path::PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// It is not a signed operators list.
    #[error("{path}: {source}")]
    List {
        /// The file.
        path: std::path::PathBuf,
        /// Why.
        source: crate::operator::plant::ListError,
    },
    /// The list it signs does not read.
    #[error("{path}: {source}")]
    ListJson {
        /// The file.
        path: std::path::PathBuf,
        /// Why.
        source: serde_json::Error,
    },
    /// The host and port make no URL.
    #[error("{0}")]
    Url(#[from] hyper::http::uri::InvalidUri),
    /// The agent's metrics endpoint cannot be reached.
    #[error("{0}")]
    Http(#[from] hyper_util::client::legacy::Error),
    /// It answered, not ready: its status and what it said.
    #[error("{status}: {body}")]
    NotReady {
        /// The HTTP status.
        status: hyper::StatusCode,
        /// What it said (at most 4 KiB).
        body: String,
    },
    /// No answer in time.
    #[error("no answer in {} s", .0.as_secs())]
    NoAnswer(Duration),
}

fn sha256(bytes: &[u8]) -> String {
    hex::encode(Sha256::digest(bytes))
}

/// The plant's signed operators list, as `plant publish` puts it, and
/// its version.
///
/// # Errors
/// It cannot be read, or it does not read as one.
pub(crate) fn operators_list(layout: &Layout) -> Result<(Vec<u8>, u64), CheckError> {
    let path = layout.operators_list();
    let bytes = match std::fs::read(&path) {
        Ok(b) => b,
        Err(source) => return Err(CheckError::ReadList { path, source }),
    };
    let signed = match crate::operator::plant::SignedList::parse(&bytes) {
        Ok(s) => s,
        Err(source) => return Err(CheckError::List { path, source }),
    };
    let list: crate::operator::plant::PlantList = match serde_json::from_str(&signed.list) {
        Ok(l) => l,
        Err(source) => return Err(CheckError::ListJson { path, source }),
    };
    Ok((bytes, list.version))
}

/// What a certificate's end means at `now_ms`, added to `f`.
fn expiry(what: &str, not_after_ms: u64, now_ms: u64, f: &mut Finding) {
    let mut j = Judged::default();
    super::judge::expiry(what, not_after_ms, now_ms, &mut j);
    f.facts.extend(j.facts);
    f.problems.extend(j.problems);
}

/// What the plant deployed, read from its folder now: each cell's
/// configuration and bus certificate on its host (by hash), the keys it is
/// being rotated from, the operators list's version.
pub(crate) fn deployed(inventory: &Inventory) -> DeployedPlant {
    let layout = Layout::of(inventory);
    let etc = layout.etc().to_string();
    let cells = inventory
        .cells
        .iter()
        .map(|(id, cell)| {
            let config = layout.on_host(&cell.host, &format!("{etc}/{id}.toml"));
            let cert = layout.on_host(&cell.host, &format!("{etc}/agent-{id}.pem"));
            let deployed = DeployedCell {
                config: layout.shown(&config),
                config_sha256: std::fs::read(&config)
                    .map(|bytes| sha256(&bytes))
                    .map_err(super::judge::Unreadable::from),
                bus_certificate: layout.shown(&cert),
                bus_certificate_sha256: std::fs::read_to_string(&cert)
                    .ok()
                    .and_then(|pem| facts(&pem).ok())
                    .map(|c| c.sha256),
                signing_key: layout.shown(&layout.on_host(&cell.host, &layout.signing_key(id))),
                rotated_from: trust_previous(&layout, id),
            };
            (id.clone(), deployed)
        })
        .collect();
    DeployedPlant {
        schema: super::judge::DEPLOYED_SCHEMA.into(),
        operators_version: operators_list(&layout).ok().map(|l| l.1),
        cells,
    }
}

/// The check of the plant's folder at `now_ms`; the trust file it holds
/// (for the bus part) if it reads.
pub(crate) fn folder(inventory: &Inventory, now_ms: u64) -> (Report, Option<Trust>) {
    let layout = Layout::of(inventory);
    let mut report = Report::default();
    let trust = match Trust::load(&layout.trust()) {
        Ok(t) => Some(t),
        Err(e) => {
            report.findings.push(Finding {
                subject: "plant".into(),
                facts: Vec::new(),
                problems: vec![format!("{e}: make the plant first (cellwatch plant init)")],
            });
            None
        }
    };
    let etc = layout.etc().to_string();
    for (id, cell) in &inventory.cells {
        let mut f = Finding {
            subject: format!("cell {id}"),
            ..Finding::default()
        };
        let signing = layout.on_host(&cell.host, &layout.signing_key(id));
        match (AgentKey::load(&signing), &trust) {
            (Ok(key), Some(trust)) => {
                if !trust.previous_hex(id).is_empty() {
                    f.problems.push(format!(
                        "the rotation of its signing key is under way: once every client has trust.toml and the agent signs with the new key, cellwatch plant rotate-key --cell {id} --done"
                    ));
                }
                if trust.public_hex(id).as_deref() != Some(key.public_hex().as_str()) {
                    f.problems.push(format!(
                        "its signing key {} is not the trust file's: make the plant again (cellwatch plant init) and give every client the new trust file",
                        layout.shown(&signing)
                    ));
                }
            }
            (Err(e), _) => f.problems.push(format!("{e}")),
            (_, None) => {}
        }
        let cert = layout.on_host(&cell.host, &format!("{etc}/agent-{id}.pem"));
        let read = std::fs::read_to_string(&cert);
        match read.as_deref().map(facts) {
            Ok(Ok(c)) => expiry("its bus certificate", c.not_after_ms, now_ms, &mut f),
            Ok(Err(e)) => f.problems.push(format!("{}: {e}", layout.shown(&cert))),
            Err(e) => f.problems.push(format!("{}: {e}", layout.shown(&cert))),
        }
        report.findings.push(f);
    }
    // Agents the folder still makes start on a host, the inventory no
    // longer naming them there.
    if let Ok(hosts) = std::fs::read_dir(layout.dir().join("hosts")) {
        for host in hosts.flatten() {
            let host = host.file_name().to_string_lossy().to_string();
            let wants = layout.on_host(&host, "/etc/systemd/system/multi-user.target.wants");
            let Ok(links) = std::fs::read_dir(&wants) else {
                continue;
            };
            for link in links.flatten() {
                let name = link.file_name().to_string_lossy().to_string();
                let Some(id) = name
                    .strip_prefix("cellwatch@")
                    .and_then(|n| n.strip_suffix(".service"))
                else {
                    continue;
                };
                if inventory.cells.get(id).is_some_and(|c| c.host == host) {
                    continue;
                }
                report.findings.push(Finding {
                    subject: format!("host {host}"),
                    facts: Vec::new(),
                    problems: vec![format!(
                        "cell {id} is no longer in the inventory on this host: stop and disable cellwatch@{id} there, then remove its files from {}",
                        layout.shown(&layout.host(&host))
                    )],
                });
            }
        }
    }
    for (name, r) in &inventory.routers {
        let mut f = Finding {
            subject: format!("router {name}"),
            ..Finding::default()
        };
        let file = layout
            .router(name)
            .join(layout.router_etc().trim_start_matches('/'))
            .join("router.json5");
        let expected = render::router(inventory, name, r, &layout);
        match std::fs::read_to_string(&file) {
            Ok(text) if text == expected => {
                f.facts.push("access control as the inventory says".into());
            }
            Ok(_) => f.problems.push(format!(
                "{}: its access control is not the inventory's (changed by hand, or the inventory changed since: cellwatch plant init)",
                layout.shown(&file)
            )),
            Err(e) => f.problems.push(format!("{}: {e}", layout.shown(&file))),
        }
        report.findings.push(f);
    }
    (report, trust)
}

/// The running plant: each cell's agent asked `about` over `bus` (and its
/// `/readyz` over HTTP), its findings added to `report`'s.
pub(crate) async fn running(
    inventory: &Inventory,
    bus: &BusClient,
    timeout: Duration,
    now_ms: u64,
    report: &mut Report,
) {
    let plant = deployed(inventory);
    let asks = inventory.cells.keys().map(|id| async move {
        let about = bus.ask(id, Service::About, "", None, timeout).await;
        (id.clone(), about)
    });
    let answers: BTreeMap<String, _> = futures_util::future::join_all(asks)
        .await
        .into_iter()
        .collect();
    let readiness = inventory
        .cells
        .iter()
        .map(|(id, c)| async move { (id.clone(), ready(&c.host, c.metrics, timeout).await) });
    let ready: BTreeMap<String, _> = futures_util::future::join_all(readiness)
        .await
        .into_iter()
        .collect();
    for (id, cell) in &inventory.cells {
        let Some(f) = report
            .findings
            .iter_mut()
            .find(|f| f.subject == format!("cell {id}"))
        else {
            continue;
        };
        match &answers[id] {
            Err(e) => {
                let said = e.to_string();
                if said.contains("signature") || said.contains("not believed") {
                    f.problems.push(format!(
                        "its agent answers, but is not believed with the trust file's key: it signs with another key ({said})"
                    ));
                } else {
                    f.problems
                        .push(format!("its agent does not answer on the bus: {said}"));
                }
            }
            Ok(text) => match serde_json::from_str::<AboutPayload>(text) {
                Err(e) => f
                    .problems
                    .push(format!("its agent's about does not read: {e}")),
                Ok(about) => {
                    let j = judge(
                        id,
                        &about,
                        plant.cells.get(id),
                        plant.operators_version,
                        now_ms,
                    );
                    f.facts.extend(j.facts);
                    f.problems.extend(j.problems);
                }
            },
        }
        match &ready[id] {
            Ok(()) => f.facts.push("ready".into()),
            Err(why) => f.problems.push(format!(
                "its /readyz on {}:{}: {why}",
                cell.host, cell.metrics
            )),
        }
    }
}

/// The keys cell `id` is being rotated from, as the plant's trust file
/// says.
fn trust_previous(layout: &Layout, id: &str) -> Vec<String> {
    Trust::load(&layout.trust()).map_or_else(|_| Vec::new(), |t| t.previous_hex(id))
}

/// Asks `http://host:port/readyz`.
async fn ready(host: &str, port: u16, timeout: Duration) -> Result<(), CheckError> {
    use http_body_util::{BodyExt, Empty};
    use hyper_util::client::legacy::Client;
    let client: Client<_, Empty<bytes::Bytes>> =
        Client::builder(hyper_util::rt::TokioExecutor::new()).build_http();
    let uri: hyper::Uri = format!("http://{host}:{port}/readyz").parse()?;
    let asked = tokio::time::timeout(timeout, async {
        let response = client.get(uri).await?;
        let status = response.status();
        let body = http_body_util::Limited::new(response.into_body(), 4096)
            .collect()
            .await
            .map(|b| String::from_utf8_lossy(&b.to_bytes()).trim().to_string())
            .unwrap_or_default();
        if status.is_success() {
            Ok(())
        } else {
            Err(CheckError::NotReady { status, body })
        }
    })
    .await;
    asked.unwrap_or(Err(CheckError::NoAnswer(timeout)))
}

/// How long a probe put is repeated, waiting for it to come through.
const PROBE_FOR: Duration = Duration::from_secs(2);

/// Whether router `name` (reached by `speaker` and `hearer`, two sessions
/// of the plant administrator's certificate through it alone) lets a
/// certificate that is not a cell's agent put under that cell's prefix:
/// `hearer` subscribes, `speaker` puts a probe there again and again for
/// [`PROBE_FOR`]. Through a router with the inventory's access control
/// nothing comes; the finding is added to `report`'s.
pub(crate) async fn probe(
    inventory: &Inventory,
    name: &str,
    speaker: &zenoh::Session,
    hearer: &zenoh::Session,
    report: &mut Report,
) {
    let Some(cell) = inventory.cells.keys().next() else {
        return;
    };
    let key = format!(
        "{}/_probe",
        crate::config::cell_prefix(&inventory.root, cell)
    );
    let Ok(heard) = hearer.declare_subscriber(&key).await else {
        return;
    };
    let until = tokio::time::Instant::now() + PROBE_FOR;
    let mut through = false;
    while tokio::time::Instant::now() < until && !through {
        let _ = speaker
            .put(&key, "cellwatch plant check: a put no router may carry")
            .await;
        through = tokio::time::timeout(Duration::from_millis(100), heard.recv_async())
            .await
            .is_ok_and(|s| s.is_ok());
    }
    let subject = format!("router {name}");
    let Some(f) = report.findings.iter_mut().find(|f| f.subject == subject) else {
        return;
    };
    if through {
        f.problems.push(format!(
            "it carried a put under {key} from the plant-admin certificate: its running access control is off or not the inventory's (start it with routers/{name}/…/router.json5)"
        ));
    } else {
        f.facts
            .push("its running access control keeps others from speaking for a cell".into());
    }
}
