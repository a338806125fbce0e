//! `cellwatch alarms`, `history`, `ack` and `reset`: clients that talk to
//! agents over Zenoh only.

use std::io::Write;
use std::time::Duration;

use zenoh_ext::{AdvancedSubscriberBuilderExt, HistoryConfig, RecoveryConfig};

use crate::cli::{AlarmsArgs, CommandArgs, Failure, HistoryArgs, ZenohArgs};
use crate::config::{ZenohConfig, ZenohMode};
use crate::operator::{Action, Command, OperatorKeys};
use crate::payload::AlarmPayload;

async fn session(z: &ZenohArgs) -> Result<zenoh::Session, Failure> {
    let mode = match z.mode.as_str() {
        "peer" => ZenohMode::Peer,
        "client" => ZenohMode::Client,
        other => {
            return Err(Failure::Input(format!(
                "--mode '{other}': use peer or client"
            )))
        }
    };
    let cfg = ZenohConfig {
        mode,
        connect: z.connect.clone(),
        listen: Vec::new(),
        prefix: String::new(),
        multicast_scouting: false,
    };
    crate::sinks::zenoh::open(&cfg)
        .await
        .map_err(Failure::runtime)
}

fn io(e: std::io::Error) -> Failure {
    Failure::output(e)
}

fn print_alarm(out: &mut dyn Write, a: &AlarmPayload, json: bool) -> std::io::Result<()> {
    if json {
        return writeln!(out, "{}", serde_json::to_string(a).unwrap_or_default());
    }
    let step = a
        .fault_step
        .map(|s| format!(" step {s}"))
        .unwrap_or_default();
    writeln!(
        out,
        "{}  {}/{}  {} {} [{}] {}{step}: {}",
        a.at, a.cell, a.id, a.transition, a.state, a.severity, a.fault_type, a.message
    )?;
    for c in &a.culprits {
        writeln!(out, "    {}", c.line())?;
    }
    Ok(())
}

/// `cellwatch alarms`.
pub(crate) async fn alarms(args: &AlarmsArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let s = session(&args.zenoh).await?;
    let cell = args.cell.as_deref().unwrap_or("*");
    let root = &args.zenoh.root;
    if args.follow {
        let sub = s
            .declare_subscriber(format!("{root}/{cell}/alarms/**"))
            .history(HistoryConfig::default().detect_late_publishers())
            .recovery(RecoveryConfig::default().heartbeat())
            .subscriber_detection()
            .await
            .map_err(|e| Failure::Runtime(format!("cannot subscribe: {e}")))?;
        loop {
            tokio::select! {
                _ = tokio::signal::ctrl_c() => break,
                sample = sub.recv_async() => {
                    let Ok(sample) = sample else { break };
                    let text = sample.payload().try_to_string().map(|s| s.into_owned()).unwrap_or_default();
                    match serde_json::from_str::<AlarmPayload>(&text) {
                        Ok(a) => print_alarm(out, &a, args.json).map_err(io)?,
                        Err(e) => tracing::warn!(key = %sample.key_expr(), error = %e, "not an alarm payload"),
                    }
                    out.flush().map_err(io)?;
                }
            }
        }
        return Ok(());
    }
    let replies = s
        .get(format!("{root}/{cell}/snapshot"))
        .timeout(Duration::from_secs(args.zenoh.timeout_secs))
        .await
        .map_err(|e| Failure::Runtime(format!("query failed: {e}")))?;
    let mut agents = 0;
    while let Ok(reply) = replies.recv_async().await {
        let Ok(sample) = reply.result() else { continue };
        agents += 1;
        let text = sample
            .payload()
            .try_to_string()
            .map(|s| s.into_owned())
            .unwrap_or_default();
        let v: serde_json::Value = serde_json::from_str(&text).unwrap_or_default();
        for a in v["alarms"].as_array().into_iter().flatten() {
            if let Ok(a) = serde_json::from_value::<AlarmPayload>(a.clone()) {
                print_alarm(out, &a, args.json).map_err(io)?;
            }
        }
    }
    if agents == 0 {
        return Err(Failure::Runtime(format!(
            "no agent answered on {root}/{cell}/snapshot (is one running, and is --connect right?)"
        )));
    }
    Ok(())
}

