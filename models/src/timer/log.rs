//! Signal logs of runs: the input of the transition-timer learner.
//!
//! Two forms, one run per file:
//! - CSV `time_ms,tag,value` with a header; rows at time 0 give initial
//!   values, later rows are changes; values `0`, `1`, `true`, `false`;
//! - the paper's numeric form: a map `number,tag` (one a line) and an
//!   event list `t,e` with `e` = `+s` (signal `s` rises) or `-s` (falls);
//!   every signal starts at 0.
//!
//! A signal without an initial value starts at the opposite of its first
//! change. Errors are `FILE:LINE: message`.

use std::collections::HashMap;

use crate::source::{Location, SourceError};

/// One change of one signal.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Change {
    /// When, ms from the start of the run.
    pub at: u64,
    /// Index into [`RunLog::signals`].
    pub signal: usize,
    /// The new value.
    pub value: bool,
}

/// One run: signal names, initial values, changes in time order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunLog {
    /// Signal names, in order of first appearance.
    pub signals: Vec<String>,
    /// Value of each signal at time 0.
    pub initial: Vec<bool>,
    /// Changes, in time order; each flips its signal.
    pub changes: Vec<Change>,
}

fn err(origin: &str, line: usize, message: String) -> SourceError {
    SourceError::new(origin, Location::line_start(line), message)
}

/// A line-numbered error printed as `FILE:LINE: message`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{origin}:{line}: {message}")]
pub struct LogError {
    /// The file.
    pub origin: String,
    /// The line.
    pub line: usize,
    /// What is wrong.
    pub message: String,
}

impl From<SourceError> for LogError {
    fn from(e: SourceError) -> Self {
        LogError {
            origin: e.origin,
            line: e.at.line,
            message: e.message,
        }
    }
}

fn value(text: &str) -> Option<bool> {
    match text.trim().to_ascii_lowercase().as_str() {
        "1" | "true" => Some(true),
        "0" | "false" => Some(false),
        _ => None,
    }
}

/// A row whose time is before the previous row's.
#[derive(Debug, thiserror::Error)]
#[error("time {at} ms goes backwards (previous row at {previous} ms)")]
struct Backwards {
    /// The row's time, ms.
    at: u64,
    /// The previous row's time, ms.
    previous: u64,
}

struct Builder {
    index: HashMap<String, usize>,
    log: RunLog,
    initial_set: Vec<bool>,
    last_at: u64,
    current: Vec<bool>,
}

impl Builder {
    fn new() -> Self {
        Builder {
            index: HashMap::new(),
            log: RunLog {
                signals: Vec::new(),
                initial: Vec::new(),
                changes: Vec::new(),
            },
            initial_set: Vec::new(),
            last_at: 0,
            current: Vec::new(),
        }
    }

    fn signal(&mut self, name: &str) -> usize {
        if let Some(&i) = self.index.get(name) {
            return i;
        }
        let i = self.log.signals.len();
        self.index.insert(name.to_string(), i);
        self.log.signals.push(name.to_string());
        self.log.initial.push(false);
        self.initial_set.push(false);
        self.current.push(false);
        i
    }

    /// Records `signal = value` at `at`.
    ///
    /// # Errors
    /// [`Backwards`] if `at` is before the previous row's time.
    fn row(&mut self, at: u64, signal: usize, value: bool) -> Result<(), Backwards> {
        if at < self.last_at {
            return Err(Backwards {
                at,
                previous: self.last_at,
            });
        }
        self.last_at = at;
        if at == 0
            && !self.initial_set[signal]
            && self.log.changes.iter().all(|c| c.signal != signal)
        {
            self.log.initial[signal] = value;
            self.initial_set[signal] = true;
            self.current[signal] = value;
            return Ok(());
        }
        if !self.initial_set[signal] && self.log.changes.iter().all(|c| c.signal != signal) {
            // First seen as a change: it was the opposite before.
            self.log.initial[signal] = !value;
            self.initial_set[signal] = true;
            self.current[signal] = !value;
        }
        if self.current[signal] != value {
            self.current[signal] = value;
            self.log.changes.push(Change { at, signal, value });
        }
        Ok(())
    }
}

/// Parses the CSV form.
///
/// # Errors
/// The first bad line, as `FILE:LINE: message`.
pub fn parse_csv(origin: &str, text: &str) -> Result<RunLog, LogError> {
    let mut b = Builder::new();
    let mut header = false;
    for (n, raw) in text.lines().enumerate() {
        let line_no = n + 1;
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        if !header {
            let cols: Vec<&str> = line.split(',').map(str::trim).collect();
            if cols != ["time_ms", "tag", "value"] {
                return Err(err(
                    origin,
                    line_no,
                    format!("expected the header 'time_ms,tag,value', found '{line}'"),
                )
                .into());
            }
            header = true;
            continue;
        }
        let cols: Vec<&str> = line.split(',').map(str::trim).collect();
        if cols.len() != 3 {
            return Err(err(
                origin,
                line_no,
                format!("malformed row '{line}': expected time_ms,tag,value"),
            )
            .into());
        }
        let at: u64 = cols[0].parse().map_err(|_| {
            err(
                origin,
                line_no,
                format!("time '{}' is not a whole number of milliseconds", cols[0]),
            )
        })?;
        if cols[1].is_empty() {
            return Err(err(
                origin,
                line_no,
                format!("malformed row '{line}': the tag is empty"),
            )
            .into());
        }
        let v = value(cols[2]).ok_or_else(|| {
            err(
                origin,
                line_no,
                format!(
                    "value '{}' for {} is not 0, 1, true or false",
                    cols[2], cols[1]
                ),
            )
        })?;
        let s = b.signal(cols[1]);
        b.row(at, s, v)
            .map_err(|e| err(origin, line_no, e.to_string()))?;
    }
    if !header {
        return Err(err(
            origin,
            1,
            "empty log: expected the header 'time_ms,tag,value'".into(),
        )
        .into());
    }
    Ok(b.log)
}

