//! The console's HTTP(S) side: the page and its assets (embedded in the
//! binary), the live stream of changes, the agents' history and snapshots
//! asked on the page's behalf, and operators' signed commands forwarded.
//!
//! Every response carries a strict Content-Security-Policy (scripts and
//! styles from the console only, no inline script, Trusted Types required:
//! the page cannot turn a text from the bus into HTML), no framing, no
//! referrer, no sniffing.

use std::convert::Infallible;
use std::sync::Arc;
use std::time::Duration;

use axum::body::Bytes;
use axum::extract::{Path, Query, State};
use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::Router;
use futures_util::Stream;
use tokio::sync::broadcast::error::RecvError;

use super::config::HttpTls;
use super::shared::{ConsoleError, Shared};
use crate::bus::keys::Service;
use crate::client::ClientError;
use crate::operator::Command;

const INDEX: &str = include_str!("assets/index.html");
const SCRIPT: &str = include_str!("assets/console.js");
const STYLE: &str = include_str!("assets/console.css");

/// What every response says of itself.
const CSP: &str = "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self'; \
     connect-src 'self'; form-action 'none'; frame-ancestors 'none'; base-uri 'none'; \
     require-trusted-types-for 'script'; trusted-types 'none'";

/// The largest command the console forwards (an agent's own limit).
const MAX_COMMAND_BYTES: usize = 4096;

/// How long the console waits for an agent's answer to the page.
const ANSWER: Duration = Duration::from_secs(10);

/// At most this many connections are served at once.
const MAX_CONNECTIONS: usize = 512;

/// The TLS acceptor of the console's certificate and key (PEM).
pub(super) fn tls_acceptor(t: &HttpTls) -> Result<tokio_rustls::TlsAcceptor, ConsoleError> {
    use tokio_rustls::rustls;
    use tokio_rustls::rustls::pki_types::pem::PemObject;
    use tokio_rustls::rustls::pki_types::{CertificateDer, PrivateKeyDer};
    let bad = |what: &std::path::Path, e: String| {
        ConsoleError::Input(format!("http.tls: {}: {e}", what.display()))
    };
    let certs: Vec<CertificateDer<'static>> = CertificateDer::pem_file_iter(&t.cert)
        .and_then(Iterator::collect)
        .map_err(|e| bad(&t.cert, e.to_string()))?;
    if certs.is_empty() {
        return Err(bad(&t.cert, "no certificate in the file".into()));
    }
    let key = PrivateKeyDer::from_pem_file(&t.key).map_err(|e| bad(&t.key, e.to_string()))?;
    let config = rustls::ServerConfig::builder_with_provider(Arc::new(
        rustls::crypto::ring::default_provider(),
    ))
    .with_safe_default_protocol_versions()
    .map_err(|e| ConsoleError::Input(format!("http.tls: {e}")))?
    .with_no_client_auth()
    .with_single_cert(certs, key)
    .map_err(|e| bad(&t.cert, e.to_string()))?;
    Ok(tokio_rustls::TlsAcceptor::from(Arc::new(config)))
}

/// Serves until `stopped` says so.
pub(super) async fn serve(
    listener: tokio::net::TcpListener,
    tls: Option<tokio_rustls::TlsAcceptor>,
    shared: Arc<Shared>,
    mut stopped: tokio::sync::watch::Receiver<bool>,
) {
    let https = tls.is_some();
    let app = router(shared, https);
    let slots = Arc::new(tokio::sync::Semaphore::new(MAX_CONNECTIONS));
    loop {
        let (stream, peer) = tokio::select! {
            _ = stopped.changed() => return,
            accepted = listener.accept() => match accepted {
                Ok(a) => a,
                Err(e) => {
                    tracing::warn!(error = %e, "console: accept failed");
                    tokio::time::sleep(Duration::from_millis(50)).await;
                    continue;
                }
            },
        };
        let Ok(slot) = slots.clone().try_acquire_owned() else {
            tracing::warn!(%peer, "console: {MAX_CONNECTIONS} connections already: refused");
            continue;
        };
        let app = app.clone();
        let tls = tls.clone();
        tokio::spawn(async move {
            let _slot = slot;
            let service = hyper_util::service::TowerToHyperService::new(app);
            let mut http = hyper::server::conn::http1::Builder::new();
            http.timer(hyper_util::rt::TokioTimer::new())
                .header_read_timeout(Duration::from_secs(10));
            let served = match tls {
                Some(acceptor) => {
                    let Ok(Ok(stream)) =
                        tokio::time::timeout(Duration::from_secs(10), acceptor.accept(stream))
                            .await
                    else {
                        tracing::debug!(%peer, "console: TLS handshake failed");
                        return;
                    };
                    http.serve_connection(hyper_util::rt::TokioIo::new(stream), service)
                        .await
                }
                None => {
                    http.serve_connection(hyper_util::rt::TokioIo::new(stream), service)
                        .await
                }
            };
            if let Err(e) = served {
                tracing::debug!(%peer, error = %e, "console: connection ended");
            }
        });
    }
}

