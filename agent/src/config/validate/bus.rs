//! Validating the configuration: the Zenoh bus.

use toml::Spanned;

use super::Validator;
use crate::config::raw;
use crate::config::{cell_prefix, link_problem, ZenohConfig, ZenohMode, ZenohTls, DEFAULT_ROOT};

impl Validator<'_> {
    pub(super) fn zenoh(&mut self, raw: raw::RawZenoh, cell: &str) -> ZenohConfig {
        let mode = match raw.mode.as_ref().map(|m| (m.get_ref().as_str(), m.span())) {
            None | Some(("peer", _)) => ZenohMode::Peer,
            Some(("client", _)) => ZenohMode::Client,
            Some(("router", _)) => ZenohMode::Router,
            Some((m, span)) => {
                self.problem(
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
                ca: self.path(t.ca.get_ref()),
                cert: self.path(t.cert.get_ref()),
                key: self.path(t.key.get_ref()),
            }
        });
        let config_file = raw.config_file.map(|f| {
            let path = self.path(f.get_ref());
            if let Err(e) = crate::config::zenoh_file(&path) {
                self.problem(
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
                    self.problem(
                        e.span(),
                        key,
                        format!("'{text}' is not an endpoint like quic/127.0.0.1:7447"),
                    );
                } else if let Some(why) = with_tls.then(|| link_problem(text)).flatten() {
                    self.problem(e.span(), key, format!("'{text}': {why}"));
                }
                out.push(e.into_inner());
            }
            out
        };
        let connect = endpoints(raw.connect, "zenoh.connect");
        let listen = endpoints(raw.listen, "zenoh.listen");
        match (&tls, plain) {
            (Some(_), true) => self.problem(
                raw.plain.as_ref().map_or(table, Spanned::span),
                "zenoh.plain",
                "plain = true and [zenoh.tls] contradict each other: remove one",
            ),
            (None, true) => self.warnings.push(
                "zenoh.plain = true: the bus is neither encrypted nor authenticated; anyone on the network can publish alarms and answer queries as this agent".into(),
            ),
            (None, false) if config_file.is_none() => self.problem(
                table,
                "zenoh",
                "no [zenoh.tls]: the bus would be neither encrypted nor authenticated; give tls = { ca, cert, key } (made by `cellwatch pki`), or write plain = true to accept that",
            ),
            _ => {}
        }
        if mode == ZenohMode::Client && connect.is_empty() {
            self.warnings.push("zenoh.mode is client but zenoh.connect is empty: the agent relies on scouting to find a router".into());
        }
        let prefix = match raw.key_prefix {
            None => cell_prefix(DEFAULT_ROOT, cell),
            Some(p) => {
                let s = p.get_ref().trim_end_matches('/').to_string();
                if s.is_empty() || s.contains(['*', '$', '?', '#']) {
                    self.problem(
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
            self.path(
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
}
