//! What every request to the console passes before it is served: the
//! `Host` and `Origin` it names (a page from another site, or a name
//! rebound to this address, gets nothing), the client's share of the
//! console (connections, requests a second, live streams, agents' history
//! asked at once), and who it is ([`super::access`]).
//!
//! Every count here is bounded by what it counts: clients by the
//! connections the console takes, identities by its sessions, cells by
//! the trust file.

use std::collections::{BTreeMap, HashMap};
use std::net::IpAddr;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::sync::{OwnedSemaphorePermit, Semaphore};
use tokio::time::Instant;

use super::access::{Identity, Readers, Sessions};

/// The most connections one client address holds at once.
pub(super) const CONNECTIONS_EACH: usize = 64;
/// Requests a second one client address may make to `/api/`, on average.
pub(super) const REQUESTS_PER_SECOND: f64 = 20.0;
/// Requests one client address may make at once before the average
/// counts (a page that opens asks a few things together).
pub(super) const REQUESTS_BURST: f64 = 100.0;
/// The most live streams (`/api/events`) one identity holds at once.
pub(super) const STREAMS_EACH: usize = 8;
/// The most history questions one identity has asked of agents at once.
pub(super) const HISTORY_EACH: usize = 2;
/// The most history questions the console asks of one agent at once,
/// whoever asks: an agent answers four at a time, and operators' own
/// `cellwatch history` keeps the rest.
pub(super) const HISTORY_PER_AGENT: usize = 2;
/// The most client addresses remembered; past it, those with no
/// connection are forgotten.
const CLIENTS_KEPT: usize = 16_384;
/// How long a question waits for its turn before the client is told the
/// console is busy.
pub(super) const TURN: Duration = Duration::from_secs(10);

/// A client address's share.
struct Client {
    connections: usize,
    tokens: f64,
    refilled: Instant,
}

/// The console's doors and counts.
pub(super) struct Gate {
    /// The host names the console answers to (lowercase, no port).
    names: Vec<String>,
    /// The readers' rules.
    pub(super) readers: Readers,
    /// Sign-in challenges and sessions.
    pub(super) sessions: Mutex<Sessions>,
    /// Each client address's connections and request budget; an address
    /// with no connection is forgotten once its budget is whole again.
    clients: Mutex<HashMap<IpAddr, Client>>,
    /// Each identity's live streams.
    streams: Mutex<HashMap<String, usize>>,
    /// Each identity's turn at agents' history (an entry per identity
    /// that asked; identities are bounded by the sessions).
    history_each: Mutex<HashMap<String, Arc<Semaphore>>>,
    /// Each cell's turn at its agent's history (one per trusted cell).
    history_cell: BTreeMap<String, Arc<Semaphore>>,
}

