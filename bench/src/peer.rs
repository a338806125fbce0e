//! The peer benchmark: for each load, the agent under test (the release
//! `cellwatch` binary, its own process), the Python asyncua baseline (its
//! own process) and, with `--reference c`, the bare open62541 client
//! (`bench/bare-client`, its own process), each alone against a fresh load
//! server, measured the same way.

use std::collections::HashMap;
use std::io::{BufRead, BufReader, Write};
use std::net::{SocketAddr, TcpListener};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc, Mutex};
use std::time::{Duration, Instant, SystemTime};

use anyhow::{anyhow, bail, Context};

use crate::alertmanager::Alertmanager;
use crate::load::{self, Fault, LoadServer, SWITCHES};
use crate::measure::{self, Scrape};

/// One load: how many noise tags, how many changes per second.
#[derive(Debug, Clone, Copy)]
pub struct Load {
    /// Noise tags (the ten limit switches come on top).
    pub tags: usize,
    /// Noise changes per second.
    pub rate: u64,
}

impl std::str::FromStr for Load {
    type Err = String;
    fn from_str(s: &str) -> Result<Load, String> {
        let (t, r) = s
            .split_once(':')
            .ok_or_else(|| format!("{s:?}: write TAGS:CHANGES_PER_SECOND, e.g. 100000:500000"))?;
        let num = |x: &str| {
            x.replace('_', "")
                .parse::<u64>()
                .map_err(|e| format!("{s:?}: {x:?}: {e}"))
        };
        Ok(Load {
            tags: num(t)? as usize,
            rate: num(r)?,
        })
    }
}

/// The OPC UA security the agent connects with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Security {
    /// No security (as the baseline).
    None,
    /// Basic256Sha256 with SignAndEncrypt (the agent's default).
    SignEncrypt,
}

impl Security {
    fn label(self) -> &'static str {
        match self {
            Security::None => "None",
            Security::SignEncrypt => "Basic256Sha256+SignAndEncrypt",
        }
    }
}

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

/// A Zenoh configuration: `mode`, the `listen` and `connect` endpoints,
/// no multicast scouting.
pub fn zenoh_config(
    mode: &str,
    listen: &[String],
    connect: &[String],
) -> anyhow::Result<zenoh::Config> {
    let mut config = zenoh::Config::default();
    for (key, value) in [
        ("mode", serde_json::to_string(mode)?),
        ("listen/endpoints", serde_json::to_string(listen)?),
        ("connect/endpoints", serde_json::to_string(connect)?),
        ("scouting/multicast/enabled", "false".to_string()),
    ] {
        config
            .insert_json5(key, &value)
            .map_err(|e| anyhow!("zenoh configuration {key}: {e}"))?;
    }
    Ok(config)
}

/// A free loopback port (bound, then released for the agent to take).
pub fn free_port() -> anyhow::Result<u16> {
    Ok(TcpListener::bind("127.0.0.1:0")?.local_addr()?.port())
}

/// The fault check's program: the coil is on while any limit switch is
/// open (ESE's shape: an OR of negated contacts).
fn program() -> String {
    let mut s = String::from("(* cellwatch-bench: FAULT while any limit switch is open *)\n");
    for k in 0..SWITCHES {
        let op = if k == 0 { "LDN" } else { "ORN" };
        s.push_str(&format!("{op} LS_{k}\n"));
    }
    s.push_str("ST FAULT\n");
    s
}

/// How the agent subscribes.
#[derive(Debug, Clone, Copy)]
pub struct Subscription {
    /// The publishing interval.
    pub publishing: Duration,
    /// `opcua.max_notifications_per_publish`; `None`: the agent's default.
    pub max_notifications: Option<u32>,
    /// `opcua.verify_interval`; `None`: the agent's default.
    pub verify_interval: Option<Duration>,
}

