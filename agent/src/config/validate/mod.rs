//! Validation: the raw structs of `raw` into a [`CellConfig`](super::CellConfig),
//! collecting every problem, each at its file, line and column. One
//! `Validator` walks the file; its methods are split by component over
//! this folder's files.

mod alarms;
mod checks;
mod commands;
mod kpi;
mod rates;
mod recorder;
mod sfc;
mod tag_ref_error;
mod tags;

use std::collections::{HashMap, HashSet};
use std::fmt;
use std::net::SocketAddr;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::time::Duration;

use cellwatch_models::alarm::Severity;
use cellwatch_models::programs::Dialect;
use cellwatch_models::signal::Signal;
use cellwatch_models::value::ValueType;
use toml::Spanned;

use self::tag_ref_error::TagRefError;
use crate::config::raw::{self, RawConfig};
use crate::config::{
    key_chunk, timer_signal, Addressing, CellConfig, ConfigErrors, Files, TimerCheck,
    DEFAULT_MAX_SHELVE, MAX_SHELVE_LIMIT,
};
use crate::table::line_col;

/// Ids of the alarms the agent raises of itself, which no check may take.
const RESERVED_IDS: [&str; 3] = ["communication", "tag-quality", "journal"];

/// Validates `raw`, read from `text` (named `origin`), relative paths
/// from `base`, files read through `files`.
pub(super) fn validate(
    origin: &str,
    text: &str,
    base: &Path,
    files: &dyn Files,
    raw: RawConfig,
    toml_tags: Option<crate::config::document::TomlTags<'_>>,
) -> Result<CellConfig, ConfigErrors> {
    let mut v = Validator {
        origin,
        text,
        base,
        files,
        problems: Vec::new(),
        warnings: Vec::new(),
        namespace_uri: None,
        kinds: HashMap::new(),
        names: HashMap::new(),
        bus: false,
        tag_comments: HashMap::new(),
        tags_file: None,
        addressing: Addressing::PmcOrIec,
        tag_tables: HashMap::new(),
    };
    let config = v.config(raw, toml_tags);
    if v.problems.is_empty() {
        let mut config = config.expect("a configuration with no problems is complete");
        config.warnings = v.warnings;
        config.source_sha256 = {
            use sha2::Digest;
            hex::encode(sha2::Sha256::digest(text.as_bytes()))
        };
        Ok(config)
    } else {
        Err(ConfigErrors(v.problems))
    }
}

pub(super) struct Validator<'a> {
    origin: &'a str,
    text: &'a str,
    base: &'a Path,
    files: &'a dyn Files,
    problems: Vec<String>,
    warnings: Vec<String>,
    /// `opcua.namespace_uri` and where it is written, for the tags.
    namespace_uri: Option<(Range<usize>, String)>,
    /// Every tag's type and whether it is a contact, by address.
    kinds: HashMap<Signal, (ValueType, bool)>,
    /// Every tag's address, by name (a check may name a tag either way).
    names: HashMap<String, Signal>,
    /// The tags' node ids are `@` bus nodes.
    bus: bool,
    /// The tags' comments, by address.
    tag_comments: HashMap<Signal, String>,
    /// While the tags of a `tags_file` are checked: its name and text,
    /// which their spans point into.
    tags_file: Option<(String, String)>,
    /// How the tags' addresses are written (`cell.dialect`).
    addressing: Addressing,
    /// The TIA Portal tag tables of each folder a SimaticML block was read
    /// from: a folder's files are read once, however many checks read
    /// blocks in it.
    tag_tables: HashMap<PathBuf, std::rc::Rc<Vec<(PathBuf, String)>>>,
}

