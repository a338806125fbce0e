//! `cellwatch-bench console`: the operators' console under a plant's
//! alarms. A publisher in this process seals alarm events with the keys of
//! `cells` agents and puts them on a loopback bus; the console under test
//! (`cellwatch console`, its own process) and, as the baseline, a bare bus
//! subscriber that opens every event against the same trust file, both
//! take them. A headless Chromium shows the console's alarm table. It
//! measures how long after the first put the baseline, the console's page
//! (every alarm in its model) and its table (drawn) have all of them, the
//! page's JavaScript heap and the console's memory, then clears every alarm
//! and raises as many new ones, three times, to show both stay bounded.
//! Each round it also takes the console's CPU time and the CPU time the
//! baseline spent opening the envelopes (the same [`Trust::open`] the
//! console runs): the share of the console's CPU that goes to verifying
//! signatures. A cell's alarms may be sealed `alarms_per_step` at a time,
//! as an agent seals what one step raises together.

use std::io::BufRead;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use cellwatch::bus::envelope::{AgentKey, Kind, Trust};
use cellwatch::payload::AlarmPayload;
use cellwatch_models::alarm::{AlarmKind, AlarmState, Severity, Transition};

/// What to run.
pub struct Setup {
    /// The `cellwatch` binary under test.
    pub agent: PathBuf,
    /// Where its files go.
    pub workdir: PathBuf,
    /// Simulated cells.
    pub cells: usize,
    /// Alarms active at once, spread over the cells.
    pub alarms: usize,
    /// Chromium and chromedriver.
    pub chromium: PathBuf,
    /// See `chromium`.
    pub chromedriver: PathBuf,
    /// A cell's alarms sealed together, as one step of its agent puts
    /// them (1: each alone).
    pub alarms_per_step: usize,
}

const SEVERITIES: [Severity; 4] = [
    Severity::Low,
    Severity::Medium,
    Severity::High,
    Severity::Critical,
];

/// One round's figures.
struct Round {
    what: String,
    baseline_ms: f64,
    model_ms: f64,
    table_ms: f64,
    heap_mb: f64,
    console_rss_mb: f64,
    /// The console's CPU over the round, ms.
    console_cpu_ms: f64,
    /// The baseline's CPU opening the round's envelopes, ms.
    opening_ms: f64,
}

