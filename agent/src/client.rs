//! The bus client: what a process that is not a cell's agent does on the
//! bus — asks agents (history, snapshot, signed commands) and listens to
//! their alarms — believing only what the plant trust file verifies.
//!
//! It owns asking well: a querier that takes every answer, waiting for the
//! agent's queryable to be known, a fresh nonce per query (an answer is
//! believed only if the agent sealed it for that very query), asking again
//! while there is no answer yet or the agent is busy, and telling an
//! agent's own error answer apart from no answer at all ([`ClientError`]).
//! The CLI's commands (`alarms`, `history`, `ack`, …) print what it
//! returns; it prints nothing itself. Keys come from [`crate::bus::keys`].

use std::time::Duration;

use crate::bus::config::ZenohConfig;
use crate::bus::envelope::{Distrust, Kind, Opened, Trust};
use crate::bus::keys::{CellKeys, Service};
use crate::bus::ZenohError;
use crate::operator::{Action, Command};
use crate::step::{command_digest, CommandOutcome};

/// What an agent answers when it is answering as many queries as it may.
pub const BUSY: &str = "the agent is busy";

/// The pause before a query that got no answer, or "busy", is asked
/// again.
const RETRY_AFTER: Duration = Duration::from_millis(250);

/// The least a force waits for its answer: the agent answers once the
/// chart got there, or the force timed out.
pub const FORCE_ANSWER: Duration = Duration::from_secs(75);

/// Why the bus client got no believable answer.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// The session's configuration was refused (not TLS, a file missing):
    /// the caller's input.
    #[error(transparent)]
    Config(ZenohError),
    /// The session could not be opened or a declaration failed.
    #[error(transparent)]
    Bus(ZenohError),
    /// Zenoh refused the query itself.
    #[error("query failed: {0}")]
    Query(String),
    /// The cell's agent answered with an error (a bad request, busy, …).
    #[error(transparent)]
    Answered(ErrorAnswer),
    /// The cell's agent answered a command with something else than a
    /// command's outcome.
    #[error("not a command's outcome: {0}")]
    NotAnOutcome(#[source] serde_json::Error),
    /// An answer believed, but sealed by another cell's agent.
    #[error("{what}: answered by cell {from}'s agent, not {cell}'s")]
    OtherCell {
        /// What was asked.
        what: String,
        /// The cell whose agent answered.
        from: String,
        /// The cell asked.
        cell: String,
    },
    /// Nothing believed came back in time.
    #[error("{}", no_answer(.cell, .what, .not_believed))]
    NoAnswer {
        /// The cell asked.
        cell: String,
        /// What was asked.
        what: String,
        /// Why each answer that came was not believed.
        not_believed: Vec<String>,
    },
}

/// An agent's error answer, believed: what it said (a bad request, "the
/// agent is busy", …), after the key it said it on when Zenoh carried it
/// as an error.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{}{said}", .key.as_deref().map(|k| format!("{k}: ")).unwrap_or_default())]
pub struct ErrorAnswer {
    /// The key of the service that answered, for an answer Zenoh carried
    /// as an error.
    pub key: Option<String>,
    /// What the agent said.
    pub said: String,
}

impl ErrorAnswer {
    /// Whether the agent said it is busy (asked again).
    pub fn busy(&self) -> bool {
        self.said.contains(BUSY)
    }
}

/// Why an answer that came was not believed (said with the Zenoh session
/// it came from).
#[derive(Debug, thiserror::Error)]
#[error("{why} (from Zenoh session {from})")]
struct NotBelieved {
    /// Why.
    why: Distrust,
    /// The session that sent it, or "an unknown node".
    from: String,
}

fn no_answer(cell: &str, what: &str, not_believed: &[String]) -> String {
    if not_believed.is_empty() {
        format!("the agent of cell {cell} did not answer {what}")
    } else {
        format!(
            "the agent of cell {cell} did not answer {what}; {} answer(s) were not believed: {}",
            not_believed.len(),
            not_believed.join("; ")
        )
    }
}

/// A client's view of the bus: its session, the plant trust file every
/// payload is opened against, and the root of the agents' prefixes.
#[derive(Clone)]
pub struct BusClient {
    session: zenoh::Session,
    trust: Trust,
    root: String,
}

/// One believed answer of a cell's agent to a query on several cells
/// ([`BusClient::ask_every`]).
pub struct CellAnswer {
    /// The cell whose agent sealed it.
    pub cell: String,
    /// Its text, or its error answer.
    pub answer: Result<String, ErrorAnswer>,
}

