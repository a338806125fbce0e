//! The bus client: `cellwatch alarms`, `history`, and the signed commands
//! (`ack`, `reset`, `shelve`, `write`, `force`, …), which talk to agents
//! over Zenoh only and believe only what the plant trust file verifies.

mod args;
mod print;

use std::io::Write;
use std::time::Duration;

use zenoh_ext::{AdvancedSubscriberBuilderExt, HistoryConfig, RecoveryConfig};

pub(crate) use args::{
    AckArgs, AlarmsArgs, CommandArgs, ForceArgs, HistoryArgs, ReasonArgs, ReloadArgs, ShelveArgs,
    SignerArgs, StopArgs, WriteArgs, ZenohArgs,
};
pub(crate) use print::print_alarm;

use crate::bus::envelope::Trust;
use crate::bus::keys::Service;
use crate::client::{BusClient, CellAnswer, ClientError};
use crate::commands::Failure;
use crate::config::{ZenohConfig, ZenohMode};
use crate::operator::{Action, Command, OperatorKey};
use crate::payload::AlarmPayload;

/// Opens the client's session: TLS only unless `--plain`, listening on
/// nothing, linking only to the endpoints given; and reads the trust file.
pub(crate) async fn session(z: &ZenohArgs) -> Result<BusClient, Failure> {
    let trust = trust(z)?;
    let mode = match z.mode.as_str() {
        "peer" => ZenohMode::Peer,
        "client" => ZenohMode::Client,
        other => {
            return Err(Failure::Input(format!(
                "--mode '{other}': use peer or client"
            )))
        }
    };
    let tls = z.tls_ca.as_ref().map(|ca| crate::config::ZenohTls {
        ca: ca.clone(),
        cert: z.tls_cert.clone().unwrap_or_default(),
        key: z.tls_key.clone().unwrap_or_default(),
    });
    let connect = if !z.connect.is_empty() {
        z.connect.clone()
    } else if z.zenoh_config.is_some() {
        Vec::new()
    } else if z.plain {
        vec!["tcp/127.0.0.1:7447".into()]
    } else {
        vec!["quic/127.0.0.1:7447".into()]
    };
    let cfg = ZenohConfig {
        mode,
        connect,
        listen: Vec::new(),
        prefix: String::new(),
        multicast_scouting: false,
        tls,
        config_file: z.zenoh_config.clone(),
        plain: z.plain,
        signing_key: None,
    };
    BusClient::open(&cfg, trust, &z.root).await.map_err(failure)
}

/// The end of `cell`'s journal command chain as its agent signs it now
/// (in its snapshot's answer, the rows staged before it committed).
pub(crate) async fn command_chain(
    z: &ZenohArgs,
    cell: &str,
) -> Result<crate::payload::CommandChain, Failure> {
    let bus = session(z).await?;
    let timeout = Duration::from_secs(z.timeout_secs);
    let text = bus
        .ask(cell, Service::Snapshot, "", None, timeout)
        .await
        .map_err(failure)?;
    let v: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| Failure::Runtime(format!("cell {cell}: not a snapshot: {e}")))?;
    serde_json::from_value(v["command_chain"].clone()).map_err(|_| {
        Failure::Runtime(format!(
            "cell {cell}: its agent's snapshot carries no command chain (an agent older than this client)"
        ))
    })
}

/// How the CLI reports what the bus client could not do: a refused
/// configuration and an agent's error answer are the user's input, the
/// rest a runtime failure.
fn failure(e: ClientError) -> Failure {
    match e {
        e @ (ClientError::Config(_) | ClientError::Answered(_) | ClientError::NotAnOutcome(_)) => {
            Failure::Input(e.to_string())
        }
        e => Failure::Runtime(e.to_string()),
    }
}

/// The plant trust file named by `--trust` (or `CELLWATCH_TRUST`).
fn trust(z: &ZenohArgs) -> Result<Trust, Failure> {
    let path = z.trust.as_ref().ok_or_else(|| {
        Failure::Input(
            "give --trust FILE (or set CELLWATCH_TRUST): the plant trust file with each cell's agent's public key, against which every answer and alarm is checked (the demo writes cellwatch-demo/trust.toml)".into(),
        )
    })?;
    Trust::load(path).map_err(|e| Failure::Input(e.to_string()))
}

