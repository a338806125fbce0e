//! The answers of the health probes (`/healthz`, `/readyz`): a status, a
//! head line and one line per cell saying why.

use axum::http::header::{HeaderName, CACHE_CONTROL, CONTENT_TYPE};
use axum::http::StatusCode;

/// 200 and `good`, or 503 and `bad`, then the lines.
pub(super) fn health_answer(
    good: &str,
    bad: &str,
    answer: Result<Vec<String>, Vec<String>>,
) -> (StatusCode, [(HeaderName, &'static str); 2], String) {
    let (status, head, lines) = match answer {
        Ok(lines) => (StatusCode::OK, good, lines),
        Err(lines) => (StatusCode::SERVICE_UNAVAILABLE, bad, lines),
    };
    let mut body = format!("{head}\n");
    for l in lines {
        body.push_str(&l);
        body.push('\n');
    }
    (
        status,
        [
            (CONTENT_TYPE, "text/plain; charset=utf-8"),
            (CACHE_CONTROL, "no-store"),
        ],
        body,
    )
}
