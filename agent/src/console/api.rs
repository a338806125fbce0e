//! The console's routes under `/api/`, each served to an identity the
//! door ([`super::http`]) let in, and only for the cells it may read: the
//! plant at once and live, the operator's own permissions, the alarm
//! figures, a cell's history and snapshot asked of its agent, and signed
//! commands forwarded.
//!
//! What a question costs the agents is bounded: the alarm figures and a
//! history page look back at most [`MAX_WINDOW`], the same figures asked
//! again within [`super::web::KPI_FRESH`] are answered from what was asked, and each
//! identity and each agent has its turns at history ([`super::gate`]).

use std::collections::BTreeMap;
use std::convert::Infallible;
use std::sync::Arc;
use std::time::Duration;

use axum::body::Bytes;
use axum::extract::{Path, Query, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::Response;
use axum::Extension;
use futures_util::Stream;
use tokio::sync::broadcast::error::RecvError;
use tokio::time::Instant;

use super::api_error::ApiError;
use super::web::{error, json, Web, Who};
use crate::bus::keys::Service;
use crate::client::ClientError;
use crate::operator::Command;

/// The largest command the console forwards (an agent's own limit).
const MAX_COMMAND_BYTES: usize = 4096;

/// How long the console waits for an agent's answer to the page.
const ANSWER: Duration = Duration::from_secs(10);

/// How far back a page may ask an agent's history or figures.
pub(super) const MAX_WINDOW: Duration = Duration::from_secs(31 * 86_400);

/// How often a live stream checks that its session is still open.
const SESSION_CHECK: Duration = Duration::from_secs(15);

/// Everything the identity may read at once (`type: snapshot`), as the
/// live stream starts.
pub(super) async fn plant(State(web): State<Arc<Web>>, Extension(who): Extension<Who>) -> Response {
    json(StatusCode::OK, web.shared.view(&who.identity.scope).0)
}

/// The live stream: everything the identity may read first, then each
/// change of its cells; a page that fell behind is sent everything again.
/// At most [`super::gate::STREAMS_EACH`] an identity; a stream ends when
/// its session does.
pub(super) async fn events(
    State(web): State<Arc<Web>>,
    Extension(who): Extension<Who>,
) -> Result<Sse<impl Stream<Item = Result<Event, Infallible>>>, Response> {
    let Some(guard) = web.gate.stream(&who.identity) else {
        return Err(error(
            StatusCode::TOO_MANY_REQUESTS,
            format!(
                "{} holds {} live streams already: close a page",
                who.identity.name,
                super::gate::STREAMS_EACH
            ),
        ));
    };
    let (first, changes) = web.shared.view(&who.identity.scope);
    let state = (Some(first), changes, web, who, guard);
    let stream =
        futures_util::stream::unfold(state, |(first, mut changes, web, who, guard)| async move {
            if let Some(first) = first {
                return Some((
                    Ok(Event::default().data(first)),
                    (None, changes, web, who, guard),
                ));
            }
            loop {
                let change = tokio::select! {
                    c = changes.recv() => c,
                    () = tokio::time::sleep(SESSION_CHECK) => {
                        if !still_open(&web, &who) {
                            return None;
                        }
                        continue;
                    }
                };
                match change {
                    Ok(change) if who.identity.scope.covers(&change.cell) => {
                        let event = Event::default().data(&change.json);
                        return Some((Ok(event), (None, changes, web, who, guard)));
                    }
                    Ok(_) => {}
                    Err(RecvError::Lagged(_)) => {
                        let (view, fresh) = web.shared.view(&who.identity.scope);
                        return Some((
                            Ok(Event::default().data(view)),
                            (None, fresh, web, who, guard),
                        ));
                    }
                    Err(RecvError::Closed) => return None,
                }
            }
        });
    Ok(Sse::new(stream).keep_alive(KeepAlive::new().interval(Duration::from_secs(15))))
}

/// Whether the session a stream was opened with is still open (a client
/// certificate's stream lasts as long as its connection).
fn still_open(web: &Web, who: &Who) -> bool {
    let Some(token) = &who.session else {
        return true;
    };
    web.gate
        .sessions
        .lock()
        .is_ok_and(|s| s.identity(Instant::now(), token).is_some())
}

/// The signed-in operator and what they may do (public key only):
/// `[{"operator", "public_key", "allow"}]`, empty for a certificate.
pub(super) async fn operators(
    State(web): State<Arc<Web>>,
    Extension(who): Extension<Who>,
) -> Response {
    let list: Vec<serde_json::Value> = web
        .shared
        .operators
        .iter()
        .filter(|(name, _, _)| {
            who.identity.by == super::access::Proof::OperatorKey && *name == who.identity.name
        })
        .map(|(name, key, allow)| {
            serde_json::json!({
                "operator": name,
                "public_key": key,
                "allow": allow.iter().map(|a| a.as_str()).collect::<Vec<_>>(),
            })
        })
        .collect();
    json(StatusCode::OK, serde_json::Value::from(list).to_string())
}

/// The response that says `cell` is not the identity's to read, if it is
/// not (or not in the trust file).
fn not_readable(web: &Web, who: &Who, cell: &str) -> Option<Response> {
    let known = web
        .shared
        .plant
        .lock()
        .map(|p| p.cell(cell).is_some())
        .unwrap_or(false);
    if !known {
        return Some(error(
            StatusCode::NOT_FOUND,
            format!(
                "no cell '{}' in the plant trust file",
                crate::operator::escaped(cell)
            ),
        ));
    }
    (!who.identity.scope.covers(cell)).then(|| {
        error(
            StatusCode::FORBIDDEN,
            format!(
                "{} may not read cell '{cell}' ([readers])",
                who.identity.name
            ),
        )
    })
}

fn answered(result: Result<String, ClientError>) -> Response {
    match result {
        Ok(text) => json(StatusCode::OK, text),
        Err(ClientError::Answered(why)) => error(StatusCode::BAD_REQUEST, why),
        Err(e) => error(StatusCode::BAD_GATEWAY, e),
    }
}

/// The history parameters the page may give, each passed on only if it
/// holds nothing but letters, digits and `:.+-_`.
const HISTORY_PARAMETERS: [&str; 5] = ["since", "until", "kind", "limit", "after"];

/// The query parameters checked: only `allowed`, each plain, `since`
/// given and at most [`MAX_WINDOW`] back; returned as `name=value`.
fn window(q: &BTreeMap<String, String>, allowed: &[&str]) -> Result<Vec<String>, Box<Response>> {
    let mut parameters = Vec::new();
    for (name, value) in q {
        if !allowed.contains(&name.as_str()) {
            return Err(Box::new(error(
                StatusCode::BAD_REQUEST,
                format!("unknown parameter '{name}': use {}", allowed.join(", ")),
            )));
        }
        plain_value(name, value).map_err(|why| Box::new(error(StatusCode::BAD_REQUEST, why)))?;
        parameters.push(format!("{name}={value}"));
    }
    let now = crate::clock::now_ms();
    let since = q.get("since").ok_or_else(|| {
        Box::new(error(
            StatusCode::BAD_REQUEST,
            "since: missing (a time, or a duration back from now such as 24h)",
        ))
    })?;
    let from = crate::clock::parse_time(since, now)
        .map_err(|why| Box::new(error(StatusCode::BAD_REQUEST, format!("since: {why}"))))?;
    if now.saturating_sub(from) > MAX_WINDOW.as_millis() as u64 {
        return Err(Box::new(error(
            StatusCode::BAD_REQUEST,
            format!(
                "since: '{since}' is more than {} days back: ask the agent with `cellwatch history` for older rows",
                MAX_WINDOW.as_secs() / 86_400
            ),
        )));
    }
    Ok(parameters)
}

/// The cell's journal, asked of its agent (`since`, `until`, `kind`,
/// `limit`, `after` as `cellwatch history` takes them), in the identity's
/// and the agent's turn.
pub(super) async fn history(
    State(web): State<Arc<Web>>,
    Extension(who): Extension<Who>,
    Path(cell): Path<String>,
    Query(q): Query<BTreeMap<String, String>>,
) -> Response {
    if let Some(r) = not_readable(&web, &who, &cell) {
        return r;
    }
    let parameters = match window(&q, &HISTORY_PARAMETERS) {
        Ok(p) => p,
        Err(r) => return *r,
    };
    let Some(_turn) = web
        .gate
        .history_turn(&who.identity, &cell, super::gate::TURN)
        .await
    else {
        return error(
            StatusCode::SERVICE_UNAVAILABLE,
            format!("cell {cell}'s history is busy: ask again in a moment"),
        );
    };
    // An agent without its liveliness token is not asked: its rows come
    // from the plant archive at once.
    let up = web
        .shared
        .plant
        .lock()
        .map(|p| p.view().cells.iter().any(|c| c.cell == cell && c.agent))
        .unwrap_or(true);
    if up {
        match web
            .shared
            .bus
            .ask(&cell, Service::History, &parameters.join(";"), None, ANSWER)
            .await
        {
            Err(ClientError::NoAnswer { .. }) => {}
            answer => return answered(answer),
        }
    }
    from_archive(&web, &cell, &q).await
}

/// A cell's history from the plant archive the routers keep (alarm events,
/// machine states, recordings), for an agent that does not answer; the
/// page says so (`"from": "archive"`). Commands are not archived: asked
/// for, the agent's silence is the answer.
async fn from_archive(web: &Web, cell: &str, q: &BTreeMap<String, String>) -> Response {
    use crate::archive::read::{self, Kept, Range};
    let silent = || {
        error(
            StatusCode::BAD_GATEWAY,
            format!("the agent of cell {cell} did not answer history"),
        )
    };
    let kinds: &[Kept] = match q.get("kind").map(String::as_str) {
        None => &[Kept::Alarm, Kept::State],
        Some("alarm") => &[Kept::Alarm],
        Some("state") => &[Kept::State],
        Some("recording") => &[Kept::Recording],
        Some(_) => return silent(),
    };
    let since = q.get("since").map_or("24h", String::as_str);
    let Ok(range) = Range::new(since, q.get("until").map(String::as_str)) else {
        return silent();
    };
    let limit = q
        .get("limit")
        .and_then(|l| l.parse().ok())
        .unwrap_or(crate::journal::DEFAULT_ROWS)
        .min(crate::journal::MAX_ROWS);
    match read::read(&web.shared.bus, cell, kinds, &range, ANSWER).await {
        Ok(reading) if !reading.entries.is_empty() => {
            for (key, why) in &reading.refused {
                tracing::warn!(cell, key, "console: an archived entry not believed: {why}");
            }
            json(
                StatusCode::OK,
                read::as_history_page(&reading, limit).to_string(),
            )
        }
        _ => silent(),
    }
}

/// How many agents are asked what they are at once.
const ABOUT_AT_ONCE: usize = 16;

/// Every agent the identity may read, what it says it is (its signed
/// `about`) judged against what the plant deployed to it (`plant.deployed`)
/// as `cellwatch plant check` judges it: `{"deployed": {"file", "error"} or
/// null, "cells": [{"cell", "area", "about" (or null), "facts",
/// "problems"}]}`. The same question is answered from what was asked for
/// [`super::web::KPI_FRESH`].
pub(super) async fn agents(
    State(web): State<Arc<Web>>,
    Extension(who): Extension<Who>,
) -> Response {
    use futures_util::StreamExt;
    let cells: Vec<(String, Option<String>, bool)> = web
        .shared
        .plant
        .lock()
        .map(|p| {
            p.view()
                .cells
                .iter()
                .filter(|c| who.identity.scope.covers(&c.cell))
                .map(|c| (c.cell.clone(), c.area.clone(), c.agent))
                .collect()
        })
        .unwrap_or_default();
    // The file read each time (it is small): one written anew is judged
    // against at once, not after the cache's while.
    let read = web
        .shared
        .deployed
        .as_deref()
        .map(|path| (path, read_deployed(path)));
    let key = format!(
        "agents|{}|{}",
        read.as_ref()
            .map_or(String::new(), |(_, d)| format!("{d:?}")),
        cells
            .iter()
            .map(|(c, _, up)| format!("{c}:{up}"))
            .collect::<Vec<_>>()
            .join(",")
    );
    if let Some(answer) = web
        .kpi
        .lock()
        .ok()
        .and_then(|k| k.get(&key, Instant::now()))
    {
        return json(StatusCode::OK, answer);
    }
    let (deployed, said) = match read {
        None => (None, serde_json::Value::Null),
        Some((path, read)) => match read {
            Ok(d) => (
                Some(d),
                serde_json::json!({ "file": path.display().to_string(), "error": null }),
            ),
            Err(e) => (
                None,
                serde_json::json!({ "file": path.display().to_string(), "error": e.to_string() }),
            ),
        },
    };
    let deployed = Arc::new(deployed);
    let answers: Vec<serde_json::Value> = futures_util::stream::iter(cells)
        .map(|(cell, area, up)| {
            let (web, deployed) = (web.clone(), deployed.clone());
            async move {
                let said = |problem: String| {
                    serde_json::json!({ "cell": cell, "area": area, "about": null, "facts": [], "problems": [problem] })
                };
                if !up {
                    return said("its agent is not on the bus".into());
                }
                let about = web
                    .shared
                    .bus
                    .ask(&cell, Service::About, "", None, ANSWER)
                    .await
                    .map_err(ApiError::NoAbout)
                    .and_then(|t| {
                        serde_json::from_str::<crate::payload::AboutPayload>(&t)
                            .map_err(ApiError::AboutUnreadable)
                    });
                match about {
                    Err(problem) => said(problem.to_string()),
                    Ok(about) => {
                        let plant = deployed.as_ref().as_ref();
                        let j = crate::plant::judge::judge(
                            &cell,
                            &about,
                            plant.and_then(|p| p.cells.get(&cell)),
                            plant.and_then(|p| p.operators_version),
                            crate::clock::now_ms(),
                        );
                        serde_json::json!({ "cell": cell, "area": area, "about": about, "facts": j.facts, "problems": j.problems })
                    }
                }
            }
        })
        .buffered(ABOUT_AT_ONCE)
        .collect()
        .await;
    let answer = serde_json::json!({ "deployed": said, "cells": answers }).to_string();
    if let Ok(mut k) = web.kpi.lock() {
        k.put(key, Instant::now(), answer.clone());
    }
    json(StatusCode::OK, answer)
}

/// The file of what the plant deployed, read whole (at most
/// [`crate::plant::judge::MAX_DEPLOYED_BYTES`]).
fn read_deployed(path: &std::path::Path) -> Result<crate::plant::judge::DeployedPlant, ApiError> {
    use crate::plant::judge::{DEPLOYED_SCHEMA, MAX_DEPLOYED_BYTES};
    use std::io::Read;
    let mut text = String::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(MAX_DEPLOYED_BYTES + 1).read_to_string(&mut text))
        .map_err(|source| ApiError::DeployedRead {
            path: path.into(),
            source,
        })?;
    if text.len() as u64 > MAX_DEPLOYED_BYTES {
        return Err(ApiError::DeployedTooLarge {
            path: path.into(),
            max: MAX_DEPLOYED_BYTES,
        });
    }
    let plant: crate::plant::judge::DeployedPlant =
        serde_json::from_str(&text).map_err(|source| ApiError::DeployedJson {
            path: path.into(),
            source,
        })?;
    if plant.schema != DEPLOYED_SCHEMA {
        return Err(ApiError::DeployedSchema {
            path: path.into(),
            schema: crate::operator::escaped(&plant.schema).into_owned(),
            expected: DEPLOYED_SCHEMA,
        });
    }
    Ok(plant)
}