/// Parses the paper's numeric form: `map` gives `number,tag` lines,
/// `events` gives `t,e` lines.
///
/// # Errors
/// The first bad line of either text.
pub fn parse_numeric(
    map_origin: &str,
    map: &str,
    origin: &str,
    events: &str,
) -> Result<RunLog, LogError> {
    let mut names: HashMap<u32, String> = HashMap::new();
    let mut order: Vec<u32> = Vec::new();
    for (n, raw) in map.lines().enumerate() {
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let (num, tag) = line.split_once(',').ok_or_else(|| {
            err(
                map_origin,
                n + 1,
                format!("malformed line '{line}': expected number,tag"),
            )
        })?;
        let num: u32 = num.trim().parse().map_err(|_| {
            err(
                map_origin,
                n + 1,
                format!("'{}' is not a signal number", num.trim()),
            )
        })?;
        if names.insert(num, tag.trim().to_string()).is_some() {
            return Err(err(
                map_origin,
                n + 1,
                format!("signal number {num} is mapped twice"),
            )
            .into());
        }
        order.push(num);
    }
    let mut b = Builder::new();
    order.sort_unstable();
    for num in &order {
        let s = b.signal(&names[num]);
        b.row(0, s, false)
            .map_err(|e| err(origin, 1, e.to_string()))?;
    }
    for (n, raw) in events.lines().enumerate() {
        let line_no = n + 1;
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') || line.eq_ignore_ascii_case("t,e") {
            continue;
        }
        let (t, e) = line.split_once(',').ok_or_else(|| {
            err(
                origin,
                line_no,
                format!("malformed row '{line}': expected t,e"),
            )
        })?;
        let at: u64 = t.trim().parse().map_err(|_| {
            err(
                origin,
                line_no,
                format!("time '{}' is not a whole number of milliseconds", t.trim()),
            )
        })?;
        let e = e.trim();
        let (rise, num) = match e.as_bytes().first() {
            Some(b'+') => (true, &e[1..]),
            Some(b'-') => (false, &e[1..]),
            _ => return Err(err(origin, line_no, format!("event '{e}' must be +s or -s")).into()),
        };
        let num: u32 = num.parse().map_err(|_| {
            err(
                origin,
                line_no,
                format!("event '{e}' must be +s or -s with a signal number"),
            )
        })?;
        let name = names.get(&num).ok_or_else(|| {
            err(
                origin,
                line_no,
                format!("unknown signal number {num} in '{e}' (not in {map_origin})"),
            )
        })?;
        let s = b.signal(&name.clone());
        b.row(at, s, rise)
            .map_err(|e| err(origin, line_no, e.to_string()))?;
    }
    Ok(b.log)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_runs() {
        let log = parse_csv(
            "r.csv",
            "time_ms,tag,value\n0,a,0\n0,b,1\n10,a,1\n20,b,false\n25,c,1\n",
        )
        .unwrap();
        assert_eq!(log.signals, ["a", "b", "c"]);
        assert_eq!(log.initial, [false, true, false]);
        assert_eq!(log.changes.len(), 3);
        assert_eq!(
            log.changes[2],
            Change {
                at: 25,
                signal: 2,
                value: true
            }
        );
    }

    #[test]
    fn bad_logs_are_pinned() {
        let e = |t: &str| parse_csv("r.csv", t).unwrap_err().to_string();
        assert_eq!(
            e("time,tag,value\n"),
            "r.csv:1: expected the header 'time_ms,tag,value', found 'time,tag,value'"
        );
        assert_eq!(
            e("time_ms,tag,value\n0,a,0\n10,a\n"),
            "r.csv:3: malformed row '10,a': expected time_ms,tag,value"
        );
        assert_eq!(
            e("time_ms,tag,value\n20,a,1\n10,a,0\n"),
            "r.csv:3: time 10 ms goes backwards (previous row at 20 ms)"
        );
        assert_eq!(
            e("time_ms,tag,value\nx,a,1\n"),
            "r.csv:2: time 'x' is not a whole number of milliseconds"
        );
        assert_eq!(
            e("time_ms,tag,value\n0,a,2\n"),
            "r.csv:2: value '2' for a is not 0, 1, true or false"
        );
        assert_eq!(
            e(""),
            "r.csv:1: empty log: expected the header 'time_ms,tag,value'"
        );
        let n = parse_numeric(
            "map.csv",
            "1,S1\n2,S2\n3,S3\n",
            "run.csv",
            "t,e\n10,+2\n140,+4\n",
        )
        .unwrap_err();
        assert_eq!(
            n.to_string(),
            "run.csv:3: unknown signal number 4 in '+4' (not in map.csv)"
        );
        let n = parse_numeric("map.csv", "1,S1\n", "run.csv", "10,*1\n").unwrap_err();
        assert_eq!(n.to_string(), "run.csv:1: event '*1' must be +s or -s");
    }
}
