//! The replay source's answers to everything but the hot path: the
//! secure channel's opening, the endpoints, the session, the reads the
//! agent makes (the namespace array, the server's limit on monitored items
//! per call, the tags' values), and the subscription's services, each
//! built as the library's typed response.
//!
//! It owns the server's identity (certificate, key, endpoints) and the
//! node ids it serves; the subscription's state is `subscription.rs`'s.

use opcua::core::comms::secure_channel::SecureChannel;
use opcua::core::comms::security_header::SecurityHeader;
use opcua::core::ResponseMessage;
use opcua::crypto::{PrivateKey, SecurityPolicy, X509};
use opcua::types::{
    ActivateSessionRequest, ActivateSessionResponse, ApplicationDescription, ApplicationType,
    AttributeId, ChannelSecurityToken, CreateSessionRequest, CreateSessionResponse, DataValue,
    DateTime, EndpointDescription, GetEndpointsResponse, Identifier, MessageSecurityMode, NodeId,
    OpenSecureChannelRequest, OpenSecureChannelResponse, ReadRequest, ReadResponse, RequestHeader,
    ResponseHeader, ServiceFault, SignatureData, StatusCode, UAString, UserTokenPolicy,
    UserTokenType, Variant,
};

use crate::load::{switch_id, NAMESPACE, SWITCHES};

/// `Server_NamespaceArray`.
const NAMESPACE_ARRAY: u32 = 2255;

/// `Server_ServerStatus_State` (the client's keep-alive reads it).
const SERVER_STATE: u32 = 2259;

/// `Server_ServerCapabilities_OperationLimits_MaxMonitoredItemsPerCall`.
const MAX_MONITORED_ITEMS_PER_CALL: u32 = 11714;

/// Monitored items one CreateMonitoredItems may ask for.
pub const ITEMS_PER_CALL: u32 = 10_000;

/// The transport profile of OPC UA binary over TCP.
const UATCP: &str = "http://opcfoundation.org/UA-Profile/Transport/uatcp-uasc-uabinary";

/// The server's identity and what it serves.
pub struct Server {
    /// Its certificate (sent in endpoints and the session).
    pub cert: X509,
    /// Its private key (signs the session's nonce).
    pub key: PrivateKey,
    /// The URI in its certificate.
    pub uri: String,
    /// Noise tags served: `ns=1;i=1..=tags`.
    pub tags: usize,
}

/// A node the replay source serves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Served {
    /// Noise tag `i` (0-based; node `i + 1`).
    Noise(usize),
    /// Limit switch `k`.
    Switch(usize),
}

impl Server {
    /// Which served node `id` is, if any.
    pub fn served(&self, id: &NodeId) -> Option<Served> {
        let Identifier::Numeric(n) = id.identifier else {
            return None;
        };
        if id.namespace != 1 {
            return None;
        }
        let n = n as usize;
        if (1..=self.tags).contains(&n) {
            Some(Served::Noise(n - 1))
        } else {
            (0..SWITCHES)
                .find(|&k| switch_id(k) as usize == n)
                .map(Served::Switch)
        }
    }

    /// The endpoints at `url`: None, and Basic256Sha256 with Sign (the
    /// hot path signs; it does not encrypt).
    pub fn endpoints(&self, url: &UAString) -> Vec<EndpointDescription> {
        let server = ApplicationDescription {
            application_uri: self.uri.as_str().into(),
            product_uri: "urn:cellwatch".into(),
            application_name: "cellwatch replay source".into(),
            application_type: ApplicationType::Server,
            discovery_urls: Some(vec![url.clone()]),
            ..Default::default()
        };
        let anonymous = UserTokenPolicy {
            policy_id: "anonymous".into(),
            token_type: UserTokenType::Anonymous,
            ..Default::default()
        };
        [
            (SecurityPolicy::None, MessageSecurityMode::None, 0),
            (SecurityPolicy::Basic256Sha256, MessageSecurityMode::Sign, 1),
        ]
        .into_iter()
        .map(|(policy, mode, level)| EndpointDescription {
            endpoint_url: url.clone(),
            server: server.clone(),
            server_certificate: self.cert.as_byte_string(),
            security_mode: mode,
            security_policy_uri: policy.to_uri().into(),
            user_identity_tokens: Some(vec![anonymous.clone()]),
            transport_profile_uri: UATCP.into(),
            security_level: level,
        })
        .collect()
    }

