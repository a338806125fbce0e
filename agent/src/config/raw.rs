//! The configuration file as written: serde structs mirroring the TOML,
//! every one rejecting unknown keys. Values whose problems are found only at
//! validation keep their span, so the error can point at them.

use serde::Deserialize;
use toml::Spanned;

/// The whole file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawConfig {
    pub(crate) cell: RawCell,
    pub(crate) opcua: Option<Spanned<crate::sources::opcua::config::RawOpcUa>>,
    pub(crate) legacy: Option<Spanned<crate::sources::at_bus::config::RawLegacy>>,
    #[serde(default)]
    pub(crate) tags: Vec<RawTag>,
    /// The tags as a CSV file instead of `[[tags]]` tables.
    pub(crate) tags_file: Option<Spanned<String>>,
    #[serde(default)]
    pub(crate) checks: RawChecks,
    #[serde(default)]
    pub(crate) state: RawState,
    #[serde(default)]
    pub(crate) zenoh: crate::bus::config::RawZenoh,
    #[serde(default)]
    pub(crate) journal: crate::journal::config::RawJournal,
    #[serde(default)]
    pub(crate) metrics: RawMetrics,
    #[serde(default)]
    pub(crate) commands: RawCommands,
    #[serde(default)]
    pub(crate) production: RawProduction,
    /// `[alertmanager]`: the sink owns its table.
    pub(crate) alertmanager: Option<Spanned<crate::sinks::alertmanager::config::RawAlertmanager>>,
    /// `[alarm_server]`: the server owns its table.
    pub(crate) alarm_server: Option<Spanned<crate::services::alarm_server::config::RawAlarmServer>>,
    /// `[sparkplug]`: the sink owns its table.
    pub(crate) sparkplug: Option<Spanned<crate::config::sparkplug::RawSparkplug>>,
    /// `[oee]`: the OEE sink owns its table.
    pub(crate) oee: Option<Spanned<crate::config::oee::RawOee>>,
    #[serde(default)]
    pub(crate) kpi: RawKpi,
    #[serde(default)]
    pub(crate) alarms: RawSystemAlarms,
    #[serde(default)]
    pub(crate) recorder: RawRecorder,
}

/// `[recorder]`: the flight recorder around every alarm.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawRecorder {
    pub(crate) enabled: Option<bool>,
    pub(crate) before: Option<Spanned<String>>,
    pub(crate) after: Option<Spanned<String>>,
    pub(crate) capacity: Option<Spanned<i64>>,
    pub(crate) max_changes: Option<Spanned<i64>>,
    pub(crate) max_open: Option<Spanned<i64>>,
}

/// `[alarms.<id>]`: the delays of the agent's own alarms, and
/// `[alarms.consequences]`.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawSystemAlarms {
    pub(crate) communication: Option<RawDelays>,
    #[serde(rename = "tag-quality")]
    pub(crate) tag_quality: Option<RawDelays>,
    pub(crate) consequences: Option<RawConsequences>,
    pub(crate) database: Option<Spanned<String>>,
}

/// `[alarms.consequences]`: whether consequences are annunciated, and
/// edges added to or removed from the derived relation.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawConsequences {
    pub(crate) suppress: Option<bool>,
    #[serde(default)]
    pub(crate) add: Vec<Spanned<RawEdge>>,
    #[serde(default)]
    pub(crate) remove: Vec<Spanned<RawEdge>>,
}

/// One edge of the consequence relation: `effect` follows from `cause`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawEdge {
    pub(crate) cause: String,
    pub(crate) effect: String,
}

/// An alarm's on-delay and off-delay.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawDelays {
    pub(crate) on_delay: Option<Spanned<String>>,
    pub(crate) off_delay: Option<Spanned<String>>,
}

/// `[kpi]`: the plant's alarm-performance rules.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawKpi {
    pub(crate) flood_raises: Option<Spanned<i64>>,
    pub(crate) flood_ends_below: Option<Spanned<i64>>,
    pub(crate) chatter_raises: Option<Spanned<i64>>,
    pub(crate) chatter_window: Option<Spanned<String>>,
    pub(crate) stale_after: Option<Spanned<String>>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawProduction {
    pub(crate) part_done: Option<Spanned<String>>,
    pub(crate) counter: Option<Spanned<OneOrMany>>,
    pub(crate) item: Option<Spanned<String>>,
    pub(crate) target: Option<Spanned<String>>,
}

