//! `cellwatch-bench replay`: the agent under a load from the replay
//! source, measured as the peer benchmark measures it (changes handled,
//! CPU per change, fault → alarm latency, the agent's own latency, loss),
//! with the source's own CPU beside each row; and, in the same run, the
//! agent under the same load from the load server (async-opcua), for the
//! check that the source changes nothing but its own cost.

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use anyhow::anyhow;

use opcua::core::comms::secure_channel::Role;
use opcua::types::{MessageSecurityMode, StatusCode, TimestampsToReturn};

use super::control::Order;
use super::frame::{channel_with_keys, chunks, publish_body, Publish};
use super::stream::{Segment, Stream};
use super::ReplaySource;
use crate::alarms::{match_faults, subscribe_alarms};
use crate::alertmanager::Alertmanager;
use crate::cell::{
    agent_config, flood_checks, free_port, handled, spawn_agent, stop_agent, tags_csv, trust,
    wait_ready, Load, Security, Subscription,
};
use crate::measure::{self, Scrape};
use crate::peer::{self, Kind, Row, Setup};

/// The OPC UA security of the agent's session with the replay source.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ReplaySecurity {
    /// No security.
    None,
    /// Basic256Sha256, every message signed (not encrypted).
    Sign,
}

impl ReplaySecurity {
    fn label(self) -> &'static str {
        match self {
            ReplaySecurity::None => "None",
            ReplaySecurity::Sign => "Basic256Sha256+Sign",
        }
    }
}

/// The agent against the replay source under `load`: one row, the
/// source's own CPU share in its last column; and the changes the source
/// dropped unsent (no Publish request came for them).
pub async fn agent(
    setup: &Setup,
    load: Load,
    security: ReplaySecurity,
) -> anyhow::Result<(Row, u64)> {
    let dir = setup
        .workdir
        .join(format!("replay-{}-{}-{security:?}", load.tags, load.rate));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir)?;
    let pki = dir.join("server-pki");
    let mut source = ReplaySource::start("127.0.0.1:0".parse()?, &pki, load.tags)?;
    let (zenoh_port, metrics_port) = (free_port()?, free_port()?);
    let config = dir.join("cell.toml");
    let secure = if security == ReplaySecurity::Sign {
        Security::SignEncrypt
    } else {
        Security::None
    };
    let mut text = agent_config(
        "bench",
        &source.endpoint(),
        secure,
        Subscription {
            publishing: setup.publishing,
            max_notifications: setup.max_notifications,
            verify_interval: None,
        },
        &format!("mode = \"peer\"\nlisten = [\"tcp/127.0.0.1:{zenoh_port}\"]"),
        metrics_port,
    );
    if security == ReplaySecurity::Sign {
        text = text.replacen(
            "security_mode = \"SignAndEncrypt\"",
            "security_mode = \"Sign\"",
            1,
        );
    }
    text.push_str(&flood_checks(setup.alarms_per_fault));
    std::fs::write(&config, text)?;
    std::fs::write(dir.join("tags.csv"), tags_csv(load))?;
    if security == ReplaySecurity::Sign {
        std::fs::write(dir.join("fault.il"), crate::cell::program())?;
        trust(&config, &pki)?;
    }
    let mut child = spawn_agent(&setup.agent, &dir, setup.agent_priority)?;
    let pid = child.id();
    let result = async {
        let (alarms, _) =
            subscribe_alarms(&[format!("tcp/127.0.0.1:{zenoh_port}")], "bench").await?;
        let metrics: SocketAddr = format!("127.0.0.1:{metrics_port}").parse()?;
        wait_ready(&mut child, metrics, &dir).await?;
        let before = Scrape::get(metrics)?;
        let c0 = handled(&before);
        let (cpu0, rss_ready, source0) = (
            measure::cpu_seconds(pid)?,
            measure::rss(pid)?.0,
            source.control().cpu(),
        );
        let dropped0 = source.control().dropped_so_far();
        let started = Instant::now();
        source.start_run(Order {
            at: Instant::now(),
            wall: std::time::SystemTime::now(),
            rate: load.rate,
            fault_every: setup.fault_every,
            fault_hold: setup.fault_hold,
        });
        tokio::time::sleep(setup.seconds).await;
        let seconds = started.elapsed().as_secs_f64();
        let (produced, faults) = source.end_run(setup.publishing).await;
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
        let (rss_end, rss_peak) = measure::rss(pid)?;
        let cpu = measure::cpu_seconds(pid)? - cpu0;
        let source_cpu = (source.control().cpu() - source0) / (seconds + drain);
        let dropped = source.control().dropped_so_far() - dropped0;
        if dropped > 0 {
            eprintln!("cellwatch-bench: the replay source dropped {dropped} change(s) no publish request came for");
        }
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
        let delta = |name: &str| after.value(name) - before.value(name);
        let gaps = delta("cellwatch_source_gaps_total");
        if gaps > 0.0 {
            eprintln!("cellwatch-bench: the agent said {gaps} gap(s) in the replay source");
        }
        let row = Row {
            kind: Kind::Agent,
            security: secure,
            subject: format!("cellwatch ({}) ← replay source", security.label()),
            load,
            produced,
            received: handled(&after) - c0,
            seconds,
            drain,
            cpu,
            rss_ready,
            rss_end,
            rss_peak,
            server_cpu: source_cpu,
            faults: (faults.len(), latencies.len()),
            latencies,
            internal,
            internal_counts,
            generator_lag: 0.0,
            signing: Some((
                delta("cellwatch_bus_signatures_total"),
                delta("cellwatch_bus_signing_seconds_total"),
                delta("process_cpu_seconds_total"),
            )),
        };
        Ok((row, dropped))
    }
    .await;
    stop_agent(child);
    eprintln!(
        "cellwatch-bench: the agent asked the replay source for {:?}",
        source.control().asked()
    );
    source.stop();
    result
}