/// Runs the benchmark; returns its Markdown.
pub async fn run(setup: &Setup) -> anyhow::Result<String> {
    std::fs::create_dir_all(&setup.workdir)?;
    // Absolute: the console takes relative paths from its file's folder.
    let workdir = std::fs::canonicalize(&setup.workdir)?;
    let keys: Vec<AgentKey> = (0..setup.cells)
        .map(|i| AgentKey::generate(&format!("cell{i:03}")))
        .collect();
    let entries: String = keys.iter().map(AgentKey::trust_entry).collect();
    let trust_path = workdir.join("trust.toml");
    std::fs::write(&trust_path, &entries)?;
    let trust = Trust::parse("trust.toml", &entries)?;

    // The bus: the publisher listens on loopback, plain TCP (a bench on
    // one machine; the envelopes are signed all the same).
    let publisher = cellwatch::bus::open(&plain(vec![], vec!["tcp/127.0.0.1:0".into()]))
        .await
        .context("publisher session")?;
    let endpoint = publisher
        .info()
        .locators()
        .await
        .first()
        .map(ToString::to_string)
        .context("the publisher listens nowhere")?;

    // The baseline: a bare subscriber opening every event, timing it.
    let seen = Arc::new(AtomicUsize::new(0));
    let opening_ns = Arc::new(AtomicU64::new(0));
    let baseline = cellwatch::bus::open(&plain(vec![endpoint.clone()], vec![])).await?;
    let (counted, timed) = (seen.clone(), opening_ns.clone());
    let _sub = baseline
        .declare_subscriber("cellwatch/*/alarms/**")
        .callback(move |s| {
            let payload = s.payload().to_bytes();
            let start = cellwatch::clock::thread_cpu_ns();
            let opened = trust.open(&payload, Kind::Put, s.key_expr().as_str(), "");
            timed.fetch_add(
                cellwatch::clock::thread_cpu_ns().saturating_sub(start),
                Ordering::Relaxed,
            );
            if opened.is_ok() {
                counted.fetch_add(1, Ordering::Relaxed);
            }
        })
        .await
        .map_err(|e| anyhow::anyhow!("{e}"))?;

    // The console under test, and the operator who signs in to its page.
    let operator = cellwatch::operator::OperatorKey::generate("bench");
    std::fs::write(
        setup.workdir.join("operators.toml"),
        operator.operators_entry(&[cellwatch::operator::Action::Ack]),
    )?;
    std::fs::write(setup.workdir.join("bench.key"), operator.to_file())?;
    std::fs::write(
        setup.workdir.join("console.toml"),
        format!(
            "[http]\nlisten = \"127.0.0.1:0\"\n[bus]\nconnect = [\"{endpoint}\"]\nplain = true\ntrust = {trust_path:?}\n[operators]\nfile = {:?}\n[console]\nmax_alarms = {}\n",
            setup.workdir.join("operators.toml"),
            (setup.alarms * 2).max(100)
        ),
    )?;
    let mut console = std::process::Command::new(&setup.agent)
        .args(["console", "--config"])
        .arg(setup.workdir.join("console.toml"))
        .stdout(std::process::Stdio::piped())
        .stderr(std::fs::File::create(setup.workdir.join("console.log"))?)
        .spawn()
        .context("cellwatch console")?;
    let mut line = String::new();
    std::io::BufReader::new(console.stdout.take().context("stdout")?).read_line(&mut line)?;
    let url = line
        .trim()
        .strip_prefix("cellwatch console: ")
        .context("the console did not say its URL (see console.log)")?
        .to_string();
    let bus = Bus {
        publisher: &publisher,
        seen: &seen,
        opening_ns: &opening_ns,
    };
    let result = measure(setup, &keys, &bus, &url, console.id()).await;
    let _ = console.kill();
    let _ = console.wait();
    result
}

pub fn plain(connect: Vec<String>, listen: Vec<String>) -> cellwatch::config::ZenohConfig {
    cellwatch::config::ZenohConfig {
        mode: cellwatch::config::ZenohMode::Peer,
        connect,
        listen,
        prefix: String::new(),
        multicast_scouting: false,
        tls: None,
        config_file: None,
        plain: true,
        signing_key: None,
    }
}

/// The publisher's session, and what the baseline counted and spent.
struct Bus<'a> {
    publisher: &'a zenoh::Session,
    seen: &'a AtomicUsize,
    opening_ns: &'a AtomicU64,
}

impl Bus<'_> {
    /// Puts `(key, sealed)` each, in order, as an agent does (blocking
    /// congestion control).
    async fn put(&self, sealed: Vec<(String, String)>) -> anyhow::Result<()> {
        for (k, v) in sealed {
            self.publisher
                .put(k, v)
                .congestion_control(zenoh::qos::CongestionControl::Block)
                .await
                .map_err(|e| anyhow::anyhow!("{e}"))?;
        }
        Ok(())
    }
}

/// Alarm events `(cell, id, n, raised)` sealed by their cells' keys, each
/// cell's `per_step` at a time under one signature, in the cells' order.
fn sealed(
    keys: &[AgentKey],
    events: impl IntoIterator<Item = (usize, String, usize, bool)>,
    per_step: usize,
) -> Vec<(String, String)> {
    let mut by_cell: Vec<Vec<(String, String)>> = vec![Vec::new(); keys.len()];
    for (cell, id, n, raised) in events {
        by_cell[cell].push(event(&keys[cell], &id, n, raised));
    }
    let now = cellwatch::clock::now_ms();
    let mut out = Vec::new();
    for (cell, puts) in by_cell.into_iter().enumerate() {
        let mut puts = puts.into_iter().peekable();
        while puts.peek().is_some() {
            let step: Vec<(String, String)> = puts.by_ref().take(per_step.max(1)).collect();
            let refs: Vec<(&str, &str)> =
                step.iter().map(|(k, b)| (k.as_str(), b.as_str())).collect();
            let sealed = keys[cell].seal_puts(now, &refs);
            for (i, (k, b)) in step.iter().enumerate() {
                out.push((k.clone(), sealed.envelope(i, k, b)));
            }
        }
    }
    out
}

