//! `cellwatch-bench console-bounds`: what one client's share of the console
//! leaves the others. The console under test (`cellwatch console`, its own
//! process) reads `cells` cells, each with one alarm put on a loopback bus
//! and a stand-in agent answering its history (a page of 100 rows, sealed
//! with the cell's key for each question, as an agent seals its answers).
//! An operator signed in from 127.0.0.1 asks `/api/plant` and a cell's
//! history five times a second each, on one kept-alive connection, and
//! the latency of each answer is taken: first alone (the baseline), then
//! while another operator signed in from 127.0.0.2 (mallory, a key of the
//! operators file on a host gone bad) opens as many connections and live
//! streams as it can and floods requests, `/api/kpi?since=1970-01-01` and
//! histories among them. The operator runs on a thread and runtime of its
//! own, so the attacker's tasks in this process do not delay its clock.

use std::collections::BTreeMap;
use std::io::BufRead;
use std::net::{IpAddr, SocketAddr};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::Context;
use cellwatch::bus::envelope::{AgentKey, Kind};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

/// What to run.
pub struct Setup {
    /// The `cellwatch` binary under test.
    pub agent: PathBuf,
    /// Where its files go.
    pub workdir: PathBuf,
    /// Cells the console reads.
    pub cells: usize,
    /// How long each phase (alone, under attack) lasts.
    pub phase: Duration,
    /// Connections the attacker tries to hold at once.
    pub connections: usize,
}

/// The attacker's address.
const ATTACKER: &str = "127.0.0.2";

/// Runs the benchmark; returns its Markdown.
pub async fn run(setup: &Setup) -> anyhow::Result<String> {
    std::fs::create_dir_all(&setup.workdir)?;
    let workdir = std::fs::canonicalize(&setup.workdir)?;
    let keys: Vec<Arc<AgentKey>> = (0..setup.cells)
        .map(|i| Arc::new(AgentKey::generate(&format!("cell{i:03}"))))
        .collect();
    let entries: String = keys.iter().map(|k| k.trust_entry()).collect();
    let trust_path = workdir.join("trust.toml");
    std::fs::write(&trust_path, &entries)?;
    let publisher = cellwatch::bus::open(&crate::console::plain(
        vec![],
        vec!["tcp/127.0.0.1:0".into()],
    ))
    .await
    .context("publisher session")?;
    let endpoint = publisher
        .info()
        .locators()
        .await
        .first()
        .map(ToString::to_string)
        .context("the publisher listens nowhere")?;

    // The stand-in agents: each cell's history answered, sealed.
    let page = history_page();
    let answered = Arc::new(AtomicU64::new(0));
    let mut queryables = Vec::new();
    for key in &keys {
        let (key, page, answered) = (key.clone(), page.clone(), answered.clone());
        let on = format!("cellwatch/{}/history", key.cell());
        let replier = on.clone();
        queryables.push(
            publisher
                .declare_queryable(on)
                .callback(move |q| {
                    let sealed = key.seal(
                        Kind::Reply,
                        &replier,
                        q.parameters().as_str(),
                        cellwatch::clock::now_ms(),
                        page.clone(),
                    );
                    let (replier, answered) = (replier.clone(), answered.clone());
                    tokio::spawn(async move {
                        if q.reply(replier, sealed).await.is_ok() {
                            answered.fetch_add(1, Ordering::Relaxed);
                        }
                    });
                })
                .await
                .map_err(|e| anyhow::anyhow!("{e}"))?,
        );
    }

    // Two operators: the one measured, and mallory.
    let operator = cellwatch::operator::OperatorKey::generate("operator");
    let mallory = cellwatch::operator::OperatorKey::generate("mallory");
    let ack = [cellwatch::operator::Action::Ack];
    std::fs::write(
        workdir.join("operators.toml"),
        operator.operators_entry(&ack) + &mallory.operators_entry(&ack),
    )?;
    std::fs::write(
        workdir.join("console.toml"),
        format!(
            "[http]\nlisten = \"127.0.0.1:0\"\n[bus]\nconnect = [\"{endpoint}\"]\nplain = true\ntrust = {trust_path:?}\n[operators]\nfile = {:?}\n",
            workdir.join("operators.toml"),
        ),
    )?;
    let mut console = std::process::Command::new(&setup.agent)
        .args(["console", "--config"])
        .arg(workdir.join("console.toml"))
        .stdout(std::process::Stdio::piped())
        .stderr(std::fs::File::create(workdir.join("console.log"))?)
        .spawn()
        .context("cellwatch console")?;
    let mut line = String::new();
    std::io::BufReader::new(console.stdout.take().context("stdout")?).read_line(&mut line)?;
    let result = async {
        let url = line
            .trim()
            .strip_prefix("cellwatch console: ")
            .context("the console did not say its URL (see console.log)")?;
        let addr: SocketAddr = url
            .trim_start_matches("http://")
            .trim_end_matches('/')
            .parse()
            .context("the console's address")?;
        // One alarm a cell, so that the plant is not empty.
        for (i, key) in keys.iter().enumerate() {
            let (k, body) = crate::console::event(key, "ese", i, true);
            let sealed = key.seal_puts(cellwatch::clock::now_ms(), &[(&k, &body)]);
            let envelope = sealed.envelope(0, &k, &body);
            publisher
                .put(k, envelope)
                .await
                .map_err(|e| anyhow::anyhow!("{e}"))?;
        }
        let operator_cookie = sign_in(addr, None, &operator).await?;
        let mallory_cookie = sign_in(addr, Some(ATTACKER.parse()?), &mallory).await?;
        wait_for_plant(addr, &operator_cookie, keys.len()).await?;
        measure(
            setup,
            addr,
            &operator_cookie,
            &mallory_cookie,
            &answered,
            console.id(),
        )
        .await
    }
    .await;
    let _ = console.kill();
    let _ = console.wait();
    drop(queryables);
    result
}