pub(crate) fn io(e: std::io::Error) -> Failure {
    Failure::output(e)
}

/// The newest event time known of each alarm (cell, id), at most
/// [`Latest::KEPT`] alarms (the oldest known forgotten first).
#[derive(Default)]
struct Latest {
    at: std::collections::HashMap<(String, String), String>,
    order: std::collections::VecDeque<(String, String)>,
}

impl Latest {
    const KEPT: usize = 100_000;

    /// Whether `a` is not older than what is known of its alarm; if so,
    /// it becomes what is known.
    fn newer(&mut self, a: &AlarmPayload) -> bool {
        let key = (a.cell.clone(), a.id.clone());
        match self.at.get_mut(&key) {
            Some(known) if a.at < *known => return false,
            Some(known) => known.clone_from(&a.at),
            None => {
                if self.at.len() >= Self::KEPT {
                    if let Some(oldest) = self.order.pop_front() {
                        self.at.remove(&oldest);
                    }
                }
                self.at.insert(key.clone(), a.at.clone());
                self.order.push_back(key);
            }
        }
        true
    }
}

/// `cellwatch alarms`.
pub(crate) async fn alarms(args: &AlarmsArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let bus = session(&args.zenoh).await?;
    let cell = args.cell.as_deref().unwrap_or("*");
    let timeout = Duration::from_secs(args.zenoh.timeout_secs);
    if args.follow {
        let sub = bus
            .session()
            .declare_subscriber(bus.keys(cell).alarms())
            .history(HistoryConfig::default().detect_late_publishers())
            .recovery(RecoveryConfig::default().heartbeat())
            .await
            .map_err(|e| Failure::Runtime(format!("cannot subscribe: {e}")))?;
        // The journal's recent events first (a subscriber joining after the
        // agent restarted gets them too); what the subscription then
        // delivers again is not printed twice.
        let mut printed = std::collections::HashSet::new();
        // The newest event printed of each alarm: an older one (a replay of
        // a genuine, signed event) is not printed after it.
        let mut latest = Latest::default();
        if let Some(since) = &args.since {
            let Some(cell) = &args.cell else {
                return Err(Failure::Input(
                    "--since needs --cell: the journal is read from one agent".into(),
                ));
            };
            let base = format!("kind=alarm;since={since};limit=1000");
            let mut after = 0;
            loop {
                let text = bus
                    .ask(
                        cell,
                        Service::History,
                        &format!("{base};after={after}"),
                        None,
                        timeout,
                    )
                    .await
                    .map_err(failure)?;
                let page: serde_json::Value = serde_json::from_str(&text).unwrap_or_default();
                for r in page["rows"].as_array().into_iter().flatten() {
                    if let Ok(a) =
                        serde_json::from_value::<AlarmPayload>(r["fields"]["payload"].clone())
                    {
                        printed.insert((a.id.clone(), a.at.clone(), a.transition));
                        latest.newer(&a);
                        print_alarm(out, &a, args.json, None).map_err(io)?;
                    }
                }
                match page["next"].as_i64() {
                    Some(next) => after = next,
                    None => break,
                }
            }
            out.flush().map_err(io)?;
        }
        loop {
            tokio::select! {
                _ = crate::commands::signals::stop_requested() => break,
                sample = sub.recv_async() => {
                    let Ok(sample) = sample else { break };
                    let key = sample.key_expr().as_str();
                    // Believed only if the cell's own agent sealed it for
                    // this key, whoever relayed it.
                    let opened = match bus.open_put(&sample.payload().to_bytes(), key) {
                        Ok(opened) => opened,
                        Err(why) => {
                            tracing::error!(key, why = %why, "an alarm event not believed: ignored");
                            continue;
                        }
                    };
                    let a = match serde_json::from_str::<AlarmPayload>(&opened.body) {
                        Ok(a) if a.cell == opened.cell => a,
                        Ok(a) => {
                            tracing::error!(key, cell = %a.cell, sealed_by = %opened.cell, "an alarm event for another cell than its sealer's: ignored");
                            continue;
                        }
                        Err(e) => {
                            tracing::warn!(key, error = %e, "not an alarm payload");
                            continue;
                        }
                    };
                    if printed.remove(&(a.id.clone(), a.at.clone(), a.transition)) {
                        continue;
                    }
                    if !latest.newer(&a) {
                        tracing::warn!(key, at = %a.at, "an alarm event older than one already printed of that alarm (replayed?): not printed");
                        continue;
                    }
                    print_alarm(out, &a, args.json, None).map_err(io)?;
                    out.flush().map_err(io)?;
                }
            }
        }
        return Ok(());
    }
    let key = bus.keys(cell).service(Service::Snapshot);
    let (answers, mut refused) = bus
        .ask_every(cell, Service::Snapshot, timeout)
        .await
        .map_err(failure)?;
    let mut answered = 0;
    let now = crate::clock::now_ms();
    for CellAnswer {
        cell: of_cell,
        answer,
    } in answers
    {
        let text = match answer {
            Ok(text) => text,
            Err(e) => {
                tracing::warn!(cell = %of_cell, error = %e, "the agent could not answer");
                refused.push(format!("cell {of_cell}: {e}"));
                continue;
            }
        };
        let v: serde_json::Value = serde_json::from_str(&text).unwrap_or_default();
        // The cell it speaks for, believed only from that cell's agent.
        if v["cell"].as_str() != Some(of_cell.as_str()) {
            tracing::error!(cell = ?v["cell"].as_str(), sealed_by = %of_cell, "a snapshot for another cell than its sealer's: ignored");
            continue;
        }
        answered += 1;
        for a in v["alarms"].as_array().into_iter().flatten() {
            if let Ok(a) = serde_json::from_value::<AlarmPayload>(a.clone()) {
                print_alarm(out, &a, args.json, Some(now)).map_err(io)?;
            }
        }
    }
    if answered == 0 {
        let why = if refused.is_empty() {
            String::new()
        } else {
            format!(
                "; {} answer(s) not believed or failed: {}",
                refused.len(),
                refused.join("; ")
            )
        };
        return Err(Failure::Runtime(format!(
            "no agent answered on {key} (is one running, is --connect right, and is the cell in the trust file?){why}"
        )));
    }
    Ok(())
}