/// The agent's configuration against `endpoint`; its tags are in
/// `tags.csv` beside it ([`tags_csv`]).
pub fn agent_config(
    cell: &str,
    endpoint: &str,
    security: Security,
    subscription: Subscription,
    zenoh: &str,
    metrics_port: u16,
) -> String {
    let (policy, mode) = match security {
        Security::None => ("None", "None"),
        Security::SignEncrypt => ("Basic256Sha256", "SignAndEncrypt"),
    };
    format!(
        "# Generated by cellwatch-bench peer.\n\
         tags_file = \"tags.csv\"\n\n\
         [cell]\nid = \"{cell}\"\n\n\
         [opcua]\nendpoint = \"{endpoint}\"\nsecurity_policy = \"{policy}\"\n\
         security_mode = \"{mode}\"\npki_dir = \"pki\"\n\
         publishing_interval = \"{}ms\"\nsampling_interval = \"0\"\n{}{}\
         namespace_uri = \"{}\"\n\n\
         [[checks.switching]]\nid = \"fault\"\nprogram = \"fault.il\"\ndialect = \"iec\"\n\
         coil = \"FAULT\"\nfault_when = \"on\"\nseverity = \"high\"\n\n\
         [zenoh]\n{zenoh}\nplain = true\n\n\
         [journal]\npath = \"journal.sqlite\"\n\n\
         [metrics]\nlisten = \"127.0.0.1:{metrics_port}\"\n",
        subscription.publishing.as_millis(),
        subscription
            .max_notifications
            .map(|n| format!("max_notifications_per_publish = {n}\n"))
            .unwrap_or_default(),
        subscription
            .verify_interval
            .map(|d| format!("verify_interval = \"{}ms\"\n", d.as_millis()))
            .unwrap_or_default(),
        load::NAMESPACE
    )
}

/// The checks besides `fault` that the same switch trips, for `alarms` in
/// all per fault: the same program under other ids (an interlock chain
/// one opened guard breaks at once).
pub fn flood_checks(alarms: usize) -> String {
    (2..=alarms)
        .map(|k| {
            format!(
                "\n[[checks.switching]]\nid = \"fault{k}\"\nprogram = \"fault.il\"\n\
                 dialect = \"iec\"\ncoil = \"FAULT\"\nfault_when = \"on\"\nseverity = \"high\"\n"
            )
        })
        .collect()
}

/// The tags of `load` as `[[tags]]` tables, in [`tags_csv`]'s order.
pub fn tags_toml(load: Load) -> String {
    let mut s = String::new();
    let mut table = |name: &str, id: String, address: &str| {
        s.push_str(&format!(
            "\n[[tags]]\nname = \"{name}\"\nnode_id = \"{id}\"\naddress = \"{address}\"\n"
        ));
    };
    for k in 0..SWITCHES {
        table(
            &format!("ls_{k}"),
            format!("ns=1;i={}", load::switch_id(k)),
            &format!("LS_{k}"),
        );
    }
    for i in 1..=load.tags {
        table(&format!("n_{i}"), format!("ns=1;i={i}"), &format!("N_{i}"));
    }
    s
}

