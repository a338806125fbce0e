//! What the console's HTTP side and its routes share: the state they
//! work with, who is asking, and how an answer or a refusal is written.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::http::{header, StatusCode};
use axum::response::{IntoResponse, Response};
use tokio::time::Instant;

use super::access::Identity;
use super::gate::Gate;
use super::shared::Shared;

/// What the HTTP side works with.
pub(super) struct Web {
    /// The plant, the bus and the operators.
    pub(super) shared: Arc<Shared>,
    /// Doors and counts.
    pub(super) gate: Arc<Gate>,
    /// The alarm figures asked recently, answered again for a while.
    pub(super) kpi: Mutex<KpiCache>,
    /// Whether the console serves HTTPS (cookies marked `Secure`).
    pub(super) https: bool,
}

/// Who is asking, as the routes see it: the identity and, when signed in
/// with a key, the session it holds.
#[derive(Debug, Clone)]
pub(super) struct Who {
    pub(super) identity: Identity,
    pub(super) session: Option<String>,
}

/// A JSON answer.
pub(super) fn json(status: StatusCode, body: String) -> Response {
    (
        status,
        [(header::CONTENT_TYPE, "application/json; charset=utf-8")],
        body,
    )
        .into_response()
}

/// A refusal: `{"error": message}`.
pub(super) fn error(status: StatusCode, message: impl std::fmt::Display) -> Response {
    json(
        status,
        serde_json::json!({ "error": message.to_string() }).to_string(),
    )
}

/// How long the same alarm figures are answered from what was asked.
pub(super) const KPI_FRESH: Duration = Duration::from_secs(10);

/// The most answers of alarm figures kept.
const KPI_KEPT: usize = 64;

/// Alarm figures asked recently: (what was asked, of which cells) → when,
/// the answer.
#[derive(Default)]
pub(super) struct KpiCache {
    answers: VecDeque<(String, Instant, String)>,
}

impl KpiCache {
    pub(super) fn get(&self, key: &str, now: Instant) -> Option<String> {
        self.answers
            .iter()
            .find(|(k, at, _)| k == key && now.duration_since(*at) < KPI_FRESH)
            .map(|(_, _, answer)| answer.clone())
    }

    pub(super) fn put(&mut self, key: String, now: Instant, answer: String) {
        self.answers
            .retain(|(k, at, _)| *k != key && now.duration_since(*at) < KPI_FRESH);
        if self.answers.len() >= KPI_KEPT {
            self.answers.pop_front();
        }
        self.answers.push_back((key, now, answer));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn the_same_figures_are_answered_from_the_cache_for_a_while() {
        let mut k = KpiCache::default();
        let now = Instant::now();
        k.put("a".into(), now, "A".into());
        assert_eq!(
            k.get("a", now + Duration::from_secs(1)).as_deref(),
            Some("A")
        );
        assert_eq!(k.get("a", now + KPI_FRESH), None);
        for i in 0..KPI_KEPT + 5 {
            k.put(format!("k{i}"), now, String::new());
        }
        assert_eq!(k.answers.len(), KPI_KEPT);
    }
}
