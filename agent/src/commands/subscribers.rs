//! `cellwatch alarms`, `history`, `ack` and `reset`: clients that talk to
//! agents over Zenoh only.

use std::io::Write;
use std::time::Duration;

use zenoh_ext::{AdvancedSubscriberBuilderExt, HistoryConfig, RecoveryConfig};

use crate::cli::{
    AlarmsArgs, CommandArgs, Failure, ForceArgs, HistoryArgs, ReasonArgs, ShelveArgs, SignerArgs,
    StopArgs, WriteArgs, ZenohArgs,
};
use crate::config::{ZenohConfig, ZenohMode};
use crate::operator::{Action, Command, OperatorKey};
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
    let tls = z.tls_ca.as_ref().map(|ca| crate::config::ZenohTls {
        ca: ca.clone(),
        cert: z.tls_cert.clone().unwrap_or_default(),
        key: z.tls_key.clone().unwrap_or_default(),
    });
    let connect = if !z.connect.is_empty() {
        z.connect.clone()
    } else if z.zenoh_config.is_some() {
        Vec::new()
    } else if tls.is_some() {
        vec!["tls/127.0.0.1:7447".into()]
    } else {
        vec!["tcp/127.0.0.1:7447".into()]
    };
    let cfg = ZenohConfig {
        mode,
        connect,
        listen: Vec::new(),
        prefix: String::new(),
        multicast_scouting: false,
        tls,
        config_file: z.zenoh_config.clone(),
    };
    crate::sinks::zenoh::open(&cfg)
        .await
        .map_err(Failure::runtime)
}

/// The Zenoh id of each cell's agent matching `cell` (a name or `*`), from
/// their liveliness tokens (`<root>/<cell>/agent/<zid>`). A cell claimed by
/// two sessions is an error: neither is trusted.
async fn agents(
    s: &zenoh::Session,
    root: &str,
    cell: &str,
    timeout: Duration,
) -> Result<std::collections::BTreeMap<String, String>, Failure> {
    let key = format!("{root}/{cell}/agent/*");
    let replies = s
        .liveliness()
        .get(key.as_str())
        .timeout(timeout)
        .await
        .map_err(|e| Failure::Runtime(format!("liveliness query failed: {e}")))?;
    let mut claims: std::collections::BTreeMap<String, Vec<String>> = Default::default();
    while let Ok(reply) = replies.recv_async().await {
        let Ok(sample) = reply.result() else { continue };
        let chunks: Vec<&str> = sample.key_expr().as_str().rsplitn(3, '/').collect();
        if let [zid, "agent", rest] = chunks[..] {
            let cell = rest.rsplit('/').next().unwrap_or_default().to_string();
            claims.entry(cell).or_default().push(zid.to_string());
        }
    }
    let mut out = std::collections::BTreeMap::new();
    for (c, mut zids) in claims {
        zids.sort();
        zids.dedup();
        if zids.len() > 1 {
            return Err(Failure::Runtime(format!(
                "{} Zenoh sessions claim to be the agent of cell {c} ({}): trusting none",
                zids.len(),
                zids.join(", ")
            )));
        }
        out.insert(c, zids.remove(0));
    }
    if out.is_empty() {
        return Err(Failure::Runtime(format!(
            "no agent is alive on {key} (is one running, and is --connect right?)"
        )));
    }
    Ok(out)
}

/// The agent of one cell.
async fn agent(
    s: &zenoh::Session,
    root: &str,
    cell: &str,
    timeout: Duration,
) -> Result<String, Failure> {
    let found = agents(s, root, cell, timeout).await?;
    found
        .get(cell)
        .cloned()
        .ok_or_else(|| Failure::Runtime(format!("no agent of cell {cell} is alive on the bus")))
}

/// Who answered `reply`.
fn replier(reply: &zenoh::query::Reply) -> String {
    reply
        .replier_id()
        .map_or_else(|| "an unknown node".into(), |id| id.zid().to_string())
}

