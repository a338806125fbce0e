//! Who is asking the console, and what they may read.
//!
//! Nothing of the plant is served to a client without a plant identity:
//! - a **client certificate** from the plant CA (mutual TLS, with
//!   `http.tls.clients`): the identity is the certificate's common name,
//!   as on the bus (`operator-kim`, `dashboard-hall`);
//! - or an **operator signed in with their own key**: the console hands
//!   out a fresh challenge, the page signs [`sign_in_text`] with the
//!   operator's private key (which never leaves the browser), and the
//!   console checks it against the operators file's public key; the
//!   answer is a session cookie that expires (`http.session`).
//!
//! What an identity may read is its [`Scope`]: every cell, or the cells
//! and areas `[readers]` gives it. Without `[readers]` every plant
//! identity reads every cell, as every plant certificate does on the bus.
//! Everything here is bounded: challenges, sessions, sessions per
//! identity.

use std::collections::{BTreeMap, BTreeSet, HashMap, VecDeque};
use std::time::Duration;

use ed25519_dalek::{Signature, Verifier, VerifyingKey};
use tokio::time::Instant;

/// What the page signs to sign in: the challenge the console gave and the
/// host the page was served from (a signature made for another console
/// signs another text).
pub(super) fn sign_in_text(challenge: &str, host: &str) -> String {
    format!("cellwatch-console-sign-in-v1\n{challenge}\n{host}\n")
}

/// How long a challenge may be answered.
const CHALLENGE_LIFE: Duration = Duration::from_secs(60);
/// The most challenges outstanding at once; the oldest goes first.
const MAX_CHALLENGES: usize = 1024;
/// The most sessions at once; the oldest goes first.
const MAX_SESSIONS: usize = 4096;
/// The most sessions one identity holds; its oldest goes first.
const MAX_SESSIONS_EACH: usize = 16;

/// The cookie that carries a session.
pub(super) const COOKIE: &str = "cellwatch-session";

/// Who is asking.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) struct Identity {
    /// The operator's name, or the client certificate's common name.
    pub(super) name: String,
    /// How it was proven.
    pub(super) by: Proof,
    /// What it may read.
    pub(super) scope: Scope,
}

/// How an identity was proven.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Proof {
    /// A client certificate from the plant CA.
    Certificate,
    /// An operator's signature with their own key.
    OperatorKey,
}

impl Proof {
    pub(super) fn as_str(self) -> &'static str {
        match self {
            Proof::Certificate => "certificate",
            Proof::OperatorKey => "operator key",
        }
    }
}

/// The cells an identity may read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) enum Scope {
    /// Every cell of the trust file.
    Every,
    /// These cells only.
    Cells(BTreeSet<String>),
}

impl Scope {
    /// Whether `cell` may be read.
    pub(super) fn covers(&self, cell: &str) -> bool {
        match self {
            Scope::Every => true,
            Scope::Cells(cells) => cells.contains(cell),
        }
    }
}

/// Why a sign-in was refused (said to the page as it is).
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub(super) enum SignInError {
    /// The challenge was never given, was used, or expired.
    #[error("the sign-in challenge is unknown or expired: sign in again")]
    Challenge,
    /// The operator is not in the operators file.
    #[error("no operator '{0}' in the console's operators file")]
    UnknownOperator(String),
    /// The signature is not the operator's over this challenge and host.
    #[error("this is not the key the operators file holds for '{0}'")]
    BadSignature(String),
    /// The operator may read nothing (`[readers]`).
    #[error("operator '{0}' may read no cell here ([readers])")]
    NoCells(String),
}

/// Names in `[readers]` that are neither `*`, an area nor a cell of the
/// trust file: each with its reader, one a line.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[error("{}", unknown_readers(.0))]
pub(super) struct UnknownNames(Vec<(String, String)>);

