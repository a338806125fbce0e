//! Validating the configuration: the delays of the agent's own alarms
//! (`[alarms.communication]`, `[alarms.tag-quality]`).

use std::time::Duration;

use toml::Spanned;

use super::Validator;
use crate::config::raw::{RawDelays, RawSystemAlarms};

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
    pub(super) fn system_alarms(&mut self, raw: RawSystemAlarms) -> Vec<(String, u64, u64)> {
        [
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
        .collect()
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
