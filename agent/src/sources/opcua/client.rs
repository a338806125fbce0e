//! The OPC UA client as the configuration asks for it: security, identity, limits.

use std::time::Duration;

use opcua::client::{ClientBuilder, IdentityToken, Session};
use opcua::crypto::SecurityPolicy as UaPolicy;
use opcua::types::{MessageSecurityMode, NodeId, ReadValueId, TimestampsToReturn, Variant};

use super::requests::Requests;
use super::subscription;
use super::OpcUaError;

use crate::sources::opcua::config::{
    Identity, OpcUaConfig, PasswordSource, SecurityMode, SecurityPolicy,
};
use crate::sources::SourceError;

pub(super) fn ua_policy(p: SecurityPolicy) -> UaPolicy {
    match p {
        SecurityPolicy::None => UaPolicy::None,
        SecurityPolicy::Basic256Sha256 => UaPolicy::Basic256Sha256,
        SecurityPolicy::Aes128Sha256RsaOaep => UaPolicy::Aes128Sha256RsaOaep,
        SecurityPolicy::Aes256Sha256RsaPss => UaPolicy::Aes256Sha256RsaPss,
    }
}

pub(super) fn ua_mode(m: SecurityMode) -> MessageSecurityMode {
    match m {
        SecurityMode::None => MessageSecurityMode::None,
        SecurityMode::Sign => MessageSecurityMode::Sign,
        SecurityMode::SignAndEncrypt => MessageSecurityMode::SignAndEncrypt,
    }
}

pub(super) fn identity(config: &OpcUaConfig) -> Result<IdentityToken, SourceError> {
    match &config.identity {
        Identity::Anonymous => Ok(IdentityToken::Anonymous),
        Identity::User { user, password } => {
            let secret = match password {
                PasswordSource::Env(var) => std::env::var(var)
                    .map_err(|_| SourceError::PasswordVariable { var: var.clone() })?,
                PasswordSource::File(path) => std::fs::read_to_string(path)
                    .map_err(|source| SourceError::PasswordFile {
                        path: path.clone(),
                        source,
                    })?
                    .lines()
                    .next()
                    .unwrap_or_default()
                    .to_string(),
            };
            Ok(IdentityToken::new_user_name(user.clone(), secret))
        }
    }
}

/// The largest message the client sends or accepts.
pub(super) const MAX_MESSAGE_BYTES: usize = 64 << 20;

/// The longest array the client decodes.
pub(super) fn array_limit(config: &OpcUaConfig) -> usize {
    2 * (config.max_notifications_per_publish as usize).max(subscription::MAX_ITEMS_PER_CALL)
}

/// Builds the client, creating the agent's key pair in the PKI directory if
/// it has none (the private key owner-only from the start:
/// [`crate::sources::pki::own_key_pair`]).
///
/// # Errors
/// The client configuration is invalid.
pub fn client(cell: &str, config: &OpcUaConfig) -> Result<opcua::client::Client, SourceError> {
    client_retrying(cell, config, -1)
}

