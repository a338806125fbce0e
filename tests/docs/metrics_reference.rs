//! The metrics reference (`docs/reference/metrics.md`) lists every metric an
//! agent exports and every value of its labels.

use std::collections::BTreeSet;
use std::path::Path;

use crate::util::root;

use super::documented_keys;

/// The metric families an agent exports, as `/metrics` renders them, with
/// a sample in every labelled family.
fn exported_metrics() -> BTreeSet<String> {
    use cellwatch_models::alarm::{AlarmKind, Severity};
    let m = cellwatch::metrics::Metrics::new("docs");
    m.raised("ese", AlarmKind::Switching, Severity::High);
    m.active_delta(AlarmKind::Switching, Severity::High, 1);
    m.state("running", "idle", 1.0);
    m.add_state_time("running", 1.0);
    m.culprit("ese", "high", "ESE", Some("X0.06"), None, true);
    m.command(None, false);
    m.refused("command", "busy");
    m.transition_seconds
        .with_label_values(&["line-001"])
        .observe(1.0);
    m.transition_window_seconds
        .with_label_values(&["line-001", "lo"])
        .set(1.0);
    m.transition_window_position
        .with_label_values(&["line-001"])
        .set(0.1);
    m.tag_value.with_label_values(&["t"]).set(1.0);
    m.modes.mode("setup", true);
    m.opcua_requests.with_label_values(&["Read", "good"]).inc();
    m.sfc_step_active
        .with_label_values(&["sfc", "F1", "S2"])
        .set(1);
    m.render()
        .lines()
        .filter_map(|l| l.strip_prefix("# TYPE "))
        .filter_map(|l| l.split(' ').next())
        .map(str::to_string)
        .collect()
}

/// Every `cellwatch_…` metric name written in the agent's sources (the
/// console's, which exports no metric, name its session cookie so).
fn metric_names_in_sources() -> BTreeSet<String> {
    fn walk(dir: &Path, out: &mut BTreeSet<String>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.ends_with("agent/src/console") {
                continue;
            }
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|e| e == "rs") {
                let text = std::fs::read_to_string(&p).unwrap();
                for (at, _) in text.match_indices("\"cellwatch_") {
                    let name: String = text[at + 1..]
                        .chars()
                        .take_while(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || *c == '_')
                        .collect();
                    if text[at + 1 + name.len()..].starts_with('"') {
                        out.insert(name);
                    }
                }
            }
        }
    }
    let mut out = BTreeSet::new();
    walk(&root().join("agent/src"), &mut out);
    out
}

#[test]
fn the_metrics_reference_lists_every_metric() {
    let exported = exported_metrics();
    let declared = metric_names_in_sources();
    assert!(exported.len() > 30, "{exported:?}");
    let text = std::fs::read_to_string(root().join("docs/reference/metrics.md")).unwrap();
    let rows = documented_keys(&text);
    let named: BTreeSet<String> = text
        .match_indices("cellwatch_")
        .map(|(at, _)| {
            text[at..]
                .chars()
                .take_while(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || *c == '_')
                .collect::<String>()
        })
        .collect();
    let mut problems = Vec::new();
    for m in exported.union(&declared) {
        if !rows.contains(m) {
            problems.push(format!("{m}: exported, but has no row"));
        }
    }
    for m in named.iter().filter(|m| m.len() > "cellwatch_".len()) {
        if !exported.contains(m) {
            problems.push(format!("{m}: named, but the agent exports no such metric"));
        }
    }
    assert!(
        problems.is_empty(),
        "docs/reference/metrics.md:\n{}",
        problems.join("\n")
    );
}

/// The OPC UA services the source counts requests of, as its sources name
/// them (`requests.answered("Read", …)`, `requests.status("Republish", …)`).
fn opcua_services_in_sources() -> BTreeSet<String> {
    fn walk(dir: &Path, out: &mut BTreeSet<String>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|e| e == "rs") {
                let text = std::fs::read_to_string(&p).unwrap();
                for call in [".answered(", ".status("] {
                    for (at, _) in text.match_indices(call) {
                        let rest = text[at + call.len()..].trim_start();
                        if let Some(name) = rest.strip_prefix('"').and_then(|r| r.split('"').next())
                        {
                            out.insert(name.to_string());
                        }
                    }
                }
            }
        }
    }
    let mut out = BTreeSet::new();
    walk(&root().join("agent/src/sources/opcua"), &mut out);
    out
}

/// Labels whose values are a fixed set the code names (not a check id, a
/// tag, a culprit or a version); the OPC UA requests' `result` is the
/// status code's name, of which the reference lists `good`.
const FIXED_LABELS: [&str; 8] = [
    "kind", "severity", "state", "action", "result", "service", "reason", "bound",
];

#[test]
fn the_metrics_reference_lists_every_label_value() {
    use cellwatch_models::alarm::{AlarmKind, Severity};
    // Every value the code gives each fixed label: the enums' every member,
    // the series made at start (machine states, refusals, Alertmanager's
    // results), the OPC UA services the source names.
    let m = cellwatch::metrics::Metrics::new("docs");
    for kind in AlarmKind::ALL {
        for severity in Severity::ALL {
            m.raised("c", kind, severity);
            m.active_delta(kind, severity, 1);
            m.culprit("c", severity.as_str(), "F", Some("X0.00"), None, true);
        }
    }
    let actions = cellwatch::operator::Action::ALL.map(Some);
    for action in actions.into_iter().chain([None]) {
        m.command(action, true);
        m.command(action, false);
    }
    let services = opcua_services_in_sources();
    assert!(services.len() >= 10, "{services:?}");
    for service in &services {
        m.opcua_requests.with_label_values(&[service, "good"]).inc();
    }
    for bound in ["lo", "hi"] {
        m.transition_window_seconds
            .with_label_values(&["line-001", bound])
            .set(1.0);
    }
    let text = std::fs::read_to_string(root().join("docs/reference/metrics.md")).unwrap();
    let row = |metric: &str| {
        ["", "_bucket", "_sum", "_count"].iter().find_map(|suffix| {
            let name = metric.strip_suffix(suffix)?;
            text.lines()
                .find(|l| l.starts_with(&format!("| `{name}` |")))
        })
    };
    let mut problems = BTreeSet::new();
    let mut checked = 0;
    for line in m.render().lines().filter(|l| !l.starts_with('#')) {
        let Some((metric, rest)) = line.split_once('{') else {
            continue;
        };
        let labels = rest.rsplit_once('}').map_or("", |(l, _)| l);
        for pair in labels.split("\",") {
            let Some((label, value)) = pair.split_once("=\"") else {
                continue;
            };
            let value = value.trim_end_matches('"');
            let open = metric == "cellwatch_opcua_requests_total" && label == "result";
            if !FIXED_LABELS.contains(&label) || (open && value != "good") {
                continue;
            }
            checked += 1;
            match row(metric) {
                Some(r) if r.contains(&format!("`{value}`")) => {}
                Some(_) => {
                    problems.insert(format!("{metric}: {label} `{value}` not in its row"));
                }
                None => {
                    problems.insert(format!("{metric}: no row"));
                }
            }
        }
    }
    assert!(checked > 200, "{checked} label values checked");
    assert!(
        problems.is_empty(),
        "docs/reference/metrics.md:\n{}",
        problems.into_iter().collect::<Vec<_>>().join("\n")
    );
}