/// A history page of 100 state rows, as an agent answers one.
fn history_page() -> String {
    let rows: Vec<serde_json::Value> = (0..100)
        .map(|i| {
            serde_json::json!({
                "table": "state_history",
                "seq": i + 1,
                "at": cellwatch::clock::rfc3339(1_700_000_000_000 + i * 1000),
                "fields": {"kind": "state", "state": if i % 2 == 0 { "running" } else { "idle" }},
            })
        })
        .collect();
    serde_json::json!({ "schema": "cellwatch.history.v1", "rows": rows, "next": null }).to_string()
}

/// A kept-alive HTTP/1.1 connection to the console.
pub struct Connection {
    stream: TcpStream,
    host: String,
    buffered: Vec<u8>,
}

impl Connection {
    /// Connects to `addr` from `from` (the system's choice when `None`).
    pub async fn open(addr: SocketAddr, from: Option<IpAddr>) -> std::io::Result<Connection> {
        let socket = tokio::net::TcpSocket::new_v4()?;
        if let Some(ip) = from {
            socket.bind(SocketAddr::new(ip, 0))?;
        }
        let stream = socket.connect(addr).await?;
        stream.set_nodelay(true)?;
        Ok(Connection {
            stream,
            host: addr.to_string(),
            buffered: Vec::new(),
        })
    }

    /// Writes a request; `cookie` is a `Cookie` header line's value.
    pub async fn send(
        &mut self,
        method: &str,
        path: &str,
        cookie: &str,
        body: &str,
    ) -> std::io::Result<()> {
        let cookie = if cookie.is_empty() {
            String::new()
        } else {
            format!("Cookie: {cookie}\r\n")
        };
        let text = format!(
            "{method} {path} HTTP/1.1\r\nHost: {}\r\n{cookie}Content-Type: application/json\r\nContent-Length: {}\r\n\r\n{body}",
            self.host,
            body.len()
        );
        self.stream.write_all(text.as_bytes()).await
    }

    /// Reads the head of an answer: its status and header lines.
    pub async fn head(&mut self) -> std::io::Result<(u16, Vec<String>)> {
        let end = loop {
            if let Some(i) = self.buffered.windows(4).position(|w| w == b"\r\n\r\n") {
                break i;
            }
            self.fill().await?;
        };
        let head = String::from_utf8_lossy(&self.buffered[..end]).to_string();
        self.buffered.drain(..end + 4);
        let mut lines = head.lines().map(str::to_string);
        let status = lines
            .next()
            .and_then(|l| l.split(' ').nth(1).and_then(|s| s.parse().ok()))
            .unwrap_or(0);
        Ok((status, lines.collect()))
    }

    /// Reads a whole answer (its length given): status, headers, body.
    pub async fn answer(&mut self) -> std::io::Result<(u16, Vec<String>, Vec<u8>)> {
        let (status, headers) = self.head().await?;
        let length = headers
            .iter()
            .find_map(|h| {
                let (name, value) = h.split_once(':')?;
                name.eq_ignore_ascii_case("content-length")
                    .then(|| value.trim().parse::<usize>().ok())?
            })
            .unwrap_or(0);
        while self.buffered.len() < length {
            self.fill().await?;
        }
        let body = self.buffered.drain(..length).collect();
        Ok((status, headers, body))
    }