/// An alarm event of `cell`, unsealed: its key and body (`n` picks its
/// severity and text).
pub fn event(key: &AgentKey, id: &str, n: usize, raised: bool) -> (String, String) {
    let now = cellwatch::clock::now_ms();
    let at = cellwatch::clock::rfc3339(now);
    let a = AlarmPayload {
        schema: "cellwatch.alarm.v1".into(),
        cell: key.cell().into(),
        id: id.into(),
        kind: AlarmKind::Switching,
        severity: SEVERITIES[n % SEVERITIES.len()],
        state: if raised {
            AlarmState::ActiveUnacknowledged
        } else {
            AlarmState::Normal
        },
        transition: if raised {
            Transition::Raised
        } else {
            Transition::Acknowledged
        },
        at: at.clone(),
        raised_at: at,
        cleared_at: None,
        acked_by: None,
        ack_comment: None,
        latched: false,
        fault_type: "ESE".into(),
        fault_step: Some(n % 9),
        culprits: Vec::new(),
        message: format!(
            "ESE at step {}: X{}.{:02} = 0 (expected 1): limit switch {n}",
            n % 9,
            n % 64,
            n % 8
        ),
        shelved: None,
        out_of_service: None,
        consequence: None,
        suppressed_by_design: None,
        guidance: None,
    };
    let key_expr = format!("cellwatch/{}/alarms/{id}", key.cell());
    (key_expr, serde_json::to_string(&a).unwrap_or_default())
}

