//! The plant operators list on the agent's side (`commands.plant_key`):
//! the newest list it holds is kept in a file (`commands.plant_list`), so
//! a restart without the bus still judges by it; lists put on
//! `<root>/_plant/operators` (`cellwatch plant publish`) are heard, and
//! at start every other agent is asked for the one it holds (an agent
//! that was down when a list was put catches up from its peers). A list is
//! taken only if the plant administrator's key verifies it and its version
//! is newer than the one held: the cell loop judges commands by its
//! operators from then on and journals the change; `about` says the
//! version held. The agent answers `<prefix>/operators` with it.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use ed25519_dalek::VerifyingKey;
use tokio::sync::{mpsc, oneshot, watch};
use zenoh::Session;

use crate::bus::keys::{every_cells_operators, plant_operators, root_of, CellKeys};
use crate::bus::ZenohError;
use crate::operator::plant::{admin_key, PlantList, SignedList};
use crate::operator::{KeysError, OperatorKeys};
use crate::payload::AboutPayload;
use crate::step::{OperatorsTaken, Request};

type Subscriber =
    zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>;
type Queryable = zenoh::query::Queryable<zenoh::handlers::FifoChannelHandler<zenoh::query::Query>>;

/// When, after start, the other agents are asked for their lists (the
/// session may still be reaching its routers at the first).
const ASK_AFTER: [Duration; 3] = [
    Duration::from_millis(200),
    Duration::from_secs(5),
    Duration::from_secs(30),
];

/// The list held, as read at start.
pub struct Held {
    list: PlantList,
    signed: SignedList,
}

impl Held {
    /// Its version.
    pub fn version(&self) -> u64 {
        self.list.version
    }
}

/// Where a cell takes its operators from when the plant signs them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PlantOperatorsConfig {
    /// The plant administrator's Ed25519 public key, 64 hex digits.
    pub key: String,
    /// The newest list taken, kept across restarts.
    pub list: PathBuf,
}

/// The parts of a cell's configuration the operators' list reads.
#[derive(Debug, Clone, Copy)]
pub struct OperatorsSetup<'a> {
    /// The cell's id.
    pub cell: &'a str,
    /// The cell's key prefix on the bus.
    pub prefix: &'a str,
    /// `commands.operators_file`, if any.
    pub operators_file: Option<&'a Path>,
    /// The plant's list, when the configuration has a plant key.
    pub plant: Option<&'a PlantOperatorsConfig>,
}

/// The operators a cell judges commands by when it starts or reads its
/// configuration again: the kept plant operators list's, if the plant
/// signs them and one is kept, else the operators file's.
///
/// # Errors
/// The operators file or the kept list does not read, or the
/// administrator's key does not verify the list: the file is named.
pub(crate) fn operators(
    config: OperatorsSetup<'_>,
) -> Result<(OperatorKeys, Option<Held>), KeysError> {
    let from_file = match &config.operators_file {
        Some(path) => OperatorKeys::load(path)?,
        None => OperatorKeys::default(),
    };
    initial(config, from_file)
}

/// The held list's operators for the cell, if one is kept, else
/// `from_file`.
fn initial(
    config: OperatorsSetup<'_>,
    from_file: OperatorKeys,
) -> Result<(OperatorKeys, Option<Held>), KeysError> {
    let Some(p) = config.plant else {
        return Ok((from_file, None));
    };
    let bytes = match std::fs::read(&p.list) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok((from_file, None)),
        Err(source) => {
            return Err(KeysError::Read {
                path: p.list.clone(),
                source,
            })
        }
    };
    let at = |message: String| KeysError::Syntax {
        origin: p.list.display().to_string(),
        message,
    };
    let key = admin_key(&p.key).map_err(|e| at(format!("commands.plant_key: {e}")))?;
    let at = |e: crate::operator::plant::ListError| at(e.to_string());
    let signed = SignedList::parse(&bytes).map_err(at)?;
    let list = signed.open(&key).map_err(at)?;
    let keys = list.keys_for(config.cell).map_err(at)?;
    tracing::info!(
        cell = %config.cell,
        version = list.version,
        operators = keys.len(),
        "the plant operators list kept in {} is the one commands are judged by",
        p.list.display()
    );
    Ok((keys, Some(Held { list, signed })))
}

/// The list's side of the agent's services.
pub struct Listener {
    cell: String,
    /// `<prefix>/operators`: where it answers (its own key, whatever the
    /// query's wildcard).
    mine: String,
    admin: VerifyingKey,
    file: PathBuf,
    held: Option<Held>,
    heard: Subscriber,
    asked: Queryable,
    /// What the other agents answered to the asking at start.
    answered: mpsc::Receiver<Vec<u8>>,
    about: Arc<watch::Sender<AboutPayload>>,
}