/// How many agents are asked for their figures at once.
const KPI_AT_ONCE: usize = 16;

/// The ISA-18.2 alarm figures of every cell the identity may read whose
/// agent is up, for `since` and `until` (as `history` takes them), each
/// asked of the cell's agent (`history?kind=kpi`): `{"cells": [{"cell",
/// "area", "report"} or {"cell", "area", "error"}]}`.
pub(super) async fn kpi(
    State(web): State<Arc<Web>>,
    Extension(who): Extension<Who>,
    Query(q): Query<BTreeMap<String, String>>,
) -> Response {
    use futures_util::StreamExt;
    let mut parameters = match window(&q, &["since", "until"]) {
        Ok(p) => p,
        Err(r) => return *r,
    };
    parameters.insert(0, "kind=kpi".to_string());
    let parameters = parameters.join(";");
    let cells: Vec<(String, Option<String>)> = web
        .shared
        .plant
        .lock()
        .map(|p| {
            p.view()
                .cells
                .iter()
                .filter(|c| c.agent && who.identity.scope.covers(&c.cell))
                .map(|c| (c.cell.clone(), c.area.clone()))
                .collect()
        })
        .unwrap_or_default();
    let key = format!(
        "{parameters}|{}",
        cells
            .iter()
            .map(|(c, _)| c.as_str())
            .collect::<Vec<_>>()
            .join(",")
    );
    if let Some(answer) = web
        .kpi
        .lock()
        .ok()
        .and_then(|k| k.get(&key, Instant::now()))
    {
        return json(StatusCode::OK, answer);
    }
    let answers: Vec<serde_json::Value> = futures_util::stream::iter(cells)
        .map(|(cell, area)| {
            let web = web.clone();
            let parameters = parameters.clone();
            async move {
                match web
                    .shared
                    .bus
                    .ask(&cell, Service::History, &parameters, None, ANSWER)
                    .await
                    .map_err(ApiError::from)
                    .and_then(|t| {
                        serde_json::from_str::<serde_json::Value>(&t).map_err(ApiError::from)
                    }) {
                    Ok(report) => {
                        serde_json::json!({ "cell": cell, "area": area, "report": report })
                    }
                    Err(e) => {
                        serde_json::json!({ "cell": cell, "area": area, "error": e.to_string() })
                    }
                }
            }
        })
        .buffered(KPI_AT_ONCE)
        .collect()
        .await;
    let answer = serde_json::json!({ "cells": answers }).to_string();
    if let Ok(mut k) = web.kpi.lock() {
        k.put(key, Instant::now(), answer.clone());
    }
    json(StatusCode::OK, answer)
}