impl BusClient {
    /// Opens a client's session (TLS only unless `plain`, listening on
    /// nothing, linking only to the endpoints given).
    ///
    /// # Errors
    /// [`ClientError::Config`] for a configuration Zenoh or cellwatch
    /// refuses, [`ClientError::Bus`] when nothing can be reached.
    pub async fn open(
        config: &ZenohConfig,
        trust: Trust,
        root: &str,
    ) -> Result<BusClient, ClientError> {
        let session = crate::bus::open(config).await.map_err(|e| match e {
            e @ (ZenohError::Insecure { .. } | ZenohError::Config { .. }) => ClientError::Config(e),
            e => ClientError::Bus(e),
        })?;
        Ok(BusClient::on(session, trust, root))
    }

    /// A client on a session opened elsewhere.
    pub fn on(session: zenoh::Session, trust: Trust, root: &str) -> BusClient {
        BusClient {
            session,
            trust,
            root: root.into(),
        }
    }

    /// The session.
    pub fn session(&self) -> &zenoh::Session {
        &self.session
    }

    /// The plant trust file.
    pub fn trust(&self) -> &Trust {
        &self.trust
    }

    /// The keys of `cell` (`*`: every cell).
    pub fn keys(&self, cell: &str) -> CellKeys {
        CellKeys::of(&self.root, cell)
    }

    /// Opens an alarm event put on `key`: believed only if the cell's own
    /// agent sealed it for this key, whoever relayed it.
    ///
    /// # Errors
    /// Why it is not believed.
    pub fn open_put(&self, payload: &[u8], key: &str) -> Result<Opened, Distrust> {
        self.trust.open(payload, Kind::Put, key, "")
    }

    /// Asks `service` of `cell`'s agent with `parameters` (`a=1;b=2`, a
    /// fresh nonce added) and `payload`, and returns its believed answer.
    /// No answer yet, or "busy", is asked again until `timeout`.
    ///
    /// # Errors
    /// As [`ClientError`].
    pub async fn ask(
        &self,
        cell: &str,
        service: Service,
        parameters: &str,
        payload: Option<String>,
        timeout: Duration,
    ) -> Result<String, ClientError> {
        let judge = |answer: &Result<String, ErrorAnswer>| match answer {
            Err(why) if why.busy() => Judged::Again,
            _ => Judged::Take,
        };
        self.ask_judging(cell, service, parameters, payload, timeout, judge)
            .await
    }

