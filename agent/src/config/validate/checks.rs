//! Validating the configuration: checks.

use std::collections::{HashMap, HashSet};

use cellwatch_models::alarm::Severity;
use cellwatch_models::comments::CommentDb;
use cellwatch_models::engine::{AlarmPattern, Mode, StateRules, SwitchingCheck};
use cellwatch_models::explain::Polarity;
use cellwatch_models::expr::Expr;
use cellwatch_models::limit::{Level, LimitCheck, LimitLevel};
use cellwatch_models::program::Program;
use cellwatch_models::programs::Dialect;
use cellwatch_models::signal::{Observability, Signal};
use cellwatch_models::switching::SwitchingFunction;
use cellwatch_models::value::{CmpOperand, Comparison, ValueType};
use toml::Spanned;

use super::Validator;
use crate::config::raw;
use crate::config::Addressing;
use crate::tags::map_signals;

impl Validator<'_> {
    /// The tag tables exported beside SimaticML block `path` (of `text`),
    /// the block itself among them if it is one: none for another format.
    /// Each folder's files are read once.
    fn tag_tables_beside(
        &mut self,
        path: &std::path::Path,
        text: &str,
    ) -> std::rc::Rc<Vec<(std::path::PathBuf, String)>> {
        if !cellwatch_models::comments::is_simaticml(text) {
            return std::rc::Rc::default();
        }
        let dir = path
            .parent()
            .unwrap_or(std::path::Path::new(""))
            .to_path_buf();
        let files = self.files;
        self.tag_tables
            .entry(dir)
            .or_insert_with_key(|dir| {
                std::rc::Rc::new(crate::config::files::tag_tables_in(files, dir))
            })
            .clone()
    }

    /// `KEY.dialect`, when given: a program's dialect where its text does
    /// not tell.
    pub(super) fn dialect(&mut self, key: &str, d: Option<&Spanned<String>>) -> Option<Dialect> {
        let d = d?;
        match d.get_ref().parse() {
            Ok(d) => Some(d),
            Err(e) => {
                self.problem(d.span(), &format!("{key}.dialect"), e);
                None
            }
        }
    }

    pub(super) fn switching(
        &mut self,
        key: &str,
        c: raw::RawSwitching,
        tags: &HashMap<Signal, usize>,
    ) -> Option<SwitchingCheck> {
        let dialect = self.dialect(key, c.dialect.as_ref());
        let polarity = self.parsed(
            c.fault_when.clone(),
            &format!("{key}.fault_when"),
            Polarity::On,
        );
        let severity = self.parsed(
            c.severity.clone(),
            &format!("{key}.severity"),
            Severity::High,
        );
        let path = self.path(c.program.get_ref());
        let text = self.read_text(
            c.program.span(),
            &format!("{key}.program"),
            &path,
            "program",
        )?;
        let language = c
            .comment_language
            .as_ref()
            .map(|l| l.get_ref().trim().to_string());
        if let Some(l) = c
            .comment_language
            .as_ref()
            .filter(|l| !is_culture(l.get_ref()))
        {
            self.problem(
                l.span(),
                &format!("{key}.comment_language"),
                format!(
                    "'{}' is not a language as TIA Portal names one: write e.g. de-DE or en-US",
                    l.get_ref()
                ),
            );
            return None;
        }
        let language = language.as_deref();
        let program =
            match Program::compile_in(&path.display().to_string(), &text, dialect, language) {
                Ok(p) => p,
                Err(e) => {
                    self.problems.extend(e.lines());
                    return None;
                }
            };
        let observable = match &c.observable {
            None => Observability::default_for(program.dialect()),
            Some(o) => match Observability::parse(program.dialect(), o.get_ref()) {
                Ok(o) => o,
                Err(e) => {
                    self.problem(o.span(), &format!("{key}.observable"), e);
                    return None;
                }
            },
        };
        let coil = match program.resolve(c.coil.get_ref()) {
            Ok(s) => s,
            Err(e) => {
                self.problem(c.coil.span(), &format!("{key}.coil"), e);
                return None;
            }
        };
        let sf = match SwitchingFunction::expand(&program, &coil, &observable) {
            Ok(sf) => sf,
            Err(e) => {
                self.problem(c.coil.span(), &format!("{key}.coil"), e);
                return None;
            }
        };
        // Tags read as another dialect's addresses than the program's
        // cannot match its signals: say which key fixes it.
        let hint = match self.addressing {
            Addressing::In(d) if d == program.dialect() => String::new(),
            Addressing::PmcOrIec if program.dialect() != Dialect::Stl => String::new(),
            _ => format!(
                " (the program is {}: set cell.dialect = \"{}\" to read the tags' addresses as it writes them)",
                program.dialect(),
                program.dialect()
            ),
        };
        for leaf in sf.leaves() {
            if !tags.contains_key(&leaf) {
                self.problem(
                    c.coil.span(),
                    &format!("{key}.coil"),
                    format!("{coil} reads {leaf}, but no tag has that address; add a [[tags]] entry for it{hint}"),
                );
            } else if let Some((t, false)) = self.kinds.get(&leaf) {
                self.problem(
                    c.coil.span(),
                    &format!("{key}.coil"),
                    format!("{coil} reads {leaf} as a contact, but its tag is a {t}: make it Boolean or give it a bit"),
                );
            }
        }
        // The program's own declarations, then the tag tables exported
        // beside it, then the tags' comments, then the I/O list: each
        // overrides the one before.
        let tag_comments: CommentDb = sf
            .leaves()
            .into_iter()
            .filter_map(|s| Some((s.clone(), self.tag_comments.get(&s)?.clone())))
            .collect();
        let mut declared = program.documentation().clone();
        // A TIA Portal block's tag tables, exported beside it.
        for (table, text) in self.tag_tables_beside(&path, &text).iter() {
            if table.file_name() == path.file_name() {
                continue;
            }
            match CommentDb::parse_in(
                &table.display().to_string(),
                text,
                |a| program.resolve(a),
                language,
            ) {
                Ok(db) => declared = declared.overridden_by(db),
                Err(e) => {
                    self.problems.push(e.to_string());
                    return None;
                }
            }
        }
        let declared = declared.overridden_by(tag_comments);
        let comments = match &c.comments {
            None => declared,
            Some(p) => {
                let path = self.path(p.get_ref());
                let text = self.read_text(
                    p.span(),
                    &format!("{key}.comments"),
                    &path,
                    "comment database",
                )?;
                match CommentDb::parse_in(
                    &path.display().to_string(),
                    &text,
                    |a| program.resolve(a),
                    language,
                ) {
                    Ok(db) => declared.overridden_by(db),
                    Err(e) => {
                        self.problems.push(e.to_string());
                        return None;
                    }
                }
            }
        };
        let armed_when = match &c.armed_when {
            None => None,
            Some(a) => {
                let expr = self.expression(a, &format!("{key}.armed_when"), tags)?;
                Some(SwitchingFunction::from_expr(
                    Signal::new(&format!("{}.armed", c.id.get_ref())),
                    &expr,
                ))
            }
        };
        // The outputs the program derives from the fault coil, where the
        // cell reads them: a check reading one follows from this fault.
        let forces =
            cellwatch_models::consequence::forced_outputs(&program, &coil, &observable, |s| {
                tags.contains_key(s)
            });
        Some(SwitchingCheck {
            forces,
            text: None,
            armed_when,
            id: c.id.into_inner(),
            fault_type: c.fault_type.unwrap_or_else(|| coil.to_string()),
            sf,
            polarity,
            severity,
            comments,
        })
    }

    /// The discrete alarms: one contact on (or off) is the fault. Each is
    /// a switching check over that one contact, so it has the same
    /// lifecycle, explanation and delays (pushed to `delays`).
    pub(super) fn discrete(
        &mut self,
        raw: Vec<raw::RawDiscrete>,
        ids: &mut HashSet<String>,
        delays: &mut Vec<(String, u64, u64)>,
        tags: &HashMap<Signal, usize>,
    ) -> Vec<SwitchingCheck> {
        let mut out = Vec::new();
        for (i, c) in raw.into_iter().enumerate() {
            let key = format!("checks.discrete[{i}]");
            self.unique_id(&c.id, &key, ids);
            let on = self.delay(c.on_delay, &format!("{key}.on_delay"));
            let off = self.delay(c.off_delay, &format!("{key}.off_delay"));
            let polarity = self.parsed(c.fault_when, &format!("{key}.fault_when"), Polarity::On);
            let severity = self.parsed(c.severity, &format!("{key}.severity"), Severity::High);
            let tag = match self.tag_ref(c.tag.get_ref()) {
                Ok(a) => a,
                Err(e) => {
                    self.problem(c.tag.span(), &format!("{key}.tag"), e);
                    continue;
                }
            };
            if let Some((t, false)) = self.kinds.get(&tag) {
                self.problem(
                    c.tag.span(),
                    &format!("{key}.tag"),
                    format!("{tag} is a {t}: a discrete alarm needs a Boolean tag or one bit of a word (bit = n); for a number use [[checks.limit]]"),
                );
                continue;
            }
            let armed_when = match &c.armed_when {
                None => None,
                Some(a) => {
                    let Some(expr) = self.expression(a, &format!("{key}.armed_when"), tags) else {
                        continue;
                    };
                    Some(SwitchingFunction::from_expr(
                        Signal::new(&format!("{}.armed", c.id.get_ref())),
                        &expr,
                    ))
                }
            };
            let comment = self.tag_comments.get(&tag).cloned();
            let message = match c.message {
                Some(m) if m.get_ref().trim().is_empty() => {
                    self.problem(
                        m.span(),
                        &format!("{key}.message"),
                        "is empty: leave it out to use the tag's comment",
                    );
                    continue;
                }
                Some(m) => m.into_inner(),
                None => comment.clone().unwrap_or_else(|| {
                    let name = self
                        .names
                        .iter()
                        .find(|(_, a)| **a == tag)
                        .map(|(n, _)| n.clone());
                    name.unwrap_or_else(|| tag.to_string())
                }),
            };
            let id = c.id.into_inner();
            if on > 0 || off > 0 {
                delays.push((id.clone(), on, off));
            }
            out.push(SwitchingCheck {
                forces: Vec::new(),
                armed_when,
                sf: SwitchingFunction::from_expr(Signal::new(&id), &Expr::Lit(tag.clone(), false)),
                id,
                fault_type: format!(
                    "{tag} {}",
                    if polarity == Polarity::On {
                        "ON"
                    } else {
                        "OFF"
                    }
                ),
                text: Some(message),
                polarity,
                severity,
                comments: comment.into_iter().map(|c| (tag.clone(), c)).collect(),
            });
        }
        out
    }

    /// A condition over tag addresses in the paper's notation, every
    /// address a contact tag's; comparisons (`TEMP > 80.5`) read numeric
    /// tags.
    pub(super) fn expression(
        &mut self,
        text: &Spanned<String>,
        key: &str,
        tags: &HashMap<Signal, usize>,
    ) -> Option<Expr> {
        // Each signal by address, or by a tag's name where no tag has it
        // as its address.
        let (addressing, kinds, names) = (self.addressing, &self.kinds, &self.names);
        let by_name_or_address = |s: &Signal| {
            let address = addressing.signal(s.name()).ok();
            match address {
                Some(a) if kinds.contains_key(&a) => a,
                _ => names
                    .get(s.name())
                    .cloned()
                    .or(address)
                    .unwrap_or_else(|| s.clone()),
            }
        };
        let e = match Expr::parse(text.get_ref()) {
            Ok(e) => map_signals(e, &by_name_or_address),
            Err(m) => {
                self.problem(text.span(), key, format!("'{}': {m}", text.get_ref()));
                return None;
            }
        };
        let mut problems = Vec::new();
        for s in e.signals() {
            match Comparison::of_signal(&s) {
                Some(c) => {
                    let operands = std::iter::once(&c.lhs).chain(match &c.rhs {
                        CmpOperand::Tag(t) => Some(t),
                        CmpOperand::Const(_) => None,
                    });
                    for a in operands {
                        match self.kinds.get(a) {
                            None => problems
                                .push(format!("no tag has the name or address {a} (in '{s}')")),
                            Some((t, _)) if !t.is_numeric() && *t != ValueType::Boolean => problems
                                .push(format!(
                                    "{a} is a {t} and cannot be compared as a number (in '{s}')"
                                )),
                            Some(_) => {}
                        }
                    }
                }
                None if !tags.contains_key(&s) => {
                    problems.push(format!("no tag has the name or address {s}"));
                }
                None => {
                    if let Some((t, false)) = self.kinds.get(&s) {
                        problems.push(format!(
                            "{s} is a {t}, not a contact: compare it (`{s} > 0`) or give the tag a bit"
                        ));
                    }
                }
            }
        }
        if problems.is_empty() {
            Some(e)
        } else {
            self.problem(text.span(), key, problems.join("; "));
            None
        }
    }

    /// The limit checks.
    pub(super) fn limits(
        &mut self,
        raw: Vec<raw::RawLimit>,
        ids: &mut HashSet<String>,
    ) -> Vec<LimitCheck> {
        let mut out = Vec::new();
        for (i, c) in raw.into_iter().enumerate() {
            let key = format!("checks.limit[{i}]");
            self.unique_id(&c.id, &key, ids);
            let tag = match self.tag_ref(c.tag.get_ref()) {
                Ok(a) => a,
                Err(e) => {
                    self.problem(c.tag.span(), &format!("{key}.tag"), e);
                    continue;
                }
            };
            match self.kinds.get(&tag) {
                None => continue,
                Some((t, _)) if !t.is_numeric() => {
                    self.problem(
                        c.tag.span(),
                        &format!("{key}.tag"),
                        format!("{tag} is a {t}: a limit check needs a numeric tag (type = \"Double\", \"Int16\", ...)"),
                    );
                    continue;
                }
                Some(_) => {}
            }
            // `hysteresis`; `deadband` is its former name, which the
            // server-side change filter of [[tags]] also has.
            let (hysteresis, name) = match (c.hysteresis, c.deadband) {
                (Some(h), Some(d)) => {
                    self.problem(
                        d.span(),
                        &format!("{key}.deadband"),
                        "give hysteresis only (deadband is its former name)",
                    );
                    (Some(h), "hysteresis")
                }
                (Some(h), None) => (Some(h), "hysteresis"),
                (None, Some(d)) => {
                    self.warnings.push(format!(
                        "{key} ({}): deadband is called hysteresis now (the deadband of [[tags]] is the server's change filter): rename it",
                        c.id.get_ref()
                    ));
                    (Some(d), "deadband")
                }
                (None, None) => (None, "hysteresis"),
            };
            let deadband = match hysteresis {
                None => 0.0,
                Some(d) if *d.get_ref() >= 0.0 && d.get_ref().is_finite() => *d.get_ref(),
                Some(d) => {
                    self.problem(
                        d.span(),
                        &format!("{key}.{name}"),
                        format!("{} must be zero or more", d.get_ref()),
                    );
                    0.0
                }
            };
            let on_delay = self.delay(c.on_delay, &format!("{key}.on_delay"));
            let off_delay = self.delay(c.off_delay, &format!("{key}.off_delay"));
            let mut levels = Vec::new();
            for (level, raw, default) in [
                (Level::HH, c.hh, Severity::Critical),
                (Level::H, c.h, Severity::High),
                (Level::L, c.l, Severity::High),
                (Level::LL, c.ll, Severity::Critical),
            ] {
                let Some(raw) = raw else { continue };
                let span = raw.span();
                let raw = raw.into_inner();
                let lkey = format!("{key}.{}", level.as_str().to_ascii_lowercase());
                if !raw.limit.is_finite() {
                    self.problem(
                        span.clone(),
                        &format!("{lkey}.limit"),
                        "must be a finite number",
                    );
                }
                let severity = self.parsed(raw.severity, &format!("{lkey}.severity"), default);
                levels.push(LimitLevel {
                    level,
                    limit: raw.limit,
                    severity,
                });
            }
            let rates = self.rate_levels(&key, c.rising, c.falling, deadband);
            if levels.is_empty() && rates.is_empty() {
                self.problem(
                    c.id.span(),
                    &key,
                    "give at least one level: hh, h, l or ll = { limit = ..., severity = ... }, \
                     or a rate: rising or falling = { rate = ..., per = ... }",
                );
            }
            let limit = |l: Level| levels.iter().find(|x| x.level == l).map(|x| x.limit);
            let ordered = [Level::HH, Level::H, Level::L, Level::LL]
                .iter()
                .filter_map(|&l| limit(l))
                .collect::<Vec<_>>()
                .windows(2)
                .all(|w| w[0] > w[1]);
            if !ordered {
                self.problem(
                    c.id.span(),
                    &key,
                    "the limits must fall in the order hh > h > l > ll",
                );
            }
            out.push(LimitCheck {
                id: c.id.into_inner(),
                label: String::new(),
                comment: None,
                tag,
                unit: c.unit,
                deadband,
                on_delay,
                off_delay,
                levels,
                rates,
            });
        }
        out
    }

    pub(super) fn state(
        &mut self,
        raw: &raw::RawState,
        tags: &HashMap<Signal, usize>,
    ) -> StateRules {
        let fault_severity = self.parsed(
            raw.fault_severity.clone(),
            "state.fault_severity",
            Severity::High,
        );
        let running = raw
            .running
            .as_ref()
            .and_then(|r| self.expression(r, "state.running", tags));
        StateRules {
            running,
            fault_severity,
            modes: self.modes(&raw.modes, tags),
        }
    }

    /// The machine modes (`[[state.modes]]`): each id a key chunk used
    /// once, its `when` an expression over the cell's tags, and at least
    /// one alarm pattern to suppress. (Whether a pattern names an alarm
    /// of the cell is the engine's to say: `cell::compile`.)
    fn modes(&mut self, raw: &[Spanned<raw::RawMode>], tags: &HashMap<Signal, usize>) -> Vec<Mode> {
        let mut ids = HashSet::new();
        let mut out = Vec::new();
        for (k, m) in raw.iter().enumerate() {
            let key = format!("state.modes[{k}]");
            let m = m.get_ref();
            let id = m.id.get_ref();
            self.key_chunk(m.id.span(), &format!("{key}.id"), "", id);
            if !ids.insert(id.clone()) {
                self.problem(
                    m.id.span(),
                    &format!("{key}.id"),
                    format!("mode '{id}' is declared twice"),
                );
            }
            if m.suppress.get_ref().is_empty() {
                self.problem(
                    m.suppress.span(),
                    &format!("{key}.suppress"),
                    "names no alarm: list the alarm ids (or patterns with *) the mode suppresses",
                );
            }
            for (j, p) in m.suppress.get_ref().iter().enumerate() {
                if p.get_ref().trim().is_empty() {
                    self.problem(
                        p.span(),
                        &format!("{key}.suppress[{j}]"),
                        "is empty: an alarm id, or a pattern with * (`door-*`)",
                    );
                }
            }
            let when = self.expression(&m.when, &format!("{key}.when"), tags);
            if let Some(when) = when {
                out.push(Mode {
                    id: id.clone(),
                    when,
                    suppress: m
                        .suppress
                        .get_ref()
                        .iter()
                        .map(|p| AlarmPattern::new(p.get_ref().trim()))
                        .collect(),
                });
            }
        }
        out
    }
}

