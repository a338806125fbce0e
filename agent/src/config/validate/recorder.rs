//! Validating the configuration: the flight recorder (`[recorder]`).

use std::time::Duration;

use cellwatch_models::engine::recorder::MAX_OPEN;
use cellwatch_models::engine::RecorderConfig;

use super::Validator;
use crate::config::raw::RawRecorder;

/// The longest a recording reaches before or after its alarm's raise.
const MAX_SPAN: Duration = Duration::from_secs(600);

impl Validator<'_> {
    /// `[recorder]`: on unless `enabled = false`, the models' defaults
    /// where it says nothing; `None` when off.
    pub(super) fn recorder(&mut self, raw: RawRecorder) -> Option<RecorderConfig> {
        let d = RecorderConfig::default();
        let span = |v: &mut Self, value, key: &str, default: u64| {
            v.within(
                value,
                key,
                Duration::ZERO..=MAX_SPAN,
                "between 0 and 10min",
                Duration::from_millis(default),
            )
            .as_millis() as u64
        };
        let before = span(self, raw.before, "recorder.before", d.before);
        let after = span(self, raw.after, "recorder.after", d.after);
        let capacity = raw.capacity.map_or(d.capacity, |v| {
            self.count(
                v,
                "recorder.capacity",
                1_000..=10_000_000,
                d.capacity as u32,
            ) as usize
        });
        let max_changes = raw.max_changes.map_or(d.max_changes, |v| {
            self.count(
                v,
                "recorder.max_changes",
                10..=100_000,
                d.max_changes as u32,
            ) as usize
        });
        let max_open = raw.max_open.map_or(d.max_open, |v| {
            self.count(
                v,
                "recorder.max_open",
                1..=MAX_OPEN as u32,
                d.max_open as u32,
            ) as usize
        });
        raw.enabled.unwrap_or(true).then_some(RecorderConfig {
            before,
            after,
            capacity,
            max_changes,
            max_open,
        })
    }
}
