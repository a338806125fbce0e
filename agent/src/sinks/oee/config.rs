//! `[oee]`: how the cell's overall equipment effectiveness is judged. The
//! table as written ([`RawOee`], unknown keys rejected), the validated
//! rules ([`OeeConfig`]) and [`validate`], which finds every problem and
//! says where it is. No I/O. The configuration's validator calls
//! [`validate`] with the machine modes and a way to look a tag up, and
//! places each problem at its line and column; it imports nothing else of
//! the sink.

use std::collections::BTreeMap;
use std::ops::Range;

use cellwatch_models::oee::{Calendar, OeeRules, Shift};
use serde::Deserialize;
use toml::Spanned;

/// An idle stop shorter than this is a small stop unless
/// `oee.small_stop` says.
pub const DEFAULT_SMALL_STOP_MS: u64 = 5 * 60_000;

/// Rejects this soon after a start are start-up rejects unless
/// `oee.startup` says.
pub const DEFAULT_STARTUP_MS: u64 = 10 * 60_000;

/// `[oee]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawOee {
    utc_offset: Option<Spanned<String>>,
    #[serde(default)]
    shifts: Vec<Spanned<RawShift>>,
    #[serde(default)]
    planned_stops: Vec<Spanned<String>>,
    #[serde(default)]
    setup: Vec<Spanned<String>>,
    small_stop: Option<Spanned<String>>,
    startup: Option<Spanned<String>>,
    ideal_cycle: Option<Spanned<String>>,
    #[serde(default)]
    items: Vec<Spanned<RawItem>>,
    reject_counter: Option<Spanned<String>>,
    reject_signal: Option<Spanned<String>>,
}

/// `[[oee.shifts]]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawShift {
    name: Spanned<String>,
    days: Option<Vec<Spanned<String>>>,
    start: Spanned<String>,
    end: Spanned<String>,
    #[serde(default)]
    breaks: Vec<Spanned<String>>,
}

/// `[[oee.items]]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawItem {
    item: Spanned<String>,
    ideal_cycle: Spanned<String>,
}

/// Where rejects are counted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RejectTag {
    /// Each rising edge of this contact (tag index) is one reject.
    Signal(usize),
    /// This integer tag counts rejects.
    Counter(usize),
}

/// The validated `[oee]`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OeeConfig {
    /// The calendar, modes, cycle times and stop lengths.
    pub rules: OeeRules,
    /// Where rejects are counted, if anywhere (quality is then 100 %).
    pub rejects: Option<RejectTag>,
}

/// What the validator knows of a tag the section names.
#[derive(Debug, Clone, Copy)]
pub struct TagFacts {
    /// Its index in the configuration's tags.
    pub index: usize,
    /// A contact (Boolean, or a bit).
    pub contact: bool,
    /// A whole integer word.
    pub integer: bool,
}

/// What is wrong with a key of `[oee]`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum OeeConfigError {
    /// No shift.
    #[error("give at least one [[oee.shifts]]: OEE is judged over planned production time")]
    NoShift,
    /// No default cycle time.
    #[error("required: the ideal cycle time of an item not listed, like \"30s\"")]
    NoIdealCycle,
    /// Not a duration.
    #[error("'{0}' is not a duration longer than zero; write e.g. 45s, 5m")]
    NotADuration(String),
    /// Not a time of day.
    #[error("'{0}' is not a time of day; write it as 06:00")]
    NotATime(String),
    /// Not a break.
    #[error("'{0}' is not a break; write it as 10:00-10:15")]
    NotABreak(String),
    /// Not a weekday.
    #[error("'{0}' is not a weekday; write mon, tue, wed, thu, fri, sat or sun")]
    NotAWeekday(String),
    /// Not an offset.
    #[error("'{0}' is not an offset from UTC; write it as +09:00 or -05:30")]
    NotAnOffset(String),
    /// A mode `[[state.modes]]` does not define.
    #[error("'{0}' is no machine mode of [[state.modes]]")]
    UnknownMode(String),
    /// A shift or item named twice.
    #[error("'{0}' is named twice")]
    Twice(String),
    /// No such tag.
    #[error("'{0}' is no configured tag")]
    UnknownTag(String),
    /// A reject signal that is not a contact.
    #[error("'{0}' is not a contact (Boolean, or a bit): a reject signal counts rising edges")]
    NotAContact(String),
    /// A reject counter that is not an integer word.
    #[error("'{0}' is not an integer tag: a reject counter counts increments")]
    NotACounter(String),
    /// Both ways of counting rejects.
    #[error("give reject_counter or reject_signal, not both")]
    BothRejects,
}

