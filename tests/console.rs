//! `cellwatch console` end to end: the real agent and console binaries on
//! the simulated CNC, a real headless Chromium on the console's pages
//! (`browser`), operators' keys loaded into the page and commands signed
//! there with WebCrypto Ed25519.

mod access;
mod forcing;
mod https;
mod pages;
mod ringing;

use std::io::BufRead;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use cellwatch::operator::{Action, OperatorKey};
use cellwatch::sim::cnc::SimulatedCnc;
use fantoccini::Locator;

use crate::browser::Browser;
use crate::spawned::{self, kim, Cell};
use crate::util::{bus_pki, bus_tls, trust_file};

/// Operator ana may acknowledge, nothing else.
const ANA: &str = "ffeeddccbbaa99887766554433221100ffeeddccbbaa99887766554433221100";

/// What a hostile comment in an I/O list would do if the page made HTML
/// of it.
const HOSTILE: &str = "<script>window.__pwned=1</script><img src=x onerror=window.__pwned=2>";

/// The agent, the console and their files.
struct Plant {
    sim: SimulatedCnc,
    cell: Cell,
    agent: Child,
    console: Child,
    url: String,
}

impl Drop for Plant {
    fn drop(&mut self) {
        for child in [&mut self.console, &mut self.agent] {
            let _ = child.kill();
            let _ = child.wait();
        }
        self.sim.stop();
    }
}

/// The simulated CNC, its agent (kim may do everything, ana only
/// acknowledge; every comment of the CSD check's I/O list ends with [`HOSTILE`]) and
/// a console on it, on ports the system picks.
async fn plant(dir: &Path) -> Plant {
    plant_with(dir, "", "").await
}

/// [`plant`] with `http` added to the console's `[http]` section and
/// `sections` at the end of its configuration.
async fn plant_with(dir: &Path, http: &str, sections: &str) -> Plant {
    plant_with_cell(dir, http, sections, "").await
}

/// [`plant_with`] with `cell_sections` at the end of the cell's
/// configuration.
async fn plant_with_cell(dir: &Path, http: &str, sections: &str, cell_sections: &str) -> Plant {
    let (sim, mut cell) = spawned::start(dir).await;
    let ana = OperatorKey::from_hex("ana", ANA).unwrap();
    let operators = dir.join("operators.toml");
    let all =
        std::fs::read_to_string(&operators).unwrap() + "\n" + &ana.operators_entry(&[Action::Ack]);
    std::fs::write(&operators, all).unwrap();
    std::fs::write(dir.join("kim.key"), kim().to_file()).unwrap();
    std::fs::write(dir.join("ana.key"), ana.to_file()).unwrap();
    // Every comment of the CSD machine's I/O list ends with it: whichever
    // contacts CSD names, their comments carry it.
    let csd: String =
        std::fs::read_to_string(crate::util::root().join("config/cnc/csd-comments.csv"))
            .unwrap()
            .lines()
            .enumerate()
            .map(|(i, l)| {
                if i == 0 {
                    format!("{l}\n")
                } else {
                    format!("{l} {HOSTILE}\n")
                }
            })
            .collect();
    std::fs::write(dir.join("csd-comments.csv"), csd).unwrap();
    let config = std::fs::read_to_string(&cell.config).unwrap().replace(
        &format!(
            "{}/config/cnc/csd-comments.csv",
            crate::util::root().display()
        ),
        &dir.join("csd-comments.csv").display().to_string(),
    ) + cell_sections;
    std::fs::write(&cell.config, config).unwrap();
    let agent = cell.spawn("agent.log").await;

    let trust = trust_file(dir);
    bus_pki(dir, &["console"]);
    let tls = bus_tls(dir, "console");
    std::fs::write(
        dir.join("console.toml"),
        format!(
            "[http]\nlisten = \"127.0.0.1:0\"\n{http}\n\n[bus]\nconnect = [\"quic/127.0.0.1:{}\"]\ntrust = {:?}\ntls = {{ ca = {:?}, cert = {:?}, key = {:?} }}\n\n[operators]\nfile = {:?}\n\n[areas]\nmachining = [\"m01ps0004\"]\n{sections}\n",
            cell.zenoh_port, trust, tls.ca, tls.cert, tls.key, operators
        ),
    )
    .unwrap();
    let mut console = Command::new(env!("CARGO_BIN_EXE_cellwatch"))
        .args(["console", "--config"])
        .arg(dir.join("console.toml"))
        .stdout(Stdio::piped())
        .stderr(std::fs::File::create(dir.join("console.log")).unwrap())
        .spawn()
        .unwrap();
    let mut first = String::new();
    std::io::BufReader::new(console.stdout.take().unwrap())
        .read_line(&mut first)
        .unwrap();
    let url = first
        .trim()
        .strip_prefix("cellwatch console: ")
        .unwrap_or_else(|| {
            panic!(
                "the console said {first:?}:\n{}",
                std::fs::read_to_string(dir.join("console.log")).unwrap_or_default()
            )
        })
        .to_string();
    assert!(url.contains("://127.0.0.1:"), "{url}");
    Plant {
        sim,
        cell,
        agent,
        console,
        url,
    }
}

