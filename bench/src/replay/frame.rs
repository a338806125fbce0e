//! The hot path: a Publish answered with a notification message whose
//! notifications are copied from the templates (`stream.rs`), and the
//! message cut into secure-channel chunks by hand, each signed with the
//! channel's keys (async-opcua's own signing) under Sign.
//!
//! Only the few fields around the notifications are encoded per publish,
//! with the library's encoders: the response header, the subscription's
//! numbers, the notification message's header and the acknowledgements'
//! results. It owns no state of the subscription; `subscription.rs` says
//! what goes in.

use opcua::core::comms::secure_channel::SecureChannel;
use opcua::types::{
    BinaryEncodable, Context, DateTime, MessageSecurityMode, NodeId, ObjectId, ResponseHeader,
    StatusCode,
};

use super::stream::{Segment, Stream};

/// Message header (12: type, size, channel id), the symmetric security
/// header (4: token id) and the sequence header (8).
const CHUNK_HEADER: usize = 24;

/// What a publish answer carries besides its notifications.
pub struct Publish<'a> {
    /// The Publish request's handle.
    pub request_handle: u32,
    /// The subscription.
    pub subscription_id: u32,
    /// Sequence numbers sent and not acknowledged (this one among them).
    pub available: &'a [u32],
    /// Whether more messages are queued.
    pub more: bool,
    /// This message's sequence number.
    pub sequence_number: u32,
    /// When it was published (OPC UA ticks).
    pub publish_time: i64,
    /// The results of the request's acknowledgements.
    pub results: &'a [StatusCode],
}

/// Encodes the PublishResponse (with its type id) for `publish` carrying
/// `segments` into `body`: the library's encoders around the
/// notifications, the notifications from the templates.
pub fn publish_body(
    publish: &Publish<'_>,
    segments: &[Segment],
    stream: &mut Stream,
    ctx: &Context<'_>,
    body: &mut Vec<u8>,
) -> Result<(), opcua::types::Error> {
    body.clear();
    let n: usize = segments.iter().map(Segment::len).sum();
    let item = stream.item_len();
    let header = ResponseHeader {
        timestamp: DateTime::now(),
        request_handle: publish.request_handle,
        ..ResponseHeader::null()
    };
    NodeId::from(ObjectId::PublishResponse_Encoding_DefaultBinary).encode(body, ctx)?;
    header.encode(body, ctx)?;
    publish.subscription_id.encode(body, ctx)?;
    Some(publish.available.to_vec()).encode(body, ctx)?;
    publish.more.encode(body, ctx)?;
    publish.sequence_number.encode(body, ctx)?;
    DateTime::from(publish.publish_time).encode(body, ctx)?;
    // notification_data: one ExtensionObject, a DataChangeNotification in
    // binary (its length: the items' count, the items, no diagnostics).
    1i32.encode(body, ctx)?;
    NodeId::from(ObjectId::DataChangeNotification_Encoding_DefaultBinary).encode(body, ctx)?;
    1u8.encode(body, ctx)?;
    ((4 + n * item + 4) as i32).encode(body, ctx)?;
    (n as i32).encode(body, ctx)?;
    body.reserve(n * item + 64);
    for s in segments {
        stream.write(s, body);
    }
    (-1i32).encode(body, ctx)?;
    Some(publish.results.to_vec()).encode(body, ctx)?;
    (-1i32).encode(body, ctx)?;
    Ok(())
}

