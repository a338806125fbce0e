//! One client's connection to the replay source: the Hello answered, raw
//! messages read off the socket by a task of their own, chunks checked
//! and decoded into requests by async-opcua's secure channel and chunker,
//! and answers written back: typed ones chunked and secured by the
//! library, publishes by the hot path (`frame.rs`). Both share the
//! channel's chunk sequence numbers.

use opcua::core::comms::chunker::Chunker;
use opcua::core::comms::message_chunk::{MessageChunk, MessageIsFinalType};
use opcua::core::comms::secure_channel::{Role, SecureChannel};
use opcua::core::comms::security_header::SecurityHeader;
use opcua::core::comms::sequence_number::SequenceNumberHandle;
use opcua::core::comms::tcp_types::{AcknowledgeMessage, HelloMessage};
use opcua::core::{RequestMessage, ResponseMessage};
use opcua::crypto::CertificateStore;
use opcua::sync::RwLock;
use opcua::types::{
    ContextOwned, DecodingOptions, NamespaceMap, SimpleBinaryDecodable, SimpleBinaryEncodable,
};
use std::sync::Arc;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::tcp::{OwnedReadHalf, OwnedWriteHalf};
use tokio::net::TcpStream;
use tokio::sync::mpsc;

use super::frame::{self, Publish};
use super::stream::{Segment, Stream};

/// The largest chunk the source accepts or sends, bytes.
const BUFFER: u32 = 1 << 16;

/// A request decoded from its chunks.
pub struct Request {
    /// The request id its chunks carried (the answer's).
    pub id: u32,
    /// The security header of its first chunk (an OpenSecureChannel's
    /// holds the client's certificate).
    pub security: SecurityHeader,
    /// The request.
    pub message: RequestMessage,
}

/// A client's connection, after the Hello.
pub struct Wire {
    write: OwnedWriteHalf,
    /// The secure channel: its policy, mode, keys, ids.
    pub channel: SecureChannel,
    /// The next chunk's sequence number (typed answers and publishes).
    sequence: u32,
    /// The client's receive buffer: the largest chunk it takes.
    max_chunk: usize,
    /// Chunks of a request not complete yet.
    pending: Vec<MessageChunk>,
    /// Reusable buffers: a message's body, a chunk before signing, the
    /// bytes to write.
    body: Vec<u8>,
    scratch: Vec<u8>,
    out: Vec<u8>,
}

/// Reads whole messages (header and all) off `read` into `tx` until it
/// closes or fails.
async fn read_messages(mut read: OwnedReadHalf, tx: mpsc::Sender<bytes::Bytes>) {
    loop {
        let mut header = [0u8; 8];
        if read.read_exact(&mut header).await.is_err() {
            return;
        }
        let size = u32::from_le_bytes([header[4], header[5], header[6], header[7]]) as usize;
        if !(8..=64 << 20).contains(&size) {
            return;
        }
        let mut message = vec![0u8; size];
        message[..8].copy_from_slice(&header);
        if read.read_exact(&mut message[8..]).await.is_err() {
            return;
        }
        if tx.send(message.into()).await.is_err() {
            return;
        }
    }
}

