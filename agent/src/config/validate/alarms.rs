//! Validating the configuration: the delays of the agent's own alarms
//! (`[alarms.communication]`, `[alarms.tag-quality]`) and
//! `[alarms.consequences]`.

use std::time::Duration;

use toml::Spanned;

use super::Validator;
use crate::config::checks::Consequences;
use crate::config::raw::{RawConsequences, RawDelays, RawEdge, RawSystemAlarms};

/// How long the connection, or every tag, must be good again before the
/// `communication` or `tag-quality` alarm clears, unless configured: a
/// link or a sensor that comes and goes is one occurrence, its losses
/// counted in the alarm's text (ISA-18.2).
const DEFAULT_SYSTEM_OFF_DELAY: Duration = Duration::from_secs(10);

/// The longest delay of an agent's own alarm.
const MAX_SYSTEM_DELAY: Duration = Duration::from_secs(3600);

impl Validator<'_> {
    /// `[alarms.*]`: `(alarm id, on-delay, off-delay)` in ms for the
    /// `communication` and `tag-quality` alarms, defaults where unsaid.
    pub(super) fn system_alarms(
        &mut self,
        raw: RawSystemAlarms,
    ) -> (Vec<(String, u64, u64)>, Consequences) {
        let consequences = self.consequences(raw.consequences);
        let delays = [
            ("communication", raw.communication),
            ("tag-quality", raw.tag_quality),
        ]
        .into_iter()
        .map(|(id, delays)| {
            let (on, off) = match delays {
                None => (None, None),
                Some(RawDelays {
                    on_delay,
                    off_delay,
                }) => (on_delay, off_delay),
            };
            let on = self.system_delay(on, &format!("alarms.{id}.on_delay"), Duration::ZERO);
            let off = self.system_delay(
                off,
                &format!("alarms.{id}.off_delay"),
                DEFAULT_SYSTEM_OFF_DELAY,
            );
            (id.to_string(), on, off)
        })
        .collect();
        (delays, consequences)
    }

    /// `alarms.database`: the cell's master alarm database, read and
    /// checked row by row (each problem at its line and column); whether
    /// its ids are alarms of the cell is known once the checks are built
    /// ([`crate::cell::compile::engine`]).
    pub(super) fn database(
        &mut self,
        raw: Option<&Spanned<String>>,
    ) -> Option<(std::path::PathBuf, cellwatch_models::madb::Database)> {
        let raw = raw?;
        let path = self.path(raw.get_ref());
        let text = self.read_text(
            raw.span(),
            "alarms.database",
            &path,
            "the master alarm database",
        )?;
        match cellwatch_models::madb::Database::parse(&path.display().to_string(), &text) {
            Ok(db) => Some((path, db)),
            Err(e) => {
                self.problems.extend(e.problems);
                None
            }
        }
    }

    /// `[alarms.consequences]`: an edge names two different alarms; whether
    /// they are alarms of the cell's checks is known once the checks are
    /// built ([`crate::cell::compile::engine`]).
    fn consequences(&mut self, raw: Option<RawConsequences>) -> Consequences {
        let Some(raw) = raw else {
            return Consequences::default();
        };
        let mut edges = |list: Vec<toml::Spanned<RawEdge>>, what: &str| {
            let mut out = Vec::new();
            for (i, e) in list.into_iter().enumerate() {
                let key = format!("alarms.consequences.{what}[{i}]");
                let span = e.span();
                let RawEdge { cause, effect } = e.into_inner();
                if cause.trim().is_empty() || effect.trim().is_empty() {
                    self.problem(
                        span,
                        &key,
                        "names no alarm: give cause and effect alarm ids",
                    );
                } else if cause == effect {
                    self.problem(span, &key, format!("'{cause}' cannot follow from itself"));
                } else {
                    out.push((key, cause, effect));
                }
            }
            out
        };
        let add = edges(raw.add, "add");
        let remove = edges(raw.remove, "remove");
        Consequences {
            suppress: raw.suppress.unwrap_or(false),
            add,
            remove,
        }
    }

    /// A delay of the agent's own alarm in ms: `0` or a duration of at
    /// most an hour.
    fn system_delay(
        &mut self,
        value: Option<Spanned<String>>,
        key: &str,
        default: Duration,
    ) -> u64 {
        let Some(v) = value else {
            return default.as_millis() as u64;
        };
        let span = v.span();
        let ms = self.delay(Some(v), key);
        if ms > MAX_SYSTEM_DELAY.as_millis() as u64 {
            self.problem(span, key, "at most 1h");
            return default.as_millis() as u64;
        }
        ms
    }
}