/// Cuts `body` (a message with its type id) into chunks for
/// `request_id`, from chunk sequence number `*sequence` on, each at most
/// `max_chunk` bytes, signed when the channel signs; appends them to
/// `out`.
///
/// # Errors
/// The channel encrypts (this path signs at most), or signing failed.
pub fn chunks(
    channel: &SecureChannel,
    request_id: u32,
    sequence: &mut u32,
    max_chunk: usize,
    body: &[u8],
    scratch: &mut Vec<u8>,
    out: &mut Vec<u8>,
) -> Result<(), StatusCode> {
    let signed = match channel.security_mode() {
        MessageSecurityMode::None => false,
        MessageSecurityMode::Sign => true,
        _ => return Err(StatusCode::BadSecurityModeRejected),
    };
    let signature = if signed {
        channel.security_policy().symmetric_signature_size()
    } else {
        0
    };
    let room = max_chunk - CHUNK_HEADER - signature;
    let mut parts = body.chunks(room).peekable();
    while let Some(part) = parts.next() {
        let last = parts.peek().is_none();
        let size = CHUNK_HEADER + part.len() + signature;
        let header = [b'M', b'S', b'G', if last { b'F' } else { b'C' }];
        let fields = [
            size as u32,
            channel.secure_channel_id(),
            channel.token_id(),
            *sequence,
            request_id,
        ];
        *sequence = sequence.wrapping_add(1);
        let write = |chunk: &mut Vec<u8>| {
            chunk.extend_from_slice(&header);
            for f in fields {
                chunk.extend_from_slice(&f.to_le_bytes());
            }
            chunk.extend_from_slice(part);
        };
        if !signed {
            write(out);
            continue;
        }
        scratch.clear();
        write(scratch);
        scratch.resize(size, 0);
        let at = out.len();
        out.resize(at + size, 0);
        let n = channel.symmetric_sign_and_encrypt(
            &mut scratch[..],
            0..size - signature,
            12..size,
            &mut out[at..],
        )?;
        out.truncate(at + n);
    }
    Ok(())
}