/// Opens `route` of the console, signed in as kim, and waits until its
/// live stream runs and the cell's agent is known to be there.
async fn open(b: &Browser, p: &Plant, route: &str) {
    let key = p.cell.dir.join("kim.key");
    open_at(b, &p.url, "m01ps0004", route, &key, "kim").await;
}

/// Opens `route` of the console at `url`, as [`open`], for `cell`,
/// signed in with `key` (of `operator`) unless a key is loaded already.
async fn open_at(b: &Browser, url: &str, cell: &str, route: &str, key: &Path, operator: &str) {
    b.client.goto(&format!("{url}{route}")).await.unwrap();
    b.wait_until(
        "the page knows whether it is signed in",
        "return typeof S !== 'undefined' && S.started === true;",
    )
    .await;
    let loaded = b
        .client
        .execute("return S.key !== null;", vec![])
        .await
        .unwrap();
    if loaded != serde_json::json!(true) {
        load_key(b, key, operator).await;
    }
    b.wait_for("#link.up").await;
    b.wait_until(
        "the console knows the agent is up",
        &format!("return typeof S !== 'undefined' && S.cells.has('{cell}') && S.cells.get('{cell}').agent === true;"),
    )
    .await;
}

/// Loads the operator key file `key` into the page.
async fn load_key(b: &Browser, key: &Path, operator: &str) {
    b.client
        .find(Locator::Css("#key-file"))
        .await
        .unwrap()
        .send_keys(key.to_str().unwrap())
        .await
        .unwrap();
    b.wait_until(
        "the key is loaded",
        &format!("return S.key !== null && S.key.operator === '{operator}';"),
    )
    .await;
}

/// The answer line after an action, once the agent answered.
async fn answer(b: &Browser) -> String {
    b.wait_until(
        "the agent answered",
        "const a = document.getElementById('answer'); return !!a && (a.classList.contains('accepted') || a.classList.contains('refused'));",
    )
    .await;
    b.text("#answer").await
}

/// One HTTP/1.1 request to `addr` (`IP:PORT`) as written in `head` (the
/// `Connection: close` and length added), and its status, head and body.
pub(crate) fn request(addr: &str, head: &str, body: &str) -> (u16, String, String) {
    use std::io::{Read, Write};
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    let text = format!(
        "{head}\r\nConnection: close\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    );
    s.write_all(text.as_bytes()).unwrap();
    let mut got = String::new();
    let _ = s.read_to_string(&mut got);
    let (head, body) = got.split_once("\r\n\r\n").unwrap_or((&got, ""));
    let status = head
        .split(' ')
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    (status, head.to_string(), body.to_string())
}

/// Signs `operator` (key file `key`) in over HTTP as the page does, and
/// returns the session's `Cookie` header line.
pub(crate) fn sign_in(addr: &str, key: &Path) -> Result<String, (u16, String)> {
    use ed25519_dalek::Signer;
    let file =
        cellwatch::operator::OperatorKey::parse("key", &std::fs::read_to_string(key).unwrap())
            .unwrap();
    let seed = std::fs::read_to_string(key)
        .unwrap()
        .lines()
        .find_map(|l| l.strip_prefix("private_key = \""))
        .map(|l| l.trim_end_matches('"').to_string())
        .unwrap();
    let signing =
        ed25519_dalek::SigningKey::from_bytes(&hex::decode(seed).unwrap().try_into().unwrap());
    let host = format!("Host: {addr}");
    let (_, _, body) = request(
        addr,
        &format!("POST /api/sign-in/challenge HTTP/1.1\r\n{host}"),
        "",
    );
    let challenge = serde_json::from_str::<serde_json::Value>(&body).unwrap()["challenge"]
        .as_str()
        .unwrap()
        .to_string();
    let text = format!("cellwatch-console-sign-in-v1\n{challenge}\n{addr}\n");
    let signature = hex::encode(signing.sign(text.as_bytes()).to_bytes());
    let answer = serde_json::json!({ "operator": file.operator, "challenge": challenge, "signature": signature });
    let (status, head, body) = request(
        addr,
        &format!("POST /api/sign-in HTTP/1.1\r\n{host}\r\nContent-Type: application/json"),
        &answer.to_string(),
    );
    if status != 200 {
        return Err((status, body));
    }
    let cookie = head
        .lines()
        .find_map(|l| l.strip_prefix("set-cookie: "))
        .and_then(|c| c.split(';').next())
        .unwrap()
        .to_string();
    Ok(format!("Cookie: {cookie}"))
}
