//! The text form of charts: TOML, written by hand or generated.
//!
//! ```toml
//! [[chart]]
//! name = "F1"
//! initial = "S0"
//! # step_word = "D300"        # steps by number in this word instead of flags
//!
//! [[chart.step]]
//! name = "S2"
//! flag = "M0.02"              # the PLC's step flag (S2.X); or number = 2
//! supervision = "8s"          # stuck when active longer (ms, s, m, h)
//! comment = "Shuttle to waiting position"
//!
//! [[chart.transition]]
//! id = "t3"
//! from = "S2"                 # or ["S6", "S9"]: simultaneous convergence
//! to = "F2.S5"                # or ["S5", "S8"]: simultaneous divergence;
//!                             # CHART.STEP jumps to another chart
//! condition = "X0.03"         # paper notation over tag addresses
//! comment = "Shuttle at waiting position"
//! ```
//!
//! Every problem is reported as `FILE:LINE:COL: what`, all of them (up to
//! [`MAX_ERRORS`]), not just the first.

use std::collections::{HashMap, HashSet};
use std::fmt;

use serde::Deserialize;
use toml::Spanned;

use super::{Chart, Sfc, SfcTransition, Step, StepRef};
use crate::comments::CommentDb;
use crate::expr::Expr;
use crate::signal::Signal;

/// At most this many problems are listed.
pub const MAX_ERRORS: usize = 20;