/// What came back to one query.
enum Answer {
    /// The agent's answer: its text, or its error (an error answer from
    /// the agent is [`Failure::Input`]).
    Agent(Result<String, Failure>),
    /// Nothing from the agent; answers from these other sessions were not
    /// believed.
    Nothing(Vec<String>),
}

/// The agent's answer among `replies`; answers from any other session are
/// not believed (and named in the error when the agent said nothing).
async fn answer_of(
    replies: zenoh::handlers::FifoChannelHandler<zenoh::query::Reply>,
    agent: &str,
    what: &str,
) -> Answer {
    let mut others = Vec::new();
    while let Ok(reply) = replies.recv_async().await {
        let from = replier(&reply);
        if from != agent {
            tracing::error!(from = %from, agent, what, "an answer from a session that is not the agent: ignored");
            others.push(from);
            continue;
        }
        return Answer::Agent(match reply.result() {
            Ok(sample) => Ok(text(sample.payload())),
            Err(e) => Err(Failure::Input(format!("{what}: {}", text(e.payload())))),
        });
    }
    Answer::Nothing(others)
}

impl Answer {
    fn into_result(self, agent: &str, what: &str) -> Result<String, Failure> {
        match self {
            Answer::Agent(answer) => answer,
            Answer::Nothing(others) if others.is_empty() => Err(Failure::Runtime(format!(
                "the agent ({agent}) did not answer {what}"
            ))),
            Answer::Nothing(others) => Err(Failure::Runtime(format!(
                "the agent ({agent}) did not answer {what}; answers from {} are not the agent's and were ignored",
                others.join(", ")
            ))),
        }
    }
}