    /// [`BusClient::ask`], each believed answer judged by `judge`: taken,
    /// asked again (busy), or not the answer to what was asked (skipped,
    /// as an answer not believed).
    async fn ask_judging(
        &self,
        cell: &str,
        service: Service,
        parameters: &str,
        payload: Option<String>,
        timeout: Duration,
        judge: impl Fn(&Result<String, ErrorAnswer>) -> Judged,
    ) -> Result<String, ClientError> {
        let key = self.keys(cell).service(service);
        let what = if parameters.is_empty() {
            key.clone()
        } else {
            format!("{key}?{parameters}")
        };
        let querier = self.querier(&key, timeout).await?;
        wait_for_queryable(&querier, timeout).await;
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            let asked = if parameters.is_empty() {
                fresh()
            } else {
                format!("{parameters};{}", fresh())
            };
            let mut get = querier.get().parameters(asked.as_str());
            if let Some(p) = &payload {
                get = get.payload(p.clone());
            }
            let replies = get.await.map_err(|e| ClientError::Query(e.to_string()))?;
            let answer = self.first_believed(replies, &key, &asked, &judge).await;
            let again = match &answer {
                Answer::Nothing(refused) => refused.is_empty(),
                Answer::Agent(_, answer) => matches!(judge(answer), Judged::Again),
            };
            if again && tokio::time::Instant::now() + RETRY_AFTER < deadline {
                tracing::debug!(key, "no answer yet, or busy: asking again");
                tokio::time::sleep(RETRY_AFTER).await;
                continue;
            }
            return answer.of(cell, &what);
        }
    }

    /// Asks `service` of every agent under the root (`<root>/*/…`) once and
    /// returns each believed answer; why the others were not believed in
    /// the second list. A cell's agent is believed only for its own cell.
    ///
    /// # Errors
    /// Zenoh refused the query.
    pub async fn ask_every(
        &self,
        cell: &str,
        service: Service,
        timeout: Duration,
    ) -> Result<(Vec<CellAnswer>, Vec<String>), ClientError> {
        let key = self.keys(cell).service(service);
        let parameters = fresh();
        let querier = self.querier(&key, timeout).await?;
        wait_for_queryable(&querier, timeout).await;
        let replies = querier
            .get()
            .parameters(parameters.as_str())
            .await
            .map_err(|e| ClientError::Query(e.to_string()))?;
        let mut answers = Vec::new();
        let mut refused = Vec::new();
        while let Ok(reply) = replies.recv_async().await {
            match self.open_reply(&reply, &key, &parameters) {
                Ok((cell, answer)) => answers.push(CellAnswer { cell, answer }),
                Err(why) => {
                    tracing::error!(key, why = %why, "an answer not believed: ignored");
                    refused.push(why.to_string());
                }
            }
        }
        Ok((answers, refused))
    }

    /// Sends the signed command `cmd` to `cell`'s agent (a force waits at
    /// least [`FORCE_ANSWER`]) and returns (accepted, detail), believed
    /// only if `cell`'s agent sealed it for this query and it names this
    /// very payload ([`command_digest`]): the agent's answer to another or
    /// a garbled payload sent with the same parameters is never taken. The
    /// same command sent before (its first answer lost, or someone sent it
    /// first) is answered as a replay: what its first sending came to,
    /// said so.
    ///
    /// # Errors
    /// As [`BusClient::ask`]; an error answer is [`ClientError::Answered`].
    pub async fn command(
        &self,
        cell: &str,
        cmd: &Command,
        timeout: Duration,
    ) -> Result<(bool, String), ClientError> {
        let timeout = if cmd.action == Action::Force {
            timeout.max(FORCE_ANSWER)
        } else {
            timeout
        };
        let payload = serde_json::to_string(cmd).unwrap_or_default();
        let digest = command_digest([payload.as_bytes()]);
        let judge = |answer: &Result<String, ErrorAnswer>| judge_command(answer, &digest);
        let text = self
            .ask_judging(
                cell,
                Service::Command,
                "",
                Some(payload.clone()),
                timeout,
                judge,
            )
            .await?;
        let outcome: CommandOutcome =
            serde_json::from_str(&text).map_err(ClientError::NotAnOutcome)?;
        Ok(match outcome.replayed {
            Some(first) => (
                first.accepted,
                format!(
                    "{} (sent before: the outcome of its first sending; not carried out again)",
                    first.detail
                ),
            ),
            None => (outcome.accepted, outcome.detail),
        })
    }

    /// A querier on `key` that takes every answer (none consolidated away).
    async fn querier(
        &self,
        key: &str,
        timeout: Duration,
    ) -> Result<zenoh::query::Querier<'_>, ClientError> {
        self.session
            .declare_querier(key.to_string())
            .consolidation(zenoh::query::ConsolidationMode::None)
            .timeout(timeout)
            .await
            .map_err(|e| ClientError::Query(e.to_string()))
    }

    /// The first believed answer among `replies`; answers not believed are
    /// logged and named when nothing was believed.
    async fn first_believed(
        &self,
        replies: zenoh::handlers::FifoChannelHandler<zenoh::query::Reply>,
        key: &str,
        parameters: &str,
        judge: &impl Fn(&Result<String, ErrorAnswer>) -> Judged,
    ) -> Answer {
        let mut refused = Vec::new();
        while let Ok(reply) = replies.recv_async().await {
            let opened = match self.open_reply(&reply, key, parameters) {
                Err(not_believed) => Err(not_believed.to_string()),
                Ok((cell, answer)) => match judge(&answer) {
                    Judged::Unbound(why) => Err(why),
                    _ => Ok((cell, answer)),
                },
            };
            match opened {
                Ok((cell, answer)) => return Answer::Agent(cell, answer),
                Err(why) => {
                    tracing::error!(key, why = %why, "an answer not believed: ignored");
                    refused.push(why);
                }
            }
        }
        Answer::Nothing(refused)
    }

    /// Opens one reply to a query with `parameters` on `key`: believed
    /// only if a cell's agent in the trust file sealed it for this query.
    /// Returns the cell and its answer (`Err`: its error answer), or why it
    /// is not believed.
    fn open_reply(
        &self,
        reply: &zenoh::query::Reply,
        key: &str,
        parameters: &str,
    ) -> Result<(String, Result<String, ErrorAnswer>), NotBelieved> {
        let from = reply
            .replier_id()
            .map_or_else(|| "an unknown node".into(), |id| id.zid().to_string());
        let distrust = |why: Distrust| NotBelieved {
            why,
            from: from.clone(),
        };
        match reply.result() {
            Ok(sample) => {
                let opened = self
                    .trust
                    .open(
                        &sample.payload().to_bytes(),
                        Kind::Reply,
                        sample.key_expr().as_str(),
                        parameters,
                    )
                    .map_err(distrust)?;
                let body = match opened.kind {
                    Kind::Error => Err(ErrorAnswer {
                        key: None,
                        said: opened.body,
                    }),
                    _ => Ok(opened.body),
                };
                Ok((opened.cell, body))
            }
            Err(e) => {
                // An error answer has no key of its own: the envelope's, if
                // it is one the query could be answered on.
                let bytes = e.payload().to_bytes();
                let sealed_on = serde_json::from_slice::<serde_json::Value>(&bytes)
                    .ok()
                    .and_then(|v| v["key"].as_str().map(str::to_string))
                    .unwrap_or_default();
                let fits = match (
                    zenoh::key_expr::KeyExpr::try_from(sealed_on.as_str()),
                    zenoh::key_expr::KeyExpr::try_from(key),
                ) {
                    (Ok(a), Ok(b)) => a.intersects(&b),
                    _ => false,
                };
                if !fits {
                    return Err(distrust(Distrust::NotAnEnvelope(format!(
                        "an error answer sealed for '{sealed_on}', not {key}"
                    ))));
                }
                let opened = self
                    .trust
                    .open(&bytes, Kind::Reply, &sealed_on, parameters)
                    .map_err(distrust)?;
                Ok((
                    opened.cell,
                    Err(ErrorAnswer {
                        key: Some(key.into()),
                        said: opened.body,
                    }),
                ))
            }
        }
    }
}

