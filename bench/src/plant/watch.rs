//! The plant watched: a bare subscriber on a router (fault alarms and the
//! agents' liveliness tokens), the console's event stream and plant, the
//! processes' CPU and memory, Prometheus's targets.

use std::collections::HashMap;
use std::net::SocketAddr;
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime};

use anyhow::{anyhow, bail, Context};
use tokio::io::{AsyncBufReadExt, AsyncWriteExt};

use crate::alarms::{self, Seen};
use crate::console_bounds::Connection;
use crate::measure;

use super::parts::{Cell, Process, BACK_WITHIN};

/// Prometheus's targets: how many are up, of how many.
pub(super) async fn targets_up(port: u16) -> anyhow::Result<(usize, usize)> {
    let addr: SocketAddr = format!("127.0.0.1:{port}").parse()?;
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let v: serde_json::Value =
            serde_json::from_slice(&read_to_end(addr, "/api/v1/targets?state=active").await?)
                .context("Prometheus's targets")?;
        let targets = v["data"]["activeTargets"]
            .as_array()
            .cloned()
            .unwrap_or_default();
        let up = targets.iter().filter(|t| t["health"] == "up").count();
        if up == targets.len() && up > 0 || Instant::now() > deadline {
            return Ok((up, targets.len()));
        }
        tokio::time::sleep(Duration::from_secs(1)).await;
    }
}

/// The body of `GET path` over HTTP/1.0 (read to the end: no chunks).
async fn read_to_end(addr: SocketAddr, path: &str) -> anyhow::Result<Vec<u8>> {
    use tokio::io::AsyncReadExt;
    let mut stream = tokio::net::TcpStream::connect(addr).await?;
    stream
        .write_all(format!("GET {path} HTTP/1.0\r\nHost: {addr}\r\n\r\n").as_bytes())
        .await?;
    let mut all = Vec::new();
    stream.read_to_end(&mut all).await?;
    let start = all
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .map_or(all.len(), |i| i + 4);
    Ok(all.split_off(start))
}

/// The processes measured.
pub(super) struct Pids {
    pub(super) agents: Vec<u32>,
    pub(super) routers: Vec<u32>,
    pub(super) console: u32,
    pub(super) prometheus: Option<u32>,
}

/// CPU seconds used so far, per process group.
pub(super) struct Cpu {
    pub(super) agents: f64,
    pub(super) routers: Vec<f64>,
    pub(super) console: f64,
    pub(super) prometheus: Option<f64>,
}

/// CPU shares (of a core) and resident memory (bytes).
pub(super) struct Shares {
    pub(super) agents: f64,
    pub(super) routers: Vec<(f64, u64)>,
    pub(super) console: (f64, u64),
    pub(super) prometheus: Option<(f64, u64)>,
}

impl Pids {
    pub(super) fn of(
        cells: &[Cell],
        routers: &[Process],
        console: &Process,
        prometheus: Option<&Process>,
    ) -> Pids {
        Pids {
            agents: cells
                .iter()
                .filter_map(|c| c.agent.as_ref().map(Process::pid))
                .collect(),
            routers: routers.iter().map(Process::pid).collect(),
            console: console.pid(),
            prometheus: prometheus.map(Process::pid),
        }
    }

    pub(super) fn cpu(&self) -> anyhow::Result<Cpu> {
        let mut agents = 0.0;
        for &p in &self.agents {
            agents += measure::cpu_seconds(p)?;
        }
        Ok(Cpu {
            agents,
            routers: self
                .routers
                .iter()
                .map(|&p| measure::cpu_seconds(p))
                .collect::<anyhow::Result<_>>()?,
            console: measure::cpu_seconds(self.console)?,
            prometheus: self.prometheus.map(measure::cpu_seconds).transpose()?,
        })
    }
}

