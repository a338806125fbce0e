//! Alarm-system performance after ISA-18.2 / IEC 62682 (and EEMUA 191):
//! the figures the standard's benchmark table is written in, live
//! ([`LiveKpis`], for the metrics) and for a period ([`alarm_report`], for
//! `cellwatch report alarms`). One cell is one operator position.
//!
//! Definitions (the same on both sides):
//! - the *alarm rate* counts raises (new occurrences) per 10 minutes;
//! - a *flood* begins with more than [`KpiRules::flood_raises`] raises
//!   within 10 minutes and ends when fewer than
//!   [`KpiRules::flood_ends_below`] are left (ISA-18.2's hysteresis: 10 and
//!   5): live, over the sliding last 10 minutes; in a report, per fixed
//!   10-minute interval from the period's start (an interval after one in
//!   flood stays in flood while it has at least `flood_ends_below` raises);
//! - an alarm *chatters* when it is raised [`KpiRules::chatter_raises`]
//!   times or more within [`KpiRules::chatter_window_ms`];
//! - an occurrence is *stale* once active longer than
//!   [`KpiRules::stale_ms`];
//! - the *acknowledgement time* runs from the raise to the acknowledgement.
//!
//! Everything here is bounded: the live side keeps one counter per second
//! of the window and, per alarm, its last three raise times.

mod live;
mod report;

#[cfg(test)]
mod tests;

pub use live::{KpiSnapshot, LiveKpis};
pub use report::{
    alarm_report, AckTimes, AlarmEvent, AlarmReport, Benchmark, Chattering, Frequent, Stale,
};

/// The rate window and report interval: 10 minutes, ms.
pub const INTERVAL_MS: u64 = 600_000;
/// More raises than this within [`INTERVAL_MS`] is a flood (ISA-18.2).
pub const FLOOD_RAISES: u64 = 10;
/// A flood ends when fewer raises than this are left within
/// [`INTERVAL_MS`] (ISA-18.2).
pub const FLOOD_ENDS_BELOW: u64 = 5;
/// Raises of one alarm within [`CHATTER_WINDOW_MS`] that make it chatter.
pub const CHATTER_RAISES: usize = 3;
/// See [`CHATTER_RAISES`]: 60 s.
pub const CHATTER_WINDOW_MS: u64 = 60_000;
/// Active longer than this is stale: 24 h.
pub const STALE_MS: u64 = 24 * 3_600_000;

/// The plant's rules the figures are judged by; by default ISA-18.2's
/// example figures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct KpiRules {
    /// More raises than this within 10 minutes begins a flood.
    pub flood_raises: u64,
    /// Fewer raises than this within 10 minutes ends it (at most
    /// `flood_raises + 1`, which is no hysteresis).
    pub flood_ends_below: u64,
    /// Raises of one alarm within `chatter_window_ms` that make it chatter.
    pub chatter_raises: usize,
    /// See `chatter_raises`, ms.
    pub chatter_window_ms: u64,
    /// Active longer than this is stale, ms.
    pub stale_ms: u64,
}

impl Default for KpiRules {
    fn default() -> Self {
        KpiRules {
            flood_raises: FLOOD_RAISES,
            flood_ends_below: FLOOD_ENDS_BELOW,
            chatter_raises: CHATTER_RAISES,
            chatter_window_ms: CHATTER_WINDOW_MS,
            stale_ms: STALE_MS,
        }
    }
}