/// `cellwatch history`: the newest rows, or with `--all` every row of the
/// range, fetched in bounded pages.
pub(crate) async fn history(args: &HistoryArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let bus = session(&args.zenoh).await?;
    let mut params = vec![format!("since={}", args.since)];
    if let Some(u) = &args.until {
        params.push(format!("until={u}"));
    }
    if let Some(k) = &args.kind {
        params.push(format!("kind={k}"));
    }
    params.push(format!("limit={}", args.limit));
    let base = params.join(";");
    let timeout = Duration::from_secs(args.zenoh.timeout_secs);
    let mut after = args.all.then_some(0);
    loop {
        let selector = match after {
            Some(a) => format!("{base};after={a}"),
            None => base.clone(),
        };
        let text = bus
            .ask(&args.cell, Service::History, &selector, None, timeout)
            .await
            .map_err(failure)?;
        if matches!(args.kind.as_deref(), Some("kpi" | "production")) {
            // Figures, not rows: printed as the agent computed them.
            let v: serde_json::Value = serde_json::from_str(&text).unwrap_or_default();
            writeln!(
                out,
                "{}",
                serde_json::to_string_pretty(&v).unwrap_or_default()
            )
            .map_err(io)?;
            return Ok(());
        }
        if args.json {
            writeln!(out, "{text}").map_err(io)?;
        }
        let page: serde_json::Value = serde_json::from_str(&text).unwrap_or_default();
        if !args.json {
            print_rows(out, &page["rows"])?;
        }
        match (after, page["next"].as_i64()) {
            (Some(_), Some(next)) => after = Some(next),
            (None, _) if page["more"] == true => {
                eprintln!("(older rows not shown: raise --limit, narrow --since, or use --all)");
                break;
            }
            _ => break,
        }
    }
    Ok(())
}