async fn measure(
    setup: &Setup,
    keys: &[AgentKey],
    bus: &Bus<'_>,
    url: &str,
    console_pid: u32,
) -> anyhow::Result<String> {
    let seen = bus.seen;
    let browser =
        crate::console_browser::Browser::start(&setup.chromium, &setup.chromedriver).await?;
    let b = &browser.client;
    b.goto(&format!("{url}#/alarms")).await?;
    browser
        .until("return typeof S !== 'undefined' && S.started === true;")
        .await?;
    b.find(fantoccini::Locator::Css("#key-file"))
        .await?
        .send_keys(
            &std::fs::canonicalize(setup.workdir.join("bench.key"))?
                .display()
                .to_string(),
        )
        .await?;
    let cells = setup.cells;
    browser
        .until(&format!(
            "return typeof S !== 'undefined' && S.live && S.cells.size === {cells};"
        ))
        .await?;
    // One event first, until both take it: the subscriptions are known to
    // the publisher.
    loop {
        bus.put(sealed(keys, [(0, "warmup".into(), 0, true)], 1))
            .await?;
        tokio::time::sleep(Duration::from_millis(200)).await;
        let page = b
            .execute("return S.alarms.size;", vec![])
            .await?
            .as_u64()
            .unwrap_or(0);
        if page >= 1 && seen.load(Ordering::Relaxed) >= 1 {
            break;
        }
    }
    bus.put(sealed(keys, [(0, "warmup".into(), 0, false)], 1))
        .await?;
    browser.until("return S.alarms.size === 0;").await?;

    let n = setup.alarms;
    let mut rounds = Vec::new();
    for round in 0..4 {
        // Round 0 raises `n` alarms; each later one clears them and raises
        // `n` new ones.
        let before = seen.load(Ordering::Relaxed);
        let puts = if round == 0 { n } else { 2 * n };
        b.execute(
            &format!("window.__all = null; window.__table = null; const want = {n}; const tick = () => {{ if (window.__all === null && S.alarms.size === want && [...S.alarms.values()].every(a => a.id.startsWith('r{round}-'))) window.__all = Date.now(); const note = document.querySelector('#view .note'); if (window.__all !== null && window.__table === null && note && note.textContent.includes(want + ' alarm')) window.__table = Date.now(); if (window.__table === null) setTimeout(tick, 5); }}; tick(); return true;"),
            vec![],
        )
        .await?;
        let started = Instant::now();
        let t0 = cellwatch::clock::now_ms() as f64;
        let (cpu0, opening0) = (cpu_ms(console_pid), bus.opening_ns.load(Ordering::Relaxed));
        let cells = keys.len();
        let per_step = setup.alarms_per_step;
        if round > 0 {
            let ended = (0..n).map(|i| (i % cells, format!("r{}-{i}", round - 1), i, false));
            bus.put(sealed(keys, ended, per_step)).await?;
        }
        let raised = (0..n).map(|i| (i % cells, format!("r{round}-{i}"), i, true));
        bus.put(sealed(keys, raised, per_step)).await?;
        let deadline = Instant::now() + Duration::from_secs(300);
        let baseline_ms = loop {
            if seen.load(Ordering::Relaxed) >= before + puts {
                break started.elapsed().as_secs_f64() * 1000.0;
            }
            anyhow::ensure!(
                Instant::now() < deadline,
                "the baseline never saw every event"
            );
            tokio::time::sleep(Duration::from_millis(2)).await;
        };
        browser.until("return window.__table !== null;").await?;
        let console_cpu_ms = cpu_ms(console_pid) - cpu0;
        let opening_ms = bus
            .opening_ns
            .load(Ordering::Relaxed)
            .saturating_sub(opening0) as f64
            / 1e6;
        let times = b
            .execute("return [window.__all, window.__table];", vec![])
            .await?;
        let at = |i: usize| times[i].as_f64().unwrap_or(f64::NAN) - t0;
        b.execute("if (window.gc) { window.gc(); } return true;", vec![])
            .await?;
        let heap = b
            .execute(
                "return performance.memory ? performance.memory.usedJSHeapSize : null;",
                vec![],
            )
            .await?
            .as_f64()
            .unwrap_or(f64::NAN);
        rounds.push(Round {
            what: if round == 0 {
                format!("{n} raised")
            } else {
                format!("{n} cleared, {n} new raised")
            },
            baseline_ms,
            model_ms: at(0),
            table_ms: at(1),
            heap_mb: heap / 1e6,
            console_rss_mb: rss_mb(console_pid, "VmRSS"),
            console_cpu_ms,
            opening_ms,
        });
        eprintln!(
            "cellwatch-bench: console round {round}: baseline {:.0} ms, page {:.0} ms, table {:.0} ms",
            baseline_ms,
            at(0),
            at(1)
        );
    }
    let mut out = format!(
        "{} cells, {n} alarms active at once, {} a cell's alarms under one signature; time from the first put, ms (one machine, one clock)\n\n| round | events | baseline: bare subscriber has all | console's page has all | its table drawn | page JS heap after GC (MB) | console RSS (MB) | console CPU (ms) | opening them (ms, in the baseline) | opening ÷ console CPU |\n|---|---|---|---|---|---|---|---|---|---|\n",
        setup.cells, setup.alarms_per_step
    );
    for (i, r) in rounds.iter().enumerate() {
        out += &format!(
            "| {i} | {} | {:.0} | {:.0} | {:.0} | {:.1} | {:.1} | {:.0} | {:.0} | {:.0} % |\n",
            r.what,
            r.baseline_ms,
            r.model_ms,
            r.table_ms,
            r.heap_mb,
            r.console_rss_mb,
            r.console_cpu_ms,
            r.opening_ms,
            r.opening_ms * 100.0 / r.console_cpu_ms.max(1e-9)
        );
    }
    out += &format!(
        "\n- console peak RSS: {:.1} MB\n- ratio, page has all / baseline has all (round 0): {:.2}\n",
        rss_mb(console_pid, "VmHWM"),
        rounds[0].model_ms / rounds[0].baseline_ms
    );
    Ok(out)
}

/// A process's CPU time so far (user and system), ms.
fn cpu_ms(pid: u32) -> f64 {
    crate::measure::cpu_seconds(pid).map_or(f64::NAN, |s| s * 1000.0)
}

/// A process's memory line from /proc (`VmRSS`, `VmHWM`), MB.
fn rss_mb(pid: u32, field: &str) -> f64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with(field))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map_or(f64::NAN, |kb| kb / 1000.0)
}