fn unknown_readers(names: &[(String, String)]) -> String {
    names
        .iter()
        .map(|(who, name)| {
            format!(
                "readers.{who}: '{name}' is neither an area of [areas] nor a cell of the trust file"
            )
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// The readers' rules: who reads which cells.
#[derive(Debug, Clone)]
pub(super) struct Readers {
    /// Identity → cells; `None`: every identity reads every cell.
    rules: Option<BTreeMap<String, Scope>>,
}

impl Readers {
    /// Resolves `[readers]` (identity → areas, cells or `*`) against the
    /// areas and the trust file's cells.
    ///
    /// # Errors
    /// A name that is neither `*`, an area nor a cell of the trust file,
    /// said with its reader.
    pub(super) fn resolve(
        readers: Option<&BTreeMap<String, Vec<String>>>,
        areas: &BTreeMap<String, Vec<String>>,
        cells: &BTreeSet<String>,
    ) -> Result<Readers, UnknownNames> {
        let Some(readers) = readers else {
            return Ok(Readers { rules: None });
        };
        let mut rules = BTreeMap::new();
        let mut problems = Vec::new();
        for (who, names) in readers {
            let mut scope = BTreeSet::new();
            let mut every = false;
            for name in names {
                if name == "*" {
                    every = true;
                } else if let Some(members) = areas.get(name) {
                    scope.extend(members.iter().cloned());
                } else if cells.contains(name) {
                    scope.insert(name.clone());
                } else {
                    problems.push((who.clone(), name.clone()));
                }
            }
            let scope = if every {
                Scope::Every
            } else {
                Scope::Cells(scope)
            };
            rules.insert(who.clone(), scope);
        }
        if problems.is_empty() {
            Ok(Readers { rules: Some(rules) })
        } else {
            Err(UnknownNames(problems))
        }
    }

    /// What `name` may read; `None`: nothing.
    pub(super) fn scope_of(&self, name: &str) -> Option<Scope> {
        match &self.rules {
            None => Some(Scope::Every),
            Some(rules) => rules
                .get(name)
                .filter(|s| !matches!(s, Scope::Cells(c) if c.is_empty()))
                .cloned(),
        }
    }
}

struct Session {
    identity: Identity,
    expires: Instant,
}

/// The challenges given and the sessions opened, bounded.
pub(super) struct Sessions {
    life: Duration,
    challenges: HashMap<String, Instant>,
    challenge_order: VecDeque<String>,
    sessions: HashMap<String, Session>,
    session_order: VecDeque<String>,
}

impl Sessions {
    /// No challenge, no session; a session lasts `life`.
    pub(super) fn new(life: Duration) -> Sessions {
        Sessions {
            life,
            challenges: HashMap::new(),
            challenge_order: VecDeque::new(),
            sessions: HashMap::new(),
            session_order: VecDeque::new(),
        }
    }

    /// How long a session lasts.
    pub(super) fn life(&self) -> Duration {
        self.life
    }

    /// A fresh challenge, valid for a minute and once.
    pub(super) fn challenge(&mut self, now: Instant) -> String {
        let challenge = random_hex();
        while self.challenges.len() >= MAX_CHALLENGES {
            let Some(oldest) = self.challenge_order.pop_front() else {
                break;
            };
            self.challenges.remove(&oldest);
        }
        self.challenges
            .insert(challenge.clone(), now + CHALLENGE_LIFE);
        self.challenge_order.push_back(challenge.clone());
        challenge
    }

    /// Checks an operator's signature over the challenge and `host`, and
    /// opens a session for them; returns its token and the identity.
    ///
    /// # Errors
    /// The challenge is unknown or expired, the operator unknown, the
    /// signature not theirs, or they may read nothing.
    pub(super) fn sign_in(
        &mut self,
        now: Instant,
        answer: &SignIn,
        host: &str,
        operators: &[(String, String, Vec<crate::operator::Action>)],
        readers: &Readers,
    ) -> Result<(String, Identity), SignInError> {
        // A challenge is taken whatever follows: one try each.
        match self.challenges.remove(&answer.challenge) {
            Some(until) if until > now => {}
            _ => return Err(SignInError::Challenge),
        }
        self.challenge_order.retain(|c| c != &answer.challenge);
        let Some((_, public, _)) = operators.iter().find(|(n, _, _)| *n == answer.operator) else {
            return Err(SignInError::UnknownOperator(answer.operator.clone()));
        };
        let bad = || SignInError::BadSignature(answer.operator.clone());
        let key = hex::decode(public)
            .ok()
            .and_then(|b| <[u8; 32]>::try_from(b).ok())
            .and_then(|b| VerifyingKey::from_bytes(&b).ok())
            .ok_or_else(bad)?;
        let signature = hex::decode(&answer.signature)
            .ok()
            .and_then(|b| <[u8; 64]>::try_from(b).ok())
            .map(|b| Signature::from_bytes(&b))
            .ok_or_else(bad)?;
        key.verify(sign_in_text(&answer.challenge, host).as_bytes(), &signature)
            .map_err(|_| bad())?;
        let scope = readers
            .scope_of(&answer.operator)
            .ok_or_else(|| SignInError::NoCells(answer.operator.clone()))?;
        let identity = Identity {
            name: answer.operator.clone(),
            by: Proof::OperatorKey,
            scope,
        };
        Ok((self.open(now, identity.clone()), identity))
    }

    fn open(&mut self, now: Instant, identity: Identity) -> String {
        self.expire(now);
        let theirs: Vec<String> = self
            .session_order
            .iter()
            .filter(|t| {
                self.sessions
                    .get(*t)
                    .is_some_and(|s| s.identity.name == identity.name)
            })
            .cloned()
            .collect();
        if theirs.len() >= MAX_SESSIONS_EACH {
            self.close(&theirs[0]);
        }
        while self.sessions.len() >= MAX_SESSIONS {
            let Some(oldest) = self.session_order.pop_front() else {
                break;
            };
            self.sessions.remove(&oldest);
        }
        let token = random_hex();
        self.sessions.insert(
            token.clone(),
            Session {
                identity,
                expires: now + self.life,
            },
        );
        self.session_order.push_back(token.clone());
        token
    }

    /// The identity of a session token, if it is open.
    pub(super) fn identity(&self, now: Instant, token: &str) -> Option<Identity> {
        self.sessions
            .get(token)
            .filter(|s| s.expires > now)
            .map(|s| s.identity.clone())
    }

    /// Ends a session.
    pub(super) fn close(&mut self, token: &str) {
        if self.sessions.remove(token).is_some() {
            self.session_order.retain(|t| t != token);
        }
    }

    fn expire(&mut self, now: Instant) {
        while let Some(oldest) = self.session_order.front() {
            match self.sessions.get(oldest) {
                Some(s) if s.expires > now => break,
                _ => {
                    if let Some(t) = self.session_order.pop_front() {
                        self.sessions.remove(&t);
                    }
                }
            }
        }
        while let Some(oldest) = self.challenge_order.front() {
            match self.challenges.get(oldest) {
                Some(until) if *until > now => break,
                _ => {
                    if let Some(c) = self.challenge_order.pop_front() {
                        self.challenges.remove(&c);
                    }
                }
            }
        }
    }

    /// How many sessions are open (for tests and the log).
    #[cfg(test)]
    fn open_sessions(&self) -> usize {
        self.sessions.len()
    }
}

/// A signed sign-in, as the page posts it.
#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct SignIn {
    /// The operator's name.
    pub(super) operator: String,
    /// The challenge given.
    pub(super) challenge: String,
    /// Ed25519 over [`sign_in_text`], hex.
    pub(super) signature: String,
}

/// 32 random bytes, hex.
fn random_hex() -> String {
    use rand::RngCore;
    let mut bytes = [0u8; 32];
    rand::rngs::OsRng.fill_bytes(&mut bytes);
    hex::encode(bytes)
}

/// The session token in a `Cookie` header, if any.
pub(super) fn session_cookie(header: &str) -> Option<&str> {
    header
        .split(';')
        .filter_map(|c| c.trim().split_once('='))
        .find(|(name, _)| *name == COOKIE)
        .map(|(_, value)| value)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::operator::Action;
    use ed25519_dalek::{Signer, SigningKey};

    const KIM: [u8; 32] = [7; 32];

    fn operators() -> Vec<(String, String, Vec<Action>)> {
        let kim = SigningKey::from_bytes(&KIM);
        let public = hex::encode(kim.verifying_key().to_bytes());
        vec![("kim".into(), public, vec![Action::Ack])]
    }

    fn signed(s: &mut Sessions, now: Instant, host: &str) -> SignIn {
        let challenge = s.challenge(now);
        let kim = SigningKey::from_bytes(&KIM);
        let signature = hex::encode(
            kim.sign(sign_in_text(&challenge, host).as_bytes())
                .to_bytes(),
        );
        SignIn {
            operator: "kim".into(),
            challenge,
            signature,
        }
    }

    fn every() -> Readers {
        Readers::resolve(None, &BTreeMap::new(), &BTreeSet::new()).unwrap()
    }

    #[tokio::test]
    async fn an_operator_signs_in_once_per_challenge_for_a_while() {
        let mut s = Sessions::new(Duration::from_secs(3600));
        let now = Instant::now();
        let answer = signed(&mut s, now, "127.0.0.1:8470");
        let (token, who) = s
            .sign_in(now, &answer, "127.0.0.1:8470", &operators(), &every())
            .unwrap();
        assert_eq!(who.name, "kim");
        assert_eq!(who.scope, Scope::Every);
        assert_eq!(s.identity(now, &token).map(|i| i.name), Some("kim".into()));
        // The same answer again: the challenge was used.
        assert_eq!(
            s.sign_in(now, &answer, "127.0.0.1:8470", &operators(), &every()),
            Err(SignInError::Challenge)
        );
        // The session ends when its life does.
        assert!(s
            .identity(now + Duration::from_secs(3601), &token)
            .is_none());
    }

    #[tokio::test]
    async fn a_signature_for_another_host_or_by_another_key_is_refused() {
        let mut s = Sessions::new(Duration::from_secs(3600));
        let now = Instant::now();
        let answer = signed(&mut s, now, "console.evil.example");
        assert_eq!(
            s.sign_in(now, &answer, "127.0.0.1:8470", &operators(), &every()),
            Err(SignInError::BadSignature("kim".into()))
        );
        let mut answer = signed(&mut s, now, "h");
        answer.operator = "ana".into();
        assert_eq!(
            s.sign_in(now, &answer, "h", &operators(), &every()),
            Err(SignInError::UnknownOperator("ana".into()))
        );
        let late = signed(&mut s, now, "h");
        assert_eq!(
            s.sign_in(now + CHALLENGE_LIFE, &late, "h", &operators(), &every()),
            Err(SignInError::Challenge)
        );
    }

    #[tokio::test]
    async fn sessions_and_challenges_are_bounded() {
        let mut s = Sessions::new(Duration::from_secs(3600));
        let now = Instant::now();
        let first = signed(&mut s, now, "h");
        for _ in 0..MAX_CHALLENGES {
            s.challenge(now);
        }
        assert_eq!(s.challenges.len(), MAX_CHALLENGES);
        assert_eq!(
            s.sign_in(now, &first, "h", &operators(), &every()),
            Err(SignInError::Challenge),
            "the oldest challenge went first"
        );
        let mut tokens = Vec::new();
        for _ in 0..MAX_SESSIONS_EACH + 3 {
            let a = signed(&mut s, now, "h");
            tokens.push(s.sign_in(now, &a, "h", &operators(), &every()).unwrap().0);
        }
        assert_eq!(s.open_sessions(), MAX_SESSIONS_EACH);
        assert!(s.identity(now, &tokens[0]).is_none());
        assert!(s.identity(now, tokens.last().unwrap()).is_some());
    }

    #[test]
    fn readers_resolve_areas_and_cells_and_name_what_is_neither() {
        let areas = BTreeMap::from([("press-shop".to_string(), vec!["press7".to_string()])]);
        let cells: BTreeSet<String> = ["press7", "m01"].map(String::from).into();
        let rules = BTreeMap::from([
            (
                "kim".to_string(),
                vec!["press-shop".to_string(), "m01".to_string()],
            ),
            ("dashboard".to_string(), vec!["*".to_string()]),
            ("nobody".to_string(), vec![]),
        ]);
        let r = Readers::resolve(Some(&rules), &areas, &cells).unwrap();
        assert_eq!(
            r.scope_of("kim"),
            Some(Scope::Cells(["press7", "m01"].map(String::from).into()))
        );
        assert_eq!(r.scope_of("dashboard"), Some(Scope::Every));
        assert_eq!(r.scope_of("nobody"), None);
        assert_eq!(r.scope_of("stranger"), None);
        let bad = BTreeMap::from([("kim".to_string(), vec!["press-shpo".to_string()])]);
        assert_eq!(
            Readers::resolve(Some(&bad), &areas, &cells)
                .unwrap_err()
                .to_string(),
            "readers.kim: 'press-shpo' is neither an area of [areas] nor a cell of the trust file"
        );
    }

    #[test]
    fn the_session_cookie_is_found_among_others() {
        assert_eq!(
            session_cookie("a=1; cellwatch-session=abc; b=2"),
            Some("abc")
        );
        assert_eq!(session_cookie("a=1"), None);
    }
}