    async fn fill(&mut self) -> std::io::Result<()> {
        let mut chunk = [0u8; 16_384];
        let n = self.stream.read(&mut chunk).await?;
        if n == 0 {
            return Err(std::io::ErrorKind::UnexpectedEof.into());
        }
        self.buffered.extend_from_slice(&chunk[..n]);
        Ok(())
    }

    /// A GET answered in full: its status.
    pub async fn get(&mut self, path: &str, cookie: &str) -> std::io::Result<u16> {
        self.send("GET", path, cookie, "").await?;
        Ok(self.answer().await?.0)
    }
}

/// Signs `key`'s operator in from `from` as the page does: the session
/// cookie (`name=value`).
pub async fn sign_in(
    addr: SocketAddr,
    from: Option<IpAddr>,
    key: &cellwatch::operator::OperatorKey,
) -> anyhow::Result<String> {
    use ed25519_dalek::Signer;
    let file = key.to_file();
    let seed = file
        .lines()
        .find_map(|l| l.strip_prefix("private_key = \""))
        .map(|l| l.trim_end_matches('"').to_string())
        .context("the key file's private key")?;
    let seed: [u8; 32] = hex::decode(seed)?
        .try_into()
        .map_err(|_| anyhow::anyhow!("a private key of 32 bytes"))?;
    let signing = ed25519_dalek::SigningKey::from_bytes(&seed);
    let mut c = Connection::open(addr, from).await?;
    c.send("POST", "/api/sign-in/challenge", "", "").await?;
    let (_, _, body) = c.answer().await?;
    let challenge = serde_json::from_slice::<serde_json::Value>(&body)?["challenge"]
        .as_str()
        .context("a challenge")?
        .to_string();
    let text = format!("cellwatch-console-sign-in-v1\n{challenge}\n{addr}\n");
    let signature = hex::encode(signing.sign(text.as_bytes()).to_bytes());
    let operator = file
        .lines()
        .find_map(|l| l.strip_prefix("operator = \""))
        .map(|l| l.trim_end_matches('"').to_string())
        .context("the key file's operator")?;
    let answer =
        serde_json::json!({ "operator": operator, "challenge": challenge, "signature": signature });
    c.send("POST", "/api/sign-in", "", &answer.to_string())
        .await?;
    let (status, headers, body) = c.answer().await?;
    anyhow::ensure!(
        status == 200,
        "sign-in refused: {}",
        String::from_utf8_lossy(&body)
    );
    headers
        .iter()
        .find_map(|h| h.strip_prefix("set-cookie: "))
        .and_then(|c| c.split(';').next())
        .map(str::to_string)
        .context("no session cookie")
}

/// Waits until the plant the operator reads holds every cell's alarm.
async fn wait_for_plant(addr: SocketAddr, cookie: &str, cells: usize) -> anyhow::Result<()> {
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let mut c = Connection::open(addr, None).await?;
        c.send("GET", "/api/plant", cookie, "").await?;
        let (_, _, body) = c.answer().await?;
        let plant: serde_json::Value = serde_json::from_slice(&body).unwrap_or_default();
        if plant["alarms"].as_array().map_or(0, Vec::len) >= cells {
            return Ok(());
        }
        anyhow::ensure!(
            Instant::now() < deadline,
            "the console never had every cell's alarm: {plant}"
        );
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
}

/// The operator's answers of one phase: latencies (ms) by route, and
/// statuses other than 200.
#[derive(Default)]
struct Answers {
    plant: Vec<f64>,
    history: Vec<f64>,
    other: BTreeMap<String, u64>,
}

