//! The console's HTTP(S) side: connections (TLS, with a client
//! certificate from the plant CA when `http.tls.clients` asks), the door
//! every request passes ([`door`]: its `Host` and `Origin`, the client's
//! share, who is asking), signing in and out, and the routes
//! ([`super::api`]).
//!
//! Every response carries a strict Content-Security-Policy (scripts and
//! styles from the console only, no inline script, Trusted Types required:
//! the page cannot turn a text from the bus into HTML), no framing, no
//! referrer, no sniffing.

use std::net::IpAddr;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::body::Bytes;
use axum::extract::{Request, State};
use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Extension, Router};
use tokio::time::Instant;

use super::access::{self, Identity, Proof, SignIn};
use super::api;
use super::config::HttpTls;
use super::gate::Gate;
use super::shared::{ConsoleError, Shared};
use super::web::{error, json, Web, Who};

const INDEX: &str = include_str!("assets/index.html");
const SCRIPT: &str = include_str!("assets/console.js");
const STYLE: &str = include_str!("assets/console.css");

/// What every response says of itself.
const CSP: &str = "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self'; \
     connect-src 'self'; form-action 'none'; frame-ancestors 'none'; base-uri 'none'; \
     require-trusted-types-for 'script'; trusted-types 'none'";

/// At most this many connections are served at once.
const MAX_CONNECTIONS: usize = 512;

/// The routes a client without an identity may ask: signing in and out,
/// and who it is.
const OPEN: [&str; 4] = [
    "/api/sign-in/challenge",
    "/api/sign-in",
    "/api/sign-out",
    "/api/session",
];

/// Who is on the other end of a connection.
#[derive(Debug, Clone)]
struct Peer {
    ip: IpAddr,
    /// The common name of its client certificate, if it gave one.
    certificate: Option<String>,
}

/// The TLS acceptor of the console's certificate and key (PEM), asking
/// for a client certificate from `clients` when given (one is not
/// required: an operator may sign in with their key instead). Also
/// returns the names the certificate is for.
pub(super) fn tls_acceptor(
    t: &HttpTls,
) -> Result<(tokio_rustls::TlsAcceptor, Vec<String>), ConsoleError> {
    use tokio_rustls::rustls;
    use tokio_rustls::rustls::pki_types::pem::PemObject;
    use tokio_rustls::rustls::pki_types::{CertificateDer, PrivateKeyDer};
    let bad = |what: &std::path::Path, e: String| {
        ConsoleError::Input(format!("http.tls: {}: {e}", what.display()))
    };
    crate::bus::envelope::check_private(&t.key).map_err(|e| bad(&t.key, e.to_string()))?;
    let certs: Vec<CertificateDer<'static>> = CertificateDer::pem_file_iter(&t.cert)
        .and_then(Iterator::collect)
        .map_err(|e| bad(&t.cert, e.to_string()))?;
    let Some(first) = certs.first() else {
        return Err(bad(&t.cert, "no certificate in the file".into()));
    };
    let names = certificate_names(first);
    let key = PrivateKeyDer::from_pem_file(&t.key).map_err(|e| bad(&t.key, e.to_string()))?;
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let builder = rustls::ServerConfig::builder_with_provider(provider.clone())
        .with_safe_default_protocol_versions()
        .map_err(|e| ConsoleError::Input(format!("http.tls: {e}")))?;
    let builder = match &t.clients {
        None => builder.with_no_client_auth(),
        Some(ca) => {
            let mut roots = rustls::RootCertStore::empty();
            for c in CertificateDer::pem_file_iter(ca).map_err(|e| bad(ca, e.to_string()))? {
                let c = c.map_err(|e| bad(ca, e.to_string()))?;
                roots.add(c).map_err(|e| bad(ca, e.to_string()))?;
            }
            if roots.is_empty() {
                return Err(bad(ca, "no certificate in the file".into()));
            }
            let verifier = rustls::server::WebPkiClientVerifier::builder_with_provider(
                Arc::new(roots),
                provider,
            )
            .allow_unauthenticated()
            .build()
            .map_err(|e| bad(ca, e.to_string()))?;
            builder.with_client_cert_verifier(verifier)
        }
    };
    let config = builder
        .with_single_cert(certs, key)
        .map_err(|e| bad(&t.cert, e.to_string()))?;
    Ok((tokio_rustls::TlsAcceptor::from(Arc::new(config)), names))
}

/// The DNS names and addresses a certificate is for.
fn certificate_names(der: &[u8]) -> Vec<String> {
    use x509_parser::extensions::GeneralName;
    let Ok((_, cert)) = x509_parser::parse_x509_certificate(der) else {
        return Vec::new();
    };
    let Ok(Some(san)) = cert.subject_alternative_name() else {
        return Vec::new();
    };
    san.value
        .general_names
        .iter()
        .filter_map(|n| match n {
            GeneralName::DNSName(d) => Some(d.to_string()),
            GeneralName::IPAddress(b) => match b.len() {
                4 => <[u8; 4]>::try_from(*b)
                    .ok()
                    .map(|o| std::net::Ipv4Addr::from(o).to_string()),
                16 => <[u8; 16]>::try_from(*b)
                    .ok()
                    .map(|o| format!("[{}]", std::net::Ipv6Addr::from(o))),
                _ => None,
            },
            _ => None,
        })
        .collect()
}