impl Gate {
    /// The gate of a console known as `names`, reading `cells`.
    pub(super) fn new<'a>(
        names: Vec<String>,
        readers: Readers,
        sessions: Sessions,
        cells: impl IntoIterator<Item = &'a str>,
    ) -> Gate {
        Gate {
            names,
            readers,
            sessions: Mutex::new(sessions),
            clients: Mutex::default(),
            streams: Mutex::default(),
            history_each: Mutex::default(),
            history_cell: cells
                .into_iter()
                .map(|c| (c.to_string(), Arc::new(Semaphore::new(HISTORY_PER_AGENT))))
                .collect(),
        }
    }

    /// Whether `host` (a `Host` header, or an `Origin`'s host, with or
    /// without its port) is one of the console's names.
    pub(super) fn known_host(&self, host: &str) -> bool {
        let name = host_name(host).to_ascii_lowercase();
        self.names.contains(&name)
    }

    /// Takes a connection of `ip`; `None` when it holds
    /// [`CONNECTIONS_EACH`] already. The connection is given back when
    /// the guard drops.
    pub(super) fn connect(self: &Arc<Self>, ip: IpAddr, now: Instant) -> Option<ConnectionGuard> {
        let mut clients = self.clients.lock().ok()?;
        if clients.len() >= CLIENTS_KEPT && !clients.contains_key(&ip) {
            let whole = Duration::from_secs_f64(REQUESTS_BURST / REQUESTS_PER_SECOND);
            clients.retain(|_, c| c.connections > 0 || now.duration_since(c.refilled) < whole);
            if clients.len() >= CLIENTS_KEPT {
                clients.retain(|_, c| c.connections > 0);
            }
        }
        let c = clients.entry(ip).or_insert(Client {
            connections: 0,
            tokens: REQUESTS_BURST,
            refilled: now,
        });
        if c.connections >= CONNECTIONS_EACH {
            return None;
        }
        c.connections += 1;
        Some(ConnectionGuard {
            gate: self.clone(),
            ip,
        })
    }

    /// Whether `ip` may make one more request now.
    pub(super) fn request(&self, ip: IpAddr, now: Instant) -> bool {
        let Ok(mut clients) = self.clients.lock() else {
            return false;
        };
        let Some(c) = clients.get_mut(&ip) else {
            return false;
        };
        let earned = now.duration_since(c.refilled).as_secs_f64() * REQUESTS_PER_SECOND;
        c.tokens = (c.tokens + earned).min(REQUESTS_BURST);
        c.refilled = now;
        if c.tokens < 1.0 {
            return false;
        }
        c.tokens -= 1.0;
        true
    }

    /// Takes a live stream for `who`; `None` when they hold
    /// [`STREAMS_EACH`] already.
    pub(super) fn stream(self: &Arc<Self>, who: &Identity) -> Option<StreamGuard> {
        let mut streams = self.streams.lock().ok()?;
        let n = streams.entry(who.name.clone()).or_default();
        if *n >= STREAMS_EACH {
            return None;
        }
        *n += 1;
        Some(StreamGuard {
            gate: self.clone(),
            name: who.name.clone(),
        })
    }

    /// Waits for `who`'s turn and `cell`'s turn at an agent's history, at
    /// most `wait` ([`TURN`]); `None`: the console is busy for them.
    pub(super) async fn history_turn(
        &self,
        who: &Identity,
        cell: &str,
        wait: Duration,
    ) -> Option<(OwnedSemaphorePermit, OwnedSemaphorePermit)> {
        let theirs = self
            .history_each
            .lock()
            .ok()?
            .entry(who.name.clone())
            .or_insert_with(|| Arc::new(Semaphore::new(HISTORY_EACH)))
            .clone();
        let agents = self.history_cell.get(cell)?.clone();
        tokio::time::timeout(wait, async move {
            let mine = theirs.acquire_owned().await.ok()?;
            let agent = agents.acquire_owned().await.ok()?;
            Some((mine, agent))
        })
        .await
        .ok()
        .flatten()
    }
}

/// A client's connection, given back on drop.
pub(super) struct ConnectionGuard {
    gate: Arc<Gate>,
    ip: IpAddr,
}

impl Drop for ConnectionGuard {
    fn drop(&mut self) {
        if let Ok(mut clients) = self.gate.clients.lock() {
            if let Some(c) = clients.get_mut(&self.ip) {
                c.connections -= 1;
            }
        }
    }
}

/// An identity's live stream, given back on drop.
pub(super) struct StreamGuard {
    gate: Arc<Gate>,
    name: String,
}

impl Drop for StreamGuard {
    fn drop(&mut self) {
        if let Ok(mut streams) = self.gate.streams.lock() {
            if let Some(n) = streams.get_mut(&self.name) {
                *n -= 1;
                if *n == 0 {
                    streams.remove(&self.name);
                }
            }
        }
    }
}

/// The host of a `Host` header or an origin's authority, without its
/// port: `[::1]:8470` → `[::1]`, `console:8443` → `console`.
pub(super) fn host_name(host: &str) -> &str {
    if host.starts_with('[') {
        return host.find(']').map_or(host, |end| &host[..=end]);
    }
    match host.rsplit_once(':') {
        Some((name, port)) if port.bytes().all(|b| b.is_ascii_digit()) => name,
        _ => host,
    }
}

