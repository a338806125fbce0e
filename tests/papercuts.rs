//! What a plant engineer hits configuring a new cell, against a real OPC UA
//! server with its own namespace (the simulated CNC, a Float register
//! added): a number that is not one (NaN, +Inf, −Inf on Float and Double)
//! is bad quality, never a limit violation; a discrete alarm needs no
//! program; a cell's own KPI rules; an untrusted server certificate said
//! at once; `report daily` runs anywhere with the shipped stop causes; a
//! pressure rising faster than its rate of change alarms.

use cellwatch::config::TagConfig;
use cellwatch::payload::AlarmPayload;
use cellwatch::sim::cnc::NAMESPACE;
use cellwatch_models::alarm::Severity;
use cellwatch_models::limit::{Level, LimitCheck, LimitLevel};
use cellwatch_models::signal::Signal;
use cellwatch_models::value::ValueType;
use opcua::types::Variant;

use crate::agent::{alarm_until, Fixture};

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn nan_and_infinities_are_bad_quality_on_float_and_double_never_a_limit() {
    let fx = Fixture::start_with_sim(
        |sim| sim.add_register("D208", Variant::Float(3.0)).unwrap(),
        |c| {
            // A server-side deadband never reports a NaN (no difference
            // with NaN exceeds it): the spindle's is taken off here.
            for t in &mut c.tags {
                if t.address == Signal::new("D100") {
                    t.deadband = None;
                }
            }
            c.tags.push(TagConfig {
                value_type: ValueType::Float,
                comment: Some("Coolant pressure after the filter".into()),
                ..TagConfig::boolean(
                    "coolant_pressure",
                    &format!("nsu={NAMESPACE};s=D208"),
                    Signal::new("D208"),
                )
            });
            c.limits.push(LimitCheck {
                comment: None,
                id: "coolant".into(),
                tag: Signal::new("D208"),
                label: "coolant_pressure".into(),
                unit: "bar".into(),
                deadband: 0.0,
                on_delay: 0,
                off_delay: 0,
                rates: Vec::new(),
                levels: vec![LimitLevel {
                    level: Level::H,
                    limit: 6.0,
                    severity: Severity::High,
                }],
            });
        },
    )
    .await;
    let sub = crate::robust::alarms(fx.client(), "m01ps0004").await;
    fx.settled().await;
    let mut seen: Vec<AlarmPayload> = Vec::new();
    // D100 is a Double (the spindle, H 85 °C after 2 s), D208 a Float
    // (H 6 bar at once).
    let set = |address: &str, x: f64| match address {
        "D100" => fx.sim.set_temperature(x).unwrap(),
        _ => fx
            .sim
            .set_registers(&[("D208".into(), Variant::Float(x as f32))])
            .unwrap(),
    };
    // Each bad tag is named with its comment.
    for (address, name) in [
        (
            "D100",
            "spindle_temperature: Spindle temperature, degrees C",
        ),
        (
            "D208",
            "coolant_pressure: Coolant pressure after the filter",
        ),
    ] {
        for (x, said) in [
            (f64::INFINITY, "+inf"),
            (f64::NAN, "NaN"),
            (f64::NEG_INFINITY, "-inf"),
        ] {
            set(address, x);
            let expected = format!("{address} ({name}): {said} received, not a number");
            let quality = alarm_until(&sub, &expected, &mut seen, |a| {
                a.id == "tag-quality"
                    && a.state.as_str().starts_with("active")
                    && a.message.contains(&expected)
            })
            .await;
            assert!(
                quality
                    .message
                    .starts_with("bad or uncertain quality, checks reading them suspended"),
                "{}",
                quality.message
            );
            fx.tag_value_is(address, serde_json::Value::Null).await;
        }
        // A number again: the quality clears and the limit is judged on it.
        let from = seen.len();
        set(address, 120.0);
        alarm_until(&sub, "the quality good again", &mut seen, |a| {
            a.id == "tag-quality" && a.transition.as_str() == "cleared"
        })
        .await;
        let check = if address == "D100" {
            "spindle-temp-"
        } else {
            "coolant-"
        };
        let judged =
            |a: &AlarmPayload| a.id.starts_with(check) && a.transition.as_str() == "raised";
        let raised = match seen[from..].iter().find(|a| judged(a)) {
            Some(a) => a.clone(),
            None => alarm_until(&sub, "the limit on a number", &mut seen, judged).await,
        };
        assert!(raised.message.contains("= 120"), "{}", raised.message);
        if address == "D100" {
            // The tag's comment ends the message, as a culprit's does.
            assert!(
                raised.message.ends_with(": Spindle temperature, degrees C"),
                "{}",
                raised.message
            );
        }
    }
    // No limit was ever raised on a number that is not one.
    let on_no_number: Vec<&AlarmPayload> = seen
        .iter()
        .filter(|a| {
            a.kind.as_str() == "limit" && (a.message.contains("inf") || a.message.contains("NaN"))
        })
        .collect();
    assert!(on_no_number.is_empty(), "{on_no_number:#?}");
    let mut fx = fx;
    fx.stop().await;
    fx.sim.stop();
}

