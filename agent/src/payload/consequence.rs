//! Why an occurrence is a consequence, in its payload: the cause, the
//! cascade's first-out, whether it is suppressed, and the signals it
//! follows through.

use serde::{Deserialize, Serialize};

/// Why an occurrence is a consequence, in its payload.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ConsequencePayload {
    /// The active alarm it follows from.
    pub cause: String,
    /// The first-out of the cascade.
    pub first_out: String,
    /// Not annunciated: not an alert, not counted as a raise of its own
    /// in the KPIs without consequences.
    pub suppressed: bool,
    /// The signals through which it follows: each held by the cause's
    /// fault and read by this alarm's check, with its value now (without
    /// the cause's fault it would have the other). Empty when an edge
    /// written in the configuration or the culprits decided.
    #[serde(default)]
    pub through: Vec<ThroughPayload>,
}

/// A signal through which a consequence follows, in its payload.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ThroughPayload {
    /// Its address (`G8.02`).
    pub signal: String,
    /// Its value now (`true`: 1).
    pub value: bool,
}

impl ConsequencePayload {
    /// Why, in words: `follows from ese: G8.02 = 1 (0 without ese's
    /// fault)`.
    pub fn why(&self) -> String {
        let mut out = format!("follows from {}", self.cause);
        let through: Vec<String> = self
            .through
            .iter()
            .map(|t| {
                format!(
                    "{} = {} ({} without {}'s fault)",
                    t.signal,
                    u8::from(t.value),
                    u8::from(!t.value),
                    self.cause
                )
            })
            .collect();
        if !through.is_empty() {
            out.push_str(": ");
            out.push_str(&through.join(", "));
        }
        out
    }
}

impl ConsequencePayload {
    /// The signals it follows through: `G8.02 = 1, Y2.00 = 0`.
    pub fn through_text(&self) -> String {
        let through: Vec<String> = self
            .through
            .iter()
            .map(|t| format!("{} = {}", t.signal, u8::from(t.value)))
            .collect();
        through.join(", ")
    }
}

impl std::fmt::Display for ConsequencePayload {
    /// `consequence of ese through G8.02 = 1`, and `suppressed` when it
    /// is.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "consequence of {}", self.cause)?;
        if !self.through.is_empty() {
            write!(f, " through {}", self.through_text())?;
        }
        if self.suppressed {
            f.write_str(", suppressed")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_consequence_says_its_cause_and_whether_it_is_suppressed() {
        let mut c = ConsequencePayload {
            cause: "ese".into(),
            first_out: "ese".into(),
            suppressed: false,
            through: Vec::new(),
        };
        assert_eq!(c.to_string(), "consequence of ese");
        assert_eq!(c.why(), "follows from ese");
        c.suppressed = true;
        assert_eq!(c.to_string(), "consequence of ese, suppressed");
        c.through = vec![ThroughPayload {
            signal: "G8.02".into(),
            value: true,
        }];
        assert_eq!(
            c.to_string(),
            "consequence of ese through G8.02 = 1, suppressed"
        );
        assert_eq!(
            c.why(),
            "follows from ese: G8.02 = 1 (0 without ese's fault)"
        );
    }
}
