//! An alarm's rationalisation in its payload, from the cell's master alarm
//! database.

use serde::{Deserialize, Serialize};

/// An alarm's rationalisation, in its payload.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct GuidancePayload {
    /// Its class, as the plant names them.
    pub class: String,
    /// What happens if nobody acts.
    pub consequence_of_inaction: String,
    /// What the operator does.
    pub corrective_action: String,
    /// How long the operator has (`5m`); `null`: not said.
    pub response_time: Option<String>,
}

impl GuidancePayload {
    /// The response time in milliseconds, if said and readable.
    pub fn response_time_ms(&self) -> Option<u64> {
        let text = self.response_time.as_deref()?;
        let d = humantime::parse_duration(text).ok()?;
        Some(u64::try_from(d.as_millis()).unwrap_or(u64::MAX))
    }
}