fn print_rows(out: &mut dyn Write, rows: &serde_json::Value) -> Result<(), Failure> {
    for r in rows.as_array().into_iter().flatten() {
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
            Some("recording") => {
                // The chart as the cell drew it: each line escaped.
                let chart = serde_json::from_value::<crate::payload::RecordingPayload>(
                    f["payload"].clone(),
                )
                .map(|p| p.recording.timeline(80))
                .unwrap_or_else(|e| format!("(a recording that does not read: {e})\n"));
                let head = format!("recording {}", f["alarm"].as_str().unwrap_or(""));
                writeln!(out, "{at}  {}", crate::operator::escaped(&head)).map_err(io)?;
                for l in chart.lines() {
                    writeln!(out, "    {}", crate::operator::escaped(l)).map_err(io)?;
                }
                continue;
            }
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
        // A newline in an operator's text never prints a line of its own.
        writeln!(out, "{at}  {}", crate::operator::escaped(&line)).map_err(io)?;
    }
    Ok(())
}

/// `cellwatch reset`, `unshelve` and `in-service`.
pub(crate) async fn command(
    action: Action,
    args: &CommandArgs,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    signed(
        Target {
            action,
            cell: &args.cell,
            alarm: &args.alarm,
            tag: None,
            value: None,
            reason: None,
        },
        &args.signer,
        out,
    )
    .await
}

/// `cellwatch ack`: a signed acknowledgement, with the operator's comment
/// if given.
pub(crate) async fn ack(args: &AckArgs, out: &mut dyn Write) -> Result<(), Failure> {
    signed(
        Target {
            action: Action::Ack,
            cell: &args.cell,
            alarm: &args.alarm,
            tag: None,
            value: None,
            reason: args.comment.as_deref(),
        },
        &args.signer,
        out,
    )
    .await
}

/// `cellwatch write`: a signed write of a tag's value to the PLC.
pub(crate) async fn write(args: &WriteArgs, out: &mut dyn Write) -> Result<(), Failure> {
    signed(
        Target {
            action: Action::Write,
            cell: &args.cell,
            alarm: "",
            tag: Some(&args.tag),
            value: Some(&args.value),
            reason: None,
        },
        &args.signer,
        out,
    )
    .await
}

/// `cellwatch shelve`: a signed shelf on an alarm, for a while or until
/// it clears.
pub(crate) async fn shelve(args: &ShelveArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let how = match (&args.duration, args.once) {
        (Some(d), false) => d.as_str(),
        (None, true) => "once",
        _ => return Err(Failure::Input("give --for DURATION or --once".into())),
    };
    signed(
        Target {
            action: Action::Shelve,
            cell: &args.cell,
            alarm: &args.alarm,
            tag: None,
            value: Some(how),
            reason: Some(&args.reason),
        },
        &args.signer,
        out,
    )
    .await
}

/// `cellwatch out-of-service`: a signed removal of an alarm from service.
pub(crate) async fn out_of_service(args: &ReasonArgs, out: &mut dyn Write) -> Result<(), Failure> {
    signed(
        Target {
            action: Action::OutOfService,
            cell: &args.cell,
            alarm: &args.alarm,
            tag: None,
            value: None,
            reason: Some(&args.reason),
        },
        &args.signer,
        out,
    )
    .await
}

/// `cellwatch force`: a signed forced transition.
pub(crate) async fn force(args: &ForceArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let transition = format!("{}.{}", args.chart, args.transition);
    signed(
        Target {
            action: Action::Force,
            cell: &args.cell,
            alarm: "",
            tag: None,
            value: Some(&transition),
            reason: None,
        },
        &args.signer,
        out,
    )
    .await
}

/// `cellwatch stop`: a signed press of a chart's stop switch.
pub(crate) async fn stop(args: &StopArgs, out: &mut dyn Write) -> Result<(), Failure> {
    signed(
        Target {
            action: Action::Stop,
            cell: &args.cell,
            alarm: "",
            tag: None,
            value: Some(&args.chart),
            reason: None,
        },
        &args.signer,
        out,
    )
    .await
}

/// `cellwatch reload`: a signed `configure reload`: the agent's
/// configuration file read again and taken live.
pub(crate) async fn reload(args: &ReloadArgs, out: &mut dyn Write) -> Result<(), Failure> {
    signed(
        Target {
            action: Action::Configure,
            cell: &args.cell,
            alarm: "",
            tag: None,
            value: Some("reload"),
            reason: None,
        },
        &args.signer,
        out,
    )
    .await
}