impl Validator<'_> {
    /// A timer check's drift warnings (`drift`, on unless `false`, and
    /// `drift_fraction`, `drift_spread`, `drift_min_samples`,
    /// `drift_weight`), each setting checked at its place.
    pub(super) fn drift(
        &mut self,
        t: &crate::config::raw::RawTimers,
        key: &str,
    ) -> Option<cellwatch_models::timer::drift::DriftRules> {
        if t.drift == Some(false) {
            return None;
        }
        let mut rules = cellwatch_models::timer::drift::DriftRules::default();
        let mut spans = std::collections::HashMap::new();
        if let Some(v) = &t.drift_fraction {
            rules.fraction = *v.get_ref();
            spans.insert("fraction", v.span());
        }
        if let Some(v) = &t.drift_spread {
            rules.spread = *v.get_ref();
            spans.insert("spread", v.span());
        }
        if let Some(v) = &t.drift_min_samples {
            rules.min_samples = u32::try_from(*v.get_ref()).unwrap_or(0);
            spans.insert("min_samples", v.span());
        }
        if let Some(v) = &t.drift_weight {
            rules.weight = *v.get_ref();
            spans.insert("weight", v.span());
        }
        let problems = rules.problems();
        for p in &problems {
            let span = spans.get(p.field).cloned().unwrap_or(t.id.span());
            self.problem(span, &format!("{key}.drift_{}", p.field), p.to_string());
        }
        problems.is_empty().then_some(rules)
    }
}

/// Whether `text` is a culture name as TIA Portal writes one (`de-DE`,
/// `en-US`, `zh-CN`): two or three letters, a dash, two letters or digits.
fn is_culture(text: &str) -> bool {
    let Some((lang, region)) = text.trim().split_once('-') else {
        return false;
    };
    (2..=3).contains(&lang.len())
        && lang.bytes().all(|b| b.is_ascii_alphabetic())
        && (2..=3).contains(&region.len())
        && region.bytes().all(|b| b.is_ascii_alphanumeric())
}