/// What a caller makes of an answer its cell's agent sealed for its query.
enum Judged {
    /// The answer.
    Take,
    /// "Busy": ask again.
    Again,
    /// Sealed for this query, but not the answer to what was sent: why.
    Unbound(String),
}

/// Judges an answer to the command whose payload's digest is `digest`:
/// only an outcome naming it is the command's.
fn judge_command(answer: &Result<String, ErrorAnswer>, digest: &str) -> Judged {
    let text = match answer {
        Ok(text) => text,
        // An agent that answers commands with outcomes only never sends
        // these; "busy" costs only another try.
        Err(why) if why.busy() => return Judged::Again,
        Err(why) => {
            return Judged::Unbound(format!(
                "an error answer that names no command: {}",
                crate::operator::escaped(&why.to_string())
            ))
        }
    };
    let Ok(outcome) = serde_json::from_str::<CommandOutcome>(text) else {
        return Judged::Unbound("an answer that is not a command's outcome".into());
    };
    match outcome.command.as_deref() {
        Some(d) if d == digest => {}
        Some(d) => {
            return Judged::Unbound(format!(
                "the answer to another command (sha256 {}), not to this one ({})",
                crate::operator::escaped(d),
                digest
            ))
        }
        None => return Judged::Unbound("an answer that names no command".into()),
    }
    if !outcome.accepted && outcome.replayed.is_none() && outcome.detail.contains(BUSY) {
        Judged::Again
    } else {
        Judged::Take
    }
}

/// A fresh query parameter: an answer is believed only if the agent
/// sealed it for this very query.
fn fresh() -> String {
    format!("nonce={}", crate::operator::nonce())
}

/// What came back to one query.
enum Answer {
    /// A cell's agent's answer (believed): the cell and its text, or its
    /// error answer.
    Agent(String, Result<String, ErrorAnswer>),
    /// Nothing believed; why each answer that came was not.
    Nothing(Vec<String>),
}

impl Answer {
    fn of(self, cell: &str, what: &str) -> Result<String, ClientError> {
        match self {
            Answer::Agent(from, _) if from != cell => Err(ClientError::OtherCell {
                what: what.into(),
                from,
                cell: cell.into(),
            }),
            Answer::Agent(_, answer) => answer.map_err(ClientError::Answered),
            Answer::Nothing(not_believed) => Err(ClientError::NoAnswer {
                cell: cell.into(),
                what: what.into(),
                not_believed,
            }),
        }
    }
}

/// Waits, up to `timeout`, until a queryable for the querier's key is
/// known: a session just opened may not know the agents' queryables yet.
async fn wait_for_queryable(querier: &zenoh::query::Querier<'_>, timeout: Duration) {
    let Ok(listener) = querier.matching_listener().await else {
        return;
    };
    let known = querier
        .matching_status()
        .await
        .map(|m| m.matching())
        .unwrap_or(false);
    if !known {
        let deadline = tokio::time::Instant::now() + timeout;
        while let Ok(Ok(status)) = tokio::time::timeout_at(deadline, listener.recv_async()).await {
            if status.matching() {
                break;
            }
        }
    }
}