fn router(shared: Arc<Shared>, https: bool) -> Router {
    Router::new()
        .route(
            "/",
            get(|| async { page(INDEX, "text/html; charset=utf-8") }),
        )
        .route(
            "/console.js",
            get(|| async { page(SCRIPT, "text/javascript; charset=utf-8") }),
        )
        .route(
            "/console.css",
            get(|| async { page(STYLE, "text/css; charset=utf-8") }),
        )
        .route("/api/plant", get(plant))
        .route("/api/events", get(events))
        .route("/api/operators", get(operators))
        .route("/api/kpi", get(kpi))
        .route("/api/cells/{cell}/history", get(history))
        .route("/api/cells/{cell}/snapshot", get(snapshot))
        .route("/api/cells/{cell}/command", post(command))
        .layer(axum::middleware::map_response(
            move |mut r: Response| async move {
                let h = r.headers_mut();
                h.insert(
                    header::CONTENT_SECURITY_POLICY,
                    HeaderValue::from_static(CSP),
                );
                h.insert(
                    header::X_CONTENT_TYPE_OPTIONS,
                    HeaderValue::from_static("nosniff"),
                );
                h.insert(header::X_FRAME_OPTIONS, HeaderValue::from_static("DENY"));
                h.insert(
                    header::REFERRER_POLICY,
                    HeaderValue::from_static("no-referrer"),
                );
                h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
                if https {
                    h.insert(
                        header::STRICT_TRANSPORT_SECURITY,
                        HeaderValue::from_static("max-age=31536000"),
                    );
                }
                r
            },
        ))
        .with_state(shared)
}

fn page(body: &'static str, kind: &'static str) -> Response {
    ([(header::CONTENT_TYPE, kind)], body).into_response()
}

fn json(status: StatusCode, body: String) -> Response {
    (
        status,
        [(header::CONTENT_TYPE, "application/json; charset=utf-8")],
        body,
    )
        .into_response()
}

fn error(status: StatusCode, message: impl std::fmt::Display) -> Response {
    json(
        status,
        serde_json::json!({ "error": message.to_string() }).to_string(),
    )
}

/// Everything at once (`type: snapshot`), as the live stream starts.
async fn plant(State(s): State<Arc<Shared>>) -> Response {
    json(StatusCode::OK, s.view().0)
}

/// The live stream: everything first, then each change; a page that fell
/// behind is sent everything again.
async fn events(
    State(s): State<Arc<Shared>>,
) -> Sse<impl Stream<Item = Result<Event, Infallible>>> {
    let (first, changes) = s.view();
    let stream = futures_util::stream::unfold(
        (Some(first), changes, s),
        |(first, mut changes, s)| async move {
            if let Some(first) = first {
                return Some((Ok(Event::default().data(first)), (None, changes, s)));
            }
            match changes.recv().await {
                Ok(change) => Some((Ok(Event::default().data(&*change)), (None, changes, s))),
                Err(RecvError::Lagged(_)) => {
                    let (view, fresh) = s.view();
                    Some((Ok(Event::default().data(view)), (None, fresh, s)))
                }
                Err(RecvError::Closed) => None,
            }
        },
    );
    Sse::new(stream).keep_alive(KeepAlive::new().interval(Duration::from_secs(15)))
}

