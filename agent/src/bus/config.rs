//! `[zenoh]`: the Zenoh session: mode, endpoints, TLS, keys, and which
//! links are refused. The table as written ([`RawZenoh`]), the validated
//! configuration ([`ZenohConfig`]) and its check (`validate`).

use std::path::PathBuf;

use serde::Deserialize;
use toml::Spanned;

use crate::table::Table;

/// Zenoh session mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ZenohMode {
    /// Peer (default; loopback).
    Peer,
    /// Client of a router.
    Client,
    /// Router.
    Router,
}

impl ZenohMode {
    /// The name zenoh's config uses.
    pub fn as_str(self) -> &'static str {
        match self {
            ZenohMode::Peer => "peer",
            ZenohMode::Client => "client",
            ZenohMode::Router => "router",
        }
    }
}

/// Why a Zenoh configuration file is not one: what a reader can act on.
#[derive(Debug, thiserror::Error)]
pub enum ZenohFileError {
    /// The file cannot be read (missing, not allowed).
    #[error(transparent)]
    Unreadable(std::io::Error),
    /// Zenoh refuses it: Zenoh's words, without the place in Zenoh's own
    /// source its errors end with.
    #[error("{0}")]
    Refused(String),
}

/// A Zenoh configuration file (JSON5, or YAML by its extension), read as
/// Zenoh reads it.
///
/// # Errors
/// The file cannot be read, or Zenoh refuses it.
pub fn zenoh_file(path: &std::path::Path) -> Result<zenoh::Config, ZenohFileError> {
    std::fs::metadata(path).map_err(ZenohFileError::Unreadable)?;
    zenoh::Config::from_file(path).map_err(|e| {
        let said = e.to_string();
        // `… at /…/zenoh-config-1.10.2/src/lib.rs:1507.`
        ZenohFileError::Refused(match said.rsplit_once(" at ") {
            Some((words, place)) if place.contains(".rs:") => words.to_string(),
            _ => said,
        })
    })
}

/// Why `endpoint` cannot carry a secure bus, if it cannot. The bus runs
/// mutual TLS over QUIC (`quic/host:port`). Zenoh's TLS-over-TCP link
/// (`tls/`) is refused: it reads and writes one TLS stream from two
/// threads at once (eclipse-zenoh/zenoh#2557, open in Zenoh 1.10), which
/// under load breaks the connection (queries then end with no answer) and
/// is undefined behaviour.
pub fn link_problem(endpoint: &str) -> Option<String> {
    if endpoint.starts_with("quic/") {
        None
    } else if endpoint.starts_with("tls/") {
        Some(format!(
            "Zenoh's tls/ link breaks its connections under load (it reads and writes one TLS stream from two threads at once, eclipse-zenoh/zenoh#2557): write {} instead, with the same certificates (mutual TLS over QUIC, UDP)",
            endpoint.replacen("tls/", "quic/", 1)
        ))
    } else {
        Some(
            "not an encrypted endpoint: the bus takes quic/host:port (mutual TLS over QUIC)".into(),
        )
    }
}

/// The root of every cell's keys unless `zenoh.key_prefix` says otherwise.
pub const DEFAULT_ROOT: &str = "cellwatch";

/// A cell's key prefix under a root: `<root>/<cell>`. The one place the
/// prefix is spelled; the keys under it are `crate::bus::keys`'.
pub fn cell_prefix(root: &str, cell: &str) -> String {
    format!("{}/{cell}", root.trim_end_matches('/'))
}

/// The Zenoh session and keys.
#[derive(Debug, Clone)]
pub struct ZenohConfig {
    /// Session mode.
    pub mode: ZenohMode,
    /// Endpoints to connect to.
    pub connect: Vec<String>,
    /// Endpoints to listen on.
    pub listen: Vec<String>,
    /// Key prefix, default `cellwatch/<cell>`.
    pub prefix: String,
    /// Multicast scouting (off by default: explicit endpoints on plant networks).
    pub multicast_scouting: bool,
    /// Mutual TLS with certificates from the plant CA; `None` only with
    /// plain TCP written explicitly (`plain = true`).
    pub tls: Option<ZenohTls>,
    /// A Zenoh configuration file (JSON5) for anything Zenoh offers;
    /// cellwatch's own settings are laid over it.
    pub config_file: Option<PathBuf>,
    /// A bus without TLS accepted (`zenoh.plain = true`): otherwise every
    /// endpoint must be TLS with the plant CA, whatever the Zenoh file says.
    pub plain: bool,
    /// The agent's Ed25519 signing key file (`zenoh.signing_key`): every
    /// alarm, state and answer it puts on the bus is sealed with it; made
    /// on first start if missing. `None` for clients.
    pub signing_key: Option<PathBuf>,
}

/// The files of mutual TLS on the bus (PEM): made by `cellwatch pki`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ZenohTls {
    /// The plant CA's certificate: peers are accepted only with a
    /// certificate it issued.
    pub ca: PathBuf,
    /// This node's certificate (listening and connecting).
    pub cert: PathBuf,
    /// Its private key.
    pub key: PathBuf,
}