impl Wire {
    /// Takes `stream`'s Hello and answers it; the messages that follow
    /// arrive on the receiver.
    ///
    /// # Errors
    /// The first message is no Hello, or the socket failed.
    pub async fn accept(
        stream: TcpStream,
        store: Arc<RwLock<CertificateStore>>,
    ) -> anyhow::Result<(Wire, mpsc::Receiver<bytes::Bytes>)> {
        let _ = stream.set_nodelay(true);
        let (read, mut write) = stream.into_split();
        let (tx, mut rx) = mpsc::channel(64);
        tokio::spawn(read_messages(read, tx));
        let hello = rx
            .recv()
            .await
            .ok_or_else(|| anyhow::anyhow!("closed before its Hello"))?;
        anyhow::ensure!(hello.starts_with(b"HEL"), "the first message is no Hello");
        let options = decoding_options();
        let hello = HelloMessage::decode(&mut &hello[..], &options)?;
        let max_chunk = hello.receive_buffer_size.min(BUFFER);
        let ack = AcknowledgeMessage::new(
            0,
            hello.send_buffer_size.min(BUFFER),
            max_chunk,
            hello.max_message_size,
            hello.max_chunk_count,
        );
        let mut buf = Vec::new();
        ack.encode(&mut buf)?;
        write.write_all(&buf).await?;
        let context = ContextOwned::new_default(NamespaceMap::new(), options);
        let channel = SecureChannel::new(store, Role::Server, Arc::new(RwLock::new(context)));
        Ok((
            Wire {
                write,
                channel,
                sequence: 1,
                max_chunk: max_chunk as usize,
                pending: Vec::new(),
                body: Vec::new(),
                scratch: Vec::new(),
                out: Vec::new(),
            },
            rx,
        ))
    }

    /// One raw message taken: a request once its last chunk is in.
    ///
    /// # Errors
    /// A chunk fails its security or does not decode.
    pub fn receive(&mut self, raw: bytes::Bytes) -> Result<Option<Request>, opcua::types::Error> {
        let chunk = self.channel.verify_and_remove_security_server(raw)?;
        let header = chunk.message_header(&self.channel.decoding_options())?;
        match header.is_final {
            MessageIsFinalType::FinalError => {
                self.pending.clear();
                return Ok(None);
            }
            MessageIsFinalType::Intermediate => {
                self.pending.push(chunk);
                return Ok(None);
            }
            MessageIsFinalType::Final => self.pending.push(chunk),
        }
        let chunks = std::mem::take(&mut self.pending);
        let info = chunks[0].chunk_info(&self.channel)?;
        let message = Chunker::decode(&chunks, &self.channel, None)?;
        Ok(Some(Request {
            id: info.sequence_header.request_id,
            security: info.security_header,
            message,
        }))
    }

    /// Writes a typed answer, chunked and secured by the library.
    ///
    /// # Errors
    /// It does not encode, or the socket failed.
    pub async fn send(&mut self, request_id: u32, message: ResponseMessage) -> anyhow::Result<()> {
        let mut numbers = SequenceNumberHandle::new(true);
        numbers.set(self.sequence);
        let chunks = Chunker::encode(
            numbers,
            request_id,
            0,
            self.max_chunk,
            &self.channel,
            &message,
        )?;
        self.sequence = self.sequence.wrapping_add(chunks.len() as u32);
        self.out.clear();
        let mut buf = vec![0u8; self.max_chunk + 4096];
        for c in &chunks {
            let n = self.channel.apply_security(c, &mut buf)?;
            self.out.extend_from_slice(&buf[..n]);
        }
        self.write.write_all(&self.out).await?;
        Ok(())
    }

    /// Writes a publish answer through the hot path.
    ///
    /// # Errors
    /// The channel encrypts, or the socket failed.
    pub async fn send_publish(
        &mut self,
        request_id: u32,
        publish: &Publish<'_>,
        segments: &[Segment],
        stream: &mut Stream,
    ) -> anyhow::Result<()> {
        {
            let context = self.channel.context();
            frame::publish_body(
                publish,
                segments,
                stream,
                &context.context(),
                &mut self.body,
            )?;
        }
        self.out.clear();
        frame::chunks(
            &self.channel,
            request_id,
            &mut self.sequence,
            self.max_chunk,
            &self.body,
            &mut self.scratch,
            &mut self.out,
        )?;
        self.write.write_all(&self.out).await?;
        Ok(())
    }
}

/// Limits for a client's requests: a CreateMonitoredItems of 10,000
/// items, certificates, no limit on the message or its chunks.
fn decoding_options() -> DecodingOptions {
    DecodingOptions {
        max_message_size: 0,
        max_chunk_count: 0,
        max_array_length: 1_000_000,
        ..Default::default()
    }
}