impl Validator<'_> {
    /// A component's check of its table, made with the document's kit:
    /// its problems placed in the file, its warnings kept.
    fn component<T>(&mut self, check: impl FnOnce(&mut crate::table::Table<'_>) -> T) -> T {
        let mut kit = crate::table::Table::new(self.base);
        let config = check(&mut kit);
        self.placed(kit.found());
        config
    }

    /// A component's check of its table: its problems placed in the
    /// file, its warnings kept; its configuration when it has none.
    fn placed<T, E: fmt::Display>(&mut self, checked: crate::table::Checked<T, E>) -> Option<T> {
        for p in checked.problems {
            self.problem(p.span, &p.key, p.error);
        }
        self.warnings.extend(checked.warnings);
        checked.config
    }

    fn problem(&mut self, span: Range<usize>, key: &str, message: impl fmt::Display) {
        let (origin, text) = match &self.tags_file {
            Some((origin, text)) => (origin.as_str(), text.as_str()),
            None => (self.origin, self.text),
        };
        let (line, col) = line_col(text, span.start);
        self.problems
            .push(format!("{origin}:{line}:{col}: {key}: {message}"));
    }

    /// A problem unless `id` can be a chunk of a Zenoh key and part of a
    /// file name ([`key_chunk`]): a check's id, a chart's, step's or
    /// transition's name, which alarm ids (`alarms/<id>`) are made of.
    /// The id of check `key` (`checks.limit[2]`): a key chunk, and not
    /// used before among `ids`.
    fn unique_id(&mut self, id: &Spanned<String>, key: &str, ids: &mut HashSet<String>) {
        self.key_chunk(id.span(), &format!("{key}.id"), "", id.get_ref());
        if RESERVED_IDS.contains(&id.get_ref().as_str()) {
            self.problem(
                id.span(),
                &format!("{key}.id"),
                format!(
                    "'{}' is the id of the agent's own alarm: choose another",
                    id.get_ref()
                ),
            );
        } else if !ids.insert(id.get_ref().clone()) {
            self.problem(
                id.span(),
                &format!("{key}.id"),
                format!("'{}' is used twice", id.get_ref()),
            );
        }
    }

    fn key_chunk(&mut self, span: Range<usize>, key: &str, what: &str, id: &str) {
        if !key_chunk(id) {
            self.problem(
                span,
                key,
                format!(
                    "{what}'{}' must be letters, digits, '-' or '_' (it is part of Zenoh keys)",
                    id.escape_debug()
                ),
            );
        }
    }

    fn path(&self, p: &str) -> PathBuf {
        crate::table::path(self.base, p)
    }

    /// The address of the tag `text` names: a tag's name, or an address
    /// (in the cell's dialect) — a name first; ambiguous when it is one
    /// tag's name and another's address.
    fn tag_ref(&self, text: &str) -> Result<Signal, TagRefError> {
        let by_name = self.names.get(text);
        let by_address = self
            .addressing
            .signal(text)
            .ok()
            .filter(|a| self.kinds.contains_key(a));
        match (by_name, by_address) {
            (Some(n), Some(a)) if *n != a => Err(TagRefError::Ambiguous {
                text: text.into(),
                named: n.clone(),
            }),
            (Some(n), _) => Ok(n.clone()),
            (None, Some(a)) => Ok(a),
            (None, None) => match self.addressing.signal(text) {
                Ok(address) => Err(TagRefError::Missing {
                    text: text.into(),
                    address,
                }),
                Err(source) => Err(TagRefError::NotAnAddress {
                    text: text.into(),
                    source,
                }),
            },
        }
    }

    /// A whole number in `range`, or a problem and `default`.
    fn count(
        &mut self,
        value: Spanned<i64>,
        key: &str,
        range: std::ops::RangeInclusive<u32>,
        default: u32,
    ) -> u32 {
        self.component(|kit| kit.count(value, key, range, default))
    }

    fn duration(
        &mut self,
        value: Option<Spanned<String>>,
        key: &str,
        default: Duration,
    ) -> Duration {
        self.component(|kit| kit.duration(value, key, default))
    }

    /// A delay in ms: `0` or a duration.
    fn delay(&mut self, value: Option<Spanned<String>>, key: &str) -> u64 {
        match value {
            Some(v) if v.get_ref().trim() == "0" => 0,
            other => self.duration(other, key, Duration::ZERO).as_millis() as u64,
        }
    }

    fn deadband(
        &mut self,
        value: Spanned<f64>,
        key: &str,
        value_type: ValueType,
        range: std::ops::RangeInclusive<f64>,
    ) -> Option<f64> {
        if !value_type.is_numeric() {
            self.problem(
                value.span(),
                key,
                format!("a deadband needs a numeric type; this tag is {value_type}"),
            );
            return None;
        }
        let v = *value.get_ref();
        if range.contains(&v) {
            Some(v)
        } else {
            self.problem(
                value.span(),
                key,
                format!("{v} is not between {} and {}", range.start(), range.end()),
            );
            None
        }
    }

    fn parsed<T: FromStr<Err: fmt::Display>>(
        &mut self,
        value: Option<Spanned<String>>,
        key: &str,
        default: T,
    ) -> T {
        let Some(v) = value else { return default };
        match v.get_ref().parse() {
            Ok(x) => x,
            Err(e) => {
                self.problem(v.span(), key, e);
                default
            }
        }
    }

    fn config(
        &mut self,
        raw: RawConfig,
        toml_tags: Option<crate::config::document::TomlTags<'_>>,
    ) -> Option<CellConfig> {
        if let Some(d) = &raw.cell.dialect {
            match d.get_ref().parse::<Dialect>() {
                Ok(d) => self.addressing = Addressing::In(d),
                Err(e) => self.problem(d.span(), "cell.dialect", e),
            }
        }
        let cell = raw.cell.id.get_ref().clone();
        if cell.is_empty()
            || !cell
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
        {
            self.problem(
                raw.cell.id.span(),
                "cell.id",
                format!("'{cell}' must be letters, digits, '-' or '_' (it is part of Zenoh keys)"),
            );
        }
        let (opcua, legacy) = match (raw.opcua, raw.legacy) {
            (Some(o), None) => {
                // The tags read with the namespace it names.
                self.namespace_uri = o
                    .get_ref()
                    .namespace_uri
                    .as_ref()
                    .filter(|u| !u.get_ref().trim().is_empty())
                    .map(|u| (u.span(), u.get_ref().clone()));
                let o = o.into_inner();
                let checked = self.component(|kit| crate::sources::opcua::config::validate(kit, o));
                (checked.map(Some), None)
            }
            (None, Some(l)) => {
                // The tags' node ids are `@` bus nodes.
                self.bus = true;
                let l = l.into_inner();
                let checked =
                    self.component(|kit| crate::sources::at_bus::config::validate(kit, l));
                (Some(None), checked)
            }
            (Some(_), Some(l)) => {
                self.problem(
                    l.span(),
                    "legacy",
                    "a cell reads one source: [opcua] or [legacy], not both",
                );
                (None, None)
            }
            (None, None) => {
                self.problem(
                    0..0,
                    "opcua",
                    "a cell needs a source: an [opcua] server or a [legacy] bus",
                );
                (None, None)
            }
        };
        let tags = match (raw.tags_file, toml_tags) {
            (None, Some(tables)) => self.tags(tables),
            (None, None) => self.tags(raw.tags.into_iter()),
            (Some(file), tables) => {
                if !raw.tags.is_empty() || tables.is_some() {
                    self.problem(
                        file.span(),
                        "tags_file",
                        "give the tags as [[tags]] tables or in tags_file, not both",
                    );
                }
                self.tags_in_file(file)
            }
        };
        let by_address: HashMap<Signal, usize> = tags
            .iter()
            .enumerate()
            .map(|(i, t)| (t.address.clone(), i))
            .collect();
        self.kinds = tags
            .iter()
            .map(|t| (t.address.clone(), (t.value_type, t.is_contact())))
            .collect();
        self.tag_comments = tags
            .iter()
            .filter_map(|t| Some((t.address.clone(), t.comment.clone()?)))
            .collect();
        self.names = tags
            .iter()
            .map(|t| (t.name.clone(), t.address.clone()))
            .collect();
        let mut switching = Vec::new();
        let mut ids = HashSet::new();
        let mut delays = Vec::new();
        for (i, c) in raw.checks.switching.into_iter().enumerate() {
            let key = format!("checks.switching[{i}]");
            let on = self.delay(c.on_delay.clone(), &format!("{key}.on_delay"));
            let off = self.delay(c.off_delay.clone(), &format!("{key}.off_delay"));
            if on > 0 || off > 0 {
                delays.push((c.id.get_ref().clone(), on, off));
            }
            self.unique_id(&c.id, &key, &mut ids);
            if let Some(check) = self.switching(&key, c, &by_address) {
                switching.push(check);
            }
        }
        switching.extend(self.discrete(raw.checks.discrete, &mut ids, &mut delays, &by_address));
        let mut timers = Vec::new();
        for (i, t) in raw.checks.timers.into_iter().enumerate() {
            let key = format!("checks.timers[{i}]");
            self.unique_id(&t.id, &key, &mut ids);
            let severity = self.parsed(
                t.severity.clone(),
                &format!("{key}.severity"),
                Severity::High,
            );
            let path = self.path(t.model.get_ref());
            let Some(text) = self.read_text(
                t.model.span(),
                &format!("{key}.model"),
                &path,
                "timer model",
            ) else {
                continue;
            };
            let model: cellwatch_models::timer::learn::TimerModel =
                match serde_json::from_str(&text) {
                    Ok(m) => m,
                    Err(e) => {
                        self.problem(
                            t.model.span(),
                            &format!("{key}.model"),
                            format!("{}: {e}", path.display()),
                        );
                        continue;
                    }
                };
            let unknown: Vec<&String> = model
                .signals
                .iter()
                .filter(|n| timer_signal(self.addressing, &tags, n).is_none())
                .collect();
            if !unknown.is_empty() {
                let list: Vec<&str> = unknown.iter().map(|s| s.as_str()).collect();
                self.problem(
                    t.model.span(),
                    &format!("{key}.model"),
                    format!(
                        "the model reads {}, which no tag has as name or address",
                        list.join(", ")
                    ),
                );
                continue;
            }
            let drift = self.drift(&t, &key);
            timers.push(TimerCheck {
                id: t.id.into_inner(),
                model,
                severity,
                drift,
            });
        }
        let sfc = self.sfc(raw.checks.sfc, &mut ids, &by_address);
        let mut limits = self.limits(raw.checks.limit, &mut ids);
        for l in &mut limits {
            if let Some(t) = by_address.get(&l.tag) {
                l.label = tags[*t].name.clone();
                l.comment = tags[*t].comment.clone();
            }
        }
        let state = self.state(&raw.state, &by_address);
        let state_interval = self.duration(
            raw.state.publish_interval,
            "state.publish_interval",
            Duration::from_secs(10),
        );
        let zenoh = self.component(|kit| crate::bus::config::validate(kit, raw.zenoh, &cell));
        let alertmanager = raw
            .alertmanager
            .and_then(|a| self.placed(crate::sinks::alertmanager::config::validate(a, self.base)));
        let alarm_server = raw.alarm_server.and_then(|a| {
            self.placed(crate::services::alarm_server::config::validate(
                a, self.base,
            ))
        });
        let sparkplug = raw.sparkplug.and_then(|s| {
            self.placed(crate::sinks::sparkplug::config::validate(
                s, &cell, self.base,
            ))
        });
        let oee = raw.oee.and_then(|o| {
            let modes: Vec<String> = state.modes.iter().map(|m| m.id.clone()).collect();
            let tag = |text: &str| {
                let t = *by_address.get(&self.tag_ref(text).ok()?)?;
                let (contact, integer) = (tags[t].is_contact(), tags[t].bit.is_none());
                let integer = integer && tags[t].value_type.is_integer();
                Some(crate::sinks::oee::config::TagFacts {
                    index: t,
                    contact,
                    integer,
                })
            };
            let checked = crate::sinks::oee::config::validate(o, &modes, &tag);
            self.placed(checked)
        });
        let kpi = self.kpi(raw.kpi);
        let recorder = self.recorder(raw.recorder);
        let database = self.database(raw.alarms.database.as_ref());
        let (system_delays, consequences) = self.system_alarms(raw.alarms);
        delays.extend(system_delays);
        let journal =
            self.component(|kit| crate::journal::config::validate(kit, raw.journal, &cell));
        let metrics = match raw.metrics.listen {
            None => Some(SocketAddr::from(([127, 0, 0, 1], 9464))),
            Some(v) if v.get_ref() == "off" => None,
            Some(v) => match v.get_ref().parse() {
                Ok(a) => Some(a),
                Err(_) => {
                    self.problem(
                        v.span(),
                        "metrics.listen",
                        format!(
                            "'{}' is not an address like 127.0.0.1:9464 (or \"off\")",
                            v.get_ref()
                        ),
                    );
                    None
                }
            },
        };
        if let Some(old) = &raw.commands.secrets_file {
            self.problem(
                old.span(),
                "commands.secrets_file",
                "shared operator secrets are no longer accepted: operators sign with their own keys (cellwatch keygen --operator NAME); name the file of their public keys with commands.operators_file",
            );
        }
        let operators_file = raw.commands.operators_file.map(|s| self.path(s.get_ref()));
        let plant_operators = self.plant_operators(
            raw.commands.plant_key,
            raw.commands.plant_list,
            &journal.path,
        );
        let max_shelve_span = raw.commands.max_shelve.as_ref().map(Spanned::span);
        let max_shelve = self.duration(
            raw.commands.max_shelve,
            "commands.max_shelve",
            DEFAULT_MAX_SHELVE,
        );
        // A shelf is temporary (ISA-18.2): out of service is for longer.
        if max_shelve > MAX_SHELVE_LIMIT {
            self.problem(
                max_shelve_span.unwrap_or(0..0),
                "commands.max_shelve",
                "at most 365d: an alarm to be kept quiet longer is taken out of service",
            );
        }
        #[derive(PartialEq)]
        enum Use {
            Contact,
            Counter,
            Item,
        }
        let mut production = |p: Spanned<String>, key: &str, usage: Use| {
            let found = match self.tag_ref(p.get_ref()) {
                Ok(a) => by_address.get(&a).copied().ok_or_else(String::new),
                Err(e) => Err(e.to_string()),
            };
            let t = match found {
                Ok(t) => t,
                Err(why) => {
                    self.problem(p.span(), key, why);
                    return None;
                }
            };
            let tag = &tags[t];
            if usage == Use::Contact && !tag.is_contact() {
                self.problem(
                    p.span(),
                    key,
                    format!(
                        "{} is a {}: a part-done tag must be a contact (Boolean, or a bit)",
                        tag.address,
                        tag.usage()
                    ),
                );
                return None;
            }
            let what = match usage {
                Use::Contact => None,
                Use::Counter => Some("a counter"),
                Use::Item => Some("an item code"),
            };
            let fits = tag.bit.is_none()
                && (tag.value_type.is_integer()
                    || (usage == Use::Item && tag.value_type == ValueType::String));
            if let (Some(what), false) = (what, fits) {
                let kind = if usage == Use::Item {
                    "a string or integer tag"
                } else {
                    "an integer tag"
                };
                self.problem(
                    p.span(),
                    key,
                    format!(
                        "{} is a {}: {what} must be {kind} without a bit",
                        tag.address,
                        tag.usage()
                    ),
                );
                return None;
            }
            Some(t)
        };
        let part_done = raw
            .production
            .part_done
            .and_then(|p| production(p, "production.part_done", Use::Contact));
        let order_item = raw
            .production
            .item
            .and_then(|p| production(p, "production.item", Use::Item));
        let order_target = raw
            .production
            .target
            .and_then(|p| production(p, "production.target", Use::Counter));
        let both = raw
            .production
            .counter
            .as_ref()
            .filter(|_| part_done.is_some())
            .map(Spanned::span);
        let part_counters = match raw.production.counter {
            Some(_) if both.is_some() => Vec::new(),
            Some(c) => {
                let span = c.span();
                let list = match c.into_inner() {
                    raw::OneOrMany::One(a) => vec![a],
                    raw::OneOrMany::Many(list) => list,
                };
                list.into_iter()
                    .filter_map(|a| {
                        production(
                            Spanned::new(span.clone(), a),
                            "production.counter",
                            Use::Counter,
                        )
                    })
                    .collect()
            }
            None => Vec::new(),
        };
        if let Some(span) = both {
            self.problem(
                span,
                "production.counter",
                "give part_done or counter, not both",
            );
        }
        if operators_file.is_none() {
            self.warnings.push(
                "no commands.operators_file: every acknowledge and reset will be refused".into(),
            );
        }
        Some(CellConfig {
            cell,
            description: raw.cell.description,
            addressing: self.addressing,
            opcua: opcua?,
            legacy,
            tags,
            switching,
            timers,
            state,
            state_interval,
            zenoh,
            journal,
            metrics,
            operators_file,
            plant_operators,
            max_shelve,
            part_done,
            part_counters,
            order_item,
            order_target,
            limits,
            sfc,
            delays,
            alertmanager,
            alarm_server,
            sparkplug,
            oee,
            kpi,
            consequences,
            database,
            recorder,
            warnings: Vec::new(),
            source_sha256: String::new(),
        })
    }
}