#[cfg(test)]
mod zenoh_file_tests {
    #[test]
    fn a_zenoh_file_that_does_not_read_is_said_without_zenoh_s_source_place() {
        let dir = tempfile::tempdir().unwrap();
        let missing = super::zenoh_file(&dir.path().join("router.json5"))
            .unwrap_err()
            .to_string();
        assert!(missing.contains("No such file"), "{missing}");
        let bad = dir.path().join("bad.json5");
        std::fs::write(&bad, "{ mode: ").unwrap();
        let said = super::zenoh_file(&bad).unwrap_err().to_string();
        assert!(!said.contains(".rs:"), "{said}");
        assert!(!said.is_empty());
    }
}

/// `[zenoh]` as written.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawZenoh {
    pub(crate) mode: Option<Spanned<String>>,
    #[serde(default)]
    pub(crate) connect: Vec<Spanned<String>>,
    #[serde(default)]
    pub(crate) listen: Vec<Spanned<String>>,
    pub(crate) key_prefix: Option<Spanned<String>>,
    pub(crate) multicast_scouting: Option<bool>,
    pub(crate) tls: Option<Spanned<RawTls>>,
    pub(crate) plain: Option<Spanned<bool>>,
    pub(crate) config_file: Option<Spanned<String>>,
    pub(crate) signing_key: Option<Spanned<String>>,
}

/// `[zenoh.tls]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawTls {
    pub(crate) ca: Spanned<String>,
    pub(crate) cert: Spanned<String>,
    pub(crate) key: Spanned<String>,
}

pub(crate) fn validate(kit: &mut Table<'_>, raw: RawZenoh, cell: &str) -> ZenohConfig {
    let mode = match raw.mode.as_ref().map(|m| (m.get_ref().as_str(), m.span())) {
        None | Some(("peer", _)) => ZenohMode::Peer,
        Some(("client", _)) => ZenohMode::Client,
        Some(("router", _)) => ZenohMode::Router,
        Some((m, span)) => {
            kit.problem(
                span,
                "zenoh.mode",
                format!("unknown mode '{m}': use peer, client or router"),
            );
            ZenohMode::Peer
        }
    };
    let plain = raw.plain.as_ref().is_some_and(|p| *p.get_ref());
    let tls = raw.tls.map(|t| {
        let t = t.into_inner();
        ZenohTls {
            ca: kit.path(t.ca.get_ref()),
            cert: kit.path(t.cert.get_ref()),
            key: kit.path(t.key.get_ref()),
        }
    });
    let config_file = raw.config_file.map(|f| {
        let path = kit.path(f.get_ref());
        if let Err(e) = zenoh_file(&path) {
            kit.problem(
                f.span(),
                "zenoh.config_file",
                format!("{}: {e}", path.display()),
            );
        }
        path
    });
    // Where the [zenoh] table is, for problems of the table as a whole.
    let table = raw
        .listen
        .first()
        .or(raw.connect.first())
        .map_or(0..0, Spanned::span);
    let with_tls = tls.is_some();
    let mut endpoints = |list: Vec<Spanned<String>>, key: &str| -> Vec<String> {
        let mut out = Vec::new();
        for e in list {
            let text = e.get_ref();
            if !text.contains('/') {
                kit.problem(
                    e.span(),
                    key,
                    format!("'{text}' is not an endpoint like quic/127.0.0.1:7447"),
                );
            } else if let Some(why) = with_tls.then(|| link_problem(text)).flatten() {
                kit.problem(e.span(), key, format!("'{text}': {why}"));
            }
            out.push(e.into_inner());
        }
        out
    };
    let connect = endpoints(raw.connect, "zenoh.connect");
    let listen = endpoints(raw.listen, "zenoh.listen");
    match (&tls, plain) {
            (Some(_), true) => kit.problem(
                raw.plain.as_ref().map_or(table, Spanned::span),
                "zenoh.plain",
                "plain = true and [zenoh.tls] contradict each other: remove one",
            ),
            (None, true) => kit.warn(
                "zenoh.plain = true: the bus is neither encrypted nor authenticated; anyone on the network can publish alarms and answer queries as this agent".into(),
            ),
            (None, false) if config_file.is_none() => kit.problem(
                table,
                "zenoh",
                "no [zenoh.tls]: the bus would be neither encrypted nor authenticated; give tls = { ca, cert, key } (made by `cellwatch pki`), or write plain = true to accept that",
            ),
            _ => {}
        }
    if mode == ZenohMode::Client && connect.is_empty() {
        kit.warn("zenoh.mode is client but zenoh.connect is empty: the agent relies on scouting to find a router".into());
    }
    let prefix = match raw.key_prefix {
        None => cell_prefix(DEFAULT_ROOT, cell),
        Some(p) => {
            let s = p.get_ref().trim_end_matches('/').to_string();
            if s.is_empty() || s.contains(['*', '$', '?', '#']) {
                kit.problem(
                    p.span(),
                    "zenoh.key_prefix",
                    format!(
                        "'{}' must be a plain key expression without wildcards",
                        p.get_ref()
                    ),
                );
            }
            s
        }
    };
    let signing_key = Some(
        kit.path(
            raw.signing_key
                .as_ref()
                .map_or(&format!("{cell}.agent.key"), |k| k.get_ref()),
        ),
    );
    ZenohConfig {
        mode,
        connect,
        listen,
        prefix,
        multicast_scouting: raw.multicast_scouting.unwrap_or(false),
        tls,
        config_file,
        plain,
        signing_key,
    }
}