/// The hot path alone, in memory: `messages` publishes of `per_publish`
/// changes each from a stream of `tags` noise tags, encoded, cut into
/// 64 KiB chunks and, under Sign, signed; the CPU time (this thread's)
/// per change, ns.
pub fn hot_path(tags: usize, per_publish: u32, mode: MessageSecurityMode, messages: u32) -> f64 {
    let thread_cpu = || {
        let t = rustix::time::clock_gettime(rustix::time::ClockId::ThreadCPUTime);
        t.tv_sec as f64 + t.tv_nsec as f64 / 1e9
    };
    let Ok(pki) = tempfile::tempdir() else {
        return f64::NAN;
    };
    if cellwatch::sources::pki::own_key_pair(pki.path(), "hot path", super::URI).is_err() {
        return f64::NAN;
    }
    let channel = channel_with_keys(pki.path(), Role::Server, mode, &[1; 32], &[2; 32]);
    let noise: Vec<u32> = (0..tags as u32).map(|i| i + 11).collect();
    let mut stream = Stream::new(&noise, &[1], TimestampsToReturn::Both, 1);
    let owned = opcua::types::ContextOwned::default();
    let (mut body, mut scratch, mut out, mut seq) = (Vec::new(), Vec::new(), Vec::new(), 1);
    let start = thread_cpu();
    for m in 0..messages {
        let publish = Publish {
            request_handle: m,
            subscription_id: 1,
            available: &[m],
            more: false,
            sequence_number: m,
            publish_time: 0,
            results: &[StatusCode::Good],
        };
        let from = i64::from(m) * 1_000_000;
        let segments = [Segment::Noise {
            start: u64::from(m) * u64::from(per_publish),
            len: per_publish,
            from,
            to: from + 1_000_000,
        }];
        out.clear();
        let made = publish_body(
            &publish,
            &segments,
            &mut stream,
            &owned.context(),
            &mut body,
        )
        .ok()
        .and_then(|()| {
            chunks(
                &channel,
                m,
                &mut seq,
                1 << 16,
                &body,
                &mut scratch,
                &mut out,
            )
            .ok()
        });
        if made.is_none() {
            return f64::NAN;
        }
        std::hint::black_box(&out);
    }
    (thread_cpu() - start) * 1e9 / (f64::from(messages) * f64::from(per_publish))
}

