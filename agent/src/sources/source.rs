//! What a source is and what it sends: the [`Source`] trait, its events,
//! and the operators' writes it carries to the PLC. Every source and the
//! cell loop import this; it imports none of them.

use cellwatch_models::engine::TagReading;
use std::path::PathBuf;
use std::time::Duration;

use futures_util::future::BoxFuture;
use tokio::sync::mpsc;

/// How many events may wait between a source and the cell loop.
pub const QUEUE_CAPACITY: usize = 1024;

/// One publish's values and when the agent received them: the start of
/// the latency `cellwatch_alarm_latency_seconds` measures.
#[derive(Debug, Clone, PartialEq)]
pub struct Batch {
    /// The values, in source-time order.
    pub readings: Vec<TagReading>,
    /// When the source had them from the PLC.
    pub received: std::time::Instant,
}

impl From<Vec<TagReading>> for Batch {
    /// Values received now.
    fn from(readings: Vec<TagReading>) -> Batch {
        Batch {
            readings,
            received: std::time::Instant::now(),
        }
    }
}

impl IntoIterator for Batch {
    type Item = TagReading;
    type IntoIter = std::vec::IntoIter<TagReading>;

    fn into_iter(self) -> Self::IntoIter {
        self.readings.into_iter()
    }
}

impl<'a> IntoIterator for &'a Batch {
    type Item = &'a TagReading;
    type IntoIter = std::slice::Iter<'a, TagReading>;

    fn into_iter(self) -> Self::IntoIter {
        self.readings.iter()
    }
}

impl std::ops::Deref for Batch {
    type Target = [TagReading];

    fn deref(&self) -> &[TagReading] {
        &self.readings
    }
}

/// What a source tells the cell loop.
#[derive(Debug, Clone, PartialEq)]
pub enum SourceEvent {
    /// The connection is up and the subscription is in place; to what.
    Connected(String),
    /// The connection is lost; why.
    Disconnected(String),
    /// Values delivered together (one publish), in source-time order.
    Readings(Batch),
    /// Something about the source that is not the connection (a namespace
    /// missing on the server): raises the `system` alarm `id` with the
    /// problem, or clears it with `None`.
    Problem {
        /// The alarm's id (`opcua-namespace`).
        id: String,
        /// What is wrong, or `None` when nothing is.
        problem: Option<String>,
    },
    /// The connection is back and nothing was lost: the server kept
    /// what changed meanwhile and sends it next, in order. Each value from
    /// before the cut stands until a change says otherwise. Sent before
    /// those changes.
    Resumed,
    /// Events of the PLC's own alarms (OPC UA Alarms & Conditions), in
    /// the order the server sent them.
    Conditions(Vec<cellwatch_models::engine::PlcCondition>),
    /// The conditions the server holds now for the notifier of alarm-id
    /// prefix `prefix` (its answer to a refresh, told after their events):
    /// any other alarm of that prefix has ended and been acknowledged at
    /// the PLC.
    ConditionsHeld {
        /// The notifier's alarm-id prefix.
        prefix: String,
        /// The alarm ids of the conditions it holds.
        held: Vec<String>,
    },
    /// Changes were lost for good (a sequence gap the server could not
    /// fill, values dropped from a full queue): sent before the values
    /// that follow the gap.
    Gap {
        /// The tags that lost changes; `None`: any of them may have.
        tags: Option<Vec<usize>>,
        /// How many values were lost, when the source knows (0 if not).
        values: u64,
        /// What was lost, for the alarms judged across it.
        why: String,
    },
}

/// The sending half a source writes to: bounded, so a slow cell loop makes
/// the source wait.
pub type SourceSender = mpsc::Sender<SourceEvent>;

/// A write to the PLC an operator asked for, already verified and
/// authorised by the cell loop.
#[derive(Debug)]
pub struct WriteRequest {
    /// The tag written (index into the cell's tags); `None` for what
    /// names its own target (an acknowledgement).
    pub tag: Option<usize>,
    /// What to write.
    pub what: Write,
    /// What the PLC answered (`Ok`: done), or why it was not done.
    pub reply: tokio::sync::oneshot::Sender<Result<String, WriteError>>,
}

/// What a write puts into the PLC.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Write {
    /// A value as the operator gave it (an `@` unit's item); the source
    /// checks and encodes it, and sends nothing if it does not fit.
    Value(String),
    /// A push button: the Boolean tag on for this long, then off, each
    /// read back (the force and stop switches of paper 004, over OPC UA).
    Pulse(std::time::Duration),
    /// An operator's acknowledgement of one of the PLC's own alarms: the
    /// condition's `Acknowledge` method, with `comment` saying who.
    Acknowledge {
        /// The alarm's id.
        alarm: String,
        /// Who acknowledged it, and where.
        comment: String,
    },
}

/// Where the cell loop hands writes to its source.
pub type WriteSender = mpsc::Sender<WriteRequest>;

