//! Validating the configuration: opcua.

use std::time::Duration;

use toml::Spanned;

use super::Validator;
use crate::config::node::TagNode;
use crate::config::raw;
use crate::config::{
    EventSource, Identity, OpcUaConfig, PasswordSource, SecurityMode, SecurityPolicy,
};

impl Validator<'_> {
    pub(super) fn opcua(&mut self, raw: raw::RawOpcUa) -> Option<OpcUaConfig> {
        let endpoint = raw.endpoint.get_ref().clone();
        if !endpoint.starts_with("opc.tcp://") {
            self.problem(
                raw.endpoint.span(),
                "opcua.endpoint",
                format!("'{endpoint}' must start with opc.tcp://"),
            );
        }
        let policy = match raw
            .security_policy
            .as_ref()
            .map(|p| (p.get_ref().as_str(), p.span()))
        {
            None => SecurityPolicy::Basic256Sha256,
            Some(("None", _)) => SecurityPolicy::None,
            Some(("Basic256Sha256", _)) => SecurityPolicy::Basic256Sha256,
            Some(("Aes128_Sha256_RsaOaep" | "Aes128Sha256RsaOaep", _)) => {
                SecurityPolicy::Aes128Sha256RsaOaep
            }
            Some(("Aes256_Sha256_RsaPss" | "Aes256Sha256RsaPss", _)) => {
                SecurityPolicy::Aes256Sha256RsaPss
            }
            Some((p @ ("Basic128Rsa15" | "Basic256"), span)) => {
                self.problem(
                    span,
                    "opcua.security_policy",
                    format!("'{p}' is deprecated and insecure; use Basic256Sha256"),
                );
                SecurityPolicy::Basic256Sha256
            }
            Some((p, span)) => {
                self.problem(span, "opcua.security_policy", format!("unknown policy '{p}': use Basic256Sha256, Aes128_Sha256_RsaOaep, Aes256_Sha256_RsaPss or None"));
                SecurityPolicy::Basic256Sha256
            }
        };
        let mode = match raw
            .security_mode
            .as_ref()
            .map(|m| (m.get_ref().as_str(), m.span()))
        {
            None if policy == SecurityPolicy::None => SecurityMode::None,
            None => SecurityMode::SignAndEncrypt,
            Some(("None", _)) => SecurityMode::None,
            Some(("Sign", _)) => SecurityMode::Sign,
            Some(("SignAndEncrypt", _)) => SecurityMode::SignAndEncrypt,
            Some((m, span)) => {
                self.problem(
                    span,
                    "opcua.security_mode",
                    format!("unknown mode '{m}': use SignAndEncrypt, Sign or None"),
                );
                SecurityMode::SignAndEncrypt
            }
        };
        if (policy == SecurityPolicy::None) != (mode == SecurityMode::None) {
            let span = raw
                .security_mode
                .as_ref()
                .or(raw.security_policy.as_ref())
                .map_or(raw.endpoint.span(), Spanned::span);
            self.problem(
                span,
                "opcua.security_mode",
                "security_policy None goes with security_mode None, and only with it",
            );
        } else if policy == SecurityPolicy::None {
            self.warnings.push(format!(
                "OPC UA security is off for {endpoint}: traffic is neither signed nor encrypted"
            ));
        }
        let pki_dir = self.path(raw.pki_dir.as_ref().map_or("pki", |p| p.get_ref().as_str()));
        let identity = match raw.identity {
            None => Identity::Anonymous,
            Some(id) => self.identity(id.into_inner())?,
        };
        let publishing_interval = self.duration(
            raw.publishing_interval,
            "opcua.publishing_interval",
            Duration::from_millis(100),
        );
        // 0 is the OPC UA convention for exception-based reporting: every
        // change, as the server sees it.
        let sampling_interval = match raw.sampling_interval {
            Some(v)
                if v.get_ref().trim() == "0"
                    || humantime::parse_duration(v.get_ref()).is_ok_and(|d| d.is_zero()) =>
            {
                Duration::ZERO
            }
            other => self.duration(other, "opcua.sampling_interval", Duration::from_millis(50)),
        };
        let queue_size = match raw.queue_size {
            None => OpcUaConfig::default_queue_size(publishing_interval, sampling_interval),
            Some(q) => self.count(q, "opcua.queue_size", 1..=10_000, 10),
        };
        let max_notifications_per_publish =
            raw.max_notifications_per_publish
                .map_or(OpcUaConfig::DEFAULT_MAX_NOTIFICATIONS, |q| {
                    self.count(
                        q,
                        "opcua.max_notifications_per_publish",
                        100..=1_000_000,
                        OpcUaConfig::DEFAULT_MAX_NOTIFICATIONS,
                    )
                });
        let namespace_uri = match raw.namespace_uri {
            Some(uri) if uri.get_ref().trim().is_empty() => {
                self.problem(uri.span(), "opcua.namespace_uri", "is empty");
                None
            }
            other => other.map(|u| (u.span(), u.into_inner())),
        };
        self.namespace_uri = namespace_uri.clone();
        let overflow_clear_after = match raw.overflow_clear_after {
            None => OpcUaConfig::DEFAULT_OVERFLOW_CLEAR_AFTER,
            Some(v) if v.get_ref().trim() == "0" => Duration::ZERO,
            Some(v) => {
                let span = v.span();
                let d = self.duration(
                    Some(v),
                    "opcua.overflow_clear_after",
                    OpcUaConfig::DEFAULT_OVERFLOW_CLEAR_AFTER,
                );
                if d > Duration::from_secs(3600) {
                    self.problem(span, "opcua.overflow_clear_after", "at most 1h");
                }
                d
            }
        };
        // At least three keep-alive periods (OPC UA Part 4): the server
        // sends a keep-alive every 10 publishing intervals without data.
        let shortest = publishing_interval * 30;
        let subscription_lifetime = match raw.subscription_lifetime {
            None => OpcUaConfig::DEFAULT_SUBSCRIPTION_LIFETIME.max(shortest),
            Some(v) => {
                let span = v.span();
                let d = self.duration(
                    Some(v),
                    "opcua.subscription_lifetime",
                    OpcUaConfig::DEFAULT_SUBSCRIPTION_LIFETIME,
                );
                if d < shortest {
                    self.problem(
                        span,
                        "opcua.subscription_lifetime",
                        format!(
                            "at least three keep-alive periods (30 publishing intervals: {})",
                            humantime::format_duration(shortest)
                        ),
                    );
                } else if d > Duration::from_secs(3600) {
                    self.problem(span, "opcua.subscription_lifetime", "at most 1h");
                }
                d
            }
        };
        let verify_interval = match raw.verify_interval {
            None => OpcUaConfig::DEFAULT_VERIFY_INTERVAL,
            Some(v) => {
                let span = v.span();
                let d = self.duration(
                    Some(v),
                    "opcua.verify_interval",
                    OpcUaConfig::DEFAULT_VERIFY_INTERVAL,
                );
                if d < Duration::from_secs(1) {
                    self.problem(span, "opcua.verify_interval", "at least 1s");
                } else if d > Duration::from_secs(3600) {
                    self.problem(span, "opcua.verify_interval", "at most 1h");
                }
                d
            }
        };
        let reverse_listen = raw.reverse_listen.and_then(|r| self.reverse_listen(&r));
        let mut redundant: Vec<String> = Vec::new();
        for (i, r) in raw.redundant.iter().enumerate() {
            let key = format!("opcua.redundant[{i}]");
            let url = r.get_ref().trim().to_string();
            if !url.starts_with("opc.tcp://") {
                self.problem(
                    r.span(),
                    &key,
                    format!("'{url}' must start with opc.tcp://"),
                );
            } else if url == endpoint || redundant.contains(&url) {
                self.problem(r.span(), &key, format!("'{url}' is named twice in the set"));
            } else if reverse_listen.is_some() {
                self.problem(
                    r.span(),
                    &key,
                    "a redundant set is dialled by the agent: not with opcua.reverse_listen",
                );
            } else {
                redundant.push(url);
            }
        }
        let events = self.events(&raw.events, namespace_uri.as_ref().map(|(_, u)| u.as_str()));
        Some(OpcUaConfig {
            events,
            redundant,
            endpoint,
            policy,
            mode,
            pki_dir,
            identity,
            publishing_interval,
            sampling_interval,
            namespace_uri: namespace_uri.map(|(_, u)| u),
            queue_size,
            max_notifications_per_publish,
            overflow_clear_after,
            subscription_lifetime,
            verify_interval,
            reverse_listen,
        })
    }

    /// `[[opcua.events]]`: each notifier once, each prefix once and a key
    /// chunk, severities within 1–1000.
    fn events(
        &mut self,
        raw: &[Spanned<raw::RawEvents>],
        namespace_uri: Option<&str>,
    ) -> Vec<EventSource> {
        let mut events: Vec<EventSource> = Vec::new();
        for (i, e) in raw.iter().enumerate() {
            let key = |k: &str| format!("opcua.events[{i}].{k}");
            let e_span = e.span();
            let e = e.get_ref();
            let (text, span) = match &e.source {
                Some(s) => (s.get_ref().trim().to_string(), s.span()),
                None => (EventSource::SERVER.to_string(), e_span.clone()),
            };
            let source = match TagNode::parse(&text, namespace_uri) {
                Ok(n) => n,
                Err(why) => {
                    self.problem(span, &key("source"), why);
                    continue;
                }
            };
            let (prefix, prefix_span) = match &e.prefix {
                Some(p) => (p.get_ref().clone(), p.span()),
                None => (EventSource::DEFAULT_PREFIX.to_string(), e_span.clone()),
            };
            if !crate::config::key_chunk(&prefix) {
                self.problem(
                    prefix_span,
                    &key("prefix"),
                    format!("'{prefix}' must be letters, digits, - and _ only (it begins the alarms' ids)"),
                );
                continue;
            }
            let min_severity = match &e.min_severity {
                None => 1,
                Some(v) => match u16::try_from(*v.get_ref()) {
                    Ok(s @ 1..=1000) => s,
                    _ => {
                        self.problem(
                            v.span(),
                            &key("min_severity"),
                            "an OPC UA severity: 1 to 1000",
                        );
                        continue;
                    }
                },
            };
            if events.iter().any(|o| o.source == source) {
                self.problem(span, &key("source"), format!("'{text}' is read twice"));
            } else if events.iter().any(|o| o.prefix == prefix) {
                self.problem(
                    prefix_span,
                    &key("prefix"),
                    format!("'{prefix}' is used twice"),
                );
            } else {
                events.push(EventSource {
                    source,
                    prefix,
                    min_severity,
                });
            }
        }
        events
    }

    /// `opcua.reverse_listen`: `opc.tcp://ADDRESS:PORT` with an IP address
    /// (`0.0.0.0` or `[::]` for every interface).
    fn reverse_listen(&mut self, raw: &Spanned<String>) -> Option<std::net::SocketAddr> {
        let text = raw.get_ref().trim();
        let address = text
            .strip_prefix("opc.tcp://")
            .map(|a| a.trim_end_matches('/'));
        match address.map(str::parse::<std::net::SocketAddr>) {
            Some(Ok(a)) => Some(a),
            _ => {
                self.problem(
                    raw.span(),
                    "opcua.reverse_listen",
                    format!(
                        "'{text}' is not opc.tcp://ADDRESS:PORT with an IP address: write e.g. opc.tcp://0.0.0.0:4843"
                    ),
                );
                None
            }
        }
    }

    pub(super) fn identity(&mut self, id: raw::RawIdentity) -> Option<Identity> {
        if let Some(p) = &id.password {
            self.problem(
                p.span(),
                "opcua.identity.password",
                "passwords are never written in config files; use password_env (an environment variable) or password_file",
            );
            return None;
        }
        match id.kind.get_ref().as_str() {
            "anonymous" => Some(Identity::Anonymous),
            "user" => {
                let user = id.user.unwrap_or_default();
                if user.is_empty() {
                    self.problem(
                        id.kind.span(),
                        "opcua.identity.user",
                        "a user identity needs a user name",
                    );
                }
                let password = match (id.password_env, id.password_file) {
                    (Some(env), None) => PasswordSource::Env(env),
                    (None, Some(file)) => PasswordSource::File(self.path(file.get_ref())),
                    _ => {
                        self.problem(
                            id.kind.span(),
                            "opcua.identity",
                            "give exactly one of password_env and password_file",
                        );
                        return None;
                    }
                };
                Some(Identity::User { user, password })
            }
            other => {
                self.problem(
                    id.kind.span(),
                    "opcua.identity.kind",
                    format!("unknown identity '{other}': use anonymous or user"),
                );
                None
            }
        }
    }
}
