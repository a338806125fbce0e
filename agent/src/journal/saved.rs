//! What a restarting agent takes back from the journal: alarms not back to normal, the last
//! machine state, recent commands' nonces and outcomes.

use rusqlite::Connection;

/// What the journal keeps for the next start: the alarms not back to
/// normal, the last machine-state row, and recent verified nonces.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Saved {
    /// Payloads (JSON, as published) of the alarms not back to normal.
    pub alarms: Vec<String>,
    /// The last machine-state row: when, kind, state, fault type, element.
    pub state: Option<SavedState>,
    /// Nonces of verified commands since the given time, with their times.
    pub nonces: Vec<(u64, String)>,
    /// The outcome of each of those commands, as its final row says.
    pub outcomes: Vec<SavedOutcome>,
}

/// A recent verified command's outcome, as journaled.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SavedOutcome {
    /// Its nonce.
    pub nonce: String,
    /// Who signed it, as journaled.
    pub operator: String,
    /// What it asked, as journaled.
    pub action: String,
    /// SHA-256 of the command as signed (hex); `None` in rows journaled
    /// before digests were kept.
    pub digest: Option<String>,
    /// When it was first journaled (ms).
    pub at: u64,
    /// Accepted and the detail, from its final row; `None` when only its
    /// request was journaled (the agent stopped before the outcome).
    pub outcome: Option<(bool, String)>,
}

/// The last machine-state row.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SavedState {
    /// When it was entered, ms.
    pub at: u64,
    /// History kind (`fault`, `recovery`, ...).
    pub kind: String,
    /// State name.
    pub state: String,
    /// Fault type, in `fault`.
    pub fault_type: Option<String>,
    /// Faulty element, in `fault` when known.
    pub element: Option<String>,
}

/// Reads what was saved for a restart; nonces from `nonces_since` (ms).
///
/// # Errors
/// SQLite failing.
pub fn saved(conn: &Connection, nonces_since: u64) -> rusqlite::Result<Saved> {
    let mut stmt = conn.prepare("SELECT payload FROM alarm_current ORDER BY at_ms, alarm")?;
    let alarms = stmt
        .query_map([], |r| r.get(0))?
        .collect::<Result<Vec<String>, _>>()?;
    let state = conn
        .query_row(
            "SELECT at_ms, kind, state, fault_type, element FROM state_history ORDER BY seq DESC LIMIT 1",
            [],
            |r| {
                Ok(SavedState {
                    at: r.get::<_, i64>(0)? as u64,
                    kind: r.get(1)?,
                    state: r.get(2)?,
                    fault_type: r.get(3)?,
                    element: r.get(4)?,
                })
            },
        )
        .map(Some)
        .or_else(|e| match e {
            rusqlite::Error::QueryReturnedNoRows => Ok(None),
            e => Err(e),
        })?;
    let mut stmt = conn.prepare(
        "SELECT at_ms, nonce, accepted, detail, stage, operator, action, digest FROM commands \
         WHERE verified != 0 AND at_ms >= ?1 ORDER BY seq",
    )?;
    let rows = stmt
        .query_map([nonces_since as i64], |r| {
            Ok((
                r.get::<_, i64>(0)? as u64,
                r.get::<_, String>(1)?,
                r.get::<_, i64>(2)? != 0,
                r.get::<_, String>(3)?,
                r.get::<_, String>(4)?,
                r.get::<_, String>(5)?,
                r.get::<_, String>(6)?,
                r.get::<_, Option<String>>(7)?,
            ))
        })?
        .collect::<Result<Vec<_>, _>>()?;
    let mut nonces = Vec::new();
    let mut outcomes: Vec<SavedOutcome> = Vec::new();
    for (at, nonce, accepted, detail, stage, operator, action, digest) in rows {
        if outcomes.last().is_none_or(|o| o.nonce != nonce) {
            nonces.push((at, nonce.clone()));
            outcomes.push(SavedOutcome {
                nonce: nonce.clone(),
                operator,
                action,
                digest,
                at,
                outcome: None,
            });
        }
        // A command's own row, or the result of one in several rows.
        if matches!(stage.as_str(), "command" | "result") {
            if let Some(o) = outcomes.iter_mut().rev().find(|o| o.nonce == nonce) {
                o.outcome = Some((accepted, detail));
            }
        }
    }
    Ok(Saved {
        alarms,
        state,
        nonces,
        outcomes,
    })
}