/// `cellwatch history`.
pub(crate) async fn history(args: &HistoryArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let s = session(&args.zenoh).await?;
    let mut params = vec![format!("since={}", args.since)];
    if let Some(u) = &args.until {
        params.push(format!("until={u}"));
    }
    if let Some(k) = &args.kind {
        params.push(format!("kind={k}"));
    }
    params.push(format!("limit={}", args.limit));
    let selector = format!(
        "{}/{}/history?{}",
        args.zenoh.root,
        args.cell,
        params.join(";")
    );
    let replies = s
        .get(selector.as_str())
        .timeout(Duration::from_secs(args.zenoh.timeout_secs))
        .await
        .map_err(|e| Failure::Runtime(format!("query failed: {e}")))?;
    let mut answered = false;
    while let Ok(reply) = replies.recv_async().await {
        answered = true;
        let sample = match reply.result() {
            Ok(s) => s,
            Err(e) => {
                let why = e
                    .payload()
                    .try_to_string()
                    .map(|s| s.into_owned())
                    .unwrap_or_default();
                return Err(Failure::Input(format!("{selector}: {why}")));
            }
        };
        let text = sample
            .payload()
            .try_to_string()
            .map(|s| s.into_owned())
            .unwrap_or_default();
        if args.json {
            writeln!(out, "{text}").map_err(io)?;
            continue;
        }
        let rows: Vec<serde_json::Value> = serde_json::from_str(&text).unwrap_or_default();
        for r in rows {
            let at = crate::clock::rfc3339(r["at"].as_u64().unwrap_or(0));
            let f = &r["fields"];
            let line = match r["table"].as_str() {
                Some("state") => format!(
                    "{:<9} state={} type={} element={}",
                    f["kind"].as_str().unwrap_or(""),
                    f["state"].as_str().unwrap_or(""),
                    f["fault_type"].as_str().unwrap_or("None"),
                    f["element"].as_str().unwrap_or("None")
                ),
                Some("alarm") => format!(
                    "alarm     {} {} [{}] {}",
                    f["alarm"].as_str().unwrap_or(""),
                    f["transition"].as_str().unwrap_or(""),
                    f["severity"].as_str().unwrap_or(""),
                    f["payload"]["message"].as_str().unwrap_or("")
                ),
                _ => format!(
                    "command   {} {} by {}: {} ({})",
                    f["action"].as_str().unwrap_or(""),
                    f["alarm"].as_str().unwrap_or(""),
                    f["operator"].as_str().unwrap_or(""),
                    if f["accepted"].as_bool() == Some(true) {
                        "accepted"
                    } else {
                        "refused"
                    },
                    f["detail"].as_str().unwrap_or("")
                ),
            };
            writeln!(out, "{at}  {line}").map_err(io)?;
        }
    }
    if !answered {
        return Err(Failure::Runtime(format!("no agent answered {selector}")));
    }
    Ok(())
}

/// `cellwatch ack` and `cellwatch reset`.
pub(crate) async fn command(
    action: Action,
    args: &CommandArgs,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    let key = match (&args.key_file, std::env::var("CELLWATCH_OPERATOR_KEY")) {
        (Some(path), _) => {
            let text = std::fs::read_to_string(path)
                .map_err(|e| Failure::Input(format!("cannot read {}: {e}", path.display())))?;
            OperatorKeys::parse(&path.display().to_string(), &text)
                .map_err(Failure::input)?
                .key(&args.operator)
                .ok_or_else(|| {
                    Failure::Input(format!(
                        "{}: no key for operator '{}'",
                        path.display(),
                        args.operator
                    ))
                })?
        }
        (None, Ok(hex_key)) => hex::decode(hex_key.trim())
            .map_err(|_| Failure::Input("CELLWATCH_OPERATOR_KEY is not hex".into()))?,
        (None, Err(_)) => {
            return Err(Failure::Input(
                "give --key-file or set CELLWATCH_OPERATOR_KEY".into(),
            ))
        }
    };
    let mut cmd = Command {
        action,
        alarm: args.alarm.clone(),
        operator: args.operator.clone(),
        nonce: crate::operator::nonce(),
        issued_at: crate::clock::now_ms(),
        signature: String::new(),
    };
    cmd.sign(&args.cell, &key);
    let s = session(&args.zenoh).await?;
    let selector = format!("{}/{}/command", args.zenoh.root, args.cell);
    let replies = s
        .get(selector.as_str())
        .payload(serde_json::to_string(&cmd).unwrap_or_default())
        .timeout(Duration::from_secs(args.zenoh.timeout_secs))
        .await
        .map_err(|e| Failure::Runtime(format!("query failed: {e}")))?;
    match replies.recv_async().await {
        Ok(reply) => {
            let text = reply
                .result()
                .map(|s| {
                    s.payload()
                        .try_to_string()
                        .map(|s| s.into_owned())
                        .unwrap_or_default()
                })
                .unwrap_or_default();
            let v: serde_json::Value = serde_json::from_str(&text).unwrap_or_default();
            let detail = v["detail"].as_str().unwrap_or("");
            if v["accepted"].as_bool() == Some(true) {
                writeln!(out, "accepted: {detail}").map_err(io)?;
                Ok(())
            } else {
                Err(Failure::Runtime(format!("refused: {detail}")))
            }
        }
        Err(_) => Err(Failure::Runtime(format!("no agent answered {selector}"))),
    }
}
