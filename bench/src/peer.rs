//! The peer benchmark: for each load, the agent under test (the release
//! `cellwatch` binary, its own process), the Python asyncua baseline (its
//! own process) and, with `--reference c`, the bare open62541 client
//! (`bench/bare-client`, its own process), each alone against a fresh load
//! server, measured the same way.

use std::io::{BufRead, BufReader, Write};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant, SystemTime};

use anyhow::{anyhow, bail, Context};

use crate::alarms::{match_faults, subscribe_alarms, Generator};
use crate::alertmanager::Alertmanager;
use crate::cell::{
    agent_config, flood_checks, free_port, handled, program, spawn_agent, stop_agent, tags_csv,
    tags_toml, trust, wait_ready, Load, Security, Subscription,
};
use crate::load::{LoadServer, SWITCHES};
use crate::measure::{self, Scrape};

/// How a run is set up.
#[derive(Debug, Clone)]
pub struct Setup {
    /// The `cellwatch` binary under test.
    pub agent: PathBuf,
    /// The Python interpreter with asyncua, when the baseline runs.
    pub python: Option<PathBuf>,
    /// The baseline script.
    pub script: PathBuf,
    /// Where configurations, PKI and journals go.
    pub workdir: PathBuf,
    /// How long the load runs.
    pub seconds: Duration,
    /// The subscription's publishing interval.
    pub publishing: Duration,
    /// The agent's `opcua.max_notifications_per_publish`, if not its
    /// default.
    pub max_notifications: Option<u32>,
    /// How often a limit switch opens, and for how long.
    pub fault_every: Duration,
    /// How long it stays open.
    pub fault_hold: Duration,
    /// How much lower the load server's threads run than the agent's
    /// (niceness; 0: the same).
    pub server_nice: i32,
    /// The agent's `--realtime-priority`, if any.
    pub agent_priority: Option<u8>,
    /// How long the baseline may take to drain after the load stops.
    pub drain: Duration,
    /// How the agent is given its tags.
    pub tags_in: TagsIn,
    /// The bare open62541 client, when the C reference runs.
    pub bare_client: Option<PathBuf>,
    /// Alarms each fault raises in the agent's cell (one cause, several
    /// checks: an alarm flood); 1: the one check `fault`.
    pub alarms_per_fault: usize,
}

/// A reference besides the Python baseline (`--reference`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Reference {
    /// The bare open62541 client (`bench/bare-client`): subscribes as the
    /// agent does and only counts the notifications.
    C,
}

/// Who a row measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// The agent under test.
    Agent,
    /// The Python asyncua baseline.
    Asyncua,
    /// The bare open62541 client.
    Bare,
}

/// How the agent's configuration gives its tags.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum TagsIn {
    /// A `tags_file` (`tags.csv` beside the configuration).
    File,
    /// `[[tags]]` tables in the configuration itself, as `cellwatch
    /// discover` prints them without `--tags-file`.
    Toml,
}

/// What one subscriber did under one load.
#[derive(Debug, Clone)]
pub struct Row {
    /// Agent, baseline or bare client.
    pub kind: Kind,
    /// Who, and security.
    pub subject: String,
    /// The load.
    pub load: Load,
    /// Changes the server made.
    pub produced: u64,
    /// Changes the subscriber was given.
    pub received: u64,
    /// Seconds of load.
    pub seconds: f64,
    /// Seconds from the end of the load until the last change arrived.
    pub drain: f64,
    /// CPU seconds used from the start of the load to the end of the drain.
    pub cpu: f64,
    /// Resident memory once subscribed (before the load), bytes.
    pub rss_ready: u64,
    /// Resident memory after the drain, bytes.
    pub rss_end: u64,
    /// Peak resident memory since the process started, bytes.
    pub rss_peak: u64,
    /// CPU share of the benchmark's own process (the load server) over the
    /// load.
    pub server_cpu: f64,
    /// Fault → alarm seen, seconds, per fault reported with the right switch.
    pub latencies: Vec<f64>,
    /// Faults injected, and reported with the right switch.
    pub faults: (usize, usize),
    /// The agent's own latency (received → published), p50 and p99 bucket
    /// bounds from `cellwatch_alarm_latency_seconds`.
    pub internal: Option<(f64, f64)>,
    /// The agent's own latency between the two scrapes, cumulative per
    /// bucket: (upper bound, alarms ≤ it).
    pub internal_counts: Vec<(f64, f64)>,
    /// The most the load generator fell behind its schedule, seconds.
    pub generator_lag: f64,
    /// The security the subscriber connected with.
    pub security: Security,
    /// The agent's signatures between the two scrapes: how many, their
    /// CPU seconds, and the agent process's CPU seconds.
    pub signing: Option<(f64, f64, f64)>,
}