/// Whether a query parameter's value holds nothing but letters, digits and
/// `:.+-_` (at most 64 of them): what times, durations, kinds and numbers
/// need, and nothing that could end a Zenoh parameter.
fn plain_value(name: &str, value: &str) -> Result<(), ApiError> {
    let plain = value
        .bytes()
        .all(|b| b.is_ascii_alphanumeric() || b":.+-_".contains(&b));
    if value.is_empty() || value.len() > 64 || !plain {
        return Err(ApiError::NotPlain {
            name: name.into(),
            value: crate::operator::escaped(value).into_owned(),
        });
    }
    Ok(())
}

/// The cell's values, alarms and values at its last fault, asked of its
/// agent.
pub(super) async fn snapshot(
    State(web): State<Arc<Web>>,
    Extension(who): Extension<Who>,
    Path(cell): Path<String>,
) -> Response {
    if let Some(r) = not_readable(&web, &who, &cell) {
        return r;
    }
    answered(
        web.shared
            .bus
            .ask(&cell, Service::Snapshot, "", None, ANSWER)
            .await,
    )
}

/// Forwards an operator's command, signed in the browser, to the cell's
/// agent, and returns its answer (`accepted`, `detail`). An operator
/// signed in with their key forwards only their own commands. The console
/// checks only that it is a command: the agent checks the signature, the
/// operator's permission, the time and the nonce, and journals it.
pub(super) async fn command(
    State(web): State<Arc<Web>>,
    Extension(who): Extension<Who>,
    Path(cell): Path<String>,
    headers: HeaderMap,
    body: Bytes,
) -> Response {
    if let Some(r) = not_readable(&web, &who, &cell) {
        return r;
    }
    // A form from another site cannot send JSON without asking first.
    let is_json = headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.starts_with("application/json"));
    if !is_json {
        return error(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "a command is sent as application/json",
        );
    }
    if body.len() > MAX_COMMAND_BYTES {
        return error(
            StatusCode::PAYLOAD_TOO_LARGE,
            format!("a command is at most {MAX_COMMAND_BYTES} bytes"),
        );
    }
    let cmd: Command = match serde_json::from_slice(&body) {
        Ok(c) => c,
        Err(e) => return error(StatusCode::BAD_REQUEST, format!("not a command: {e}")),
    };
    if who.identity.by == super::access::Proof::OperatorKey && cmd.operator != who.identity.name {
        return error(
            StatusCode::FORBIDDEN,
            format!(
                "signed in as {}: a command of operator '{}' is not forwarded",
                who.identity.name,
                crate::operator::escaped(&cmd.operator)
            ),
        );
    }
    tracing::info!(
        cell,
        identity = %who.identity.name,
        operator = %crate::operator::escaped(&cmd.operator),
        action = %cmd.action,
        alarm = %crate::operator::escaped(&cmd.alarm),
        "console: forwarding a signed command"
    );
    match web.shared.bus.command(&cell, &cmd, ANSWER).await {
        Ok((accepted, detail)) => json(
            StatusCode::OK,
            serde_json::json!({ "accepted": accepted, "detail": detail }).to_string(),
        ),
        Err(e @ (ClientError::Answered(_) | ClientError::NotAnOutcome(_))) => json(
            StatusCode::OK,
            serde_json::json!({ "accepted": false, "detail": e.to_string() }).to_string(),
        ),
        Err(e) => error(StatusCode::BAD_GATEWAY, e),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn asked(pairs: &[(&str, &str)]) -> BTreeMap<String, String> {
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect()
    }

    #[test]
    fn a_window_is_at_most_a_month_back_and_plain() {
        assert!(window(
            &asked(&[("since", "7d"), ("kind", "alarm")]),
            &HISTORY_PARAMETERS
        )
        .is_ok());
        for bad in [
            asked(&[("since", "1970-01-01T00:00:00Z")]),
            asked(&[("since", "400d")]),
            asked(&[("kind", "alarm")]),
            asked(&[("since", "1h"), ("kind", "alarm;x=y")]),
            asked(&[("since", "1h"), ("other", "1")]),
        ] {
            let r = window(&bad, &HISTORY_PARAMETERS).unwrap_err();
            assert_eq!(r.status(), StatusCode::BAD_REQUEST, "{bad:?}");
        }
    }
}