fn text(payload: &zenoh::bytes::ZBytes) -> String {
    payload
        .try_to_string()
        .map(|s| s.into_owned())
        .unwrap_or_default()
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
    // Kept from operators: said first, so that no one takes it for an
    // alarm to act on.
    let mut kept = String::new();
    if let Some(s) = &a.shelved {
        let until = s.until.as_deref().unwrap_or("it clears");
        kept += &format!("SHELVED until {until} by {} ({})  ", s.by, s.reason);
    }
    if let Some(r) = &a.out_of_service {
        kept += &format!("OUT OF SERVICE since {} by {} ({})  ", r.at, r.by, r.reason);
    }
    // Operators' and the journal's text on one line each: a newline in a
    // reason never prints a line of its own.
    let line = format!(
        "{}  {}/{}  {kept}{} {} [{}] {}{step}: {}",
        a.at, a.cell, a.id, a.transition, a.state, a.severity, a.fault_type, a.message
    );
    writeln!(out, "{}", crate::operator::escaped(&line))?;
    for c in &a.culprits {
        writeln!(out, "    {}", crate::operator::escaped(&c.line()))?;
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
        // The journal's recent events first (a subscriber joining after the
        // agent restarted gets them too); what the subscription then
        // delivers again is not printed twice.
        let mut printed = std::collections::HashSet::new();
        if let Some(since) = &args.since {
            let Some(cell) = &args.cell else {
                return Err(Failure::Input(
                    "--since needs --cell: the journal is read from one agent".into(),
                ));
            };
            let base = format!("{root}/{cell}/history?kind=alarm;since={since};limit=1000");
            let timeout = Duration::from_secs(args.zenoh.timeout_secs);
            let the_agent = agent(&s, root, cell, timeout).await?;
            let mut after = 0;
            loop {
                let text =
                    history_page(&s, &format!("{base};after={after}"), timeout, &the_agent).await?;
                let page: serde_json::Value = serde_json::from_str(&text).unwrap_or_default();
                for r in page["rows"].as_array().into_iter().flatten() {
                    if let Ok(a) =
                        serde_json::from_value::<AlarmPayload>(r["fields"]["payload"].clone())
                    {
                        printed.insert((a.id.clone(), a.at.clone(), a.transition));
                        print_alarm(out, &a, args.json).map_err(io)?;
                    }
                }
                match page["next"].as_i64() {
                    Some(next) => after = next,
                    None => break,
                }
            }
            out.flush().map_err(io)?;
        }
        // Each cell's agent, as its liveliness token names it; looked up
        // again when an event comes from another session (an agent that
        // restarted has a new one).
        let timeout = Duration::from_secs(args.zenoh.timeout_secs);
        let mut known = agents(&s, root, cell, timeout).await.unwrap_or_default();
        loop {
            tokio::select! {
                _ = tokio::signal::ctrl_c() => break,
                sample = sub.recv_async() => {
                    let Ok(sample) = sample else { break };
                    let text = text(sample.payload());
                    let a = match serde_json::from_str::<AlarmPayload>(&text) {
                        Ok(a) => a,
                        Err(e) => {
                            tracing::warn!(key = %sample.key_expr(), error = %e, "not an alarm payload");
                            continue;
                        }
                    };
                    let from = sample
                        .source_info()
                        .map(|i| i.source_id().zid().to_string());
                    if from.is_none() || known.get(&a.cell) != from.as_ref() {
                        if let Ok(found) = agents(&s, root, &a.cell, timeout).await {
                            known.extend(found);
                        }
                    }
                    if from.is_none() || known.get(&a.cell) != from.as_ref() {
                        tracing::error!(cell = %a.cell, from = ?from, "an alarm event from a session that is not the cell's agent: ignored");
                        continue;
                    }
                    if !printed.remove(&(a.id.clone(), a.at.clone(), a.transition)) {
                        print_alarm(out, &a, args.json).map_err(io)?;
                    }
                    out.flush().map_err(io)?;
                }
            }
        }
        return Ok(());
    }
    let timeout = Duration::from_secs(args.zenoh.timeout_secs);
    let trusted = agents(&s, root, cell, timeout).await?;
    let replies = s
        .get(format!("{root}/{cell}/snapshot"))
        .consolidation(zenoh::query::ConsolidationMode::None)
        .timeout(timeout)
        .await
        .map_err(|e| Failure::Runtime(format!("query failed: {e}")))?;
    let mut answered = 0;
    while let Ok(reply) = replies.recv_async().await {
        let from = replier(&reply);
        let Ok(sample) = reply.result() else { continue };
        let text = text(sample.payload());
        let v: serde_json::Value = serde_json::from_str(&text).unwrap_or_default();
        // The cell it speaks for, believed only from that cell's agent.
        let of_cell = v["cell"].as_str().unwrap_or_default();
        if trusted.get(of_cell) != Some(&from) {
            tracing::error!(cell = of_cell, from = %from, "a snapshot from a session that is not the cell's agent: ignored");
            continue;
        }
        answered += 1;
        for a in v["alarms"].as_array().into_iter().flatten() {
            if let Ok(a) = serde_json::from_value::<AlarmPayload>(a.clone()) {
                print_alarm(out, &a, args.json).map_err(io)?;
            }
        }
    }
    if answered == 0 {
        return Err(Failure::Runtime(format!(
            "no agent answered on {root}/{cell}/snapshot (is one running, and is --connect right?)"
        )));
    }
    Ok(())
}

/// Asks `selector` for one history page, believing `agent` only.
async fn history_page(
    s: &zenoh::Session,
    selector: &str,
    timeout: Duration,
    agent: &str,
) -> Result<String, Failure> {
    ask_agent(s, selector, None, timeout, agent).await
}