/// [`client`], its sessions retried `retries` times (`-1`: for ever; `0`:
/// a failed connection ends the event loop with the server's status).
///
/// # Errors
/// The client configuration is invalid, or (with security) the key pair
/// cannot be made or its private key is readable by others.
pub(super) fn client_retrying(
    cell: &str,
    config: &OpcUaConfig,
    retries: i32,
) -> Result<opcua::client::Client, SourceError> {
    let (name, uri) = (
        format!("cellwatch {cell}"),
        format!("urn:cellwatch:agent:{cell}"),
    );
    // The key pair made here, the private key owner-only from the start
    // (the stack would write it with the process's umask, and only then
    // could it be tightened), with the name and URI the stack would give
    // it. Without one, a secured connection is impossible: refused now,
    // naming the PKI directory; one without security goes on without it.
    let made = match crate::sources::pki::own_key_pair(&config.pki_dir, &name, &uri) {
        Ok(_) => true,
        Err(e) if config.policy == SecurityPolicy::None => {
            tracing::warn!(pki = %config.pki_dir.display(), error = %e, "cannot make the agent's OPC UA key pair");
            false
        }
        Err(source) => {
            return Err(SourceError::KeyPair {
                pki_dir: config.pki_dir.clone(),
                source,
            })
        }
    };
    let client = ClientBuilder::new()
        .application_name(name)
        .application_uri(uri)
        .product_uri("urn:cellwatch")
        .pki_dir(&config.pki_dir)
        // Never the stack's own: it would write the key with the umask.
        .create_sample_keypair(false)
        .trust_server_certs(false)
        .verify_server_certs(true)
        .session_retry_limit(retries)
        .session_retry_initial(Duration::from_millis(500))
        .session_retry_max(Duration::from_secs(10))
        .keep_alive_interval(Duration::from_secs(1))
        .max_failed_keep_alive_count(3)
        .request_timeout(Duration::from_secs(5))
        // The session outlives the subscription: a server that ends the
        // subscriptions with a timed-out session would otherwise lose them
        // sooner than `opcua.subscription_lifetime` says.
        .session_timeout(session_timeout(config))
        // Decoding limits sized from what the subscription can produce: a
        // publish holds at most `max_notifications_per_publish` values (asked
        // of the server), a monitored-item call at most
        // `subscription::MAX_ITEMS_PER_CALL` results. A server that sends
        // more closes the connection: an error in the log and the
        // communication alarm, never a silent stall.
        .max_array_length(array_limit(config))
        .max_message_size(MAX_MESSAGE_BYTES)
        .max_chunk_count(0)
        // The source takes its subscription over into a new session itself,
        // without asking the server to send every value again before the
        // publishes it still holds are sent again (see `resume`), and
        // recreates it when it cannot; async-opcua 0.19's own re-creation
        // leaves the new subscription without publish requests.
        .recreate_subscriptions(false)
        .client()
        .map_err(|problems| SourceError::Client { problems })?;
    // A key that was there before, and that others may read, is refused.
    if made {
        crate::sources::pki::protect_own_key(&config.pki_dir, true)
            .map_err(SourceError::PrivateKey)?;
    }
    Ok(client)
}

/// The server's `NamespaceArray` (index → URI).
pub(super) async fn namespace_array(
    session: &Session,
    requests: &Requests,
) -> Result<Vec<String>, OpcUaError> {
    let node = NodeId::new(0, NAMESPACE_ARRAY);
    let values = session
        .read(&[ReadValueId::from(node)], TimestampsToReturn::Neither, 0.0)
        .await;
    requests.answered("Read", &values);
    let values = values.map_err(OpcUaError::Service)?;
    let value = values.into_iter().next().ok_or(OpcUaError::EmptyRead)?;
    if let Some(status) = value.status.filter(|s| !s.is_good()) {
        return Err(OpcUaError::Status(status));
    }
    match value.value {
        Some(Variant::Array(a)) => Ok(a
            .values
            .into_iter()
            .map(|v| match v {
                Variant::String(s) => s.as_ref().to_string(),
                _ => String::new(),
            })
            .collect()),
        other => Err(OpcUaError::NotStrings(other)),
    }
}

/// `Server_NamespaceArray`.
pub(super) const NAMESPACE_ARRAY: u32 = 2255;

/// The session timeout asked for, ms: 30 s, or the subscription's lifetime
/// if longer.
fn session_timeout(config: &OpcUaConfig) -> u32 {
    let ms = config
        .subscription_lifetime
        .max(Duration::from_secs(30))
        .as_millis();
    u32::try_from(ms).unwrap_or(u32::MAX)
}

/// The server's endpoint with the configured policy and mode, at the
/// configured address. The server's own endpoint URL is not used: a server
/// behind NAT or port forwarding advertises an address the agent may not
/// reach.
pub(super) async fn server_endpoint(
    client: &opcua::client::Client,
    config: &OpcUaConfig,
    reverse: Option<&std::sync::Arc<tokio::net::TcpListener>>,
) -> Result<opcua::types::EndpointDescription, opcua::types::Error> {
    let policy = ua_policy(config.policy);
    let mode = ua_mode(config.mode);
    let endpoints = match reverse {
        Some(listener) => super::reverse::endpoints(client, listener, &config.endpoint).await?,
        None => {
            client
                .get_server_endpoints_from_url(config.endpoint.as_str())
                .await?
        }
    };
    let mut endpoint = endpoints
        .into_iter()
        .find(|e| {
            e.security_mode == mode && UaPolicy::from_uri(e.security_policy_uri.as_ref()) == policy
        })
        .ok_or_else(|| {
            opcua::types::Error::new(
                opcua::types::StatusCode::BadSecurityPolicyRejected,
                format!(
                    "the server offers no endpoint with security policy {} and mode {mode}",
                    policy.to_str()
                ),
            )
        })?;
    endpoint.endpoint_url = config.endpoint.as_str().into();
    Ok(endpoint)
}