impl Row {
    /// Changes handled per second of load.
    pub fn rate(&self) -> f64 {
        self.received as f64 / self.seconds
    }

    /// CPU time per change handled, µs.
    pub fn cpu_per_change_us(&self) -> f64 {
        self.cpu * 1e6 / self.received.max(1) as f64
    }

    /// Share of one core over the load and the drain.
    pub fn cpu_share(&self) -> f64 {
        self.cpu / (self.seconds + self.drain)
    }

    /// Changes made but never given to the subscriber.
    pub fn lost(&self) -> u64 {
        self.produced.saturating_sub(self.received)
    }
}

/// A subscriber's process measured from the start of the load.
struct Window {
    pid: u32,
    cpu0: f64,
    rss_ready: u64,
    /// This process's CPU (the load server's) at the start.
    server0: f64,
}

/// What a [`Window`] measured.
struct Measured {
    cpu: f64,
    server_cpu: f64,
    rss_ready: u64,
    rss_end: u64,
    rss_peak: u64,
}

impl Window {
    fn open(pid: u32) -> anyhow::Result<Window> {
        Ok(Window {
            pid,
            cpu0: measure::cpu_seconds(pid)?,
            rss_ready: measure::rss(pid)?.0,
            server0: measure::cpu_seconds(std::process::id())?,
        })
    }

    /// The figures after `seconds` of load and drain.
    fn close(self, seconds: f64) -> anyhow::Result<Measured> {
        let (rss_end, rss_peak) = measure::rss(self.pid)?;
        Ok(Measured {
            cpu: measure::cpu_seconds(self.pid)? - self.cpu0,
            server_cpu: (measure::cpu_seconds(std::process::id())? - self.server0) / seconds,
            rss_ready: self.rss_ready,
            rss_end,
            rss_peak,
        })
    }
}

/// `dir` emptied, and a fresh load server for `load` with its PKI there:
/// each subscriber meets a server that has served nobody before.
async fn fresh_server(dir: &Path, load: Load, nice: i32) -> anyhow::Result<LoadServer> {
    let _ = std::fs::remove_dir_all(dir);
    std::fs::create_dir_all(dir)?;
    LoadServer::start(
        "127.0.0.1:0".parse()?,
        &dir.join("server-pki"),
        load.tags,
        1,
        nice,
    )
    .await
}

