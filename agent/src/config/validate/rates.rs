//! Validating the configuration: the rate-of-change levels of a limit
//! check (`rising`, `falling` in `[[checks.limit]]`); the check's other
//! keys are `checks.rs`'s.

use std::time::Duration;

use cellwatch_models::alarm::Severity;
use cellwatch_models::limit::{RateDirection, RateLevel};
use toml::Spanned;

use super::Validator;
use crate::config::raw::RawRate;

/// The shortest window a rate is judged over.
const MIN_PER: Duration = Duration::from_secs(1);

/// The longest window a rate is judged over.
const MAX_PER: Duration = Duration::from_secs(3600);

impl Validator<'_> {
    /// The rate levels of limit check `key` (`checks.limit[2]`): each rate
    /// above zero and above the check's `hysteresis` (else a raised alarm
    /// would never clear while the value holds still), each window from
    /// 1 s to 1 h.
    pub(super) fn rate_levels(
        &mut self,
        key: &str,
        rising: Option<Spanned<RawRate>>,
        falling: Option<Spanned<RawRate>>,
        hysteresis: f64,
    ) -> Vec<RateLevel> {
        let mut out = Vec::new();
        for (direction, raw) in [
            (RateDirection::Rising, rising),
            (RateDirection::Falling, falling),
        ] {
            let Some(raw) = raw else { continue };
            let raw = raw.into_inner();
            let rkey = format!("{key}.{direction}");
            let rate = *raw.rate.get_ref();
            if !rate.is_finite() {
                self.problem(
                    raw.rate.span(),
                    &format!("{rkey}.rate"),
                    "must be a finite number",
                );
            } else if rate <= 0.0 {
                self.problem(
                    raw.rate.span(),
                    &format!("{rkey}.rate"),
                    format!("{rate} must be more than zero"),
                );
            } else if rate <= hysteresis {
                self.problem(
                    raw.rate.span(),
                    &format!("{rkey}.rate"),
                    format!(
                        "{rate} must be more than the hysteresis {hysteresis}: a raised alarm would never clear while the value holds still"
                    ),
                );
            }
            let span = raw.per.span();
            let pkey = format!("{rkey}.per");
            let per = self.duration(Some(raw.per), &pkey, Duration::ZERO);
            if per.is_zero() {
                // Not a duration: said already.
            } else if per < MIN_PER {
                self.problem(span, &pkey, "at least 1s");
            } else if per > MAX_PER {
                self.problem(span, &pkey, "at most 1h");
            }
            let severity = self.parsed(raw.severity, &format!("{rkey}.severity"), Severity::High);
            out.push(RateLevel {
                direction,
                rate,
                per: per.as_millis() as u64,
                severity,
            });
        }
        out
    }
}