/// The operators and what each may do (public keys only).
async fn operators(State(s): State<Arc<Shared>>) -> Response {
    let list: Vec<serde_json::Value> = s
        .operators
        .iter()
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

/// The response that says `cell` is not in the trust file, if it is not.
fn unknown_cell(s: &Shared, cell: &str) -> Option<Response> {
    let known = s
        .plant
        .lock()
        .map(|p| p.cell(cell).is_some())
        .unwrap_or(false);
    (!known).then(|| {
        error(
            StatusCode::NOT_FOUND,
            format!("no cell '{cell}' in the plant trust file"),
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

/// The cell's journal, asked of its agent (`since`, `until`, `kind`,
/// `limit`, `after` as `cellwatch history` takes them).
async fn history(
    State(s): State<Arc<Shared>>,
    Path(cell): Path<String>,
    Query(q): Query<std::collections::BTreeMap<String, String>>,
) -> Response {
    if let Some(r) = unknown_cell(&s, &cell) {
        return r;
    }
    let mut parameters = Vec::new();
    for (name, value) in &q {
        if !HISTORY_PARAMETERS.contains(&name.as_str()) {
            return error(
                StatusCode::BAD_REQUEST,
                format!(
                    "unknown parameter '{name}': use {}",
                    HISTORY_PARAMETERS.join(", ")
                ),
            );
        }
        if let Err(why) = plain_value(name, value) {
            return error(StatusCode::BAD_REQUEST, why);
        }
        parameters.push(format!("{name}={value}"));
    }
    answered(
        s.bus
            .ask(&cell, Service::History, &parameters.join(";"), None, ANSWER)
            .await,
    )
}

/// How many agents are asked for their figures at once.
const KPI_AT_ONCE: usize = 16;

/// The ISA-18.2 alarm figures of every cell whose agent is up, for
/// `since` and `until` (as `history` takes them), each asked of the cell's
/// agent (`history?kind=kpi`): `{"cells": [{"cell", "area", "report"} or
/// {"cell", "area", "error"}]}`.
async fn kpi(
    State(s): State<Arc<Shared>>,
    Query(q): Query<std::collections::BTreeMap<String, String>>,
) -> Response {
    use futures_util::StreamExt;
    let mut parameters = vec!["kind=kpi".to_string()];
    for (name, value) in &q {
        if !["since", "until"].contains(&name.as_str()) {
            return error(
                StatusCode::BAD_REQUEST,
                format!("unknown parameter '{name}': use since, until"),
            );
        }
        if let Err(why) = plain_value(name, value) {
            return error(StatusCode::BAD_REQUEST, why);
        }
        parameters.push(format!("{name}={value}"));
    }
    let parameters = parameters.join(";");
    let cells: Vec<(String, Option<String>)> = s
        .plant
        .lock()
        .map(|p| {
            p.view()
                .cells
                .iter()
                .filter(|c| c.agent)
                .map(|c| (c.cell.clone(), c.area.clone()))
                .collect()
        })
        .unwrap_or_default();
    let answers: Vec<serde_json::Value> = futures_util::stream::iter(cells)
        .map(|(cell, area)| {
            let s = s.clone();
            let parameters = parameters.clone();
            async move {
                match s
                    .bus
                    .ask(&cell, Service::History, &parameters, None, ANSWER)
                    .await
                    .map_err(|e| e.to_string())
                    .and_then(|t| {
                        serde_json::from_str::<serde_json::Value>(&t).map_err(|e| e.to_string())
                    }) {
                    Ok(report) => {
                        serde_json::json!({ "cell": cell, "area": area, "report": report })
                    }
                    Err(e) => serde_json::json!({ "cell": cell, "area": area, "error": e }),
                }
            }
        })
        .buffered(KPI_AT_ONCE)
        .collect()
        .await;
    json(
        StatusCode::OK,
        serde_json::json!({ "cells": answers }).to_string(),
    )
}

/// Whether a query parameter's value holds nothing but letters, digits and
/// `:.+-_` (at most 64 of them): what times, durations, kinds and numbers
/// need, and nothing that could end a Zenoh parameter.
fn plain_value(name: &str, value: &str) -> Result<(), String> {
    let plain = value
        .bytes()
        .all(|b| b.is_ascii_alphanumeric() || b":.+-_".contains(&b));
    if value.is_empty() || value.len() > 64 || !plain {
        return Err(format!(
            "{name}: '{value}' is not a time, duration, kind or number"
        ));
    }
    Ok(())
}

/// The cell's values, alarms and values at its last fault, asked of its
/// agent.
async fn snapshot(State(s): State<Arc<Shared>>, Path(cell): Path<String>) -> Response {
    if let Some(r) = unknown_cell(&s, &cell) {
        return r;
    }
    answered(s.bus.ask(&cell, Service::Snapshot, "", None, ANSWER).await)
}

/// Forwards an operator's command, signed in the browser, to the cell's
/// agent, and returns its answer (`accepted`, `detail`). The console
/// checks only that it is a command: the agent checks the signature, the
/// operator's permission, the time and the nonce, and journals it.
async fn command(
    State(s): State<Arc<Shared>>,
    Path(cell): Path<String>,
    headers: HeaderMap,
    body: Bytes,
) -> Response {
    if let Some(r) = unknown_cell(&s, &cell) {
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
    tracing::info!(
        cell,
        operator = %crate::operator::escaped(&cmd.operator),
        action = %cmd.action,
        alarm = %crate::operator::escaped(&cmd.alarm),
        "console: forwarding a signed command"
    );
    match s.bus.command(&cell, &cmd, ANSWER).await {
        Ok((accepted, detail)) => json(
            StatusCode::OK,
            serde_json::json!({ "accepted": accepted, "detail": detail }).to_string(),
        ),
        Err(ClientError::Answered(why)) => json(
            StatusCode::OK,
            serde_json::json!({ "accepted": false, "detail": why }).to_string(),
        ),
        Err(e) => error(StatusCode::BAD_GATEWAY, e),
    }
}