/// What [`validate`] found.
pub type Checked = crate::table::Checked<OeeConfig, OeeConfigError>;

/// One problem of `[oee]` and where it is.
pub type Problem = crate::table::Problem<OeeConfigError>;

/// Validates `[oee]` (its table at `raw`'s span): `modes` are the ids of
/// `[[state.modes]]`, `tag` looks a tag up by name or address.
pub fn validate(
    raw: Spanned<RawOee>,
    modes: &[String],
    tag: &dyn Fn(&str) -> Option<TagFacts>,
) -> Checked {
    let table = raw.span();
    let raw = raw.into_inner();
    let problems = std::cell::RefCell::new(Vec::new());
    let problem = |span: Range<usize>, key: String, error| {
        problems.borrow_mut().push(Problem { span, key, error });
    };
    let utc_offset_ms = match &raw.utc_offset {
        None => 0,
        Some(o) => offset(o.get_ref()).unwrap_or_else(|| {
            problem(
                o.span(),
                "oee.utc_offset".into(),
                OeeConfigError::NotAnOffset(o.get_ref().clone()),
            );
            0
        }),
    };
    let duration = |d: &Spanned<String>, key: String| match humantime::parse_duration(d.get_ref()) {
        Ok(v) if !v.is_zero() => v.as_millis() as u64,
        _ => {
            problem(
                d.span(),
                key,
                OeeConfigError::NotADuration(d.get_ref().clone()),
            );
            0
        }
    };
    let small_stop_ms = raw.small_stop.as_ref().map_or(DEFAULT_SMALL_STOP_MS, |d| {
        duration(d, "oee.small_stop".into())
    });
    let startup_ms = raw
        .startup
        .as_ref()
        .map_or(DEFAULT_STARTUP_MS, |d| duration(d, "oee.startup".into()));
    let ideal_cycle_ms = raw
        .ideal_cycle
        .as_ref()
        .map(|d| duration(d, "oee.ideal_cycle".into()));
    let mut items = BTreeMap::new();
    for (k, i) in raw.items.iter().enumerate() {
        let i = i.get_ref();
        let ms = duration(&i.ideal_cycle, format!("oee.items[{k}].ideal_cycle"));
        if items.insert(i.item.get_ref().clone(), ms).is_some() {
            problem(
                i.item.span(),
                format!("oee.items[{k}].item"),
                OeeConfigError::Twice(i.item.get_ref().clone()),
            );
        }
    }
    if ideal_cycle_ms.is_none() {
        problem(
            table.clone(),
            "oee.ideal_cycle".into(),
            OeeConfigError::NoIdealCycle,
        );
    }
    let known_modes = |list: &[Spanned<String>], key: &str| {
        for (k, m) in list.iter().enumerate() {
            if !modes.contains(m.get_ref()) {
                problem(
                    m.span(),
                    format!("oee.{key}[{k}]"),
                    OeeConfigError::UnknownMode(m.get_ref().clone()),
                );
            }
        }
        list.iter().map(|m| m.get_ref().clone()).collect::<Vec<_>>()
    };
    let planned_stops = known_modes(&raw.planned_stops, "planned_stops");
    let setup = known_modes(&raw.setup, "setup");
    if raw.shifts.is_empty() {
        problem(table.clone(), "oee.shifts".into(), OeeConfigError::NoShift);
    }
    let mut shifts: Vec<Shift> = Vec::new();
    for (k, s) in raw.shifts.iter().enumerate() {
        let s = s.get_ref();
        let key = |field: &str| format!("oee.shifts[{k}].{field}");
        let time = |t: &Spanned<String>, field: &str| {
            minutes(t.get_ref()).unwrap_or_else(|| {
                problem(
                    t.span(),
                    key(field),
                    OeeConfigError::NotATime(t.get_ref().clone()),
                );
                0
            })
        };
        let (start, end) = (time(&s.start, "start"), time(&s.end, "end"));
        let mut days = [true; 7];
        if let Some(list) = &s.days {
            days = [false; 7];
            for d in list {
                match weekday(d.get_ref()) {
                    Some(w) => days[w] = true,
                    None => problem(
                        d.span(),
                        key("days"),
                        OeeConfigError::NotAWeekday(d.get_ref().clone()),
                    ),
                }
            }
        }
        let mut breaks = Vec::new();
        for b in &s.breaks {
            let parsed = b
                .get_ref()
                .split_once('-')
                .and_then(|(a, z)| Some((minutes(a.trim())?, minutes(z.trim())?)));
            match parsed {
                Some(p) => breaks.push(p),
                None => problem(
                    b.span(),
                    key("breaks"),
                    OeeConfigError::NotABreak(b.get_ref().clone()),
                ),
            }
        }
        if shifts.iter().any(|x| x.name == *s.name.get_ref()) {
            problem(
                s.name.span(),
                key("name"),
                OeeConfigError::Twice(s.name.get_ref().clone()),
            );
        }
        shifts.push(Shift {
            name: s.name.get_ref().clone(),
            days,
            start,
            end,
            breaks,
        });
    }
    let reject = |t: &Spanned<String>, key: &str, counter: bool| {
        let Some(facts) = tag(t.get_ref()) else {
            problem(
                t.span(),
                key.into(),
                OeeConfigError::UnknownTag(t.get_ref().clone()),
            );
            return None;
        };
        match counter {
            true if facts.integer => Some(RejectTag::Counter(facts.index)),
            false if facts.contact => Some(RejectTag::Signal(facts.index)),
            true => {
                problem(
                    t.span(),
                    key.into(),
                    OeeConfigError::NotACounter(t.get_ref().clone()),
                );
                None
            }
            false => {
                problem(
                    t.span(),
                    key.into(),
                    OeeConfigError::NotAContact(t.get_ref().clone()),
                );
                None
            }
        }
    };
    let rejects = match (&raw.reject_counter, &raw.reject_signal) {
        (Some(c), None) => reject(c, "oee.reject_counter", true),
        (None, Some(s)) => reject(s, "oee.reject_signal", false),
        (Some(_), Some(s)) => {
            problem(
                s.span(),
                "oee.reject_signal".into(),
                OeeConfigError::BothRejects,
            );
            None
        }
        (None, None) => None,
    };
    let config = problems.borrow().is_empty().then(|| OeeConfig {
        rules: OeeRules {
            calendar: Calendar {
                shifts,
                utc_offset_ms,
            },
            planned_stops,
            setup,
            small_stop_ms,
            startup_ms,
            ideal_cycle_ms: ideal_cycle_ms.unwrap_or_default(),
            items,
        },
        rejects,
    });
    Checked {
        config,
        problems: problems.take(),
        warnings: Vec::new(),
    }
}