/// `[[checks.discrete]]` of config/demo.toml: the Z2 over-travel switch
/// (a B contact, off is the fault), no program.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_discrete_alarm_from_the_config_names_its_contact_and_comment_and_is_acknowledged() {
    let fx = Fixture::start().await;
    let sub = crate::robust::alarms(fx.client(), "m01ps0004").await;
    fx.settled().await;
    let mut seen: Vec<AlarmPayload> = Vec::new();
    fx.sim.set("X0.0A", false).unwrap();
    let raised = alarm_until(&sub, "the Z2 over-travel alarm", &mut seen, |a| {
        a.id == "z2-overtravel" && a.transition.as_str() == "raised"
    })
    .await;
    assert_eq!(
        raised.message,
        "Z axis 2 on its over-travel limit: X0.0A = 0 (expected 1): Z2 Over Travel Limit SW (B)"
    );
    assert_eq!(raised.severity, Severity::Critical);
    assert_eq!(raised.kind.as_str(), "switching");
    assert_eq!(raised.culprits.len(), 1);
    assert_eq!(
        raised.culprits[0].comment.as_deref(),
        Some("Z2 Over Travel Limit SW (B)")
    );
    // The lifecycle of every alarm: kim acknowledges, the switch closes.
    let (ok, detail) = crate::spawned::send(
        fx.client(),
        &crate::spawned::signed(cellwatch::operator::Action::Ack, "z2-overtravel"),
    )
    .await;
    assert!(ok, "{detail}");
    let acked = alarm_until(&sub, "acknowledged", &mut seen, |a| {
        a.id == "z2-overtravel" && a.transition.as_str() == "acknowledged"
    })
    .await;
    assert_eq!(acked.acked_by.as_deref(), Some("kim"));
    fx.sim.set("X0.0A", true).unwrap();
    alarm_until(&sub, "cleared", &mut seen, |a| {
        a.id == "z2-overtravel" && a.transition.as_str() == "cleared"
    })
    .await;
    let mut fx = fx;
    fx.stop().await;
    fx.sim.stop();
}

/// The cell's `[kpi]` rules judge the live figures: here a flood above 1
/// raise in 10 minutes (ended below 1) and a chatter of 2 raises within
/// 10 minutes, on the Z2 over-travel alarm from the server.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn the_cells_own_kpi_rules_judge_its_live_figures() {
    let fx = Fixture::start_with(|c| {
        c.kpi = cellwatch_models::kpi::KpiRules {
            flood_raises: 1,
            flood_ends_below: 1,
            chatter_raises: 2,
            chatter_window_ms: 600_000,
            stale_ms: 3_600_000,
        };
    })
    .await;
    let sub = crate::robust::alarms(fx.client(), "m01ps0004").await;
    fx.settled().await;
    let mut seen: Vec<AlarmPayload> = Vec::new();
    let figure = |scrape: &str, metric: &str| {
        scrape
            .lines()
            .find(|l| l.starts_with(&format!("{metric}{{")))
            .and_then(|l| l.rsplit(' ').next()?.parse::<f64>().ok())
    };
    // By ISA-18.2's rules one raise is no flood; by this cell's, none yet.
    let s = fx.scrape().await;
    assert_eq!(figure(&s, "cellwatch_alarm_flood"), Some(0.0), "{s}");
    for round in 0..2 {
        fx.sim.set("X0.0A", false).unwrap();
        alarm_until(&sub, "z2-overtravel raised", &mut seen, |a| {
            a.id == "z2-overtravel" && a.transition.as_str() == "raised"
        })
        .await;
        fx.sim.set("X0.0A", true).unwrap();
        let cleared = alarm_until(&sub, "z2-overtravel cleared", &mut seen, |a| {
            a.id == "z2-overtravel" && a.transition.as_str() == "cleared"
        })
        .await;
        assert_eq!(cleared.id, "z2-overtravel", "round {round}");
    }
    // The over-travel switch also opens the emergency-stop chain (ESE):
    // four raises in all, a flood above one; the Z2 alarm (and ESE) raised
    // twice within 10 minutes: chattering by this cell's rule.
    let deadline = tokio::time::Instant::now() + std::time::Duration::from_secs(60);
    loop {
        let s = fx.scrape().await;
        let (flood, chattering) = (
            figure(&s, "cellwatch_alarm_flood"),
            figure(&s, "cellwatch_alarms_chattering"),
        );
        if flood == Some(1.0) && chattering.is_some_and(|c| c >= 1.0) {
            break;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "flood {flood:?}, chattering {chattering:?}:\n{s}"
        );
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
    }
    let mut fx = fx;
    fx.stop().await;
    fx.sim.stop();
}