/// The operator, on a thread of its own, for `phase`: each 200 ms a plant
/// and a cell's history, on one kept-alive connection (opened again if the
/// console closes it).
fn operator(
    addr: SocketAddr,
    cookie: String,
    cells: usize,
    phase: Duration,
) -> std::thread::JoinHandle<anyhow::Result<Answers>> {
    std::thread::spawn(move || {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()?;
        runtime.block_on(async move {
            let mut answers = Answers::default();
            let mut c = Connection::open(addr, None).await?;
            let mut tick = tokio::time::interval(Duration::from_millis(200));
            let end = Instant::now() + phase;
            let mut n = 0usize;
            while Instant::now() < end {
                tick.tick().await;
                let history = format!("/api/cells/cell{:03}/history?since=1h", n % cells);
                n += 1;
                for (path, plant) in [("/api/plant", true), (history.as_str(), false)] {
                    let start = Instant::now();
                    let status = match c.get(path, &cookie).await {
                        Ok(s) => s,
                        Err(_) => {
                            c = Connection::open(addr, None).await?;
                            c.get(path, &cookie).await.unwrap_or(0)
                        }
                    };
                    let ms = start.elapsed().as_secs_f64() * 1000.0;
                    if status == 200 {
                        if plant {
                            answers.plant.push(ms)
                        } else {
                            answers.history.push(ms)
                        }
                    } else {
                        let route = if plant { "plant" } else { "history" };
                        *answers
                            .other
                            .entry(format!("{route} {status}"))
                            .or_default() += 1;
                    }
                }
            }
            Ok(answers)
        })
    })
}

/// What the attacker got, by what it asked and the answer's status.
#[derive(Default)]
struct Attack {
    counts: Mutex<BTreeMap<String, u64>>,
}

impl Attack {
    fn count(&self, what: &str) {
        if let Ok(mut c) = self.counts.lock() {
            *c.entry(what.to_string()).or_default() += 1;
        }
    }
}

