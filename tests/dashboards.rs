//! The Grafana dashboards and Prometheus rules point only at metrics the
//! agent exports: every PromQL expression is parsed, and every metric it
//! names must be in a `/metrics` scrape of a running agent (demo config,
//! after a fault). Dashboards are also checked for structure.

use std::collections::{BTreeSet, HashSet};
use std::path::PathBuf;
use std::time::Duration;

use promql_parser::parser::{self, Expr};

use crate::agent::Fixture;
use crate::util::root;

/// Metrics Prometheus itself makes, not the agent.
const PROMETHEUS_OWN: &[&str] = &["up"];

fn dashboards() -> Vec<(PathBuf, serde_json::Value)> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(root().join("dashboards")).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "json") {
            let v = serde_json::from_str(&std::fs::read_to_string(&p).unwrap())
                .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            out.push((p, v));
        }
    }
    assert!(
        out.len() >= 4,
        "expected the cell, plant, agent and alarm performance dashboards"
    );
    out
}

/// Grafana variables replaced by values PromQL accepts.
fn substitute(expr: &str) -> String {
    expr.replace("$__rate_interval", "1m")
        .replace("$__range_s", "3600")
        .replace("$__range", "1h")
        .replace("$__interval", "1m")
        .replace("$cell", ".+")
}

fn names(e: &Expr, out: &mut BTreeSet<String>) {
    match e {
        Expr::VectorSelector(vs) => {
            if let Some(n) = &vs.name {
                out.insert(n.clone());
            }
        }
        Expr::MatrixSelector(ms) => {
            if let Some(n) = &ms.vs.name {
                out.insert(n.clone());
            }
        }
        Expr::Aggregate(a) => {
            names(&a.expr, out);
            if let Some(p) = &a.param {
                names(p, out);
            }
        }
        Expr::Unary(u) => names(&u.expr, out),
        Expr::Binary(b) => {
            names(&b.lhs, out);
            names(&b.rhs, out);
        }
        Expr::Paren(p) => names(&p.expr, out),
        Expr::Subquery(s) => names(&s.expr, out),
        Expr::Call(c) => c.args.args.iter().for_each(|a| names(a, out)),
        Expr::NumberLiteral(_) | Expr::StringLiteral(_) | Expr::Extension(_) => {}
    }
}

/// Every expression in the dashboards and rules, with where it is.
fn expressions() -> Vec<(String, String)> {
    let mut out = Vec::new();
    for (path, d) in dashboards() {
        for p in d["panels"].as_array().unwrap() {
            for t in p["targets"].as_array().unwrap() {
                out.push((
                    format!(
                        "{} panel '{}'",
                        path.display(),
                        p["title"].as_str().unwrap()
                    ),
                    t["expr"].as_str().unwrap().to_string(),
                ));
            }
        }
        for v in d["templating"]["list"].as_array().unwrap() {
            if let Some(q) = v["definition"].as_str() {
                // label_values(metric, label): the metric must exist too.
                let metric = q
                    .trim_start_matches("label_values(")
                    .split(',')
                    .next()
                    .unwrap()
                    .trim()
                    .to_string();
                out.push((format!("{} variable {}", path.display(), v["name"]), metric));
            }
        }
    }
    let rules: serde_norway::Value = serde_norway::from_str(
        &std::fs::read_to_string(root().join("dashboards/alerts.yml")).unwrap(),
    )
    .unwrap();
    for g in rules["groups"].as_sequence().unwrap() {
        for r in g["rules"].as_sequence().unwrap() {
            out.push((
                format!("alerts.yml {}", r["alert"].as_str().unwrap()),
                r["expr"].as_str().unwrap().to_string(),
            ));
        }
    }
    out
}

