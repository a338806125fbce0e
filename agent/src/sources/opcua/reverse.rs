//! OPC UA reverse connect (`opcua.reverse_listen`): the server dials out
//! to the agent, as a PLC behind a firewall or in a DMZ is reached. The
//! agent listens; every connection the server opens starts with a
//! `ReverseHello` naming its endpoint, which must be `opcua.endpoint`
//! (async-opcua's check), and then carries the same secure channel and
//! session as a connection the agent dials: the configured policy and
//! mode, the server's certificate trusted only if it is in `trusted/`.
//!
//! The server dials again whenever its connection ends: the endpoints are
//! asked over one connection, the session runs over the next, and a lost
//! connection is re-established over the one after. This module does not
//! own the session: the source drives it as it drives a dialled one.

use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::Arc;
use std::time::Duration;

use futures_util::Stream;
use opcua::client::reverse_connect::ReverseConnectionSource;
use opcua::client::{Client, ConnectionSource, IdentityToken, Session, SessionPollResult};
use opcua::types::{EndpointDescription, Error, MessageSecurityMode, StatusCode};
use tokio::net::TcpListener;

/// A session's event loop, whichever way its connection is made.
pub(super) type Events = Pin<Box<dyn Stream<Item = Result<SessionPollResult, StatusCode>> + Send>>;

/// Binds `addr` at once, so that the address is known (and a port in use
/// said) before the source runs.
///
/// # Errors
/// The address cannot be bound.
pub(super) fn bind(addr: SocketAddr) -> std::io::Result<std::net::TcpListener> {
    let listener = std::net::TcpListener::bind(addr)?;
    listener.set_nonblocking(true)?;
    Ok(listener)
}

/// The listener the server connects to: the one bound beforehand, or
/// `addr` bound now, tried again every second while it is in use (the
/// source this one replaces may still hold it) until it can be.
pub(super) async fn listen(
    addr: SocketAddr,
    bound: Option<std::net::TcpListener>,
) -> Arc<TcpListener> {
    if let Some(l) = bound {
        match TcpListener::from_std(l) {
            Ok(l) => return Arc::new(l),
            Err(e) => {
                tracing::warn!(%addr, error = %e, "reverse-connect listener unusable; binding again")
            }
        }
    }
    let mut said = false;
    loop {
        match TcpListener::bind(addr).await {
            Ok(l) => {
                tracing::info!(addr = %l.local_addr().unwrap_or(addr), "listening for the OPC UA server to connect (reverse connect)");
                return Arc::new(l);
            }
            Err(e) => {
                if !said {
                    tracing::warn!(%addr, error = %e, "cannot listen for the OPC UA server yet; trying every second");
                    said = true;
                }
                tokio::time::sleep(Duration::from_secs(1)).await;
            }
        }
    }
}

/// How long the agent waits for the server to connect before it says the
/// connection is down (the communication alarm); it goes on listening.
pub(super) const WAIT: Duration = Duration::from_secs(10);

/// The server's endpoints, asked over the next connection it opens.
///
/// # Errors
/// No connection within [`WAIT`]; the connection or the request fails.
pub(super) async fn endpoints(
    client: &Client,
    listener: &Arc<TcpListener>,
    endpoint_url: &str,
) -> Result<Vec<EndpointDescription>, Error> {
    let asked = asked_endpoints(client, listener, endpoint_url);
    match tokio::time::timeout(WAIT, asked).await {
        Ok(answer) => answer,
        Err(_) => Err(Error::new(
            StatusCode::BadTimeout,
            format!(
                "no connection from the server within {} s: it must dial {} (opcua.reverse_listen, reverse connect)",
                WAIT.as_secs(),
                listener
                    .local_addr()
                    .map_or_else(|e| e.to_string(), |a| a.to_string())
            ),
        )),
    }
}

async fn asked_endpoints(
    client: &Client,
    listener: &Arc<TcpListener>,
    endpoint_url: &str,
) -> Result<Vec<EndpointDescription>, Error> {
    let discovery = EndpointDescription {
        endpoint_url: endpoint_url.into(),
        security_mode: MessageSecurityMode::None,
        security_policy_uri: opcua::crypto::SecurityPolicy::None.to_uri().into(),
        ..Default::default()
    };
    let connector =
        ReverseConnectionSource::new_listener(listener.clone()).get_connector(&discovery)?;
    client.get_endpoints(connector, &[], &[]).await
}

/// A session with `endpoint` over the connections the server opens, and
/// its event loop.
///
/// # Errors
/// The session cannot be built for this endpoint.
pub(super) fn session(
    client: &Client,
    listener: &Arc<TcpListener>,
    endpoint: EndpointDescription,
    token: IdentityToken,
) -> Result<(Arc<Session>, Events), Error> {
    let (session, event_loop) = client
        .session_builder()
        .with_connector(ReverseConnectionSource::new_listener(listener.clone()))
        .connect_to_endpoint_directly(endpoint)?
        .user_identity_token(token)
        .build(client.certificate_store().clone())?;
    Ok((session, Box::pin(event_loop.enter())))
}