impl Cpu {
    /// The shares since `before`, over `wall` seconds, with the resident
    /// memory of the processes in `pids` now.
    pub(super) fn since(&self, before: &Cpu, wall: f64, pids: &Pids) -> anyhow::Result<Shares> {
        let rss = |p: u32| measure::rss(p).map(|r| r.0);
        Ok(Shares {
            agents: (self.agents - before.agents) / wall,
            routers: self
                .routers
                .iter()
                .zip(&before.routers)
                .zip(&pids.routers)
                .map(|((a, b), &p)| Ok(((a - b) / wall, rss(p)?)))
                .collect::<anyhow::Result<_>>()?,
            console: ((self.console - before.console) / wall, rss(pids.console)?),
            prometheus: match (self.prometheus, before.prometheus, pids.prometheus) {
                (Some(a), Some(b), Some(p)) => Some(((a - b) / wall, rss(p)?)),
                _ => None,
            },
        })
    }
}

/// A bare subscriber on one router: every fault alarm as it arrives, and
/// the agents' liveliness tokens.
pub(super) struct Bus {
    pub(super) seen: Seen,
    pub(super) alive: Arc<Mutex<HashMap<String, bool>>>,
    pub(super) changed: Arc<tokio::sync::Notify>,
    pub(super) _session: zenoh::Session,
}

impl Bus {
    /// A client session of the router at `endpoint`, with the plant
    /// administrator's certificate.
    pub(super) async fn open(dir: &Path, endpoint: &str) -> anyhow::Result<Bus> {
        use cellwatch::config::{ZenohConfig, ZenohMode, ZenohTls};
        let config = cellwatch::bus::session_config(&ZenohConfig {
            mode: ZenohMode::Client,
            connect: vec![endpoint.to_string()],
            listen: Vec::new(),
            prefix: "cellwatch".into(),
            multicast_scouting: false,
            tls: Some(ZenohTls {
                ca: dir.join("ca/ca.pem"),
                cert: dir.join("admin/plant-admin.pem"),
                key: dir.join("admin/plant-admin.key"),
            }),
            config_file: None,
            plain: false,
            signing_key: None,
        })
        .map_err(|e| anyhow!("{e}"))?;
        let session = zenoh::open(config).await.map_err(|e| anyhow!("{e}"))?;
        let seen = alarms::alarms_into(&session, "*").await?;
        let alive: Arc<Mutex<HashMap<String, bool>>> = Arc::default();
        let changed = Arc::new(tokio::sync::Notify::new());
        let (out, tell) = (alive.clone(), changed.clone());
        let tokens = session
            .liveliness()
            .declare_subscriber("cellwatch/*/agent/*")
            .history(true)
            .callback(move |sample| {
                let cell = sample
                    .key_expr()
                    .as_str()
                    .split('/')
                    .nth(1)
                    .unwrap_or_default()
                    .to_string();
                let up = sample.kind() == zenoh::sample::SampleKind::Put;
                if let Ok(mut a) = out.lock() {
                    a.insert(cell, up);
                }
                tell.notify_waiters();
            })
            .await
            .map_err(|e| anyhow!("{e}"))?;
        std::mem::forget(tokens);
        Ok(Bus {
            seen,
            alive,
            changed,
            _session: session,
        })
    }

    pub(super) fn up(&self) -> usize {
        self.alive
            .lock()
            .map(|a| a.values().filter(|&&up| up).count())
            .unwrap_or(0)
    }

    /// Waits until `cells` agents' tokens are there.
    pub(super) async fn all_alive(
        &self,
        cells: usize,
        within: Duration,
    ) -> anyhow::Result<Duration> {
        let started = Instant::now();
        if self.until(|up| up >= cells, within).await {
            Ok(started.elapsed())
        } else {
            bail!("{} of {cells} agents' tokens", self.up())
        }
    }

    /// Waits until `holds` of the number of tokens there, at most `within`:
    /// whether it did.
    async fn until(&self, holds: impl Fn(usize) -> bool, within: Duration) -> bool {
        let deadline = Instant::now() + within;
        loop {
            let changed = self.changed.notified();
            if holds(self.up()) {
                return true;
            }
            if tokio::time::timeout_at(deadline.into(), changed)
                .await
                .is_err()
            {
                return false;
            }
        }
    }

