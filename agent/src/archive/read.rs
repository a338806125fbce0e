//! Reading the plant archive: every cell's signed alarm events, machine
//! states and flight recordings, as the routers' storages kept them,
//! whether the cell's agent is running or its host is gone. Each entry is
//! believed only if its cell's agent sealed it for the key it is kept
//! under (the plant trust file); the routers are relays, not witnesses.

use std::collections::HashSet;
use std::time::Duration;

use zenoh::query::{ConsolidationMode, QueryTarget};

use crate::bus::envelope::Opened;
use crate::client::BusClient;
use crate::payload::{AlarmPayload, StatePayload};

/// What the archive keeps, each under its own storage.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(crate) enum Kept {
    /// `alarms/<id>`: alarm events.
    Alarm,
    /// `state`: machine states.
    State,
    /// `recordings/<id>`: flight recordings.
    Recording,
}

impl Kept {
    /// The key under a cell's prefix.
    fn key(self) -> &'static str {
        match self {
            Kept::Alarm => "alarms/**",
            Kept::State => "state",
            Kept::Recording => "recordings/**",
        }
    }

    /// What a key under a cell's prefix keeps.
    fn of(suffix: &str) -> Option<Kept> {
        if suffix.starts_with("alarms/") {
            Some(Kept::Alarm)
        } else if suffix == "state" {
            Some(Kept::State)
        } else if suffix.starts_with("recordings/") {
            Some(Kept::Recording)
        } else {
            None
        }
    }
}

/// One believed entry.
#[derive(Debug, Clone)]
pub(crate) struct ArchivedEntry {
    /// What it is.
    pub kept: Kept,
    /// The key it was put and kept on.
    pub key: String,
    /// The envelope, opened.
    pub opened: Opened,
}

/// What a reading found.
#[derive(Debug, Default)]
pub(crate) struct Reading {
    /// Believed entries, oldest first (by the time their agent sealed
    /// them), each once however many storages kept it.
    pub entries: Vec<ArchivedEntry>,
    /// Entries not believed: the key and why.
    pub refused: Vec<(String, String)>,
}

/// The time range of a reading, in Zenoh's time DSL.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Range(String);

/// A `--since`/`--until` that reads neither as a duration nor a time.
#[derive(Debug, thiserror::Error)]
#[error("--{flag} `{text}`: neither a duration back from now (24h, 30m) nor an RFC 3339 time")]
pub(crate) struct BadTime {
    flag: &'static str,
    text: String,
}

fn bound(flag: &'static str, text: &str) -> Result<String, BadTime> {
    if let Ok(d) = humantime::parse_duration(text) {
        return Ok(format!("now(-{}s)", d.as_secs()));
    }
    let t = humantime::parse_rfc3339_weak(text).map_err(|_| BadTime {
        flag,
        text: text.into(),
    })?;
    Ok(humantime::format_rfc3339_millis(t).to_string())
}

impl Range {
    /// From `since` (a duration back from now, or an RFC 3339 time) until
    /// `until` (the same forms; now when not given).
    ///
    /// # Errors
    /// A bound that reads as neither.
    pub(crate) fn new(since: &str, until: Option<&str>) -> Result<Range, BadTime> {
        let from = bound("since", since)?;
        let to = until.map(|u| bound("until", u)).transpose()?;
        Ok(Range(format!("[{from}..{}]", to.unwrap_or_default())))
    }

    /// The selector parameter.
    pub(crate) fn parameter(&self) -> String {
        format!("_time={}", self.0)
    }
}

/// At most this many entries in one reading: a day of a cell's states
/// and alarms is a few thousand.
pub(crate) const MOST_ENTRIES: usize = 1_000_000;

/// Reads what the archive keeps of `cell` (`*`: every cell) in `range`,
/// of the kinds asked, from every router's storage that answers within
/// `timeout`.
pub(crate) async fn read(
    bus: &BusClient,
    cell: &str,
    kinds: &[Kept],
    range: &Range,
    timeout: Duration,
) -> Result<Reading, zenoh::Error> {
    let mut reading = Reading::default();
    let mut seen = HashSet::new();
    let prefix = bus.keys(cell).prefix().to_string();
    let root_len = bus.keys("x").prefix().len() - 1;
    for kind in kinds {
        let selector = format!("{prefix}/{}?{}", kind.key(), range.parameter());
        let replies = bus
            .session()
            .get(&selector)
            .consolidation(ConsolidationMode::None)
            .target(QueryTarget::All)
            .timeout(timeout)
            .await?;
        while let Ok(reply) = replies.recv_async().await {
            let Ok(sample) = reply.result() else { continue };
            let key = sample.key_expr().as_str().to_string();
            let payload = sample.payload().to_bytes();
            // The same envelope from two routers' storages is one entry.
            if !seen.insert(<sha2::Sha256 as sha2::Digest>::digest(&payload)) {
                continue;
            }
            // The cell's part of the key: `<root>/<cell>/<suffix>`.
            let suffix = key
                .get(root_len..)
                .and_then(|rest| rest.split_once('/'))
                .map(|(_, s)| s)
                .unwrap_or("");
            let Some(kept) = Kept::of(suffix) else {
                reading
                    .refused
                    .push((key, "not a key the archive keeps".into()));
                continue;
            };
            match bus.open_put(&payload, &key) {
                Ok(opened) => {
                    if reading.entries.len() < MOST_ENTRIES {
                        reading.entries.push(ArchivedEntry { kept, key, opened });
                    }
                }
                Err(why) => reading.refused.push((key, why.to_string())),
            }
        }
    }
    reading
        .entries
        .sort_by(|a, b| (a.opened.at, &a.key).cmp(&(b.opened.at, &b.key)));
    Ok(reading)
}