/// One address, or a list of them.
#[derive(Debug, Deserialize)]
#[serde(untagged)]
pub(crate) enum OneOrMany {
    One(String),
    Many(Vec<String>),
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawCell {
    pub(crate) id: Spanned<String>,
    #[serde(default)]
    pub(crate) description: String,
    pub(crate) dialect: Option<Spanned<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawTag {
    pub(crate) name: Spanned<String>,
    pub(crate) node_id: Spanned<String>,
    pub(crate) address: Spanned<String>,
    #[serde(default)]
    pub(crate) comment: Option<String>,
    #[serde(rename = "type")]
    pub(crate) value_type: Option<Spanned<String>>,
    pub(crate) bit: Option<Spanned<i64>>,
    pub(crate) sampling_interval: Option<Spanned<String>>,
    pub(crate) deadband: Option<Spanned<f64>>,
    pub(crate) deadband_percent: Option<Spanned<f64>>,
    #[serde(default)]
    pub(crate) export: bool,
    pub(crate) max: Option<Spanned<u64>>,
    pub(crate) states: Option<Spanned<String>>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawChecks {
    #[serde(default)]
    pub(crate) switching: Vec<RawSwitching>,
    #[serde(default)]
    pub(crate) timers: Vec<RawTimers>,
    #[serde(default)]
    pub(crate) limit: Vec<RawLimit>,
    #[serde(default)]
    pub(crate) discrete: Vec<RawDiscrete>,
    #[serde(default)]
    pub(crate) sfc: Vec<RawSfc>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawDiscrete {
    pub(crate) id: Spanned<String>,
    pub(crate) tag: Spanned<String>,
    pub(crate) fault_when: Option<Spanned<String>>,
    pub(crate) message: Option<Spanned<String>>,
    pub(crate) severity: Option<Spanned<String>>,
    pub(crate) on_delay: Option<Spanned<String>>,
    pub(crate) off_delay: Option<Spanned<String>>,
    pub(crate) armed_when: Option<Spanned<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawSfc {
    pub(crate) id: Spanned<String>,
    pub(crate) charts: Spanned<String>,
    pub(crate) steps: Option<Spanned<String>>,
    #[serde(default)]
    pub(crate) supervision: std::collections::BTreeMap<String, Spanned<String>>,
    pub(crate) severity: Option<Spanned<String>>,
    pub(crate) force_switch: Option<Spanned<String>>,
    pub(crate) stop_switch: Option<Spanned<String>>,
    #[serde(default)]
    pub(crate) forcible: Vec<Spanned<String>>,
    pub(crate) force_pulse: Option<Spanned<String>>,
    pub(crate) force_timeout: Option<Spanned<String>>,
    pub(crate) program: Option<Spanned<String>>,
    pub(crate) dialect: Option<Spanned<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawLimit {
    pub(crate) id: Spanned<String>,
    pub(crate) tag: Spanned<String>,
    #[serde(default)]
    pub(crate) unit: String,
    pub(crate) hysteresis: Option<Spanned<f64>>,
    /// The former name of `hysteresis`: taken, with a warning.
    pub(crate) deadband: Option<Spanned<f64>>,
    pub(crate) on_delay: Option<Spanned<String>>,
    pub(crate) off_delay: Option<Spanned<String>>,
    pub(crate) hh: Option<Spanned<RawLevel>>,
    pub(crate) h: Option<Spanned<RawLevel>>,
    pub(crate) l: Option<Spanned<RawLevel>>,
    pub(crate) ll: Option<Spanned<RawLevel>>,
    pub(crate) rising: Option<Spanned<RawRate>>,
    pub(crate) falling: Option<Spanned<RawRate>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawLevel {
    pub(crate) limit: f64,
    pub(crate) severity: Option<Spanned<String>>,
}

/// A rate-of-change level of `[[checks.limit]]`: `rising = { rate = 5.0,
/// per = "1m" }`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawRate {
    pub(crate) rate: Spanned<f64>,
    pub(crate) per: Spanned<String>,
    pub(crate) severity: Option<Spanned<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawTimers {
    pub(crate) id: Spanned<String>,
    pub(crate) model: Spanned<String>,
    pub(crate) severity: Option<Spanned<String>>,
    pub(crate) drift: Option<bool>,
    pub(crate) drift_fraction: Option<Spanned<f64>>,
    pub(crate) drift_spread: Option<Spanned<f64>>,
    pub(crate) drift_min_samples: Option<Spanned<i64>>,
    pub(crate) drift_weight: Option<Spanned<f64>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawSwitching {
    pub(crate) id: Spanned<String>,
    pub(crate) program: Spanned<String>,
    pub(crate) dialect: Option<Spanned<String>>,
    pub(crate) coil: Spanned<String>,
    pub(crate) fault_when: Option<Spanned<String>>,
    pub(crate) severity: Option<Spanned<String>>,
    pub(crate) fault_type: Option<String>,
    pub(crate) comments: Option<Spanned<String>>,
    pub(crate) comment_language: Option<Spanned<String>>,
    pub(crate) observable: Option<Spanned<String>>,
    pub(crate) armed_when: Option<Spanned<String>>,
    pub(crate) on_delay: Option<Spanned<String>>,
    pub(crate) off_delay: Option<Spanned<String>>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawState {
    pub(crate) running: Option<Spanned<String>>,
    pub(crate) fault_severity: Option<Spanned<String>>,
    pub(crate) publish_interval: Option<Spanned<String>>,
    #[serde(default)]
    pub(crate) modes: Vec<Spanned<RawMode>>,
}

/// A machine mode and the alarms it suppresses by design
/// (`[[state.modes]]`).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawMode {
    pub(crate) id: Spanned<String>,
    pub(crate) when: Spanned<String>,
    pub(crate) suppress: Spanned<Vec<Spanned<String>>>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawMetrics {
    pub(crate) listen: Option<Spanned<String>>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawCommands {
    pub(crate) operators_file: Option<Spanned<String>>,
    pub(crate) plant_key: Option<Spanned<String>>,
    pub(crate) plant_list: Option<Spanned<String>>,
    pub(crate) max_shelve: Option<Spanned<String>>,
    /// The shared-secret file of earlier versions: refused with a message.
    pub(crate) secrets_file: Option<Spanned<toml::Value>>,
}

/// The columns of a tags file, as the keys of a `[[tags]]` table.
const TAG_COLUMNS: [&str; 12] = [
    "name",
    "node_id",
    "address",
    "type",
    "comment",
    "bit",
    "sampling_interval",
    "deadband",
    "deadband_percent",
    "export",
    "max",
    "states",
];

/// Tags as they are read, and the problems found reading them.
pub(crate) trait TagRows: Iterator<Item = RawTag> {
    /// The problems found while reading (byte offset, key, message).
    fn problems(&mut self) -> Vec<(usize, String, String)> {
        Vec::new()
    }
}

/// `[[tags]]` tables, read with the configuration.
impl TagRows for std::vec::IntoIter<RawTag> {}

impl TagRows for CsvTags<'_> {
    fn problems(&mut self) -> Vec<(usize, String, String)> {
        std::mem::take(&mut self.problems)
    }
}

/// The tags of a CSV tags file (`tags_file`), row by row, each value
/// spanned at the start of its row's line in the text; a row with a
/// problem is left out and its problem kept ([`TagRows::problems`]). Read
/// as the validator goes, so a 100,000-row file is never held as raw rows.
pub(crate) struct CsvTags<'a> {
    text: &'a str,
    /// `None` when the header row is wrong: no rows are read.
    reader: Option<csv::Reader<&'a [u8]>>,
    column: [Option<usize>; TAG_COLUMNS.len()],
    record: csv::StringRecord,
    /// Rows read so far, good or not.
    rows: usize,
    /// Lines in the file: at most as many rows.
    lines: usize,
    /// The problems found so far: byte offset, key, message.
    problems: Vec<(usize, String, String)>,
}

impl<'a> CsvTags<'a> {
    /// Reads the header row of `text`.
    pub(crate) fn new(text: &'a str) -> CsvTags<'a> {
        let mut tags = CsvTags {
            text,
            reader: None,
            column: [None; TAG_COLUMNS.len()],
            record: csv::StringRecord::new(),
            rows: 0,
            lines: text.lines().count(),
            problems: Vec::new(),
        };
        let mut reader = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .comment(Some(b'#'))
            .from_reader(text.as_bytes());
        let headers = match reader.headers() {
            Ok(h) => h.clone(),
            Err(e) => {
                tags.header_problem(format!("cannot read the header row: {e}"));
                return tags;
            }
        };
        for (i, h) in headers.iter().enumerate() {
            match TAG_COLUMNS.iter().position(|&c| c == h) {
                Some(k) if tags.column[k].is_none() => tags.column[k] = Some(i),
                Some(_) => tags.header_problem(format!("column '{h}' is given twice")),
                None => tags.header_problem(format!(
                    "unknown column '{h}': the columns are {}",
                    TAG_COLUMNS.join(", ")
                )),
            }
        }
        for (k, name) in TAG_COLUMNS.iter().enumerate().take(3) {
            if tags.column[k].is_none() {
                tags.header_problem(format!("the header row has no '{name}' column"));
            }
        }
        if tags.problems.is_empty() {
            tags.reader = Some(reader);
        }
        tags
    }

    fn header_problem(&mut self, message: String) {
        self.problems.push((0, "tags_file".into(), message));
    }
}

impl Iterator for CsvTags<'_> {
    type Item = RawTag;

    fn next(&mut self) -> Option<RawTag> {
        let reader = self.reader.as_mut()?;
        loop {
            match reader.read_record(&mut self.record) {
                Ok(false) => return None,
                Ok(true) => {}
                Err(e) => {
                    let at = e.position().map_or(0, |p| p.byte() as usize);
                    self.problems.push((at, "tags_file".into(), e.to_string()));
                    // A malformed row (a stray quote, a wrong number of
                    // cells) is reported and skipped; the rest is still read.
                    continue;
                }
            }
            let at = row_start(
                self.text,
                self.record.position().map_or(0, |p| p.byte() as usize),
            );
            let row = self.rows;
            self.rows += 1;
            match tag_of_row(&self.record, &self.column, at) {
                Ok(t) => return Some(t),
                Err((key, message)) => {
                    self.problems
                        .push((at, format!("tags[{row}].{key}"), message))
                }
            }
        }
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        (0, Some(self.lines))
    }
}

/// Where the row the reader says starts at `at` really starts: past the
/// blank and comment lines before it, which the reader skips.
fn row_start(text: &str, mut at: usize) -> usize {
    while let Some(rest) = text.get(at..) {
        let line = rest.split_inclusive('\n').next().unwrap_or("");
        let blank = line.trim().is_empty() || line.trim_start().starts_with('#');
        if !blank || line.is_empty() {
            break;
        }
        at += line.len();
    }
    at
}

/// One row as a `[[tags]]` table, or the key and the problem.
fn tag_of_row(
    record: &csv::StringRecord,
    column: &[Option<usize>; TAG_COLUMNS.len()],
    at: usize,
) -> Result<RawTag, (&'static str, String)> {
    let span = at..at + 1;
    let cell = |k: usize| {
        column[k]
            .and_then(|i| record.get(i))
            .filter(|v| !v.is_empty())
    };
    let text = |k: usize| cell(k).map(|v| Spanned::new(span.clone(), v.to_string()));
    let required = |k: usize| text(k).ok_or((TAG_COLUMNS[k], "is empty".to_string()));
    fn number<T: std::str::FromStr>(
        v: Option<&str>,
        key: &'static str,
        span: &std::ops::Range<usize>,
    ) -> Result<Option<Spanned<T>>, (&'static str, String)> {
        v.map(|v| {
            v.parse()
                .map(|n| Spanned::new(span.clone(), n))
                .map_err(|_| (key, format!("'{v}' is not a number")))
        })
        .transpose()
    }
    let export = match cell(9) {
        None | Some("false") => false,
        Some("true") => true,
        Some(other) => return Err(("export", format!("'{other}' is neither true nor false"))),
    };
    Ok(RawTag {
        name: required(0)?,
        node_id: required(1)?,
        address: required(2)?,
        value_type: text(3),
        comment: cell(4).map(str::to_string),
        bit: number(cell(5), "bit", &span)?,
        sampling_interval: text(6),
        deadband: number(cell(7), "deadband", &span)?,
        deadband_percent: number(cell(8), "deadband_percent", &span)?,
        export,
        max: number(cell(10), "max", &span)?,
        states: text(11),
    })
}
