//! What a recording is: the changes of the signals an alarm's check reads
//! around its raise ([`Recording`]), their values ([`Sample`]) and where
//! a recording holds less than its window ([`Cut`], [`Truncated`]). It
//! owns these types and what they answer (a signal's value at a time, the
//! memory taken); gathering the changes is the ring's (`ring.rs`), drawing
//! them the timeline's (`timeline.rs`).

use std::fmt;

use serde::{Deserialize, Serialize};

use crate::engine::tag::Value;
use crate::value::Num;

/// A recorded value: serialized as plain JSON (`true`, `1650`, `-3`,
/// `72.5`, `"A-113"`); an unknown one is `None` (`null`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Sample {
    /// A contact.
    Bool(bool),
    /// A whole number of zero or more.
    UInt(u64),
    /// A negative whole number.
    Int(i64),
    /// A number with a fraction (written with its `.0` when whole).
    Float(f64),
    /// A string.
    Text(String),
}

impl From<&Value> for Sample {
    fn from(v: &Value) -> Sample {
        match v {
            Value::Bool(b) => Sample::Bool(*b),
            Value::Num(Num::Int(n)) => match u64::try_from(*n) {
                Ok(n) => Sample::UInt(n),
                Err(_) => Sample::Int(*n),
            },
            Value::Num(Num::UInt(n)) => Sample::UInt(*n),
            Value::Num(Num::Float(x)) => Sample::Float(*x),
            Value::Text(t) => Sample::Text(t.to_string()),
        }
    }
}

impl fmt::Display for Sample {
    /// A contact as `1` or `0`, a number as the PLC gave it, a string as it
    /// is.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Sample::Bool(b) => write!(f, "{}", u8::from(*b)),
            Sample::UInt(n) => write!(f, "{n}"),
            Sample::Int(n) => write!(f, "{n}"),
            Sample::Float(x) => write!(f, "{x}"),
            Sample::Text(t) => f.write_str(t),
        }
    }
}

/// One signal of a recording.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecordedSignal {
    /// Its address as the models name it (`X0.06`, `D100 > 5`).
    pub address: String,
    /// The tag's name in the plant, when it is not the address.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Its value at [`Recording::holds_from`] (`None`: unknown).
    pub start: Option<Sample>,
    /// Its changes after that, in order: `(source time ms, value)`.
    pub changes: Vec<(u64, Option<Sample>)>,
}

/// Why a recording holds less than its window.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Cut {
    /// The ring had dropped the older changes (its capacity).
    Ring,
    /// The recording's own bound on changes
    /// ([`RecorderConfig::max_changes`](super::RecorderConfig::max_changes)).
    Changes,
    /// As many recordings were under way as may be
    /// ([`RecorderConfig::max_open`](super::RecorderConfig::max_open)): nothing after the raise was followed.
    Busy,
    /// The agent stopped, or read its configuration again, before the
    /// window's end: what came until then.
    Stopped,
}

/// Where a recording holds less than its window, and why.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Truncated {
    /// Its start: nothing before [`Recording::holds_from`].
    pub start: Option<Cut>,
    /// Its end: nothing after [`Recording::holds_to`].
    pub end: Option<Cut>,
}

/// The changes of the signals an alarm's check reads around its raise.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Recording {
    /// The alarm's id.
    pub alarm: String,
    /// When it was raised, ms since the epoch (the alarm's `raised_at`).
    pub raised_at: u64,
    /// The window's start: `raised_at - before`.
    pub from: u64,
    /// The window's end: `raised_at + after`.
    pub to: u64,
    /// From when every change of its signals is in: `from`, unless
    /// [`Truncated::start`] says why later.
    pub holds_from: u64,
    /// Until when every change of its signals is in: `to`, unless
    /// [`Truncated::end`] says why earlier.
    pub holds_to: u64,
    /// Where it holds less than its window.
    pub truncated: Truncated,
    /// The signals its check reads, in the order the check gives them.
    pub signals: Vec<RecordedSignal>,
}

impl Recording {
    /// Signal `signal`'s value at `at` (`Some(None)`: unknown then); `None`
    /// when the recording does not hold `at` (outside
    /// [`Recording::holds_from`]..=[`Recording::holds_to`]) or has no such
    /// signal.
    pub fn value_at(&self, signal: usize, at: u64) -> Option<Option<&Sample>> {
        let s = self.signals.get(signal)?;
        if at < self.holds_from || at > self.holds_to {
            return None;
        }
        let k = s.changes.partition_point(|(t, _)| *t <= at);
        Some(match k {
            0 => s.start.as_ref(),
            k => s.changes[k - 1].1.as_ref(),
        })
    }

    /// How many changes it holds.
    pub fn changes(&self) -> usize {
        self.signals.iter().map(|s| s.changes.len()).sum()
    }

    /// An estimate of the memory it takes, bytes: its parts and what they
    /// point to.
    pub fn bytes(&self) -> usize {
        let sample = |s: &Option<Sample>| match s {
            Some(Sample::Text(t)) => t.capacity(),
            _ => 0,
        };
        std::mem::size_of::<Recording>()
            + self.alarm.capacity()
            + self
                .signals
                .iter()
                .map(|s| {
                    std::mem::size_of::<RecordedSignal>()
                        + s.address.capacity()
                        + s.name.as_ref().map_or(0, String::capacity)
                        + sample(&s.start)
                        + s.changes.capacity() * std::mem::size_of::<(u64, Option<Sample>)>()
                        + s.changes.iter().map(|(_, v)| sample(v)).sum::<usize>()
                })
                .sum::<usize>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_recording_is_plain_json_and_comes_back_the_same() {
        let rec = Recording {
            alarm: "temp-h".into(),
            raised_at: 5_000,
            from: 2_000,
            to: 9_000,
            holds_from: 2_000,
            holds_to: 7_000,
            truncated: Truncated {
                start: None,
                end: Some(Cut::Busy),
            },
            signals: vec![
                RecordedSignal {
                    address: "TEMP".into(),
                    name: Some("spindle temperature".into()),
                    start: Some(Sample::Float(50.0)),
                    changes: vec![
                        (3_000, Some(Sample::UInt(90))),
                        (4_000, Some(Sample::Int(-3))),
                        (5_000, None),
                        (6_000, Some(Sample::Text("A-113".into()))),
                    ],
                },
                RecordedSignal {
                    address: "X0.06".into(),
                    name: None,
                    start: Some(Sample::Bool(true)),
                    changes: vec![(5_000, Some(Sample::Bool(false)))],
                },
            ],
        };
        let json = serde_json::to_string(&rec).unwrap();
        assert_eq!(
            json,
            r#"{"alarm":"temp-h","raised_at":5000,"from":2000,"to":9000,"holds_from":2000,"holds_to":7000,"truncated":{"start":null,"end":"busy"},"signals":[{"address":"TEMP","name":"spindle temperature","start":50.0,"changes":[[3000,90],[4000,-3],[5000,null],[6000,"A-113"]]},{"address":"X0.06","start":true,"changes":[[5000,false]]}]}"#
        );
        assert_eq!(serde_json::from_str::<Recording>(&json).unwrap(), rec);
    }
}