impl Listener {
    /// Declares what the list needs on `session`, when `config` has a
    /// plant key; starts asking the other agents.
    ///
    /// # Errors
    /// Zenoh refuses a declaration.
    pub async fn declare(
        session: &Session,
        config: OperatorsSetup<'_>,
        held: Option<Held>,
        about: Arc<watch::Sender<AboutPayload>>,
    ) -> Result<Option<Listener>, ZenohError> {
        let Some(p) = config.plant else {
            return Ok(None);
        };
        let Ok(admin) = admin_key(&p.key) else {
            return Ok(None);
        };
        let root = root_of(config.prefix).to_string();
        let declare_error = |key: String| {
            move |e: zenoh::Error| ZenohError::Declare {
                key,
                reason: e.to_string(),
            }
        };
        let heard = session
            .declare_subscriber(plant_operators(&root))
            .with(zenoh::handlers::FifoChannel::new(8))
            .await
            .map_err(declare_error(plant_operators(&root)))?;
        let mine = CellKeys::new(config.prefix.to_string()).operators();
        let asked = session
            .declare_queryable(mine.clone())
            .with(zenoh::handlers::FifoChannel::new(8))
            .await
            .map_err(declare_error(mine.clone()))?;
        let (tx, answered) = mpsc::channel(64);
        let asking = session.clone();
        tokio::spawn(async move {
            for after in ASK_AFTER {
                tokio::time::sleep(after).await;
                let Ok(replies) = asking
                    .get(every_cells_operators(&root))
                    .timeout(Duration::from_secs(5))
                    .await
                else {
                    return;
                };
                while let Ok(reply) = replies.recv_async().await {
                    if let Ok(sample) = reply.result() {
                        if tx.send(sample.payload().to_bytes().to_vec()).await.is_err() {
                            return;
                        }
                    }
                }
            }
        });
        if let Some(h) = &held {
            about.send_modify(|a| a.operators_version = Some(h.list.version));
        }
        Ok(Some(Listener {
            cell: config.cell.to_string(),
            mine,
            admin,
            file: p.list.clone(),
            held,
            heard,
            asked,
            answered,
            about,
        }))
    }

    /// The next list heard or answered, or a query for the one held.
    pub async fn next(&mut self) -> Heard {
        tokio::select! {
            Ok(sample) = self.heard.recv_async() => Heard::List(sample.payload().to_bytes().to_vec()),
            Some(bytes) = self.answered.recv() => Heard::List(bytes),
            Ok(query) = self.asked.recv_async() => Heard::Asked(query),
            else => std::future::pending().await,
        }
    }

    /// Answers `query` with the list held (an error when none is).
    pub async fn answer(&self, query: zenoh::query::Query) {
        let key = self.mine.clone();
        let sent = match &self.held {
            Some(h) => {
                query
                    .reply(key, serde_json::to_string(&h.signed).unwrap_or_default())
                    .await
            }
            None => query.reply_err("no plant operators list held").await,
        };
        if let Err(e) = sent {
            tracing::debug!(error = %e, "answering for the plant operators list failed");
        }
    }

    /// Takes the list in `bytes` if the administrator signed it and it is
    /// newer than the one held: the cell loop judges by its operators,
    /// then the file keeps it.
    pub async fn consider(&mut self, bytes: &[u8], requests: &mpsc::Sender<Request>) {
        let opened = SignedList::parse(bytes).and_then(|s| Ok((s.open(&self.admin)?, s)));
        let (list, signed) = match opened {
            Ok(o) => o,
            Err(e) => {
                tracing::warn!(cell = %self.cell, "a plant operators list refused: {e}");
                return;
            }
        };
        let held = self.held.as_ref().map_or(0, |h| h.list.version);
        if list.version <= held {
            if list.version == held && self.held.as_ref().is_some_and(|h| h.list != list) {
                tracing::warn!(cell = %self.cell, version = held, "a plant operators list of the version held but other operators: refused (a version is signed once)");
            }
            return;
        }
        let keys = match list.keys_for(&self.cell) {
            Ok(k) => k,
            Err(e) => {
                tracing::warn!(cell = %self.cell, "plant operators list v{}: {e}", list.version);
                return;
            }
        };
        let (reply, taken) = oneshot::channel();
        let asked = OperatorsTaken {
            version: list.version,
            keys,
            reply,
        };
        if requests.send(Request::Operators(asked)).await.is_err() || taken.await.is_err() {
            return;
        }
        if let Err(e) = keep(&self.file, &signed) {
            tracing::error!(cell = %self.cell, "the plant operators list v{} is taken but cannot be kept: {e}", list.version);
        }
        let version = list.version;
        self.about
            .send_modify(|a| a.operators_version = Some(version));
        self.held = Some(Held { list, signed });
    }
}

/// What the listener heard.
pub enum Heard {
    /// A list (to consider).
    List(Vec<u8>),
    /// A query for the list held.
    Asked(zenoh::query::Query),
}

/// Writes `signed` to `path`: beside it first, then renamed.
fn keep(path: &Path, signed: &SignedList) -> std::io::Result<()> {
    let text = serde_json::to_string(signed).unwrap_or_default();
    let partial = path.with_extension("partial");
    std::fs::write(&partial, text)?;
    std::fs::rename(&partial, path)
}