impl ArchivedEntry {
    /// The alarm event, for an [`Kept::Alarm`] entry whose body reads.
    pub(crate) fn alarm(&self) -> Option<AlarmPayload> {
        (self.kept == Kept::Alarm)
            .then(|| serde_json::from_str(&self.opened.body).ok())
            .flatten()
    }

    /// The machine state, for a [`Kept::State`] entry whose body reads.
    pub(crate) fn state(&self) -> Option<StatePayload> {
        (self.kept == Kept::State)
            .then(|| serde_json::from_str(&self.opened.body).ok())
            .flatten()
    }
}

/// A reading as one page of an agent's history (`{"rows": [{"table",
/// "at", "fields"}], "more", "next": null, "from": "archive"}`, the
/// fields the journal's rows have), the newest `limit` rows, oldest
/// first: what the console shows of a cell whose agent does not answer.
/// A machine state put again unchanged is one row, as in the journal.
pub(crate) fn as_history_page(reading: &Reading, limit: usize) -> serde_json::Value {
    use serde_json::{json, Value};
    let mut rows = Vec::new();
    let mut last_state: std::collections::HashMap<String, Value> = Default::default();
    for entry in &reading.entries {
        let body: Value = serde_json::from_str(&entry.opened.body).unwrap_or(Value::Null);
        let fields = match entry.kept {
            Kept::Alarm => json!({
                "alarm": body["id"],
                "kind": body["kind"],
                "severity": body["severity"],
                "transition": body["transition"],
                "payload": body,
            }),
            Kept::State => {
                let fields = json!({
                    "kind": body["kind"],
                    "state": body["state"],
                    "fault_type": body["fault_type"],
                    "element": body["element"],
                });
                let cell = entry.opened.cell.clone();
                if last_state.get(&cell) == Some(&fields) {
                    continue;
                }
                last_state.insert(cell, fields.clone());
                fields
            }
            Kept::Recording => json!({
                "alarm": entry.key.rsplit('/').next().unwrap_or(""),
                "payload": body,
            }),
        };
        let table = match entry.kept {
            Kept::Alarm => "alarm",
            Kept::State => "state",
            Kept::Recording => "recording",
        };
        rows.push(json!({"table": table, "at": entry.opened.at, "fields": fields}));
    }
    let more = rows.len() > limit;
    let rows: Vec<Value> = rows.split_off(rows.len().saturating_sub(limit));
    json!({"rows": rows, "more": more, "next": null, "from": "archive"})
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(kept: Kept, key: &str, at: u64, body: &str) -> ArchivedEntry {
        ArchivedEntry {
            kept,
            key: key.into(),
            opened: Opened {
                cell: "m01".into(),
                kind: crate::bus::envelope::Kind::Put,
                at,
                body: body.into(),
            },
        }
    }

    #[test]
    fn an_archived_reading_reads_as_the_journals_rows_each_change_once() {
        let state = |state: &str, kind: &str| {
            format!(r#"{{"state":"{state}","kind":"{kind}","fault_type":null,"element":null}}"#)
        };
        let reading = Reading {
            entries: vec![
                entry(
                    Kept::State,
                    "cellwatch/m01/state",
                    1,
                    &state("running", "normal"),
                ),
                entry(
                    Kept::State,
                    "cellwatch/m01/state",
                    2,
                    &state("running", "normal"),
                ),
                entry(
                    Kept::Alarm,
                    "cellwatch/m01/alarms/ese",
                    3,
                    r#"{"id":"ese","kind":"switching","severity":"critical","transition":"raised"}"#,
                ),
                entry(
                    Kept::State,
                    "cellwatch/m01/state",
                    4,
                    &state("fault", "fault"),
                ),
            ],
            refused: vec![],
        };
        let page = as_history_page(&reading, 10);
        let rows = page["rows"].as_array().unwrap();
        let said: Vec<(&str, u64)> = rows
            .iter()
            .map(|r| (r["table"].as_str().unwrap(), r["at"].as_u64().unwrap()))
            .collect();
        assert_eq!(said, [("state", 1), ("alarm", 3), ("state", 4)]);
        assert_eq!(rows[1]["fields"]["alarm"], "ese");
        assert_eq!(rows[1]["fields"]["transition"], "raised");
        assert_eq!(rows[2]["fields"]["kind"], "fault");
        assert_eq!(page["from"], "archive");
        // The newest `limit`, oldest first, and more said.
        let page = as_history_page(&reading, 2);
        assert_eq!(page["rows"][0]["at"], 3);
        assert_eq!(page["more"], true);
    }
}
