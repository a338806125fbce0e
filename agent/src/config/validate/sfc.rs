//! Validating the configuration: sfc.

use std::collections::{HashMap, HashSet};

use cellwatch_models::alarm::Severity;
use cellwatch_models::expr::Expr;
use cellwatch_models::program::Program;
use cellwatch_models::programs::Dialect;
use cellwatch_models::sfc::learn::StepModel;
use cellwatch_models::sfc::Sfc;
use cellwatch_models::signal::{Observability, Signal};
use cellwatch_models::value::{CmpOperand, Comparison, ValueType};
use toml::Spanned;

use super::Validator;
use crate::config::raw;
use crate::config::{SfcCheck, DEFAULT_FORCE_PULSE, DEFAULT_FORCE_TIMEOUT, MAX_FORCE_TIMEOUT};
use crate::tags::canonical_expr;

impl Validator<'_> {
    /// `KEY.program`: the PLC program that drives outputs from the
    /// supervised steps' flags. One that drives none of the cell's tags
    /// from any of them is refused: it would change nothing.
    fn driving(
        &mut self,
        key: &str,
        file: &Spanned<String>,
        dialect: Option<Dialect>,
        sfc: &Sfc,
        tags: &HashMap<Signal, usize>,
    ) -> Option<(Program, Observability)> {
        let pkey = format!("{key}.program");
        let path = self.path(file.get_ref());
        let text = self.read_text(file.span(), &pkey, &path, "program")?;
        let program = match Program::compile_in(&path.display().to_string(), &text, dialect, None) {
            Ok(p) => p,
            Err(e) => {
                self.problems.extend(e.lines());
                return None;
            }
        };
        let observable = Observability::default_for(program.dialect());
        let flags: Vec<&Signal> = sfc
            .steps()
            .filter(|(_, s)| s.supervision_ms.is_some())
            .map(|(_, s)| &s.flag)
            .collect();
        let drives = flags.iter().any(|flag| {
            !cellwatch_models::consequence::forced_outputs(&program, flag, &observable, |s| {
                tags.contains_key(s)
            })
            .is_empty()
        });
        if !drives {
            let flags: Vec<String> = flags.iter().map(ToString::to_string).collect();
            self.problem(
                file.span(),
                &pkey,
                format!(
                    "{} drives none of the cell's tags from a supervised step's flag ({}): name the program whose step actions set the outputs, or leave the key out",
                    path.display(),
                    if flags.is_empty() { "no step is supervised".to_string() } else { flags.join(", ") }
                ),
            );
            return None;
        }
        Some((program, observable))
    }

    /// Step supervision times learned by `cellwatch learn --sfc`, given to
    /// the steps of `sfc` that declare none.
    pub(super) fn learned_steps(&mut self, file: &Spanned<String>, key: &str, sfc: &mut Sfc) {
        let path = self.path(file.get_ref());
        let Some(text) = self.read_text(file.span(), key, &path, "step supervision") else {
            return;
        };
        let model: StepModel = match serde_json::from_str(&text) {
            Ok(m) => m,
            Err(e) => {
                self.problem(
                    file.span(),
                    key,
                    format!("{}:{}:{}: {e}", path.display(), e.line(), e.column()),
                );
                return;
            }
        };
        if let Err(errors) = model.apply(sfc) {
            for e in errors {
                self.problem(file.span(), key, format!("{}: {e}", path.display()));
            }
        }
    }

    /// The charts under supervision (`[[checks.sfc]]`).
    pub(super) fn sfc(
        &mut self,
        raw: Vec<raw::RawSfc>,
        ids: &mut HashSet<String>,
        tags: &HashMap<Signal, usize>,
    ) -> Vec<SfcCheck> {
        let mut out = Vec::new();
        let mut charts = HashSet::new();
        for (i, c) in raw.into_iter().enumerate() {
            let key = format!("checks.sfc[{i}]");
            self.unique_id(&c.id, &key, ids);
            let severity = self.parsed(
                c.severity.clone(),
                &format!("{key}.severity"),
                Severity::High,
            );
            let path = self.path(c.charts.get_ref());
            let Some(text) =
                self.read_text(c.charts.span(), &format!("{key}.charts"), &path, "charts")
            else {
                continue;
            };
            // A contact is known when it is a tag's bit or a comparison of
            // numeric tags, as in any other condition.
            let addressing = self.addressing;
            let kinds = &self.kinds;
            let known = |s: &Signal| {
                let canonical = canonical_expr(addressing, Expr::Lit(s.clone(), false));
                canonical
                    .signals()
                    .iter()
                    .all(|s| match Comparison::of_signal(s) {
                        Some(cmp) => std::iter::once(&cmp.lhs)
                            .chain(match &cmp.rhs {
                                CmpOperand::Tag(t) => Some(t),
                                CmpOperand::Const(_) => None,
                            })
                            .all(|a| kinds.get(a).is_some_and(|(t, _)| t.is_numeric())),
                        None => tags.contains_key(s) && !matches!(kinds.get(s), Some((_, false))),
                    })
            };
            match cellwatch_models::sfc::read(&path.display().to_string(), &text, &known) {
                Ok(mut sfc) => {
                    // The cell's own times first, then learned ones for
                    // the steps still without.
                    for (step, time) in &c.supervision {
                        let skey = format!("{key}.supervision.\"{step}\"");
                        let found = sfc
                            .steps()
                            .map(|(r, _)| r)
                            .find(|&r| sfc.step_name(r) == *step);
                        let ms = cellwatch_models::sfc::text::duration_ms(time.get_ref());
                        match (found, ms) {
                            (Some(r), Ok(ms)) => {
                                sfc.charts[r.chart].steps[r.step].supervision_ms = Some(ms)
                            }
                            (None, _) => self.problem(
                                time.span(),
                                &skey,
                                format!("no step {step} in {} (write CHART.STEP)", path.display()),
                            ),
                            (_, Err(why)) => self.problem(time.span(), &skey, why),
                        }
                    }
                    if let Some(steps) = &c.steps {
                        self.learned_steps(steps, &format!("{key}.steps"), &mut sfc);
                    }
                    // Alarm ids are made of them: `<id>-<chart>-<step>`,
                    // `force-<chart>-<transition>`.
                    let ckey = format!("{key}.charts");
                    for chart in &sfc.charts {
                        let span = c.charts.span();
                        self.key_chunk(span.clone(), &ckey, "chart ", &chart.name);
                        for step in &chart.steps {
                            let what = format!("chart {} step ", chart.name.escape_debug());
                            self.key_chunk(span.clone(), &ckey, &what, &step.name);
                        }
                        for t in &chart.transitions {
                            let what = format!("chart {} transition ", chart.name.escape_debug());
                            self.key_chunk(span.clone(), &ckey, &what, &t.id);
                        }
                    }
                    for chart in &sfc.charts {
                        if !charts.insert(chart.name.clone()) {
                            self.problem(
                                c.charts.span(),
                                &format!("{key}.charts"),
                                format!(
                                    "chart {} is supervised twice in this cell (a force or stop names a chart)",
                                    chart.name
                                ),
                            );
                        }
                    }
                    for chart in &mut sfc.charts {
                        for step in &mut chart.steps {
                            if let Expr::Lit(s, _) =
                                canonical_expr(addressing, Expr::Lit(step.flag.clone(), false))
                            {
                                step.flag = s;
                            }
                        }
                        for t in &mut chart.transitions {
                            t.condition = canonical_expr(addressing, t.condition.clone());
                        }
                    }
                    let mut switch = |v: Option<Spanned<String>>, name: &str| {
                        let v = v?;
                        let key = format!("{key}.{name}");
                        let found = self
                            .tag_ref(v.get_ref())
                            .ok()
                            .and_then(|a| Some((tags.get(&a).copied()?, self.kinds.get(&a)?.0)));
                        match found {
                            _ if self.bus => {
                                self.problem(
                                    v.span(),
                                    &key,
                                    "the switches are written over OPC UA; this cell reads an @ bus",
                                );
                                None
                            }
                            Some((i, ValueType::Boolean)) => Some(i),
                            Some((_, t)) => {
                                self.problem(
                                    v.span(),
                                    &key,
                                    format!("'{}' is {t}; a switch is a Boolean tag", v.get_ref()),
                                );
                                None
                            }
                            None => {
                                self.problem(
                                    v.span(),
                                    &key,
                                    format!("'{}' is not a tag of this cell", v.get_ref()),
                                );
                                None
                            }
                        }
                    };
                    let force_switch = switch(c.force_switch.clone(), "force_switch");
                    let stop_switch = switch(c.stop_switch, "stop_switch");
                    let mut forcible = Vec::new();
                    for (j, f) in c.forcible.into_iter().enumerate() {
                        let fkey = format!("{key}.forcible[{j}]");
                        let Some((chart, t)) = f.get_ref().split_once('.') else {
                            self.problem(
                                f.span(),
                                &fkey,
                                format!("'{}' is not CHART.TRANSITION (F1.t3)", f.get_ref()),
                            );
                            continue;
                        };
                        if sfc.transition(chart, t).is_none() {
                            self.problem(
                                f.span(),
                                &fkey,
                                format!(
                                    "no transition {t} in a chart {chart} of {}",
                                    path.display()
                                ),
                            );
                        } else if c.force_switch.is_none() {
                            self.problem(
                                f.span(),
                                &fkey,
                                "forcing needs the force switch (force_switch)",
                            );
                        } else {
                            forcible.push((chart.to_string(), t.to_string()));
                        }
                    }
                    let force_pulse = self.duration(
                        c.force_pulse,
                        &format!("{key}.force_pulse"),
                        DEFAULT_FORCE_PULSE,
                    );
                    let timeout_span = c.force_timeout.as_ref().map(Spanned::span);
                    let mut force_timeout = self.duration(
                        c.force_timeout,
                        &format!("{key}.force_timeout"),
                        DEFAULT_FORCE_TIMEOUT,
                    );
                    if force_timeout > MAX_FORCE_TIMEOUT {
                        self.problem(
                            timeout_span.unwrap_or_default(),
                            &format!("{key}.force_timeout"),
                            "at most 1 minute (the operator waits for the answer)",
                        );
                        force_timeout = DEFAULT_FORCE_TIMEOUT;
                    }
                    let program = match &c.program {
                        None => None,
                        Some(p) => {
                            let dialect = self.dialect(&key, c.dialect.as_ref());
                            self.driving(&key, p, dialect, &sfc, tags)
                        }
                    };
                    out.push(SfcCheck {
                        program,
                        id: c.id.into_inner(),
                        sfc,
                        severity,
                        force_switch,
                        stop_switch,
                        forcible,
                        force_pulse,
                        force_timeout,
                    });
                }
                // The chart file's own positions.
                Err(errors) => self.problems.extend(errors),
            }
        }
        out
    }
}
