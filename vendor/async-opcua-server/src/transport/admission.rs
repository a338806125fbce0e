//! cellwatch's patch (the whole file; see vendor/README.md): which
//! OpenSecureChannel requests reach the server's RSA decryption.
//!
//! The rsa crate's private-key operations are not constant-time
//! (RUSTSEC-2023-0071, the Marvin attack): an observer who can have the
//! server decrypt chosen ciphertexts, and time each, can in the end decrypt
//! or sign with its key, given a great many samples. 0.19.0 decrypts every
//! OpenSecureChannel request under the policy it names, from anyone, before
//! the client's certificate is looked at (at CreateSession). Here, before
//! any decryption, from what the request carries in clear (its asymmetric
//! security header), the server refuses:
//!
//! - a request from an address that opened more than its share of secure
//!   channels: a token bucket per remote address, [`SECURE_CHANNEL_BURST`] at once and
//!   [`SECURE_CHANNELS_PER_SECOND`] after (`BadTcpServerTooBusy`), so that no address
//!   collects the samples the attack needs;
//! - a security policy none of its endpoints offers
//!   (`BadSecurityPolicyRejected`): Basic128Rsa15's PKCS#1 v1.5 is never
//!   decrypted by a server that does not offer it;
//! - a sender certificate the server does not trust: the certificate
//!   store's own check (in `trusted/`, byte for byte, not in `rejected/`,
//!   key length, validity; an unknown one is left in `rejected/` for
//!   review), the check CreateSession makes, made before decrypting
//!   instead of after.
//!
//! A request under policy None decrypts nothing and passes (discovery,
//! `GetEndpoints`, needs it); what a None channel may do is the server's
//! endpoints' business, as before.

use std::{
    collections::HashMap,
    io::Cursor,
    net::IpAddr,
    sync::{
        atomic::{AtomicU64, Ordering},
        Arc, Mutex,
    },
    time::Instant,
};

use opcua_core::{
    comms::{message_chunk::MESSAGE_CHUNK_HEADER_SIZE, security_header::AsymmetricSecurityHeader},
    sync::RwLock,
};
use opcua_crypto::{CertificateStore, SecurityPolicy, X509};
use opcua_types::{DecodingOptions, Error, SimpleBinaryDecodable, StatusCode};
use tracing::{debug, warn};

/// Secure channels an address may open at once.
pub const SECURE_CHANNEL_BURST: f64 = 10.0;
/// Secure channels an address may open per second after its burst.
pub const SECURE_CHANNELS_PER_SECOND: f64 = 2.0;
/// Addresses whose buckets are kept; past it, the buckets that are full
/// again are forgotten, and while none is, new addresses share one.
const ADDRESSES: usize = 4096;

/// What became of the OpenSecureChannel requests the server was sent
/// under a security policy other than None (each one its RSA decryption).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SecureChannelCounts {
    /// Passed on to be decrypted.
    pub decrypted: u64,
    /// Refused: their address opened more than its share.
    pub refused_busy: u64,
    /// Refused: a security policy no endpoint offers.
    pub refused_policy: u64,
    /// Refused: a sender certificate the server does not trust.
    pub refused_untrusted: u64,
}

/// The server's admission of secure channels, shared by every connection.
pub(crate) struct ChannelAdmission {
    /// The security policies the endpoints offer, None excluded.
    offered: Vec<SecurityPolicy>,
    /// The server's trust list, as CreateSession reads it.
    certificate_store: Arc<RwLock<CertificateStore>>,
    /// Each remote address's bucket (tokens, when last filled); the
    /// connections' tasks take from it one at a time.
    buckets: Mutex<HashMap<Option<IpAddr>, (f64, Instant)>>,
    decrypted: AtomicU64,
    refused_busy: AtomicU64,
    refused_policy: AtomicU64,
    refused_untrusted: AtomicU64,
}