// The charts as written, with the places of their parts: the TOML form
// deserialises into these, the PLCopen XML reader builds them, and one
// builder checks them and makes the model.

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawFile {
    #[serde(default)]
    pub(super) chart: Vec<RawChart>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawChart {
    pub(super) name: Spanned<String>,
    pub(super) initial: Option<Spanned<String>>,
    pub(super) step_word: Option<Spanned<String>>,
    #[serde(default)]
    pub(super) step: Vec<RawStep>,
    #[serde(default)]
    pub(super) transition: Vec<RawTransition>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawStep {
    pub(super) name: Spanned<String>,
    pub(super) flag: Option<Spanned<String>>,
    pub(super) number: Option<Spanned<i64>>,
    pub(super) supervision: Option<Spanned<String>>,
    pub(super) comment: Option<String>,
}

#[derive(Deserialize)]
#[serde(untagged)]
pub(super) enum OneOrMany {
    One(String),
    Many(Vec<String>),
}

impl OneOrMany {
    fn items(&self) -> Vec<&str> {
        match self {
            OneOrMany::One(s) => vec![s.as_str()],
            OneOrMany::Many(v) => v.iter().map(String::as_str).collect(),
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawTransition {
    pub(super) id: Spanned<String>,
    pub(super) from: Spanned<OneOrMany>,
    pub(super) to: Spanned<OneOrMany>,
    pub(super) condition: Spanned<String>,
    pub(super) comment: Option<String>,
    /// Where each target is written, when not at `to` (PLCopen XML: the
    /// `step` or `jumpStep` element), in the order of `to`.
    #[serde(skip)]
    pub(super) to_at: Vec<usize>,
}

/// Parses the charts of `text` (the file `file`); `known` says whether a
/// signal is one of the cell's tags (comparisons included), so that an
/// unknown contact is an error at its place.
///
/// # Errors
/// Every problem found, each `FILE:LINE:COL: what`.
pub fn parse(file: &str, text: &str, known: &dyn Fn(&Signal) -> bool) -> Result<Sfc, Vec<String>> {
    let mut errors = Errors::new(file, text);
    let raw: RawFile = match toml::from_str(text) {
        Ok(r) => r,
        Err(e) => {
            let at = e.span().map_or(0, |s| s.start);
            errors.at(at, e.message().trim_end().to_string());
            return Err(errors.finish());
        }
    };
    build(errors, &raw, known, &Expr::parse)
}

/// Checks charts as written and makes the model; `condition` reads a
/// transition's condition (the paper's notation, or ST from PLCopen XML).
pub(super) fn build<E: fmt::Display>(
    mut errors: Errors<'_>,
    raw: &RawFile,
    known: &dyn Fn(&Signal) -> bool,
    condition: &dyn Fn(&str) -> Result<Expr, E>,
) -> Result<Sfc, Vec<String>> {
    if raw.chart.is_empty() {
        errors.at(0, "no chart: write at least one [[chart]]".into());
    }
    // Charts and steps by name first, so that jumps can point forward.
    let mut charts: Vec<Chart> = Vec::new();
    let mut names: HashMap<String, usize> = HashMap::new();
    for c in &raw.chart {
        if names
            .insert(c.name.get_ref().clone(), charts.len())
            .is_some()
        {
            errors.at(
                c.name.span().start,
                format!("chart '{}' is defined twice", c.name.get_ref()),
            );
        }
        let mut steps = Vec::new();
        let mut seen = HashSet::new();
        for s in &c.step {
            let name = s.name.get_ref();
            if !seen.insert(name.clone()) {
                errors.at(
                    s.name.span().start,
                    format!(
                        "step '{name}' is defined twice in chart {}",
                        c.name.get_ref()
                    ),
                );
            }
            let flag = step_flag(c, s, known, &mut errors);
            let supervision_ms = s.supervision.as_ref().and_then(|d| {
                duration_ms(d.get_ref())
                    .map_err(|why| errors.at(d.span().start, format!("supervision: {why}")))
                    .ok()
            });
            steps.push(Step {
                name: name.clone(),
                flag: flag.unwrap_or_else(|| Signal::new(name)),
                supervision_ms,
                comment: s.comment.clone(),
            });
        }
        let initial = c.initial.as_ref().and_then(|i| {
            let found = steps.iter().position(|s| &s.name == i.get_ref());
            if found.is_none() {
                errors.at(
                    i.span().start,
                    format!(
                        "initial step '{}' is no step of chart {}",
                        i.get_ref(),
                        c.name.get_ref()
                    ),
                );
            }
            found
        });
        charts.push(Chart {
            name: c.name.get_ref().clone(),
            initial,
            steps,
            transitions: Vec::new(),
        });
    }
    let find = |chart: usize, text: &str| -> Result<StepRef, StepRefError> {
        let (c, step) = match text.split_once('.') {
            Some((c, step)) => match names.get(c) {
                Some(&c) => (c, step),
                None => return Err(StepRefError::NoChart { chart: c.into() }),
            },
            None => (chart, text),
        };
        charts[c]
            .steps
            .iter()
            .position(|s| s.name == step)
            .map(|step| StepRef { chart: c, step })
            .ok_or_else(|| StepRefError::NoStep {
                step: step.into(),
                chart: charts[c].name.clone(),
            })
    };
    let mut transitions: Vec<Vec<SfcTransition>> = vec![Vec::new(); charts.len()];
    for (ci, c) in raw.chart.iter().enumerate() {
        let mut ids = HashSet::new();
        for t in &c.transition {
            let id = t.id.get_ref();
            if !ids.insert(id.clone()) {
                errors.at(
                    t.id.span().start,
                    format!(
                        "transition '{id}' is defined twice in chart {}",
                        c.name.get_ref()
                    ),
                );
            }
            let mut from = Vec::new();
            let sources = t.from.get_ref().items();
            if sources.is_empty() {
                errors.at(
                    t.from.span().start,
                    format!("transition {id} has no source step"),
                );
            }
            for s in sources {
                match find(ci, s) {
                    Ok(r) if r.chart == ci => from.push(r),
                    Ok(_) => errors.at(
                        t.from.span().start,
                        format!(
                            "transition {id}: '{s}' is a step of another chart; a transition leaves steps of its own chart ({})",
                            c.name.get_ref()
                        ),
                    ),
                    Err(why) => errors.at(t.from.span().start, format!("transition {id} leaves '{s}': {why}")),
                }
            }
            let mut to = Vec::new();
            let targets = t.to.get_ref().items();
            if targets.is_empty() {
                errors.at(
                    t.to.span().start,
                    format!("transition {id} has no target step"),
                );
            }
            for (k, s) in targets.into_iter().enumerate() {
                let at = t.to_at.get(k).copied().unwrap_or(t.to.span().start);
                match find(ci, s) {
                    Ok(r) => to.push(r),
                    Err(why) if s.contains('.') => {
                        errors.at(at, format!("transition {id} jumps to '{s}': {why}"))
                    }
                    Err(why) => errors.at(at, format!("transition {id} goes to '{s}': {why}")),
                }
            }
            let condition = match condition(t.condition.get_ref()) {
                Ok(e) => {
                    for s in e.signals() {
                        if !known(&s) {
                            errors.at(
                                t.condition.span().start,
                                format!("transition {id}: unknown contact '{s}': no tag has this address"),
                            );
                        }
                    }
                    e
                }
                Err(why) => {
                    errors.at(
                        t.condition.span().start,
                        format!("transition {id}: condition: {why}"),
                    );
                    Expr::Const(false)
                }
            };
            transitions[ci].push(SfcTransition {
                id: id.clone(),
                from,
                to,
                condition,
                comment: t.comment.clone(),
            });
        }
    }
    for (c, ts) in charts.iter_mut().zip(transitions) {
        c.transitions = ts;
    }
    // Every step is the initial step of its chart or the target of some
    // transition.
    let mut reached: HashSet<StepRef> = charts
        .iter()
        .enumerate()
        .filter_map(|(c, chart)| chart.initial.map(|step| StepRef { chart: c, step }))
        .collect();
    for chart in &charts {
        for t in &chart.transitions {
            reached.extend(t.to.iter().copied());
        }
    }
    for (ci, c) in raw.chart.iter().enumerate() {
        for (si, s) in c.step.iter().enumerate() {
            if !reached.contains(&StepRef {
                chart: ci,
                step: si,
            }) {
                errors.at(
                    s.name.span().start,
                    format!(
                        "step {}.{} is unreachable: it is not the initial step and no transition leads to it",
                        c.name.get_ref(),
                        s.name.get_ref()
                    ),
                );
            }
        }
    }
    if errors.list.is_empty() {
        Ok(Sfc {
            charts,
            variables: CommentDb::default(),
        })
    } else {
        Err(errors.finish())
    }
}

/// The flag of step `s`: its `flag`, or `step_word == number`.
fn step_flag(
    c: &RawChart,
    s: &RawStep,
    known: &dyn Fn(&Signal) -> bool,
    errors: &mut Errors<'_>,
) -> Option<Signal> {
    let at = s.name.span().start;
    let (text, at) = match (&s.flag, &s.number, &c.step_word) {
        (Some(f), None, _) => (f.get_ref().clone(), f.span().start),
        (None, Some(n), Some(w)) => (
            format!("{} == {}", w.get_ref(), n.get_ref()),
            n.span().start,
        ),
        (None, Some(n), None) => {
            errors.at(
                n.span().start,
                format!(
                    "step {}: number needs the chart's step_word",
                    s.name.get_ref()
                ),
            );
            return None;
        }
        (Some(f), Some(_), _) => {
            errors.at(
                f.span().start,
                format!("step {}: give flag or number, not both", s.name.get_ref()),
            );
            return None;
        }
        (None, None, _) => {
            errors.at(
                at,
                format!(
                    "step {}: give its flag (the PLC's step flag) or its number in step_word",
                    s.name.get_ref()
                ),
            );
            return None;
        }
    };
    match Expr::parse(&text) {
        Ok(Expr::Lit(signal, false)) => {
            if !known(&signal) {
                errors.at(
                    at,
                    format!(
                        "step {}: unknown contact '{signal}': no tag has this address",
                        s.name.get_ref()
                    ),
                );
            }
            Some(signal)
        }
        Ok(_) => {
            errors.at(
                at,
                format!(
                    "step {}: the flag is one contact, not '{text}'",
                    s.name.get_ref()
                ),
            );
            None
        }
        Err(why) => {
            errors.at(at, format!("step {}: flag: {why}", s.name.get_ref()));
            None
        }
    }
}

/// Why a transition's source or target names no step.
#[derive(Debug, thiserror::Error)]
enum StepRefError {
    /// `CHART.STEP` with no chart of that name.
    #[error("no chart '{chart}'")]
    NoChart {
        /// The chart's name as written.
        chart: String,
    },
    /// A chart without a step of that name.
    #[error("no step '{step}' in chart {chart}")]
    NoStep {
        /// The step's name as written.
        step: String,
        /// The chart looked in.
        chart: String,
    },
}

/// A duration written wrong (a step's supervision time); each variant
/// quotes the text as written.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DurationError {
    /// Not a number and a unit (`ms`, `s`, `m`, `min`, `h`).
    #[error("'{text}': write a duration such as 500ms, 8s, 2m or 1h")]
    Malformed {
        /// The duration as written.
        text: String,
    },
    /// Shorter than 1 ms, or longer than 10¹² ms.
    #[error("'{text}': between 1 ms and about 30 years")]
    OutOfRange {
        /// The duration as written.
        text: String,
    },
}

/// `500ms`, `8s`, `1.5s`, `2m`, `1h` in ms.
///
/// # Errors
/// [`DurationError`] quoting a text that is no duration, or one out of
/// range.
pub fn duration_ms(text: &str) -> Result<u64, DurationError> {
    let t = text.trim();
    let split = t
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(t.len());
    let (number, unit) = t.split_at(split);
    let malformed = || DurationError::Malformed { text: text.into() };
    let n: f64 = number.parse().map_err(|_| malformed())?;
    let scale = match unit.trim() {
        "ms" => 1.0,
        "s" => 1000.0,
        "m" | "min" => 60_000.0,
        "h" => 3_600_000.0,
        _ => return Err(malformed()),
    };
    let ms = n * scale;
    if !(1.0..=1e12).contains(&ms) {
        return Err(DurationError::OutOfRange { text: text.into() });
    }
    Ok(ms.round() as u64)
}

pub(super) struct Errors<'a> {
    file: &'a str,
    text: &'a str,
    list: Vec<String>,
    more: usize,
}

impl<'a> Errors<'a> {
    /// Problems of the file `file`, whose text is `text`.
    pub(super) fn new(file: &'a str, text: &'a str) -> Errors<'a> {
        Errors {
            file,
            text,
            list: Vec::new(),
            more: 0,
        }
    }

    /// A problem at byte `offset` of the text.
    pub(super) fn at(&mut self, offset: usize, what: String) {
        if self.list.len() >= MAX_ERRORS {
            self.more += 1;
            return;
        }
        let before = self.text.get(..offset).unwrap_or(self.text);
        let line = before.matches('\n').count() + 1;
        let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
        self.list
            .push(format!("{}:{line}:{col}: {what}", self.file));
    }

    /// Every problem, `FILE:LINE:COL: what`, and how many more.
    pub(super) fn finish(mut self) -> Vec<String> {
        if self.more > 0 {
            self.list
                .push(format!("{}: and {} more problems", self.file, self.more));
        }
        self.list
    }
}