    /// Opens (or renews) the secure channel as `request` asks.
    ///
    /// # Errors
    /// The header is not asymmetric, or the client's certificate or nonce
    /// is unusable.
    pub fn open(
        &self,
        channel: &mut SecureChannel,
        header: &SecurityHeader,
        request: &OpenSecureChannelRequest,
        channel_id: u32,
        token_id: u32,
    ) -> Result<ResponseMessage, StatusCode> {
        let SecurityHeader::Asymmetric(header) = header else {
            return Err(StatusCode::BadSecurityChecksFailed);
        };
        channel.set_security_mode(request.security_mode);
        channel.set_secure_channel_id(channel_id);
        channel.set_token_id(token_id);
        channel.set_remote_cert_from_byte_string(&header.sender_certificate)?;
        channel.set_token_lifetime(request.requested_lifetime);
        channel.set_remote_nonce_from_byte_string(&request.client_nonce)?;
        channel.create_random_nonce();
        if channel.security_policy() != SecurityPolicy::None
            && request.security_mode != MessageSecurityMode::None
        {
            channel.derive_keys();
        }
        Ok(OpenSecureChannelResponse {
            response_header: ResponseHeader::new_good(&request.request_header),
            server_protocol_version: 0,
            security_token: ChannelSecurityToken {
                channel_id,
                token_id,
                created_at: DateTime::now(),
                revised_lifetime: request.requested_lifetime,
            },
            server_nonce: channel.local_nonce_as_byte_string(),
        }
        .into())
    }

    /// GetEndpoints.
    pub fn get_endpoints(&self, header: &RequestHeader, url: &UAString) -> ResponseMessage {
        GetEndpointsResponse {
            response_header: ResponseHeader::new_good(header),
            endpoints: Some(self.endpoints(url)),
        }
        .into()
    }

    /// CreateSession: session `n`, the server's nonce and, under
    /// security, its signature of the client's certificate and nonce.
    pub fn create_session(
        &self,
        channel: &SecureChannel,
        request: &CreateSessionRequest,
        n: u32,
    ) -> ResponseMessage {
        let policy = channel.security_policy();
        let server_signature = if policy == SecurityPolicy::None {
            SignatureData::null()
        } else {
            opcua::crypto::create_signature_data(
                &self.key,
                policy,
                &request.client_certificate,
                &request.client_nonce,
            )
            .unwrap_or_else(|_| SignatureData::null())
        };
        CreateSessionResponse {
            response_header: ResponseHeader::new_good(&request.request_header),
            session_id: NodeId::new(1, format!("session-{n}")),
            authentication_token: NodeId::new(0, opcua::crypto::random::byte_string(32)),
            revised_session_timeout: request.requested_session_timeout,
            server_nonce: opcua::crypto::random::byte_string(32),
            server_certificate: self.cert.as_byte_string(),
            server_endpoints: Some(self.endpoints(&request.endpoint_url)),
            server_software_certificates: None,
            server_signature,
            max_request_message_size: 0,
        }
        .into()
    }

    /// ActivateSession: any identity is welcome.
    pub fn activate_session(&self, request: &ActivateSessionRequest) -> ResponseMessage {
        ActivateSessionResponse {
            response_header: ResponseHeader::new_good(&request.request_header),
            server_nonce: opcua::crypto::random::byte_string(32),
            results: None,
            diagnostic_infos: None,
        }
        .into()
    }

    /// Read: the namespace array, the server's state (running), the limit
    /// on monitored items per call, and served tags' values from `value`; anything else is unknown.
    pub fn read(&self, request: &ReadRequest, value: impl Fn(Served) -> bool) -> ResponseMessage {
        let results = request
            .nodes_to_read
            .iter()
            .flatten()
            .map(|r| {
                let bad = |s: StatusCode| DataValue {
                    status: Some(s),
                    ..Default::default()
                };
                if r.attribute_id != AttributeId::Value as u32 {
                    return bad(StatusCode::BadAttributeIdInvalid);
                }
                if r.node_id == NodeId::new(0, NAMESPACE_ARRAY) {
                    let uris = vec![
                        UAString::from("http://opcfoundation.org/UA/"),
                        UAString::from(NAMESPACE),
                    ];
                    return DataValue::new_now(Variant::from(uris));
                }
                if r.node_id == NodeId::new(0, SERVER_STATE) {
                    // ServerState Running.
                    return DataValue::new_now(0i32);
                }
                if r.node_id == NodeId::new(0, MAX_MONITORED_ITEMS_PER_CALL) {
                    return DataValue::new_now(ITEMS_PER_CALL);
                }
                match self.served(&r.node_id) {
                    Some(s) => DataValue::new_now(value(s)),
                    None => bad(StatusCode::BadNodeIdUnknown),
                }
            })
            .collect();
        ReadResponse {
            response_header: ResponseHeader::new_good(&request.request_header),
            results: Some(results),
            diagnostic_infos: None,
        }
        .into()
    }
}

/// A service fault for `handle`.
pub fn fault(handle: u32, status: StatusCode) -> ResponseMessage {
    ServiceFault {
        response_header: ResponseHeader::new_service_result(handle, status),
    }
    .into()
}
