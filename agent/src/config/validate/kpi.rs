//! Validating the configuration: the alarm-performance rules (`[kpi]`).

use std::ops::RangeInclusive;
use std::time::Duration;

use cellwatch_models::kpi::KpiRules;
use toml::Spanned;

use super::Validator;
use crate::config::raw::RawKpi;

impl Validator<'_> {
    /// `[kpi]`, ISA-18.2's figures where it says nothing.
    pub(super) fn kpi(&mut self, raw: RawKpi) -> KpiRules {
        let isa = KpiRules::default();
        let flood_raises = match raw.flood_raises {
            None => isa.flood_raises,
            Some(v) => u64::from(self.count(v, "kpi.flood_raises", 1..=10_000, 10)),
        };
        // ISA-18.2 ends a flood of more than 10 below 5: half.
        let half = flood_raises.div_ceil(2);
        let flood_ends_below = match raw.flood_ends_below {
            None => half,
            Some(v) => match u64::try_from(*v.get_ref()) {
                Ok(n) if (1..=flood_raises + 1).contains(&n) => n,
                _ => {
                    self.problem(
                        v.span(),
                        "kpi.flood_ends_below",
                        format!(
                            "{} is not between 1 and {} (flood_raises + 1: no hysteresis)",
                            v.get_ref(),
                            flood_raises + 1
                        ),
                    );
                    half
                }
            },
        };
        let chatter_raises = match raw.chatter_raises {
            None => isa.chatter_raises,
            Some(v) => self.count(v, "kpi.chatter_raises", 2..=100, 3) as usize,
        };
        let chatter_window = self.within(
            raw.chatter_window,
            "kpi.chatter_window",
            Duration::from_secs(1)..=Duration::from_secs(3600),
            "between 1s and 1h",
            Duration::from_millis(isa.chatter_window_ms),
        );
        let stale = self.within(
            raw.stale_after,
            "kpi.stale_after",
            Duration::from_secs(60)..=Duration::from_secs(366 * 86_400),
            "between 1min and 366d",
            Duration::from_millis(isa.stale_ms),
        );
        KpiRules {
            flood_raises,
            flood_ends_below,
            chatter_raises,
            chatter_window_ms: chatter_window.as_millis() as u64,
            stale_ms: stale.as_millis() as u64,
        }
    }

    /// A duration in `range` (`said` in words), or a problem and `default`.
    pub(super) fn within(
        &mut self,
        value: Option<Spanned<String>>,
        key: &str,
        range: RangeInclusive<Duration>,
        said: &str,
        default: Duration,
    ) -> Duration {
        let span = value.as_ref().map(Spanned::span);
        let d = self.duration(value, key, default);
        match span {
            Some(span) if !range.contains(&d) => {
                self.problem(span, key, format!("must be {said}"));
                default
            }
            _ => d,
        }
    }
}
