//! The peer benchmark's table: each row beside its references, and the
//! ratios.

use crate::cell::Security;
use crate::measure::{self};
use crate::peer::{Kind, Row};

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