/// The names a console answers to: loopback's, its listening address
/// (unless every address), its certificate's, and those configured.
pub(super) fn names_of(
    listen: std::net::SocketAddr,
    certificate: &[String],
    configured: &[String],
) -> Vec<String> {
    let mut names: Vec<String> = ["localhost", "127.0.0.1", "[::1]"].map(String::from).into();
    let ip = listen.ip();
    if !ip.is_unspecified() {
        names.push(match ip {
            IpAddr::V4(v4) => v4.to_string(),
            IpAddr::V6(v6) => format!("[{v6}]"),
        });
    }
    names.extend(certificate.iter().map(|n| n.to_ascii_lowercase()));
    names.extend(configured.iter().cloned());
    names.sort();
    names.dedup();
    names
}

#[cfg(test)]
mod tests {
    use super::super::access::{Proof, Scope};
    use super::*;

    fn gate() -> Arc<Gate> {
        let readers =
            Readers::resolve(None, &BTreeMap::new(), &std::collections::BTreeSet::new()).unwrap();
        Arc::new(Gate::new(
            names_of(
                "0.0.0.0:8443".parse().unwrap(),
                &["Console.Plant.Example".into()],
                &[],
            ),
            readers,
            Sessions::new(Duration::from_secs(60)),
            ["press7"],
        ))
    }

    #[test]
    fn hosts_are_known_by_name_whatever_the_port() {
        let g = gate();
        for known in [
            "localhost:8443",
            "127.0.0.1",
            "[::1]:8443",
            "console.plant.example:8443",
        ] {
            assert!(g.known_host(known), "{known}");
        }
        for unknown in [
            "attacker.example",
            "attacker.example:8443",
            "0.0.0.0:8443",
            "[::2]",
        ] {
            assert!(!g.known_host(unknown), "{unknown}");
        }
    }

    #[tokio::test]
    async fn a_client_has_its_connections_and_its_requests_a_second() {
        let g = gate();
        let now = Instant::now();
        let ip: IpAddr = "10.0.0.7".parse().unwrap();
        let held: Vec<_> = (0..CONNECTIONS_EACH)
            .map(|_| g.connect(ip, now).expect("within the bound"))
            .collect();
        assert!(g.connect(ip, now).is_none());
        assert!(g.connect("10.0.0.8".parse().unwrap(), now).is_some());
        let granted = (0..200).filter(|_| g.request(ip, now)).count();
        assert_eq!(granted, REQUESTS_BURST as usize);
        assert!(g.request(ip, now + Duration::from_secs(1)));
        drop(held);
        // A client that closes its connections keeps what it spent.
        let later = now + Duration::from_secs(1);
        let _again = g.connect(ip, later).unwrap();
        assert_eq!((0..200).filter(|_| g.request(ip, later)).count(), 19);
    }

    #[tokio::test]
    async fn an_identity_has_its_streams_and_its_turns_at_history() {
        let g = gate();
        let kim = Identity {
            name: "kim".into(),
            by: Proof::OperatorKey,
            scope: Scope::Every,
        };
        let streams: Vec<_> = (0..STREAMS_EACH).map(|_| g.stream(&kim).unwrap()).collect();
        assert!(g.stream(&kim).is_none());
        drop(streams);
        assert!(g.stream(&kim).is_some());
        let wait = Duration::from_millis(50);
        let first = g.history_turn(&kim, "press7", TURN).await.unwrap();
        let second = g.history_turn(&kim, "press7", TURN).await.unwrap();
        // The third waits for a turn that does not come, and is told busy.
        assert!(g.history_turn(&kim, "press7", wait).await.is_none());
        drop(first);
        assert!(g.history_turn(&kim, "press7", TURN).await.is_some());
        drop(second);
        assert!(g.history_turn(&kim, "unknown-cell", TURN).await.is_none());
    }
}
