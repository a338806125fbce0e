//! One-off OPC UA connections (`cellwatch discover`, `trust-server`): no
//! retries, and a refusal said at once with what to do about it. A cell
//! whose server connects to the agent (`opcua.reverse_listen`) is reached
//! the same way: the command listens there for the server's connection.

use std::sync::Arc;
use std::time::Duration;

use opcua::client::Session;

use super::client::server_endpoint;
use super::client::{self, identity};
use crate::sources::opcua::config::OpcUaConfig;
use crate::sources::SourceError;

/// A session for a one-off job (`cellwatch discover`): connected with the
/// same security, PKI and identity as the source, its event loop running
/// on its own task (stop it by disconnecting the session and aborting
/// the task).
///
/// # Errors
/// The client cannot be configured or the server cannot be reached.
pub async fn connect_once(
    name: &str,
    config: &OpcUaConfig,
) -> Result<
    (
        Arc<Session>,
        tokio::task::JoinHandle<opcua::types::StatusCode>,
    ),
    SourceError,
> {
    let mut client = client::client_retrying(name, config, 0)?;
    let token = identity(config)?;
    let reverse = reverse_listener(config).await?;
    let endpoint = endpoint_once(&client, config, reverse.as_ref()).await?;
    // An untrusted server certificate fails here, at once, with what to do
    // (the stack would only retry).
    if let Some(why) = crate::sources::pki::untrusted(config, &endpoint) {
        return Err(SourceError::Untrusted {
            endpoint: config.endpoint.to_string(),
            why,
        });
    }
    let connected = match &reverse {
        Some(listener) => super::reverse::session(&client, listener, endpoint, token),
        None => client
            .connect_to_endpoint_directly(endpoint, token)
            .map(|(s, l)| (s, Box::pin(l.enter()) as super::reverse::Events)),
    };
    let (session, mut events) = connected.map_err(|source| SourceError::Connect {
        endpoint: config.endpoint.to_string(),
        source,
    })?;
    // The event loop on its own task, ending with the status it ended on.
    let mut task = tokio::spawn(async move {
        use futures_util::TryStreamExt;
        loop {
            match events.try_next().await {
                Ok(None) => break opcua::types::StatusCode::Good,
                Err(e) => break e,
                Ok(Some(_)) => {}
            }
        }
    });
    // No retries: a refused connection ends the event loop at once, with
    // the server's reason.
    let outcome = tokio::time::timeout(Duration::from_secs(15), async {
        tokio::select! {
            up = session.wait_for_connection() => if up { Ok(()) } else { Err(None) },
            status = &mut task => Err(status.ok()),
        }
    })
    .await;
    match outcome {
        Ok(Ok(())) => Ok((session, task)),
        Ok(Err(status)) => {
            task.abort();
            Err(refused(config, status))
        }
        Err(_) => {
            task.abort();
            Err(refused(config, None))
        }
    }
}

/// The server's own view of itself, from its endpoint list (asked without
/// a session, before trusting anything).
pub struct ServerIdentity {
    /// Its certificate (DER); empty for security policy `None`.
    pub certificate: Vec<u8>,
    /// Its application name.
    pub application_name: String,
    /// Its application URI.
    pub application_uri: String,
}

/// Asks the server at `config.endpoint` for the endpoint with the
/// configured security, making the agent's key pair in `config.pki_dir` if
/// it has none.
///
/// # Errors
/// No client, no answer, no such endpoint.
pub async fn server_identity(config: &OpcUaConfig) -> Result<ServerIdentity, SourceError> {
    let client = client::client_retrying("trust", config, 0)?;
    let reverse = reverse_listener(config).await?;
    let endpoint = endpoint_once(&client, config, reverse.as_ref()).await?;
    Ok(ServerIdentity {
        certificate: endpoint.server_certificate.as_ref().to_vec(),
        application_name: endpoint.server.application_name.text.to_string(),
        application_uri: endpoint.server.application_uri.to_string(),
    })
}

/// Why a one-off connection got no session, and what to do about it.
fn refused(config: &OpcUaConfig, status: Option<opcua::types::StatusCode>) -> SourceError {
    use opcua::types::StatusCode;
    let endpoint = &config.endpoint;
    let why = match status {
        Some(
            StatusCode::BadSecurityChecksFailed
            | StatusCode::BadCertificateUntrusted
            | StatusCode::BadCertificateInvalid
            | StatusCode::BadCertificateRevoked
            | StatusCode::BadCertificateUriInvalid,
        ) => {
            let own = crate::sources::pki::own_cert(&config.pki_dir);
            let facts = match std::fs::read(&own) {
                Err(e) => format!("unreadable: {e}"),
                Ok(der) => crate::sources::pki::CertificateFacts::of(&der, crate::clock::now_ms())
                    .map_or_else(
                        |e| format!("unreadable: {e}"),
                        |f| format!("thumbprint {}, SHA-256 {}", f.thumbprint, f.sha256),
                    ),
            };
            format!(
                "{endpoint}: the server refused this agent's certificate ({}: {facts}): add it to the server's trusted clients, as its vendor's tool says",
                own.display()
            )
        }
        Some(
            s @ (StatusCode::BadIdentityTokenRejected
            | StatusCode::BadIdentityTokenInvalid
            | StatusCode::BadUserAccessDenied),
        ) => format!(
            "{endpoint}: the server refused the login ({s}): check the user and its password"
        ),
        Some(s) => format!("{endpoint}: no session: {s}"),
        None => format!("{endpoint}: no session within 15 s"),
    };
    SourceError::Refused {
        endpoint: endpoint.to_string(),
        status,
        why,
    }
}

/// The server's endpoint for a one-off connection. A server that takes
/// the connection and never answers, or goes away while answering, must
/// not hold it forever.
async fn endpoint_once(
    client: &opcua::client::Client,
    config: &OpcUaConfig,
    reverse: Option<&Arc<tokio::net::TcpListener>>,
) -> Result<opcua::types::EndpointDescription, SourceError> {
    tokio::time::timeout(ENDPOINTS_ANSWER, server_endpoint(client, config, reverse))
        .await
        .map_err(|_| SourceError::NoEndpoints {
            endpoint: config.endpoint.to_string(),
            within: ENDPOINTS_ANSWER,
        })?
        .map_err(|source| SourceError::Connect {
            endpoint: config.endpoint.to_string(),
            source,
        })
}

/// Where a one-off connection listens for the server to connect, for a
/// cell configured with `opcua.reverse_listen`.
///
/// # Errors
/// The address is in use (by the cell's agent, most likely).
async fn reverse_listener(
    config: &OpcUaConfig,
) -> Result<Option<Arc<tokio::net::TcpListener>>, SourceError> {
    let Some(addr) = config.reverse_listen else {
        return Ok(None);
    };
    match tokio::net::TcpListener::bind(addr).await {
        Ok(l) => Ok(Some(Arc::new(l))),
        Err(source) => Err(SourceError::ReverseListen {
            endpoint: config.endpoint.to_string(),
            addr,
            pki_dir: config.pki_dir.clone(),
            source,
        }),
    }
}

/// How long a one-off connection waits for the server's endpoints.
const ENDPOINTS_ANSWER: Duration = Duration::from_secs(30);