/// What a command acts on.
struct Target<'a> {
    action: Action,
    cell: &'a str,
    alarm: &'a str,
    tag: Option<&'a str>,
    value: Option<&'a str>,
    reason: Option<&'a str>,
}

/// Signs a command with the operator's key, sends it to the cell's agent
/// and prints its answer.
async fn signed(t: Target<'_>, args: &SignerArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let key = match (&args.key_file, std::env::var("CELLWATCH_OPERATOR_KEY")) {
        (Some(path), _) => {
            let text = std::fs::read_to_string(path)
                .map_err(|e| Failure::Input(format!("cannot read {}: {e}", path.display())))?;
            OperatorKey::parse(&path.display().to_string(), &text).map_err(Failure::input)?
        }
        (None, Ok(hex_key)) => {
            let operator = args.operator.as_deref().ok_or_else(|| {
                Failure::Input("with CELLWATCH_OPERATOR_KEY, give --operator".into())
            })?;
            OperatorKey::from_hex(operator, &hex_key)
                .map_err(|e| Failure::Input(format!("CELLWATCH_OPERATOR_KEY: {e}")))?
        }
        (None, Err(_)) => {
            return Err(Failure::Input(
                "give --key-file (made by `cellwatch keygen`) or set CELLWATCH_OPERATOR_KEY".into(),
            ))
        }
    };
    if let Some(op) = args.operator.as_deref().filter(|op| *op != key.operator) {
        return Err(Failure::Input(format!(
            "--operator {op}, but the key is {}'s",
            key.operator
        )));
    }
    let mut cmd = Command {
        action: t.action,
        alarm: t.alarm.to_string(),
        tag: t.tag.map(str::to_string),
        value: t.value.map(str::to_string),
        reason: t.reason.map(str::to_string),
        operator: key.operator.clone(),
        nonce: crate::operator::nonce(),
        issued_at: crate::clock::now_ms(),
        signature: String::new(),
    };
    cmd.check_text().map_err(Failure::input)?;
    cmd.sign(t.cell, &key);
    let bus = session(&args.zenoh).await?;
    let timeout = Duration::from_secs(args.zenoh.timeout_secs);
    let (accepted, detail) = send_signed(&bus, t.cell, &cmd, timeout).await?;
    if accepted {
        writeln!(out, "accepted: {detail}").map_err(io)?;
        Ok(())
    } else {
        Err(Failure::Runtime(format!("refused: {detail}")))
    }
}

/// Sends the signed command `cmd` to the agent of `cell` and returns
/// (accepted, detail): the answer believed only if `cell`'s agent sealed
/// it for this query. Any failure to get one is a runtime failure (the
/// command was well formed; the agent's error answer says why it was not
/// taken).
async fn send_signed(
    bus: &BusClient,
    cell: &str,
    cmd: &Command,
    timeout: Duration,
) -> Result<(bool, String), Failure> {
    bus.command(cell, cmd, timeout)
        .await
        .map_err(|e| Failure::Runtime(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::Latest;
    use crate::payload::AlarmPayload;

    #[test]
    fn an_event_older_than_the_newest_of_its_alarm_is_not_taken() {
        let at = |id: &str, at: &str| -> AlarmPayload {
            serde_json::from_value(serde_json::json!({
                "schema": "cellwatch.alarm.v1", "cell": "m01", "id": id,
                "kind": "switching", "severity": "critical", "state": "normal",
                "transition": "cleared", "at": at, "raised_at": at, "cleared_at": null,
                "acked_by": null, "fault_type": "ESE", "fault_step": 6, "culprits": [],
                "message": "ESE at step 6"
            }))
            .unwrap()
        };
        let mut l = Latest::default();
        assert!(l.newer(&at("ese", "2026-11-28T10:00:01.000Z")));
        assert!(!l.newer(&at("ese", "2026-11-28T10:00:00.000Z")), "a replay");
        assert!(
            l.newer(&at("ese", "2026-11-28T10:00:01.000Z")),
            "the same instant"
        );
        assert!(
            l.newer(&at("csd", "2026-11-28T09:00:00.000Z")),
            "another alarm"
        );
    }
}
