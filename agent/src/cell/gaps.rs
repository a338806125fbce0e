//! Changes lost for good (a sequence gap the server could not fill,
//! values dropped from a full queue): the engine told, so that alarms
//! judged across the gap say their trigger is uncertain, and a warning
//! said at most once a minute with how often, however fast the server
//! loses them.

use std::time::Instant;

use super::CellLoop;
use cellwatch_models::engine::EngineStep;

impl CellLoop {
    /// The engine's step for a gap in `tags` (`None`: any tag may have
    /// lost changes) of `values` values (0: not known), and the warning
    /// when one is due.
    pub(super) fn lost(&mut self, tags: Option<&[usize]>, values: u64, why: &str) -> EngineStep {
        if let Some(times) = self.gaps.happened(Instant::now()) {
            tracing::warn!(
                cell = %self.cell,
                %why,
                "changes lost: alarms judged across the gap say trigger uncertain \
                 ({times} such since the last warning, said at most once a minute)"
            );
        }
        self.engine.on_gap(tags, values, why)
    }
}