/// The attacker from [`ATTACKER`] until `stop`: `connections` connections
/// opened, a live stream asked on each (held while it lasts), and on the
/// connections refused a stream, requests back to back; new connections
/// tried all the while.
async fn attack(
    addr: SocketAddr,
    cookie: String,
    connections: usize,
    stop: Arc<AtomicBool>,
    attack: Arc<Attack>,
) {
    let from: IpAddr = ATTACKER.parse().unwrap_or(IpAddr::from([127, 0, 0, 2]));
    let mut tasks = Vec::new();
    for i in 0..connections {
        let (cookie, stop, attack) = (cookie.clone(), stop.clone(), attack.clone());
        tasks.push(tokio::spawn(async move {
            let Ok(mut c) = Connection::open(addr, Some(from)).await else {
                attack.count("connection refused");
                return;
            };
            // A live stream: held, its events read, while the console
            // keeps it.
            if c.send("GET", "/api/events", &cookie, "").await.is_err() {
                attack.count("connection refused");
                return;
            }
            match c.head().await {
                Err(_) => {
                    attack.count("connection closed by the console at once");
                    return;
                }
                Ok((200, _)) => {
                    attack.count("live stream opened");
                    while !stop.load(Ordering::Relaxed) {
                        if tokio::time::timeout(Duration::from_millis(200), c.fill())
                            .await
                            .is_ok_and(|r| r.is_err())
                        {
                            break;
                        }
                        c.buffered.clear();
                    }
                    return;
                }
                Ok((status, headers)) => {
                    let length = headers
                        .iter()
                        .find_map(|h| {
                            h.split_once(':')
                                .filter(|(n, _)| n.eq_ignore_ascii_case("content-length"))
                                .and_then(|(_, v)| v.trim().parse::<usize>().ok())
                        })
                        .unwrap_or(0);
                    while c.buffered.len() < length {
                        if c.fill().await.is_err() {
                            break;
                        }
                    }
                    let length = length.min(c.buffered.len());
                    c.buffered.drain(..length);
                    attack.count(&format!("live stream {status}"));
                }
            }
            // Then a flood: the plant, years of figures, histories.
            let mut n = i;
            while !stop.load(Ordering::Relaxed) {
                let (what, path) = match n % 3 {
                    0 => ("plant", "/api/plant".to_string()),
                    1 => ("kpi since 1970", "/api/kpi?since=1970-01-01".to_string()),
                    _ => (
                        "history",
                        format!("/api/cells/cell{:03}/history?since=1h", n % 7),
                    ),
                };
                n += 1;
                match c.get(&path, &cookie).await {
                    Ok(status) => attack.count(&format!("{what} {status}")),
                    Err(_) => {
                        attack.count("connection closed");
                        match Connection::open(addr, Some(from)).await {
                            Ok(again) => c = again,
                            Err(_) => break,
                        }
                    }
                }
            }
        }));
    }
    // New connections tried all the while, each asked once.
    while !stop.load(Ordering::Relaxed) {
        match Connection::open(addr, Some(from)).await {
            Ok(mut c) => match c.get("/api/plant", &cookie).await {
                Ok(status) => attack.count(&format!("new connection: plant {status}")),
                Err(_) => attack.count("new connection: closed by the console at once"),
            },
            Err(_) => attack.count("new connection: refused"),
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    for t in tasks {
        let _ = t.await;
    }
}

fn percentile(samples: &[f64], p: f64) -> f64 {
    let mut s = samples.to_vec();
    s.sort_by(f64::total_cmp);
    if s.is_empty() {
        return f64::NAN;
    }
    s[((s.len() - 1) as f64 * p).round() as usize]
}

async fn measure(
    setup: &Setup,
    addr: SocketAddr,
    operator_cookie: &str,
    mallory_cookie: &str,
    answered: &AtomicU64,
    console_pid: u32,
) -> anyhow::Result<String> {
    let cpu = || crate::measure::cpu_seconds(console_pid).unwrap_or(f64::NAN);
    eprintln!("cellwatch-bench: console-bounds: the operator alone");
    let (cpu0, answered0) = (cpu(), answered.load(Ordering::Relaxed));
    let alone = operator(addr, operator_cookie.into(), setup.cells, setup.phase)
        .join()
        .map_err(|_| anyhow::anyhow!("the operator's thread panicked"))??;
    let (cpu1, answered1) = (cpu(), answered.load(Ordering::Relaxed));
    eprintln!("cellwatch-bench: console-bounds: the operator under attack");
    let stop = Arc::new(AtomicBool::new(false));
    let counts = Arc::new(Attack::default());
    let attacker = tokio::spawn(attack(
        addr,
        mallory_cookie.into(),
        setup.connections,
        stop.clone(),
        counts.clone(),
    ));
    // The attacker's connections and streams first.
    tokio::time::sleep(Duration::from_secs(1)).await;
    let (cpu2, answered2) = (cpu(), answered.load(Ordering::Relaxed));
    let operator_cookie = operator_cookie.to_string();
    let (cells, phase) = (setup.cells, setup.phase);
    let attacked =
        tokio::task::spawn_blocking(move || operator(addr, operator_cookie, cells, phase).join())
            .await?
            .map_err(|_| anyhow::anyhow!("the operator's thread panicked"))??;
    let (cpu3, answered3) = (cpu(), answered.load(Ordering::Relaxed));
    stop.store(true, Ordering::Relaxed);
    let _ = tokio::time::timeout(Duration::from_secs(30), attacker).await;
    let seconds = setup.phase.as_secs_f64();
    let mut out = format!(
        "{} cells; each phase {seconds:.0} s; the operator from 127.0.0.1 asks the plant and a cell's history every 200 ms; mallory from {ATTACKER} holds up to {} connections\n\n| phase | `/api/plant` p50 (ms) | p99 (ms) | history p50 (ms) | p99 (ms) | operator's answers not 200 | console CPU (% of a core) | histories the agents answered |\n|---|---|---|---|---|---|---|---|\n",
        setup.cells, setup.connections
    );
    let row = |what: &str, a: &Answers, cpu_s: f64, histories: u64| {
        let other: Vec<String> = a.other.iter().map(|(k, v)| format!("{k}: {v}")).collect();
        format!(
            "| {what} | {:.2} | {:.2} | {:.2} | {:.2} | {} | {:.0} | {histories} |\n",
            percentile(&a.plant, 0.5),
            percentile(&a.plant, 0.99),
            percentile(&a.history, 0.5),
            percentile(&a.history, 0.99),
            if other.is_empty() {
                "none".to_string()
            } else {
                other.join(", ")
            },
            cpu_s * 100.0 / seconds,
        )
    };
    out += &row(
        "alone (baseline)",
        &alone,
        cpu1 - cpu0,
        answered1 - answered0,
    );
    out += &row(
        "under attack",
        &attacked,
        cpu3 - cpu2,
        answered3 - answered2,
    );
    let ratio = |f: fn(&Answers) -> &Vec<f64>, p: f64| {
        percentile(f(&attacked), p) / percentile(f(&alone), p)
    };
    out += &format!(
        "| ratio, under attack ÷ alone | {:.2} | {:.2} | {:.2} | {:.2} | | | |\n\nWhat mallory got (from {ATTACKER}, over the attack):\n\n| asked | answers |\n|---|---|\n",
        ratio(|a| &a.plant, 0.5),
        ratio(|a| &a.plant, 0.99),
        ratio(|a| &a.history, 0.5),
        ratio(|a| &a.history, 0.99),
    );
    let counts = counts.counts.lock().map(|c| c.clone()).unwrap_or_default();
    for (what, n) in counts {
        out += &format!("| {what} | {n} |\n");
    }
    Ok(out)
}