/// The tags of `load` as the agent's `tags_file` (`tags.csv` beside its
/// configuration): the limit switches, then the noise tags.
pub fn tags_csv(load: Load) -> String {
    let mut s = String::from("name,node_id,address\n");
    for k in 0..SWITCHES {
        s.push_str(&format!("ls_{k},ns=1;i={},LS_{k}\n", load::switch_id(k)));
    }
    for i in 1..=load.tags {
        s.push_str(&format!("n_{i},ns=1;i={i},N_{i}\n"));
    }
    s
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

/// How many changes the agent behind a scrape has been given.
pub fn handled(s: &Scrape) -> u64 {
    (s.value("cellwatch_tag_updates_total") + s.value("cellwatch_tag_duplicate_updates_total"))
        as u64
}

/// Waits until the agent is connected, knows every tag and nothing more
/// arrives (the initial values are in).
pub async fn wait_ready(child: &mut Child, metrics: SocketAddr, dir: &Path) -> anyhow::Result<()> {
    let deadline = Instant::now() + Duration::from_secs(300);
    let mut last = u64::MAX;
    loop {
        tokio::time::sleep(Duration::from_millis(500)).await;
        if let Ok(Some(status)) = child.try_wait() {
            bail!(
                "the agent exited ({status}); see {}",
                dir.join("agent.log").display()
            );
        }
        if Instant::now() > deadline {
            bail!(
                "the agent in {} did not subscribe every tag within 300 s",
                dir.display()
            );
        }
        let Ok(s) = Scrape::get(metrics) else {
            continue;
        };
        let n = handled(&s);
        if s.value("cellwatch_opcua_connected") == 1.0
            && s.value("cellwatch_tags_unknown") == 0.0
            && n == last
        {
            return Ok(());
        }
        last = n;
    }
}

/// Starts `agent run cell.toml` in `dir` (with the fault check's program
/// beside it; under SCHED_FIFO at `priority` if given), its output in
/// `agent.log` there.
pub fn spawn_agent(agent: &Path, dir: &Path, priority: Option<u8>) -> anyhow::Result<Child> {
    std::fs::write(dir.join("fault.il"), program())?;
    let log = std::fs::File::create(dir.join("agent.log"))?;
    Command::new(agent)
        .arg("run")
        .arg(dir.join("cell.toml"))
        .args(priority.map(|p| format!("--realtime-priority={p}")))
        .env("RUST_LOG", "warn")
        .stdout(log.try_clone()?)
        .stderr(log)
        .spawn()
        .with_context(|| format!("cannot start {}", agent.display()))
}

/// Stops an agent as its service manager would (SIGTERM), and waits.
pub fn stop_agent(mut child: Child) {
    let _ = Command::new("kill")
        .arg("-TERM")
        .arg(child.id().to_string())
        .status();
    let _ = child.wait();
}

/// The agent's key pair made and trusted by the load server, and the
/// server's certificate trusted by the agent.
fn trust(config: &Path, server_pki: &Path) -> anyhow::Result<()> {
    use cellwatch::sources::{opcua, pki};
    let config = cellwatch::config::load(config).map_err(|e| anyhow!("{e}"))?;
    let ua = config
        .opcua
        .as_ref()
        .ok_or_else(|| anyhow!("no [opcua] in the generated configuration"))?;
    drop(opcua::client(&config.cell, ua).map_err(|e| anyhow!("{e}"))?);
    pki::trust(&pki::own_cert(&ua.pki_dir), server_pki).map_err(|e| anyhow!(e))?;
    pki::trust(&pki::own_cert(server_pki), &ua.pki_dir).map_err(|e| anyhow!(e))?;
    Ok(())
}

/// Alarms seen on the bus, per cell: (when received, the switch named as
/// the changed contact) for every `raised` transition of `fault`.
pub type Seen = Arc<Mutex<HashMap<String, Vec<(SystemTime, Option<usize>)>>>>;

/// Per cell, for every `raised` transition of `fault`: seconds from the
/// agent's put (the sample's timestamp, stamped by the publishing session)
/// to the subscriber's callback — the bus's own share of the latency (one
/// machine, one clock).
pub type Transits = Arc<Mutex<HashMap<String, Vec<f64>>>>;

/// Subscribes to the alarms of `cells` (a key expression chunk: `bench`,
/// `*`) through a peer session connected to `endpoints`.
pub async fn subscribe_alarms(
    endpoints: &[String],
    cells: &str,
) -> anyhow::Result<(Seen, Transits)> {
    let config = zenoh_config("peer", &[], endpoints)?;
    let session = zenoh::open(config).await.map_err(|e| anyhow!("{e}"))?;
    let seen: Seen = Arc::default();
    let transits: Transits = Arc::default();
    let (out, transit_out) = (seen.clone(), transits.clone());
    let subscriber = session
        .declare_subscriber(format!("cellwatch/{cells}/alarms/**"))
        .callback(move |sample| {
            let now = SystemTime::now();
            // The alarm is the body of the agent's signed envelope.
            let Some(v) = serde_json::from_slice::<serde_json::Value>(&sample.payload().to_bytes())
                .ok()
                .and_then(|env| {
                    serde_json::from_str::<serde_json::Value>(env["body"].as_str()?).ok()
                })
            else {
                return;
            };
            if v["id"] != "fault" || v["transition"] != "raised" {
                return;
            }
            let switch = v["culprits"].as_array().and_then(|cs| {
                cs.iter()
                    .find(|c| c["trigger"] == true)
                    .and_then(|c| c["address"].as_str())
                    .and_then(|a| a.strip_prefix("LS_"))
                    .and_then(|k| k.parse().ok())
            });
            let cell = v["cell"].as_str().unwrap_or_default().to_string();
            let put = sample.timestamp().map(|t| t.get_time().to_system_time());
            if let Some(transit) = put.and_then(|put| now.duration_since(put).ok()) {
                if let Ok(mut t) = transit_out.lock() {
                    t.entry(cell.clone())
                        .or_default()
                        .push(transit.as_secs_f64());
                }
            }
            if let Ok(mut s) = out.lock() {
                s.entry(cell).or_default().push((now, switch));
            }
        })
        .await
        .map_err(|e| anyhow!("{e}"))?;
    // Session and subscriber live as long as the process.
    std::mem::forget(subscriber);
    std::mem::forget(session);
    Ok((seen, transits))
}

/// For each fault, in order, the first alarm after it naming its switch
/// not already taken by an earlier fault: the latency of each fault so
/// reported, seconds.
pub fn match_faults(faults: &[Fault], seen: &[(SystemTime, Option<usize>)]) -> Vec<f64> {
    let mut used = vec![false; seen.len()];
    let mut out = Vec::new();
    for f in faults {
        let found = seen
            .iter()
            .enumerate()
            .find(|(i, (at, switch))| !used[*i] && *switch == Some(f.switch) && *at >= f.at);
        if let Some((i, (at, _))) = found {
            used[i] = true;
            out.push(at.duration_since(f.at).unwrap_or_default().as_secs_f64());
        }
    }
    out
}

/// The load generator of one run.
pub struct Generator {
    stop: Arc<AtomicBool>,
    produced: Arc<load::Produced>,
    thread: std::thread::JoinHandle<()>,
    started: Instant,
}

impl Generator {
    /// Starts `rate` noise changes per second and a fault every
    /// `fault_every`, held `fault_hold`.
    pub fn start(
        server: &LoadServer,
        rate: u64,
        fault_every: Duration,
        fault_hold: Duration,
        seed: u64,
    ) -> Generator {
        let stop = Arc::new(AtomicBool::new(false));
        let (produced, thread) = server.generate(rate, fault_every, fault_hold, seed, stop.clone());
        Generator {
            stop,
            produced,
            thread,
            started: Instant::now(),
        }
    }

    /// Stops it: changes made, faults injected, its worst lag (s), and how
    /// long it ran (s).
    pub fn stop(self) -> (u64, Vec<Fault>, f64, f64) {
        self.stop.store(true, Ordering::Relaxed);
        let _ = self.thread.join();
        let seconds = self.started.elapsed().as_secs_f64();
        let faults = self
            .produced
            .faults
            .lock()
            .map(|f| f.clone())
            .unwrap_or_default();
        (
            self.produced.changes.load(Ordering::Relaxed),
            faults,
            self.produced.max_lag_us.load(Ordering::Relaxed) as f64 / 1e6,
            seconds,
        )
    }
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

/// The row of `kind` under `a`'s load: with `a`'s security if measured,
/// else with none.
fn reference<'a>(rows: &'a [Row], a: &Row, kind: Kind) -> Option<&'a Row> {
    let under = |s: Security| {
        rows.iter().find(|r| {
            r.kind == kind
                && r.security == s
                && r.load.tags == a.load.tags
                && r.load.rate == a.load.rate
        })
    };
    under(a.security).or_else(|| under(Security::None))
}