    /// After a router is lost: waits for the first token to go, then for
    /// every one to be back; the time from the call, `None` when no token
    /// went within 20 s (no agent was on the lost router).
    pub(super) async fn back_after_loss(
        &self,
        cells: usize,
        within: Duration,
    ) -> anyhow::Result<Option<Duration>> {
        let started = Instant::now();
        if !self.until(|up| up < cells, Duration::from_secs(20)).await {
            return Ok(None);
        }
        let rest = within.saturating_sub(started.elapsed());
        self.all_alive(cells, rest).await?;
        Ok(Some(started.elapsed()))
    }
}

/// The console's event stream, read on: every fault alarm's raise as it
/// arrived, and every arrival of a fault alarm shown active (a raise, or
/// the alarm as a snapshot the console asked brought it).
pub(super) async fn console_alarms(
    addr: SocketAddr,
    cookie: String,
) -> anyhow::Result<(Seen, Seen)> {
    let seen: Seen = Arc::default();
    let known: Seen = Arc::default();
    let (out, shown) = (seen.clone(), known.clone());
    let stream = tokio::net::TcpStream::connect(addr).await?;
    let (read, mut write) = stream.into_split();
    write
        .write_all(
            format!("GET /api/events HTTP/1.1\r\nHost: {addr}\r\nCookie: {cookie}\r\nAccept: text/event-stream\r\n\r\n")
                .as_bytes(),
        )
        .await?;
    let mut lines = tokio::io::BufReader::new(read).lines();
    let status = lines.next_line().await?.unwrap_or_default();
    if !status.contains(" 200 ") {
        bail!("the console's event stream: {status}");
    }
    tokio::spawn(async move {
        let _keep = write;
        // Chunk sizes and the head are lines of their own; an event's data
        // is one line in one chunk.
        while let Ok(Some(line)) = lines.next_line().await {
            let Some(data) = line.strip_prefix("data:") else {
                continue;
            };
            let now = SystemTime::now();
            let Ok(v) = serde_json::from_str::<serde_json::Value>(data.trim()) else {
                continue;
            };
            if v["type"] != "alarm" {
                continue;
            }
            if let Some((cell, switch)) = alarms::fault_raised(&v["alarm"]) {
                if let Ok(mut s) = out.lock() {
                    s.entry(cell).or_default().push((now, switch));
                }
            }
            let active = v["alarm"]["state"]
                .as_str()
                .is_some_and(|s| s.starts_with("active"));
            if active && v["alarm"]["id"] == "fault" {
                let mut raised = v["alarm"].clone();
                raised["transition"] = "raised".into();
                if let Some((cell, switch)) = alarms::fault_raised(&raised) {
                    if let Ok(mut s) = shown.lock() {
                        s.entry(cell).or_default().push((now, switch));
                    }
                }
            }
        }
    });
    Ok((seen, known))
}

/// After a router is killed at `killed`: how long until the console's
/// plant says every cell's agent is up again, from the kill, having shown
/// one down; `None` when it showed none down within 20 s (no agent was on
/// the lost router, or the console's view never lost one). Run from the
/// kill on, beside the bus's own watch, so a short loss is not missed.
pub(super) async fn console_back(
    addr: SocketAddr,
    cookie: String,
    cells: usize,
    killed: Instant,
) -> anyhow::Result<Option<Duration>> {
    let mut seen_down = false;
    loop {
        let mut c = Connection::open(addr, None).await?;
        c.send("GET", "/api/plant", &cookie, "").await?;
        let (_, _, body) = c.answer().await?;
        let v: serde_json::Value = serde_json::from_slice(&body)?;
        let up = v["cells"]
            .as_array()
            .map_or(0, |cs| cs.iter().filter(|c| c["agent"] == true).count());
        seen_down |= up < cells;
        if up >= cells && seen_down {
            return Ok(Some(killed.elapsed()));
        }
        if up >= cells && killed.elapsed() > Duration::from_secs(20) {
            return Ok(None);
        }
        if killed.elapsed() > BACK_WITHIN {
            bail!("{up} of {cells} agents up");
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}