/// Runs the agent under `load`: one row.
pub async fn agent(
    setup: &Setup,
    load: Load,
    security: Security,
    alertmanager: Alertmanager,
    verify_interval: Option<Duration>,
) -> anyhow::Result<Row> {
    let dir = setup.workdir.join(format!(
        "agent-{}-{}-{:?}-{:?}-{}-{:?}",
        load.tags,
        load.rate,
        security,
        alertmanager,
        verify_interval.map_or(0, |d| d.as_millis()),
        setup.tags_in
    ));
    let server = fresh_server(&dir, load, setup.server_nice).await?;
    let (zenoh_port, metrics_port) = (free_port()?, free_port()?);
    let config = dir.join("cell.toml");
    let mut text = agent_config(
        "bench",
        &server.endpoint(),
        security,
        Subscription {
            publishing: setup.publishing,
            max_notifications: setup.max_notifications,
            verify_interval,
        },
        &format!("mode = \"peer\"\nlisten = [\"tcp/127.0.0.1:{zenoh_port}\"]"),
        metrics_port,
    );
    match setup.tags_in {
        TagsIn::File => std::fs::write(dir.join("tags.csv"), tags_csv(load))?,
        TagsIn::Toml => {
            text = text.replacen("tags_file = \"tags.csv\"\n", "", 1) + &tags_toml(load);
        }
    }
    text.push_str(&flood_checks(setup.alarms_per_fault));
    std::fs::write(&config, text)?;
    if security == Security::SignEncrypt {
        std::fs::write(dir.join("fault.il"), program())?;
        trust(&config, &dir.join("server-pki"))?;
    }
    let stand_in = alertmanager.stand_in(&config).await?;
    let mut child = spawn_agent(&setup.agent, &dir, setup.agent_priority)?;
    let pid = child.id();
    let result = async {
        let (alarms, _) =
            subscribe_alarms(&[format!("tcp/127.0.0.1:{zenoh_port}")], "bench").await?;
        let metrics: SocketAddr = format!("127.0.0.1:{metrics_port}").parse()?;
        wait_ready(&mut child, metrics, &dir).await?;
        let before = Scrape::get(metrics)?;
        let c0 = handled(&before);
        let window = Window::open(pid)?;
        let run = Generator::start(&server, load.rate, setup.fault_every, setup.fault_hold, 2);
        tokio::time::sleep(setup.seconds).await;
        let (produced, faults, lag, seconds) = run.stop();
        // Drain: until every change arrived, or none came for 3 s.
        let stopped = Instant::now();
        let mut last = (c0, Instant::now());
        let after = loop {
            let s = Scrape::get(metrics)?;
            let n = handled(&s);
            if n != last.0 {
                last = (n, Instant::now());
            }
            if n - c0 >= produced || last.1.elapsed() > Duration::from_secs(3) {
                break s;
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        };
        let drain = last.1.saturating_duration_since(stopped).as_secs_f64();
        let m = window.close(seconds + drain)?;
        let h = "cellwatch_alarm_latency_seconds";
        let internal_counts = measure::bucket_counts(&before.buckets(h), &after.buckets(h));
        let internal = measure::counts_quantile(&internal_counts, 0.5)
            .zip(measure::counts_quantile(&internal_counts, 0.99));
        let seen = alarms
            .lock()
            .ok()
            .and_then(|a| a.get("bench").cloned())
            .unwrap_or_default();
        let latencies = match_faults(&faults, &seen);
        // Gaps said by the source: under a load without one, a deaf item
        // found by the verification would be a false one.
        let delta = |name: &str| after.value(name) - before.value(name);
        let gaps = delta("cellwatch_source_gaps_total");
        if gaps > 0.0 {
            eprintln!("cellwatch-bench: the agent said {gaps} gap(s) in the source");
        }
        let mut verify = verify_interval
            .map(|d| format!(", verify every {}", humantime::format_duration(d)))
            .unwrap_or_default();
        if setup.tags_in == TagsIn::Toml {
            verify.push_str(", [[tags]] tables");
        }
        if setup.alarms_per_fault > 1 {
            verify.push_str(&format!(", {} alarms per fault", setup.alarms_per_fault));
        }
        Ok(Row {
            kind: Kind::Agent,
            security,
            subject: match setup.agent_priority {
                Some(p) => format!(
                    "cellwatch ({}, SCHED_FIFO {p}{}{verify})",
                    security.label(),
                    alertmanager.label()
                ),
                None => format!(
                    "cellwatch ({}{}{verify})",
                    security.label(),
                    alertmanager.label()
                ),
            },
            load,
            produced,
            received: handled(&after) - c0,
            seconds,
            drain,
            cpu: m.cpu,
            rss_ready: m.rss_ready,
            rss_end: m.rss_end,
            rss_peak: m.rss_peak,
            server_cpu: m.server_cpu,
            faults: (faults.len(), latencies.len()),
            latencies,
            internal,
            internal_counts,
            generator_lag: lag,
            signing: Some((
                delta("cellwatch_bus_signatures_total"),
                delta("cellwatch_bus_signing_seconds_total"),
                delta("process_cpu_seconds_total"),
            )),
        })
    }
    .await;
    stop_agent(child);
    server.stop();
    if let Some(task) = stand_in {
        task.abort();
    }
    result
}

/// The baseline's process and its answers.
struct Baseline {
    child: Child,
    stdin: ChildStdin,
    lines: mpsc::Receiver<serde_json::Value>,
}

impl Baseline {
    fn ask(&mut self) -> anyhow::Result<serde_json::Value> {
        writeln!(self.stdin, "count")?;
        self.stdin.flush()?;
        self.lines
            .recv_timeout(Duration::from_secs(120))
            .map_err(|_| anyhow!("the baseline did not answer within 120 s"))
    }
}

/// Runs the Python baseline under `load` (security None): one row.
pub async fn baseline(setup: &Setup, python: &Path, load: Load) -> anyhow::Result<Row> {
    let dir = setup
        .workdir
        .join(format!("baseline-{}-{}", load.tags, load.rate));
    let server = fresh_server(&dir, load, setup.server_nice).await?;
    let mut command = Command::new(python);
    command
        .arg(&setup.script)
        .arg("--endpoint")
        .arg(server.endpoint())
        .arg("--noise")
        .arg(load.tags.to_string())
        .arg("--publishing-ms")
        .arg(setup.publishing.as_millis().to_string());
    let log = dir.join("baseline.log");
    counted(
        setup,
        load,
        server,
        command,
        &log,
        (Kind::Asyncua, Security::None),
        "Python asyncua (None)".into(),
    )
    .await
}

/// The URI in the bare client's certificate (and its application
/// description).
const BARE_URI: &str = "urn:cellwatch:bench:bare-client";

/// Runs the bare open62541 client `client` under `load`: one row. It
/// subscribes with what the agent's configuration for the same load says
/// (publishing and sampling intervals, queue size, notifications per
/// publish, lifetime; the keep-alive count, the filter and the timestamps
/// are the agent's constants), read from that configuration.
pub async fn bare(
    setup: &Setup,
    client: &Path,
    load: Load,
    security: Security,
) -> anyhow::Result<Row> {
    let dir = setup
        .workdir
        .join(format!("bare-{}-{}-{:?}", load.tags, load.rate, security));
    let server = fresh_server(&dir, load, setup.server_nice).await?;
    // The agent's configuration for this load, never run: what it asks.
    let config = dir.join("cell.toml");
    std::fs::write(
        &config,
        agent_config(
            "bench",
            &server.endpoint(),
            security,
            Subscription {
                publishing: setup.publishing,
                max_notifications: setup.max_notifications,
                verify_interval: None,
            },
            "mode = \"peer\"",
            9,
        ),
    )?;
    std::fs::write(dir.join("tags.csv"), tags_csv(load))?;
    std::fs::write(dir.join("fault.il"), program())?;
    let cell = cellwatch::config::load(&config).map_err(|e| anyhow!("{e}"))?;
    let ua = cell
        .opcua
        .as_ref()
        .ok_or_else(|| anyhow!("no [opcua] in the generated configuration"))?;
    let interval = ua.publishing_interval.as_millis().max(1);
    // The agent's lifetime count (subscription.rs): the lifetime in
    // publishing intervals, at least three keep-alive periods.
    let lifetime = ua
        .subscription_lifetime
        .as_millis()
        .div_ceil(interval)
        .max(30);
    let mut command = Command::new(client);
    command
        .arg("--endpoint")
        .arg(server.endpoint())
        .arg("--noise")
        .arg(load.tags.to_string())
        .arg("--publishing-ms")
        .arg(interval.to_string())
        .arg("--sampling-ms")
        .arg(ua.sampling_interval.as_millis().to_string())
        .arg("--queue-size")
        .arg(ua.queue_size.to_string())
        .arg("--max-notifications")
        .arg(ua.max_notifications_per_publish.to_string())
        .arg("--lifetime-count")
        .arg(lifetime.to_string());
    if security == Security::SignEncrypt {
        // Its own key pair, made by open62541 and trusted by the server;
        // the server's certificate trusted by it.
        let pki = dir.join("bare-pki");
        std::fs::create_dir_all(&pki)?;
        let (cert, key) = (pki.join("cert.der"), pki.join("key.der"));
        let made = Command::new(client)
            .arg("make-cert")
            .arg(&cert)
            .arg(&key)
            .arg(BARE_URI)
            .status()
            .with_context(|| format!("cannot start {}", client.display()))?;
        if !made.success() {
            bail!("{} make-cert failed ({made})", client.display());
        }
        let server_pki = dir.join("server-pki");
        cellwatch::sources::pki::trust(&cert, &server_pki).map_err(|e| anyhow!(e))?;
        command
            .arg("--cert")
            .arg(&cert)
            .arg("--key")
            .arg(&key)
            .arg("--server-cert")
            .arg(cellwatch::sources::pki::own_cert(&server_pki))
            .arg("--application-uri")
            .arg(BARE_URI);
    }
    let log = dir.join("bare-client.log");
    counted(
        setup,
        load,
        server,
        command,
        &log,
        (Kind::Bare, security),
        format!("open62541 bare client ({})", security.label()),
    )
    .await
}

/// Runs `command`, a subscriber speaking `bench/baseline.py`'s protocol
/// (its stderr to `log`), against `server` under `load`: one row.
async fn counted(
    setup: &Setup,
    load: Load,
    server: LoadServer,
    mut command: Command,
    log: &Path,
    (kind, security): (Kind, Security),
    subject: String,
) -> anyhow::Result<Row> {
    let mut child = command
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(std::fs::File::create(log)?)
        .spawn()
        .with_context(|| format!("cannot start {}", command.get_program().to_string_lossy()))?;
    let pid = child.id();
    let stdout = child.stdout.take().ok_or_else(|| anyhow!("no stdout"))?;
    let stdin = child.stdin.take().ok_or_else(|| anyhow!("no stdin"))?;
    let (tx, lines) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if let Ok(v) = serde_json::from_str(&line) {
                if tx.send(v).is_err() {
                    break;
                }
            }
        }
    });
    let mut b = Baseline {
        child,
        stdin,
        lines,
    };
    let result = async {
        let ready = b
            .lines
            .recv_timeout(Duration::from_secs(900))
            .map_err(|_| {
                anyhow!(
                    "{subject} did not subscribe within 900 s (see {})",
                    log.display()
                )
            })?;
        if ready["ready"] != true {
            bail!("{subject} said {ready} (see {})", log.display());
        }
        // Settled: the initial values all in. A subscriber that says its
        // own CPU time (the bare client: getrusage, in µs where /proc has
        // 10 ms ticks) is measured by it.
        let mut last = u64::MAX;
        let (c0, own_cpu0) = loop {
            tokio::time::sleep(Duration::from_millis(500)).await;
            let a = b.ask()?;
            let n = a["received"].as_u64().unwrap_or(0);
            if n == last && n >= (load.tags + SWITCHES) as u64 {
                break (n, a["cpu"].as_f64());
            }
            last = n;
        };
        let window = Window::open(pid)?;
        let run = Generator::start(&server, load.rate, setup.fault_every, setup.fault_hold, 2);
        tokio::time::sleep(setup.seconds).await;
        let (produced, faults, lag, seconds) = run.stop();
        let stopped = Instant::now();
        let mut last = (c0, Instant::now());
        let answer = loop {
            let a = b.ask()?;
            let n = a["received"].as_u64().unwrap_or(0);
            if n != last.0 {
                last = (n, Instant::now());
            }
            if n - c0 >= produced
                || last.1.elapsed() > Duration::from_secs(3)
                || stopped.elapsed() > setup.drain
            {
                break a;
            }
            tokio::time::sleep(Duration::from_millis(250)).await;
        };
        let drain = last.1.saturating_duration_since(stopped).as_secs_f64();
        let m = window.close(seconds + drain)?;
        let cpu = match (own_cpu0, answer["cpu"].as_f64()) {
            (Some(a), Some(b)) => b - a,
            _ => m.cpu,
        };
        let seen: Vec<(SystemTime, Option<usize>)> = answer["alarms"]
            .as_array()
            .map(|a| {
                a.iter()
                    .filter_map(|x| {
                        let k = x[0].as_u64()? as usize;
                        let detected = x[2].as_f64()?;
                        Some((
                            SystemTime::UNIX_EPOCH + Duration::from_secs_f64(detected),
                            Some(k),
                        ))
                    })
                    .collect()
            })
            .unwrap_or_default();
        let latencies = match_faults(&faults, &seen);
        Ok(Row {
            kind,
            security,
            subject,
            load,
            produced,
            received: answer["received"].as_u64().unwrap_or(0) - c0,
            seconds,
            drain,
            cpu,
            rss_ready: m.rss_ready,
            rss_end: m.rss_end,
            rss_peak: m.rss_peak,
            server_cpu: m.server_cpu,
            faults: (faults.len(), latencies.len()),
            latencies,
            internal: None,
            internal_counts: Vec::new(),
            generator_lag: lag,
            signing: None,
        })
    }
    .await;
    let _ = writeln!(b.stdin, "quit");
    let _ = b.child.kill();
    let _ = b.child.wait();
    server.stop();
    result
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::load::Fault;
    use crate::table::table;

    #[test]
    fn faults_match_the_first_alarm_naming_their_switch() {
        let t0 = SystemTime::UNIX_EPOCH + Duration::from_secs(100);
        let s = |ms: u64| t0 + Duration::from_millis(ms);
        let faults = [
            Fault {
                switch: 0,
                at: s(0),
            },
            Fault {
                switch: 1,
                at: s(500),
            },
            Fault {
                switch: 2,
                at: s(1000),
            },
        ];
        // Switch 1's alarm names switch 3: not counted; switch 2's is.
        let seen = [(s(120), Some(0)), (s(610), Some(3)), (s(1090), Some(2))];
        let l = match_faults(&faults, &seen);
        assert_eq!(l.len(), 2);
        assert!((l[0] - 0.12).abs() < 1e-9 && (l[1] - 0.09).abs() < 1e-9);
    }

    /// The agent's CPU per change over asyncua's and over the bare
    /// client's at the same load (the bare client's with the agent's
    /// security when measured, else None's); the references get none.
    #[test]
    fn the_table_shows_the_agent_over_each_reference() {
        let load: Load = "1000:10000".parse().unwrap();
        let row = |kind, security, subject: &str, cpu: f64| Row {
            kind,
            security,
            subject: subject.into(),
            load,
            produced: 100_000,
            received: 100_000,
            seconds: 10.0,
            drain: 0.0,
            cpu,
            rss_ready: 0,
            rss_end: 0,
            rss_peak: 0,
            server_cpu: 0.0,
            latencies: Vec::new(),
            faults: (0, 0),
            internal: (kind == Kind::Agent).then_some((0.001, 0.01)),
            internal_counts: Vec::new(),
            generator_lag: 0.0,
            signing: None,
        };
        let rows = [
            row(Kind::Agent, Security::None, "cellwatch (None)", 0.08),
            row(
                Kind::Agent,
                Security::SignEncrypt,
                "cellwatch (secure)",
                0.12,
            ),
            row(Kind::Asyncua, Security::None, "Python asyncua (None)", 3.2),
            row(Kind::Bare, Security::None, "bare (None)", 0.02),
        ];
        let t = table(&rows);
        // 0.80 µs over 32 µs, and over 0.20 µs.
        assert!(
            t.contains("| cellwatch (None) | 1000 | 10000 | 10000 | 1 % | 0.80 | 0.03 | 4.00 |")
        );
        // No secure bare client row: over the one without security.
        assert!(t.contains("| 1.20 | 0.04 | 6.00 |"));
        assert!(t.contains("| bare (None) | 1000 | 10000 | 10000 | 0 % | 0.20 | - | - |"));
        assert!(t.contains("cellwatch (None) vs the bare (None): 1.00× the changes handled per second, CPU per change 4.00× the bare client's (0.80 vs 0.20 µs)"));
        // The bare client checks nothing: no faults column of its own.
        assert!(t
            .lines()
            .any(|l| l.starts_with("| bare (None)") && l.contains("| - | 0 |")));
    }

    #[test]
    fn loads_parse_and_bad_ones_say_why() {
        let l: Load = "100_000:500000".parse().unwrap();
        assert_eq!((l.tags, l.rate), (100_000, 500_000));
        assert!("100000"
            .parse::<Load>()
            .unwrap_err()
            .contains("TAGS:CHANGES"));
    }

    #[test]
    fn the_program_opens_the_coil_on_any_switch() {
        let p = program();
        assert!(p.starts_with("(*") && p.contains("LDN LS_0\nORN LS_1\n"));
        assert!(p.ends_with("ORN LS_9\nST FAULT\n"));
    }

    /// The generated configuration, its tags file and its program are one
    /// the agent accepts.
    #[test]
    fn the_agent_accepts_the_generated_cell() {
        struct Files(Load);
        impl cellwatch::config::Files for Files {
            fn read(&self, path: &std::path::Path) -> std::io::Result<Vec<u8>> {
                match path.file_name().and_then(|n| n.to_str()) {
                    Some("tags.csv") => Ok(tags_csv(self.0).into_bytes()),
                    Some("fault.il") => Ok(program().into_bytes()),
                    _ => Err(std::io::ErrorKind::NotFound.into()),
                }
            }

            fn list(&self, _: &std::path::Path) -> std::io::Result<Vec<std::path::PathBuf>> {
                Ok(vec!["tags.csv".into(), "fault.il".into()])
            }
        }
        let load: Load = "1000:100".parse().unwrap();
        let text = agent_config(
            "bench",
            "opc.tcp://127.0.0.1:4840/",
            Security::None,
            Subscription {
                publishing: Duration::from_millis(100),
                max_notifications: Some(1000),
                verify_interval: None,
            },
            "mode = \"peer\"",
            9000,
        );
        let c =
            cellwatch::config::parse("cell.toml", &text, std::path::Path::new("."), &Files(load))
                .unwrap();
        assert_eq!(c.tags.len(), SWITCHES + 1000);
        assert_eq!(c.tags[0].address.to_string(), "LS_0");
        assert_eq!(c.switching.len(), 1);
        // The same tags as [[tags]] tables in the configuration.
        let inline = text.replacen("tags_file = \"tags.csv\"\n", "", 1) + &tags_toml(load);
        let i = cellwatch::config::parse(
            "cell.toml",
            &inline,
            std::path::Path::new("."),
            &Files(load),
        )
        .unwrap();
        assert_eq!(i.tags, c.tags);
    }
}