#[test]
fn dashboards_are_importable_and_consistent() {
    for (path, d) in dashboards() {
        let p = path.display();
        assert!(
            d["uid"]
                .as_str()
                .is_some_and(|u| !u.is_empty() && u.len() <= 40),
            "{p}: uid"
        );
        assert!(
            d["title"].as_str().is_some_and(|t| !t.is_empty()),
            "{p}: title"
        );
        assert!(
            d["schemaVersion"].as_u64().is_some_and(|v| v >= 39),
            "{p}: schemaVersion"
        );
        let vars = d["templating"]["list"].as_array().unwrap();
        let ds = vars
            .iter()
            .find(|v| v["type"] == "datasource")
            .unwrap_or_else(|| panic!("{p}: no datasource variable"));
        assert_eq!(ds["query"], "prometheus", "{p}");
        let cell = vars
            .iter()
            .find(|v| v["name"] == "cell")
            .unwrap_or_else(|| panic!("{p}: no cell variable"));
        assert_eq!(cell["multi"], true, "{p}: cell must be multi-value");
        let mut ids = HashSet::new();
        for panel in d["panels"].as_array().unwrap() {
            let title = panel["title"].as_str().unwrap();
            assert!(
                ids.insert(panel["id"].as_u64().unwrap()),
                "{p}: panel id {} used twice",
                panel["id"]
            );
            assert_eq!(
                panel["datasource"]["uid"], "${datasource}",
                "{p}: panel '{title}' must use the datasource variable"
            );
            let targets = panel["targets"].as_array().unwrap();
            assert!(!targets.is_empty(), "{p}: panel '{title}' has no query");
            for t in targets {
                assert_eq!(
                    t["datasource"]["uid"], "${datasource}",
                    "{p}: a query of '{title}' must use the datasource variable"
                );
                let expr = t["expr"].as_str().unwrap();
                assert!(
                    expr.contains("$cell") || title == "Agents up",
                    "{p}: '{title}' ignores the cell variable"
                );
            }
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn every_metric_named_is_exported_by_the_agent() {
    let mut wanted: BTreeSet<String> = BTreeSet::new();
    for (place, expr) in expressions() {
        let parsed =
            parser::parse(&substitute(&expr)).unwrap_or_else(|e| panic!("{place}: {expr}: {e}"));
        let mut n = BTreeSet::new();
        names(&parsed, &mut n);
        assert!(!n.is_empty(), "{place}: {expr} reads no metric");
        wanted.extend(n);
    }
    // A running agent on the demo configuration, after a fault.
    // A machine mode (JOG: not held here), for its gauge.
    let fx = Fixture::start_with(|c| {
        c.state.modes.push(cellwatch_models::engine::Mode {
            id: "setup".into(),
            when: cellwatch_models::expr::Expr::parse("D104 == 2").unwrap(),
            suppress: vec![cellwatch_models::alarm::AlarmPattern::new("es*")],
        });
    })
    .await;
    fx.settled().await;
    fx.sim.set("X0.06", false).unwrap();
    let deadline = tokio::time::Instant::now() + Duration::from_secs(20);
    let scrape = loop {
        let s = fx.scrape().await;
        if s.contains("cellwatch_alarm_culprit{") {
            break s;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "no fault in the metrics:\n{s}"
        );
        tokio::time::sleep(Duration::from_millis(200)).await;
    };
    // And an agent with transition timers (the line), once it has measured
    // a transition.
    let d = tempfile::tempdir().unwrap();
    let (line_sim, line_agent, _) = crate::agent::line_cell(d.path()).await;
    let player_sim = line_sim.clone();
    let player = tokio::spawn(async move { player_sim.play(7, None, |_| {}).await });
    let addr = line_agent.metrics_addr().unwrap();
    let deadline = tokio::time::Instant::now() + Duration::from_secs(60);
    let line_scrape = loop {
        let s = crate::util::scrape(addr).await;
        if s.contains("cellwatch_transition_duration_seconds_bucket{") {
            break s;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "no transition measured:\n{s}"
        );
        tokio::time::sleep(Duration::from_millis(500)).await;
    };
    player.abort();
    line_agent.stop().await;
    line_sim.stop();
    // And the robot of paper 004, once a step of its charts is seen.
    let d = tempfile::tempdir().unwrap();
    let robot = crate::force::RobotCell::start(
        d.path(),
        Duration::from_millis(200),
        |_| {},
        |c| c.metrics = Some("127.0.0.1:0".parse().unwrap()),
    )
    .await;
    let addr = robot.agent.metrics_addr().unwrap();
    let deadline = tokio::time::Instant::now() + Duration::from_secs(60);
    let robot_scrape = loop {
        let s = crate::util::scrape(addr).await;
        if s.contains("cellwatch_sfc_step_active{") {
            break s;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "no step in the metrics:\n{s}"
        );
        tokio::time::sleep(Duration::from_millis(200)).await;
    };
    robot.stop().await;
    let scrape = format!("{scrape}\n{line_scrape}\n{robot_scrape}");
    let exported: BTreeSet<&str> = scrape
        .lines()
        .filter(|l| !l.starts_with('#') && l.starts_with("cellwatch_"))
        .filter_map(|l| l.split(['{', ' ']).next())
        .collect();
    let missing: Vec<&String> = wanted
        .iter()
        .filter(|n| !PROMETHEUS_OWN.contains(&n.as_str()) && !exported.contains(n.as_str()))
        .collect();
    assert!(
        missing.is_empty(),
        "named in dashboards or rules but not exported: {missing:?}\nexported: {exported:?}"
    );
    fx.agent.unwrap().stop().await;
    fx.sim.stop();
}
