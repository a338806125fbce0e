//! Validating the configuration: `[alertmanager]`.

use toml::Spanned;

use super::value_error::ValueError;
use super::Validator;
use crate::config::raw::RawAlertmanager;
use crate::config::{default_escalation, AlertmanagerConfig, AlertmanagerTls, DEFAULT_RESEND};

/// The most Alertmanagers one cell sends to (each is owed every ended
/// alert until it has taken it).
const MAX_URLS: usize = 16;

/// The most steps of `alertmanager.escalation`.
const MAX_STEPS: usize = 8;

/// The longest `alertmanager.resend_interval`: an alert says it ends four
/// intervals after it was sent, and an hour's silence hides a dead agent.
const MAX_RESEND: std::time::Duration = std::time::Duration::from_secs(3600);

impl Validator<'_> {
    pub(super) fn alertmanager(
        &mut self,
        raw: Option<Spanned<RawAlertmanager>>,
    ) -> Option<AlertmanagerConfig> {
        let raw = raw?;
        let table = raw.span();
        let raw = raw.into_inner();
        if raw.urls.is_empty() {
            self.problem(
                table.clone(),
                "alertmanager.urls",
                "name at least one Alertmanager, like [\"http://alertmanager:9093\"]",
            );
        }
        if raw.urls.len() > MAX_URLS {
            self.problem(
                table.clone(),
                "alertmanager.urls",
                format!("at most {MAX_URLS} Alertmanagers (a cluster's instances)"),
            );
        }
        let mut urls = Vec::new();
        let mut https = None;
        for u in raw.urls.iter().take(MAX_URLS) {
            match web_url(u.get_ref()) {
                Ok(secure) => {
                    if secure && https.is_none() {
                        https = Some(u.span());
                    }
                    if !secure && !is_loopback(u.get_ref()) {
                        self.warnings.push(format!(
                            "alertmanager.urls: {} is plain HTTP: alerts cross the network unencrypted and unauthenticated",
                            u.get_ref()
                        ));
                    }
                    urls.push(u.get_ref().trim_end_matches('/').to_string());
                }
                Err(why) => self.problem(u.span(), "alertmanager.urls", why),
            }
        }
        let console = raw.console.and_then(|c| match web_url(c.get_ref()) {
            Ok(_) => Some(c.get_ref().trim_end_matches('/').to_string()),
            Err(why) => {
                self.problem(c.span(), "alertmanager.console", why);
                None
            }
        });
        let resend_span = raw.resend_interval.as_ref().map(Spanned::span);
        let resend = self.duration(
            raw.resend_interval,
            "alertmanager.resend_interval",
            DEFAULT_RESEND,
        );
        if resend > MAX_RESEND {
            self.problem(
                resend_span.unwrap_or(table.clone()),
                "alertmanager.resend_interval",
                "at most 1h: active alerts end four intervals after they were last sent",
            );
        }
        let tls = raw.tls.map(|t| {
            let span = t.span();
            let t = t.into_inner();
            let client = match (t.cert, t.key) {
                (Some(c), Some(k)) => Some((self.path(c.get_ref()), self.path(k.get_ref()))),
                (None, None) => None,
                _ => {
                    self.problem(
                        span,
                        "alertmanager.tls",
                        "give both cert and key (a client certificate), or neither",
                    );
                    None
                }
            };
            AlertmanagerTls {
                ca: self.path(t.ca.get_ref()),
                client,
            }
        });
        if let (Some(span), None) = (https, &tls) {
            self.problem(
                span,
                "alertmanager.tls",
                "an https:// Alertmanager needs [alertmanager.tls] ca = the CA that signed its certificate",
            );
        }
        if let Some(area) = &raw.area {
            if area.trim().is_empty() {
                self.problem(table.clone(), "alertmanager.area", "must not be empty");
            }
        }
        let escalation = match raw.escalation {
            None => default_escalation(),
            Some(steps) => self.escalation(steps, &table),
        };
        Some(AlertmanagerConfig {
            urls,
            area: raw.area,
            console,
            resend,
            tls,
            escalation,
        })
    }

    /// `alertmanager.escalation`: durations, each longer than the one
    /// before it, at most [`MAX_STEPS`].
    fn escalation(
        &mut self,
        steps: Vec<Spanned<String>>,
        table: &std::ops::Range<usize>,
    ) -> Vec<(String, std::time::Duration)> {
        const KEY: &str = "alertmanager.escalation";
        if steps.len() > MAX_STEPS {
            self.problem(table.clone(), KEY, format!("at most {MAX_STEPS} steps"));
        }
        let mut out: Vec<(String, std::time::Duration)> = Vec::new();
        for step in steps.into_iter().take(MAX_STEPS) {
            let span = step.span();
            let text = step.get_ref().trim().to_string();
            match humantime::parse_duration(&text) {
                Ok(d) if d.is_zero() => {
                    self.problem(
                        span,
                        KEY,
                        format!("'{text}': a step is a time after the raise, more than 0"),
                    );
                }
                Ok(d) if out.last().is_some_and(|(_, before)| d <= *before) => {
                    self.problem(
                        span,
                        KEY,
                        format!("'{text}': each step must be longer than the one before it"),
                    );
                }
                Ok(d) => out.push((text, d)),
                Err(e) => self.problem(
                    span,
                    KEY,
                    format!("'{text}' is not a duration like 5m or 1h ({e})"),
                ),
            }
        }
        out
    }
}

/// Whether `text` is an `http://` (false) or `https://` (true) address
/// with a host and no query; why not otherwise.
fn web_url(text: &str) -> Result<bool, ValueError> {
    let uri: hyper::Uri = text.parse().map_err(|source| ValueError::NotAUrl {
        text: text.into(),
        source,
    })?;
    let secure = match uri.scheme_str() {
        Some("http") => false,
        Some("https") => true,
        _ => return Err(ValueError::NotHttp(text.into())),
    };
    if uri.host().is_none_or(str::is_empty) {
        return Err(ValueError::NoHost(text.into()));
    }
    if uri.query().is_some() {
        return Err(ValueError::Query(text.into()));
    }
    Ok(secure)
}

/// Whether the URL's host is this machine.
fn is_loopback(text: &str) -> bool {
    let Ok(uri) = text.parse::<hyper::Uri>() else {
        return false;
    };
    match uri.host() {
        Some("localhost") => true,
        Some(h) => h
            .trim_matches(['[', ']'])
            .parse::<std::net::IpAddr>()
            .is_ok_and(|ip| ip.is_loopback()),
        None => false,
    }
}