/// Every load under every security from the replay source, then (with
/// `reference`) the same load from the load server, security None: the
/// table, and each replay row beside the load server's.
pub async fn run(
    setup: &Setup,
    loads: &[Load],
    security: &[ReplaySecurity],
    reference: bool,
) -> anyhow::Result<String> {
    let (mut rows, mut dropped) = (Vec::new(), Vec::new());
    for &load in loads {
        for &s in security {
            eprintln!(
                "cellwatch-bench: agent ← replay source, {} tags, {}/s, {s:?}",
                load.tags, load.rate
            );
            let (row, d) = agent(setup, load, s).await?;
            rows.push(row);
            dropped.push(d);
        }
        if reference {
            eprintln!(
                "cellwatch-bench: agent ← load server, {} tags, {}/s, None",
                load.tags, load.rate
            );
            let mut row = peer::agent(setup, load, Security::None, Alertmanager::Off, None).await?;
            row.subject = "cellwatch (None) ← load server (async-opcua)".into();
            rows.push(row);
        }
    }
    if rows.is_empty() {
        return Err(anyhow!("nothing measured"));
    }
    let mut out = String::from("The hot path alone (in memory, no socket; 10,000 changes a publish from 100,000 tags, 64 KiB chunks):\n");
    for (mode, name) in [
        (MessageSecurityMode::None, "None"),
        (MessageSecurityMode::Sign, "Basic256Sha256+Sign"),
    ] {
        let ns = hot_path(100_000, 10_000, mode, 500);
        out.push_str(&format!(
            "- {name}: {ns:.1} ns of CPU per change: 1,000,000 changes/s take {:.1} % of a core\n",
            ns / 10.0
        ));
    }
    out.push('\n');
    out.push_str(&crate::table::table(&rows));
    out.push_str("\nThe last column: the replay source's own thread (rows ← replay source), the benchmark's process with the load server (rows ← load server).\n\n");
    out.push_str(&compare(&rows, &dropped));
    Ok(out)
}

/// Each replay row beside the load server's row at the same load;
/// `dropped[i]`: what the source dropped unsent in the `i`th replay row.
fn compare(rows: &[Row], dropped: &[u64]) -> String {
    let ms = |v: Option<f64>| v.map_or("-".into(), |s| format!("{:.1}", s * 1e3));
    let mut out = String::new();
    let reference = |r: &Row| {
        rows.iter().find(|x| {
            x.subject.ends_with("load server (async-opcua)")
                && x.load.tags == r.load.tags
                && x.load.rate == r.load.rate
        })
    };
    let replayed = rows.iter().filter(|r| r.subject.ends_with("replay source"));
    for (r, &dropped) in replayed.zip(dropped) {
        let sent = r.produced.saturating_sub(dropped).max(1) as f64;
        out.push_str(&format!(
            "- {} tags, {}/s, {}: {:.2} µs/change, latency p50 / p99 {} / {} ms, lost {} ({dropped} dropped unsent by the source), the source {:.1} % of a core ({:.0} ns per change sent)",
            r.load.tags,
            r.load.rate,
            r.subject,
            r.cpu_per_change_us(),
            ms(measure::quantile(&r.latencies, 0.5)),
            ms(measure::quantile(&r.latencies, 0.99)),
            r.lost(),
            r.server_cpu * 100.0,
            r.server_cpu * (r.seconds + r.drain) * 1e9 / sent,
        ));
        if let Some(b) = reference(r) {
            out.push_str(&format!(
                "; the load server's row: {:.2} µs/change ({:.2}×), latency p50 / p99 {} / {} ms, lost {}, the benchmark's process {:.0} % of a core",
                b.cpu_per_change_us(),
                r.cpu_per_change_us() / b.cpu_per_change_us().max(1e-9),
                ms(measure::quantile(&b.latencies, 0.5)),
                ms(measure::quantile(&b.latencies, 0.99)),
                b.lost(),
                b.server_cpu * 100.0,
            ));
        }
        out.push('\n');
    }
    out
}