/// Asks `selector` (`key?parameters`) with `payload` and returns the
/// agent's answer ([`answer_of`]). A session just opened may not yet know
/// the agent's queryables (only its liveliness token): the query waits, up
/// to `timeout`, until a queryable for the key is known.
async fn ask_agent(
    s: &zenoh::Session,
    selector: &str,
    payload: Option<String>,
    timeout: Duration,
    agent: &str,
) -> Result<String, Failure> {
    let (key, parameters) = selector.split_once('?').unwrap_or((selector, ""));
    let failed = |e: zenoh::Error| Failure::Runtime(format!("query failed: {e}"));
    let querier = s
        .declare_querier(key.to_string())
        .consolidation(zenoh::query::ConsolidationMode::None)
        .timeout(timeout)
        .await
        .map_err(failed)?;
    let listener = querier.matching_listener().await.map_err(failed)?;
    let known = querier
        .matching_status()
        .await
        .map(|m| m.matching())
        .unwrap_or(false);
    if !known {
        let deadline = tokio::time::Instant::now() + timeout;
        while let Ok(Ok(status)) = tokio::time::timeout_at(deadline, listener.recv_async()).await {
            if status.matching() {
                break;
            }
        }
    }
    // A read that ends with no answer at all before its time is up (the
    // routes to the agent's queryable still being set up) is asked again;
    // a command is sent once (the agent would refuse its replay).
    let deadline = tokio::time::Instant::now() + timeout;
    let read_only = payload.is_none();
    loop {
        let mut get = querier.get().parameters(parameters);
        if let Some(p) = &payload {
            get = get.payload(p.clone());
        }
        let replies = get.await.map_err(failed)?;
        let answer = answer_of(replies, agent, selector).await;
        if read_only
            && matches!(&answer, Answer::Nothing(others) if others.is_empty())
            && tokio::time::Instant::now() + RETRY_AFTER < deadline
        {
            tracing::debug!(selector, "no answer yet: asking again");
            tokio::time::sleep(RETRY_AFTER).await;
            continue;
        }
        return answer.into_result(agent, selector);
    }
}

/// The pause before a read that got no answer is asked again.
const RETRY_AFTER: Duration = Duration::from_millis(250);

/// `cellwatch history`: the newest rows, or with `--all` every row of the
/// range, fetched in bounded pages.
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
    let base = format!(
        "{}/{}/history?{}",
        args.zenoh.root,
        args.cell,
        params.join(";")
    );
    let timeout = Duration::from_secs(args.zenoh.timeout_secs);
    let the_agent = agent(&s, &args.zenoh.root, &args.cell, timeout).await?;
    let mut after = args.all.then_some(0);
    loop {
        let selector = match after {
            Some(a) => format!("{base};after={a}"),
            None => base.clone(),
        };
        let text = history_page(&s, &selector, timeout, &the_agent).await?;
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

/// `cellwatch ack` and `cellwatch reset`.
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

/// How long `cellwatch force` waits for the agent's answer at least: the
/// agent answers when the chart has arrived or its `force_timeout` (at
/// most a minute) has passed.
pub(crate) const FORCE_ANSWER: Duration = Duration::from_secs(75);

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
            OperatorKey::parse(&path.display().to_string(), &text).map_err(Failure::Input)?
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
    let s = session(&args.zenoh).await?;
    let timeout = Duration::from_secs(args.zenoh.timeout_secs);
    let (accepted, detail) = send_signed(&s, &args.zenoh.root, t.cell, &cmd, timeout).await?;
    if accepted {
        writeln!(out, "accepted: {detail}").map_err(io)?;
        Ok(())
    } else {
        Err(Failure::Runtime(format!("refused: {detail}")))
    }
}

/// Sends the signed command `cmd` to the agent of `cell` (found by its
/// liveliness token within `timeout`; a force waits at least
/// [`FORCE_ANSWER`] for its answer) and returns (accepted, detail).
pub(crate) async fn send_signed(
    s: &zenoh::Session,
    root: &str,
    cell: &str,
    cmd: &Command,
    timeout: Duration,
) -> Result<(bool, String), Failure> {
    let the_agent = agent(s, root, cell, timeout).await?;
    let timeout = if cmd.action == Action::Force {
        timeout.max(FORCE_ANSWER)
    } else {
        timeout
    };
    let selector = format!("{root}/{cell}/command");
    let text = ask_agent(
        s,
        &selector,
        Some(serde_json::to_string(cmd).unwrap_or_default()),
        timeout,
        &the_agent,
    )
    .await
    .map_err(|e| match e {
        Failure::Input(why) => Failure::Runtime(why),
        other => other,
    })?;
    let v: serde_json::Value = serde_json::from_str(&text).unwrap_or_default();
    Ok((
        v["accepted"].as_bool() == Some(true),
        v["detail"].as_str().unwrap_or("").to_string(),
    ))
}