/// A channel whose keys are derived from `local` and `remote` nonces
/// under Basic256Sha256 with `mode`, as an opened one's are (its own
/// certificate and key read from `pki`, if there): the hot path measured
/// without a socket, and the two ends of a test.
pub fn channel_with_keys(
    pki: &std::path::Path,
    role: opcua::core::comms::secure_channel::Role,
    mode: MessageSecurityMode,
    local: &[u8],
    remote: &[u8],
) -> SecureChannel {
    let store = opcua::crypto::CertificateStore::new(pki);
    let mut c = SecureChannel::new(
        std::sync::Arc::new(opcua::sync::RwLock::new(store)),
        role,
        std::sync::Arc::default(),
    );
    let policy = match mode {
        MessageSecurityMode::None => opcua::crypto::SecurityPolicy::None,
        _ => opcua::crypto::SecurityPolicy::Basic256Sha256,
    };
    c.set_security_policy(policy);
    c.set_security_mode(mode);
    c.set_secure_channel_id(7);
    c.set_token_id(1);
    c.set_local_nonce(local);
    c.set_remote_nonce(remote);
    if mode != MessageSecurityMode::None {
        c.derive_keys();
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;
    use opcua::types::{
        ContextOwned, DataChangeNotification, ExtensionObject, NotificationMessage,
        PublishResponse, TimestampsToReturn,
    };

    /// The hot path's message is byte for byte the library's encoding of
    /// the same PublishResponse.
    #[test]
    fn the_hand_built_publish_is_the_librarys() {
        let noise: Vec<u32> = (11..=40).collect();
        let mut stream = Stream::new(&noise, &[1, 2], TimestampsToReturn::Both, 3);
        let from = super::super::stream::ticks(std::time::SystemTime::now());
        let segments = [
            Segment::Switch {
                k: 1,
                closed: false,
                at: from,
            },
            Segment::Noise {
                start: 25,
                len: 40,
                from,
                to: from + 400,
            },
        ];
        let owned = ContextOwned::default();
        let ctx = owned.context();
        let publish = Publish {
            request_handle: 77,
            subscription_id: 5,
            available: &[3, 4],
            more: true,
            sequence_number: 4,
            publish_time: from,
            results: &[StatusCode::Good],
        };
        let mut body = Vec::new();
        publish_body(&publish, &segments, &mut stream, &ctx, &mut body).unwrap();
        let mut items = Vec::new();
        for s in &segments {
            stream.notifications(s, &mut items);
        }
        let mut header = ResponseHeader::null();
        header.request_handle = 77;
        let mut expected = PublishResponse {
            response_header: header,
            subscription_id: 5,
            available_sequence_numbers: Some(vec![3, 4]),
            more_notifications: true,
            notification_message: NotificationMessage {
                sequence_number: 4,
                publish_time: DateTime::from(from),
                notification_data: Some(vec![ExtensionObject::from_message(
                    DataChangeNotification {
                        monitored_items: Some(items),
                        diagnostic_infos: None,
                    },
                )]),
            },
            results: Some(vec![StatusCode::Good]),
            diagnostic_infos: None,
        };
        // The response header's time is the encoder's now: taken from ours.
        let mut at = &body[4..12];
        expected.response_header.timestamp =
            DateTime::from(i64::from_le_bytes(at[..8].try_into().unwrap()));
        at = &at[8..];
        assert!(at.is_empty());
        let mut want = Vec::new();
        NodeId::from(ObjectId::PublishResponse_Encoding_DefaultBinary)
            .encode(&mut want, &ctx)
            .unwrap();
        expected.encode(&mut want, &ctx).unwrap();
        assert_eq!(body, want);
    }

    /// Signed chunks, cut small, verify and decode on the client's side;
    /// one byte changed does not verify.
    #[test]
    fn signed_chunks_verify_at_the_client() {
        use opcua::core::comms::chunker::Chunker;
        use opcua::core::comms::secure_channel::Role;
        use opcua::core::ResponseMessage;
        let (a, b) = ([1u8; 32], [2u8; 32]);
        for mode in [MessageSecurityMode::None, MessageSecurityMode::Sign] {
            // No certificates: signing a message needs only the keys.
            let none = std::path::Path::new("/nonexistent");
            let server = channel_with_keys(none, Role::Server, mode, &a, &b);
            let client = channel_with_keys(none, Role::Client, mode, &b, &a);
            let noise: Vec<u32> = (11..=1010).collect();
            let mut stream = Stream::new(&noise, &[1], TimestampsToReturn::Both, 3);
            let segments = [Segment::Noise {
                start: 0,
                len: 900,
                from: 0,
                to: 15_000,
            }];
            let publish = Publish {
                request_handle: 9,
                subscription_id: 1,
                available: &[1],
                more: false,
                sequence_number: 1,
                publish_time: 0,
                results: &[],
            };
            let owned = ContextOwned::default();
            let mut body = Vec::new();
            publish_body(
                &publish,
                &segments,
                &mut stream,
                &owned.context(),
                &mut body,
            )
            .unwrap();
            let (mut seq, mut scratch, mut out) = (5u32, Vec::new(), Vec::new());
            chunks(&server, 42, &mut seq, 8192, &body, &mut scratch, &mut out).unwrap();
            let expected = body.len().div_ceil(
                8192 - 24
                    - if mode == MessageSecurityMode::Sign {
                        32
                    } else {
                        0
                    },
            );
            assert_eq!(seq, 5 + expected as u32);
            let mut received = Vec::new();
            let mut rest = &out[..];
            while !rest.is_empty() {
                let size = u32::from_le_bytes(rest[4..8].try_into().unwrap()) as usize;
                assert!(size <= 8192);
                let chunk = bytes::Bytes::copy_from_slice(&rest[..size]);
                received.push(client.verify_and_remove_security(chunk).unwrap());
                rest = &rest[size..];
            }
            assert_eq!(received.len(), expected);
            let decoded: ResponseMessage = Chunker::decode(&received, &client, None).unwrap();
            let ResponseMessage::Publish(p) = decoded else {
                panic!("not a publish: {decoded:?}");
            };
            assert_eq!(p.response_header.request_handle, 9);
            let data = p.notification_message.notification_data.unwrap();
            let change = data[0]
                .inner_as::<DataChangeNotification>()
                .unwrap()
                .clone();
            assert_eq!(change.monitored_items.unwrap().len(), 900);
            if mode == MessageSecurityMode::Sign {
                let mut bad = out[..8192].to_vec();
                bad[100] ^= 1;
                assert!(client
                    .verify_and_remove_security(bytes::Bytes::from(bad))
                    .is_err());
            }
        }
    }
}