/// `06:00` as minutes after midnight; `24:00` is the end of the day.
fn minutes(text: &str) -> Option<u32> {
    let (h, m) = text.split_once(':')?;
    let (h, m): (u32, u32) = (h.parse().ok()?, m.parse().ok()?);
    (h < 24 && m < 60 || h == 24 && m == 0).then_some(h * 60 + m)
}

/// `mon` … `sun` as 0 … 6.
fn weekday(text: &str) -> Option<usize> {
    ["mon", "tue", "wed", "thu", "fri", "sat", "sun"]
        .iter()
        .position(|d| text.eq_ignore_ascii_case(d))
}

/// `+09:00` as ms east of UTC.
fn offset(text: &str) -> Option<i64> {
    let (sign, rest) = match text.as_bytes().first()? {
        b'+' => (1, &text[1..]),
        b'-' => (-1, &text[1..]),
        _ => return None,
    };
    let (h, m) = rest.split_once(':')?;
    let (h, m): (i64, i64) = (h.parse().ok()?, m.parse().ok()?);
    (h <= 14 && m < 60).then_some(sign * (h * 60 + m) * 60_000)
}

/// The stop causes shipped (`config/stop-causes.toml`): paper 002's Table
/// 4 and the demo's faults. The live OEE names breakdowns by them, and the
/// reports classify stops by them unless `--causes` names a table.
pub const SHIPPED_STOP_CAUSES: &str = include_str!("../../../../config/stop-causes.toml");

/// [`SHIPPED_STOP_CAUSES`], read.
///
/// # Errors
/// The shipped table does not read (a test reads it).
pub fn shipped_stop_causes() -> Result<cellwatch_models::report::StopCauses, toml::de::Error> {
    toml::from_str(SHIPPED_STOP_CAUSES)
}

#[cfg(test)]
mod shipped {
    #[test]
    fn the_shipped_stop_causes_read() {
        let causes = super::shipped_stop_causes().unwrap();
        assert!(!causes.causes.is_empty());
    }
}