/// Writes waiting for a source, at most.
pub const WRITE_CAPACITY: usize = 8;

/// Why a write was not done: the source's own error, kept whole (each
/// source has its own error type; this module knows none of them).
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    /// The source takes no such write (its kind, its tag, a value that
    /// does not fit): nothing was sent to the PLC.
    #[error(transparent)]
    Refused(Box<dyn std::error::Error + Send + Sync>),
    /// The PLC was asked and did not do it: it refused, did not answer,
    /// or the connection failed meanwhile.
    #[error(transparent)]
    Failed(Box<dyn std::error::Error + Send + Sync>),
}

/// Why a source cannot run. Connection trouble is never an error: it is
/// reported as [`SourceEvent::Disconnected`] and retried.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    /// The agent's OPC UA key pair cannot be made (a connection with
    /// security needs one).
    #[error("OPC UA client: the agent's OPC UA key pair in {}: {source}", pki_dir.display())]
    KeyPair {
        /// The PKI directory.
        pki_dir: PathBuf,
        /// Why.
        #[source]
        source: crate::sources::pki::PkiError,
    },
    /// The agent's private key is unusable (readable by others).
    #[error("OPC UA client: {0}")]
    PrivateKey(#[source] crate::sources::pki::PkiError),
    /// The OPC UA stack refused the client's configuration.
    #[error("OPC UA client: {}", problems.join("; "))]
    Client {
        /// The stack's problems with it.
        problems: Vec<String>,
    },
    /// The password's environment variable is not set.
    #[error("OPC UA identity: environment variable {var} is not set")]
    PasswordVariable {
        /// The variable.
        var: String,
    },
    /// The password file cannot be read.
    #[error("OPC UA identity: cannot read {}: {source}", path.display())]
    PasswordFile {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// A one-off connection found the server's certificate untrusted.
    #[error("OPC UA connection: {endpoint}: {why}")]
    Untrusted {
        /// The server's endpoint URL.
        endpoint: String,
        /// The certificate, and the command that trusts it.
        why: String,
    },
    /// A one-off connection failed (sources retry instead).
    #[error("OPC UA connection: {endpoint}: {source}")]
    Connect {
        /// The server's endpoint URL.
        endpoint: String,
        /// The stack's error.
        #[source]
        source: opcua::types::Error,
    },
    /// A one-off connection got no session: the server refused it (the
    /// status says why) or did not answer.
    #[error("OPC UA connection: {why}")]
    Refused {
        /// The server's endpoint URL.
        endpoint: String,
        /// The status the connection ended with; `None`: no answer.
        status: Option<opcua::types::StatusCode>,
        /// What happened and what to do, naming the endpoint.
        why: String,
    },
    /// A one-off connection's server did not send its endpoints in time.
    #[error("OPC UA connection: {endpoint}: no answer to the request for its endpoints within {} s", within.as_secs())]
    NoEndpoints {
        /// The server's endpoint URL.
        endpoint: String,
        /// How long it was given.
        within: Duration,
    },
    /// A one-off connection cannot listen for the server's reverse connect.
    #[error("OPC UA connection: {endpoint}: cannot listen on {addr} for the server to connect (opcua.reverse_listen): {source}; if the cell's agent is running there, stop it first (an untrusted server certificate it saw is in {}/rejected/)", pki_dir.display())]
    ReverseListen {
        /// The server's endpoint URL.
        endpoint: String,
        /// The address.
        addr: std::net::SocketAddr,
        /// The agent's PKI directory.
        pki_dir: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
}

/// A producer of tag values for one cell.
pub trait Source: Send + 'static {
    /// What it is, for logs (`opcua opc.tcp://...`).
    fn describe(&self) -> String;

    /// Where to send operators' writes, if this source can write to its
    /// PLC (called once, before `run`).
    fn writer(&mut self) -> Option<WriteSender> {
        None
    }

    /// Where to count the requests it makes of its PLC, by service and
    /// result (`cellwatch_opcua_requests_total`), if it makes any (called
    /// once, before `run`).
    fn count_requests(&mut self, _counter: prometheus::IntCounterVec) {}

    /// How long a change the PLC saw may take to reach the agent, beyond
    /// the moment its source timestamp names: the publishing interval of a
    /// subscription. Zero for a source that stamps readings on arrival.
    fn delivery_allowance(&self) -> Duration {
        Duration::ZERO
    }

    /// Where it listens for its PLC to connect to it (an OPC UA server's
    /// reverse connect), once bound.
    fn listening(&self) -> Option<std::net::SocketAddr> {
        None
    }

    /// Runs until `shutdown` completes, sending events on `tx`.
    ///
    /// # Errors
    /// The source cannot be set up at all (its configuration is unusable).
    fn run(
        self: Box<Self>,
        tx: SourceSender,
        shutdown: BoxFuture<'static, ()>,
    ) -> BoxFuture<'static, Result<(), SourceError>>;
}