/// The common name of a client certificate.
fn common_name(der: &[u8]) -> Option<String> {
    let (_, cert) = x509_parser::parse_x509_certificate(der).ok()?;
    let name = cert
        .subject()
        .iter_common_name()
        .next()?
        .as_str()
        .ok()?
        .to_string();
    Some(name)
}

/// Serves until `stopped` says so.
pub(super) async fn serve(
    listener: tokio::net::TcpListener,
    tls: Option<tokio_rustls::TlsAcceptor>,
    shared: Arc<Shared>,
    gate: Arc<Gate>,
    mut stopped: tokio::sync::watch::Receiver<bool>,
) {
    let https = tls.is_some();
    let web = Arc::new(Web {
        shared,
        gate: gate.clone(),
        kpi: Mutex::default(),
        https,
    });
    let app = router(web, https);
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
        let Some(client) = gate.connect(peer.ip(), Instant::now()) else {
            tracing::debug!(%peer, "console: this client's connections are all taken: refused");
            continue;
        };
        let Ok(slot) = slots.clone().try_acquire_owned() else {
            tracing::warn!(%peer, "console: {MAX_CONNECTIONS} connections already: refused");
            continue;
        };
        let app = app.clone();
        let tls = tls.clone();
        tokio::spawn(async move {
            let _slot = slot;
            let _client = client;
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
                    let certificate = stream
                        .get_ref()
                        .1
                        .peer_certificates()
                        .and_then(|c| c.first())
                        .and_then(|c| common_name(c));
                    let app = app.layer(Extension(Peer {
                        ip: peer.ip(),
                        certificate,
                    }));
                    let service = hyper_util::service::TowerToHyperService::new(app);
                    http.serve_connection(hyper_util::rt::TokioIo::new(stream), service)
                        .await
                }
                None => {
                    let app = app.layer(Extension(Peer {
                        ip: peer.ip(),
                        certificate: None,
                    }));
                    let service = hyper_util::service::TowerToHyperService::new(app);
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

fn router(web: Arc<Web>, https: bool) -> Router {
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
        .route("/api/sign-in/challenge", post(challenge))
        .route("/api/sign-in", post(sign_in))
        .route("/api/sign-out", post(sign_out))
        .route("/api/session", get(session))
        .route("/api/plant", get(api::plant))
        .route("/api/events", get(api::events))
        .route("/api/operators", get(api::operators))
        .route("/api/kpi", get(api::kpi))
        .route("/api/agents", get(api::agents))
        .route("/api/cells/{cell}/history", get(api::history))
        .route("/api/cells/{cell}/snapshot", get(api::snapshot))
        .route("/api/cells/{cell}/command", post(api::command))
        .layer(axum::middleware::from_fn_with_state(web.clone(), door))
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
        .with_state(web)
}

/// The door: a request for another host or from another site's page is
/// refused; a client past its share of `/api/` is told to slow down; an
/// `/api/` request without a plant identity gets nothing but signing in.
async fn door(
    State(web): State<Arc<Web>>,
    Extension(peer): Extension<Peer>,
    mut request: Request,
    next: Next,
) -> Response {
    let headers = request.headers();
    let Some(host) = headers.get(header::HOST).and_then(|h| h.to_str().ok()) else {
        return error(StatusCode::BAD_REQUEST, "a request names its Host");
    };
    if !web.gate.known_host(host) {
        return error(
            StatusCode::MISDIRECTED_REQUEST,
            format!(
                "'{}' is not a name of this console (http.names)",
                crate::operator::escaped(host)
            ),
        );
    }
    if let Some(origin) = headers.get(header::ORIGIN) {
        let known = origin
            .to_str()
            .ok()
            .and_then(|o| o.split_once("://"))
            .is_some_and(|(_, authority)| web.gate.known_host(authority));
        if !known {
            return error(StatusCode::FORBIDDEN, "a request from another site's page");
        }
    }
    let path = request.uri().path().to_string();
    if !path.starts_with("/api/") {
        return next.run(request).await;
    }
    if !web.gate.request(peer.ip, Instant::now()) {
        let mut r = error(
            StatusCode::TOO_MANY_REQUESTS,
            "too many requests from this address: wait a second",
        );
        r.headers_mut()
            .insert(header::RETRY_AFTER, HeaderValue::from_static("1"));
        return r;
    }
    let who = identify(&web, &peer, headers);
    match who {
        Some(who) => {
            request.extensions_mut().insert(who);
        }
        None if OPEN.contains(&path.as_str()) => {}
        None => {
            return error(
                StatusCode::UNAUTHORIZED,
                "sign in first: load your operator key in the page, or present a client certificate from the plant CA",
            )
        }
    }
    next.run(request).await
}

/// The identity of a request: its connection's client certificate (if
/// `[readers]` lets it read), else its session.
fn identify(web: &Web, peer: &Peer, headers: &HeaderMap) -> Option<Who> {
    if let Some(name) = &peer.certificate {
        if let Some(scope) = web.gate.readers.scope_of(name) {
            return Some(Who {
                identity: Identity {
                    name: name.clone(),
                    by: Proof::Certificate,
                    scope,
                },
                session: None,
            });
        }
    }
    let token = headers
        .get_all(header::COOKIE)
        .iter()
        .filter_map(|c| c.to_str().ok())
        .find_map(access::session_cookie)?;
    let identity = web
        .gate
        .sessions
        .lock()
        .ok()?
        .identity(Instant::now(), token)?;
    Some(Who {
        identity,
        session: Some(token.to_string()),
    })
}

/// A fresh challenge for the page to sign: `{"challenge"}`.
async fn challenge(State(web): State<Arc<Web>>) -> Response {
    let Ok(mut sessions) = web.gate.sessions.lock() else {
        return error(StatusCode::INTERNAL_SERVER_ERROR, "the console is stopping");
    };
    let challenge = sessions.challenge(Instant::now());
    json(
        StatusCode::OK,
        serde_json::json!({ "challenge": challenge }).to_string(),
    )
}

/// Signs an operator in: `{"operator", "challenge", "signature"}` →
/// a session cookie and `{"operator", "allow", "expires_in_s"}`.
async fn sign_in(State(web): State<Arc<Web>>, headers: HeaderMap, body: Bytes) -> Response {
    if body.len() > 1024 {
        return error(
            StatusCode::PAYLOAD_TOO_LARGE,
            "a sign-in is at most 1024 bytes",
        );
    }
    let answer: SignIn = match serde_json::from_slice(&body) {
        Ok(a) => a,
        Err(e) => return error(StatusCode::BAD_REQUEST, format!("not a sign-in: {e}")),
    };
    let host = headers
        .get(header::HOST)
        .and_then(|h| h.to_str().ok())
        .unwrap_or_default();
    let (signed, life) = {
        let Ok(mut sessions) = web.gate.sessions.lock() else {
            return error(StatusCode::INTERNAL_SERVER_ERROR, "the console is stopping");
        };
        let signed = sessions.sign_in(
            Instant::now(),
            &answer,
            host,
            &web.shared.operators,
            &web.gate.readers,
        );
        (signed, sessions.life())
    };
    let (token, identity) = match signed {
        Ok(s) => s,
        Err(why) => {
            tracing::warn!(
                operator = %crate::operator::escaped(&answer.operator),
                why = %why,
                "console: sign-in refused"
            );
            return error(StatusCode::FORBIDDEN, why);
        }
    };
    tracing::info!(operator = %identity.name, "console: operator signed in");
    let allow: Vec<&str> = web
        .shared
        .operators
        .iter()
        .find(|(n, _, _)| *n == identity.name)
        .map(|(_, _, allow)| allow.iter().map(|a| a.as_str()).collect())
        .unwrap_or_default();
    let mut r = json(
        StatusCode::OK,
        serde_json::json!({
            "operator": identity.name,
            "allow": allow,
            "expires_in_s": life.as_secs(),
        })
        .to_string(),
    );
    let secure = if web.https { "; Secure" } else { "" };
    let cookie = format!(
        "{}={token}; Path=/; HttpOnly; SameSite=Strict; Max-Age={}{secure}",
        access::COOKIE,
        life.as_secs()
    );
    if let Ok(v) = HeaderValue::from_str(&cookie) {
        r.headers_mut().insert(header::SET_COOKIE, v);
    }
    r
}

/// Ends the request's session, if any.
async fn sign_out(State(web): State<Arc<Web>>, who: Option<Extension<Who>>) -> Response {
    if let Some(Extension(Who {
        session: Some(token),
        identity,
    })) = who
    {
        if let Ok(mut sessions) = web.gate.sessions.lock() {
            sessions.close(&token);
        }
        tracing::info!(operator = %identity.name, "console: operator signed out");
    }
    let mut r = json(StatusCode::OK, "{}".into());
    r.headers_mut().insert(
        header::SET_COOKIE,
        HeaderValue::from_static(
            "cellwatch-session=; Path=/; HttpOnly; SameSite=Strict; Max-Age=0",
        ),
    );
    r
}

/// Who the request is: `{"identity", "by", "cells"}` (`cells`: `"*"` or a
/// list), or `401`.
async fn session(who: Option<Extension<Who>>) -> Response {
    let Some(Extension(who)) = who else {
        return error(StatusCode::UNAUTHORIZED, "not signed in");
    };
    let cells = match &who.identity.scope {
        access::Scope::Every => serde_json::json!("*"),
        access::Scope::Cells(c) => serde_json::json!(c),
    };
    json(
        StatusCode::OK,
        serde_json::json!({
            "identity": who.identity.name,
            "by": who.identity.by.as_str(),
            "cells": cells,
        })
        .to_string(),
    )
}

fn page(body: &'static str, kind: &'static str) -> Response {
    ([(header::CONTENT_TYPE, kind)], body).into_response()
}
