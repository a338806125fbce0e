//! When an occurrence nobody acknowledges is overdue (ISA-18.2): past the
//! response time of its rationalisation.

use cellwatch_models::alarm::AlarmState;

use super::AlarmPayload;

impl AlarmPayload {
    /// From when (ms since the epoch) this occurrence is overdue (ISA-18.2):
    /// unacknowledged, to act on (not shelved, out of service or
    /// suppressed), with a response time in the master alarm database,
    /// counted from its raise. `None` when it cannot be overdue.
    pub fn overdue_from(&self) -> Option<u64> {
        let unacknowledged = matches!(
            self.state,
            AlarmState::ActiveUnacknowledged | AlarmState::ClearedUnacknowledged
        );
        let kept = self.shelved.is_some()
            || self.out_of_service.is_some()
            || self.suppressed_by_design.is_some()
            || self.consequence.as_ref().is_some_and(|c| c.suppressed);
        if !unacknowledged || kept {
            return None;
        }
        let within = self.guidance.as_ref()?.response_time_ms()?;
        let raised = humantime::parse_rfc3339_weak(&self.raised_at).ok()?;
        let raised = raised.duration_since(std::time::UNIX_EPOCH).ok()?;
        Some(
            u64::try_from(raised.as_millis())
                .ok()?
                .saturating_add(within),
        )
    }

    /// Whether it is overdue at `now` (ms since the epoch).
    pub fn overdue(&self, now: u64) -> bool {
        self.overdue_from().is_some_and(|from| now >= from)
    }
}