/// `discover` on a server whose certificate is not trusted says so at
/// once, with the certificate's fingerprint and the command that trusts it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_untrusted_server_certificate_is_refused_at_once_with_the_command_to_trust_it() {
    use cellwatch::sim::cnc::{SimOptions, SimulatedCnc};
    let dir = tempfile::tempdir().unwrap();
    let sim = SimulatedCnc::start(&SimOptions {
        listen: "127.0.0.1:0".parse().unwrap(),
        pki_dir: dir.path().join("sim-pki"),
        insecure: false,
        decoy: None,
    })
    .await
    .unwrap();
    let endpoint = sim.endpoint();
    let pki = dir.path().join("pki").to_str().unwrap().to_string();
    let r = tokio::task::spawn_blocking({
        let (endpoint, pki) = (endpoint.clone(), pki.clone());
        move || crate::util::cellwatch(&["discover", &endpoint, "--pki-dir", &pki])
    })
    .await
    .unwrap();
    assert_eq!(r.code, 1, "{}", r.stderr);
    assert!(
        r.stderr
            .contains("the server's certificate is not trusted (CN=cellwatch simulated CNC")
            && r.stderr.contains("SHA-256 ")
            && r.stderr.contains(&format!(
                "`cellwatch trust-server {endpoint} --pki-dir {pki}`"
            )),
        "{}",
        r.stderr
    );
    // Nothing of the stack's own retries or errors besides.
    assert_eq!(r.stderr.lines().count(), 1, "{}", r.stderr);
    sim.stop();
}

#[tokio::test]
async fn report_daily_runs_outside_the_checkout_with_the_shipped_stop_causes() {
    let d = tempfile::tempdir().unwrap();
    let db = d.path().join("cell.sqlite");
    let j = cellwatch::journal::Journal::start(
        &db,
        &cellwatch::config::Keep::all(std::time::Duration::from_secs(86_400)),
        crate::util::NoCommits,
    )
    .unwrap();
    j.close().await;
    // Run from a folder that has no config/ beside it.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_cellwatch"))
        .args(["report", "daily", "--date", "2026-11-26", "--db"])
        .arg(&db)
        .current_dir(d.path())
        .output()
        .unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert!(out.status.success(), "{stdout}{stderr}");
    assert!(stdout.contains("stop causes:"), "{stdout}");
    // A table named that is not there is said, naming it.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_cellwatch"))
        .args([
            "report",
            "daily",
            "--date",
            "2026-11-26",
            "--causes",
            "mine.toml",
            "--db",
        ])
        .arg(&db)
        .current_dir(d.path())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("cannot read stop causes 'mine.toml'"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_pressure_rising_faster_than_its_rate_is_alarmed_from_an_opc_ua_server() {
    use cellwatch_models::limit::{RateDirection, RateLevel};
    let fx = Fixture::start_with_sim(
        |sim| sim.add_register("D208", Variant::Float(3.0)).unwrap(),
        |c| {
            c.tags.push(TagConfig {
                value_type: ValueType::Float,
                comment: Some("Coolant pressure after the filter".into()),
                ..TagConfig::boolean(
                    "coolant_pressure",
                    &format!("nsu={NAMESPACE};s=D208"),
                    Signal::new("D208"),
                )
            });
            // No level: only how fast it moves, 2 bar a minute at most.
            c.limits.push(LimitCheck {
                comment: None,
                id: "coolant".into(),
                tag: Signal::new("D208"),
                label: "coolant_pressure".into(),
                unit: "bar".into(),
                deadband: 0.0,
                on_delay: 0,
                off_delay: 0,
                rates: vec![RateLevel {
                    direction: RateDirection::Rising,
                    rate: 2.0,
                    per: 60_000,
                    severity: Severity::High,
                }],
                levels: Vec::new(),
            });
        },
    )
    .await;
    let sub = crate::robust::alarms(fx.client(), "m01ps0004").await;
    fx.settled().await;
    fx.tag_value_is("D208", serde_json::json!(3.0)).await;
    let set = |x: f32| {
        fx.sim
            .set_registers(&[("D208".into(), Variant::Float(x))])
            .unwrap()
    };
    // 1 bar up: within the rate. Then 3.5 more within the minute.
    set(4.0);
    fx.tag_value_is("D208", serde_json::json!(4.0)).await;
    set(7.5);
    let mut seen: Vec<AlarmPayload> = Vec::new();
    let raised = alarm_until(&sub, "the rise alarmed", &mut seen, |a| {
        a.id.starts_with("coolant") && a.transition.as_str() == "raised"
    })
    .await;
    assert_eq!(raised.id, "coolant-roc-rising", "{raised:#?}");
    assert_eq!(raised.kind.as_str(), "limit");
    assert_eq!(raised.severity, Severity::High);
    // Said in the plant's words: the tag, its change, the rate.
    assert!(
        raised
            .message
            .contains("D208 (coolant_pressure) rose 4.5 bar in 1m (more than 2 per 1m)"),
        "{}",
        raised.message
    );
    // Nothing was raised for the first, slow step.
    assert!(
        seen.iter().filter(|a| a.id == "coolant-roc-rising").count() == 1,
        "{seen:#?}"
    );
}