/// The table of rows, and the agent's ratios to the baseline and to the
/// bare client.
pub fn table(rows: &[Row]) -> String {
    // The agent's CPU per change over a reference's.
    let over = |a: &Row, kind: Kind| match (a.kind, reference(rows, a, kind)) {
        (Kind::Agent, Some(r)) => format!(
            "{:.2}",
            a.cpu_per_change_us() / r.cpu_per_change_us().max(1e-9)
        ),
        _ => "-".into(),
    };
    let ms = |v: Option<f64>| v.map_or("-".into(), |s| format!("{:.1}", s * 1e3));
    let bound = |v: f64| {
        if v.is_infinite() {
            "> 1 s".into()
        } else {
            format!("≤ {}", fmt_seconds(v))
        }
    };
    let mut out = String::from(
        "| subscriber | tags | offered/s | handled/s | CPU (core) | CPU µs/change | cellwatch ÷ asyncua | cellwatch ÷ C | RSS ready / end / peak (MB) | alarm latency p50 / p99 (ms) | agent's own p50 / p99 | faults reported | lost | drain | load server CPU |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        out.push_str(&format!(
            "| {} | {} | {} | {:.0} | {:.0} % | {:.2} | {} | {} | {:.0} / {:.0} / {:.0} | {} / {} | {} | {} | {} | {:.1} s | {:.0} % |\n",
            r.subject,
            r.load.tags,
            r.load.rate,
            r.rate(),
            r.cpu_share() * 100.0,
            r.cpu_per_change_us(),
            over(r, Kind::Asyncua),
            over(r, Kind::Bare),
            r.rss_ready as f64 / 1048576.0,
            r.rss_end as f64 / 1048576.0,
            r.rss_peak as f64 / 1048576.0,
            ms(measure::quantile(&r.latencies, 0.5)),
            ms(measure::quantile(&r.latencies, 0.99)),
            r.internal
                .map_or("-".into(), |(a, b)| format!("{} / {}", bound(a), bound(b))),
            // The bare client checks nothing.
            if r.kind == Kind::Bare {
                "-".into()
            } else {
                format!("{}/{}", r.faults.1, r.faults.0)
            },
            r.lost(),
            r.drain,
            r.server_cpu * 100.0,
        ));
    }
    let mut ratios = String::new();
    for b in rows.iter().filter(|r| r.kind == Kind::Asyncua) {
        for a in rows.iter().filter(|r| {
            r.kind == Kind::Agent && r.load.tags == b.load.tags && r.load.rate == b.load.rate
        }) {
            ratios.push_str(&format!(
                "- {} tags, {}/s, {} vs the baseline: {:.1}× the changes handled per second, {:.1}× less CPU per change, p99 latency {:.1}× lower\n",
                a.load.tags,
                a.load.rate,
                a.subject,
                a.rate() / b.rate().max(1.0),
                b.cpu_per_change_us() / a.cpu_per_change_us().max(1e-9),
                measure::quantile(&b.latencies, 0.99).unwrap_or(f64::NAN)
                    / measure::quantile(&a.latencies, 0.99).unwrap_or(f64::NAN),
            ));
        }
    }
    for a in rows.iter().filter(|r| r.kind == Kind::Agent) {
        if let Some(c) = reference(rows, a, Kind::Bare) {
            ratios.push_str(&format!(
                "- {} tags, {}/s, {} vs the {}: {:.2}× the changes handled per second, CPU per change {:.2}× the bare client's ({:.2} vs {:.2} µs)\n",
                a.load.tags,
                a.load.rate,
                a.subject,
                c.subject,
                a.rate() / c.rate().max(1.0),
                a.cpu_per_change_us() / c.cpu_per_change_us().max(1e-9),
                a.cpu_per_change_us(),
                c.cpu_per_change_us(),
            ));
        }
    }
    // What sealing the bus's payloads cost the agent.
    for a in rows.iter().filter(|r| r.kind == Kind::Agent) {
        if let Some((signatures, seconds, cpu)) = a.signing {
            ratios.push_str(&format!(
                "- {} tags, {}/s, {}: {:.0} signatures ({:.1} per fault), {:.1} ms of CPU signing, {:.1} % of the agent's CPU ({:.1} ms, its own process_cpu_seconds_total)\n",
                a.load.tags,
                a.load.rate,
                a.subject,
                signatures,
                signatures / a.faults.0.max(1) as f64,
                seconds * 1e3,
                seconds * 100.0 / cpu.max(1e-9),
                cpu * 1e3,
            ));
        }
    }
    // Cell size alone: the same subject (security) at the same rate.
    let agents: Vec<&Row> = rows.iter().filter(|r| r.kind == Kind::Agent).collect();
    for big in &agents {
        let small = agents
            .iter()
            .filter(|r| r.subject == big.subject && r.load.rate == big.load.rate)
            .min_by_key(|r| r.load.tags);
        if let Some(small) = small.filter(|s| s.load.tags < big.load.tags) {
            ratios.push_str(&format!(
                "- {}, {}/s: the agent's CPU per change at {} tags is {:.2}× that at {} tags\n",
                big.subject,
                big.load.rate,
                big.load.tags,
                big.cpu_per_change_us() / small.cpu_per_change_us().max(1e-9),
                small.load.tags
            ));
        }
    }
    // Where the quantiles fall: alarms per bucket of the agent's own
    // latency (the empty buckets left out).
    for r in rows.iter().filter(|r| r.internal.is_some()) {
        let mut last = 0.0;
        let mut parts = Vec::new();
        for &(le, n) in &r.internal_counts {
            if n > last {
                parts.push(format!("{} {}", bound(le), n - last));
            }
            last = n;
        }
        if !parts.is_empty() {
            ratios.push_str(&format!(
                "- {}, {} tags, {}/s, the agent's own latency, alarms per bucket: {}\n",
                r.subject,
                r.load.tags,
                r.load.rate,
                parts.join(", ")
            ));
        }
    }
    let lag = rows.iter().map(|r| r.generator_lag).fold(0.0, f64::max);
    out.push('\n');
    out.push_str(&ratios);
    out.push_str(&format!(
        "- the load generator fell at most {:.0} ms behind its schedule\n",
        lag * 1e3
    ));
    out
}

fn fmt_seconds(s: f64) -> String {
    if s < 1e-3 {
        format!("{:.0} µs", s * 1e6)
    } else {
        format!("{} ms", s * 1e3)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