impl ChannelAdmission {
    pub(crate) fn new(
        offered: impl IntoIterator<Item = SecurityPolicy>,
        certificate_store: Arc<RwLock<CertificateStore>>,
    ) -> Self {
        Self {
            offered: offered
                .into_iter()
                .filter(|p| *p != SecurityPolicy::None)
                .collect(),
            certificate_store,
            buckets: Mutex::new(HashMap::new()),
            decrypted: AtomicU64::new(0),
            refused_busy: AtomicU64::new(0),
            refused_policy: AtomicU64::new(0),
            refused_untrusted: AtomicU64::new(0),
        }
    }

    /// The counts so far.
    pub(crate) fn counts(&self) -> SecureChannelCounts {
        SecureChannelCounts {
            decrypted: self.decrypted.load(Ordering::Relaxed),
            refused_busy: self.refused_busy.load(Ordering::Relaxed),
            refused_policy: self.refused_policy.load(Ordering::Relaxed),
            refused_untrusted: self.refused_untrusted.load(Ordering::Relaxed),
        }
    }

    /// Whether the OpenSecureChannel chunk `chunk` (still encrypted) from
    /// `peer` may be decrypted; the error, sent to the client before the
    /// connection is closed, says why not.
    pub(crate) fn admit(
        &self,
        peer: Option<IpAddr>,
        chunk: &[u8],
        decoding_options: &DecodingOptions,
    ) -> Result<(), Error> {
        let mut stream = Cursor::new(chunk.get(MESSAGE_CHUNK_HEADER_SIZE..).unwrap_or_default());
        let header = AsymmetricSecurityHeader::decode(&mut stream, decoding_options)?;
        let uri = header.security_policy_uri.as_ref();
        if uri.is_empty() || SecurityPolicy::from_uri(uri) == SecurityPolicy::None {
            return Ok(());
        }
        let refuse = |count: &AtomicU64, status: StatusCode, why: String| {
            count.fetch_add(1, Ordering::Relaxed);
            Err(Error::new(status, why))
        };
        if !self.take(peer) {
            debug!("OpenSecureChannel from {peer:?} refused: more than its share of channels");
            return refuse(
                &self.refused_busy,
                StatusCode::BadTcpServerTooBusy,
                "too many secure channels opened from this address".into(),
            );
        }
        let policy = SecurityPolicy::from_uri(uri);
        if !self.offered.contains(&policy) {
            warn!("OpenSecureChannel from {peer:?} refused: security policy {uri} is not offered");
            return refuse(
                &self.refused_policy,
                StatusCode::BadSecurityPolicyRejected,
                format!("security policy {uri} is not offered"),
            );
        }
        let trusted = X509::from_byte_string(&header.sender_certificate).and_then(|cert| {
            self.certificate_store
                .read()
                .validate_application_instance_cert(&cert, policy, None, None)
        });
        if let Err(e) = trusted {
            warn!("OpenSecureChannel from {peer:?} refused before decryption: {e}");
            let status = match e.status() {
                StatusCode::BadUnexpectedError => StatusCode::BadSecurityChecksFailed,
                s => s,
            };
            return refuse(&self.refused_untrusted, status, e.to_string());
        }
        self.decrypted.fetch_add(1, Ordering::Relaxed);
        Ok(())
    }

    /// Takes one channel from `peer`'s bucket, if it holds one.
    fn take(&self, peer: Option<IpAddr>) -> bool {
        let now = Instant::now();
        let Ok(mut buckets) = self.buckets.lock() else {
            return false;
        };
        let fill = |(tokens, at): (f64, Instant)| {
            (tokens + now.duration_since(at).as_secs_f64() * SECURE_CHANNELS_PER_SECOND)
                .min(SECURE_CHANNEL_BURST)
        };
        if buckets.len() >= ADDRESSES && !buckets.contains_key(&peer) {
            buckets.retain(|_, b| fill(*b) < SECURE_CHANNEL_BURST);
        }
        // Too many addresses at once: the newcomers share one bucket.
        let key = if buckets.len() >= ADDRESSES && !buckets.contains_key(&peer) {
            None
        } else {
            peer
        };
        let bucket = buckets.entry(key).or_insert((SECURE_CHANNEL_BURST, now));
        let tokens = fill(*bucket);
        let taken = tokens >= 1.0;
        *bucket = (if taken { tokens - 1.0 } else { tokens }, now);
        taken
    }
}
