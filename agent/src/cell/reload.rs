//! A configuration read again while the agent runs (SIGHUP, `cellwatch
//! run`): the engine built from it takes over from the running one in the
//! loop, between two inputs — alarms with their acknowledgements, shelves
//! and removals, the machine state, the connection and every tag's value
//! carried over ([`CellEngine::take_over`]); the charts' switches, the
//! timed transitions and the longest shelf replaced. The source, the
//! journal, the bus session and the sinks go on untouched: nothing is
//! lost, and history has no gap.

use super::swap::Reload;
use super::{CellLoop, Input};

impl CellLoop {
    /// Reloads the loop from `reload` (see the module).
    pub(super) async fn reload(&mut self, reload: Reload) {
        let Reload {
            mut engine,
            mut forcing,
            timers,
            max_shelve,
            done,
        } = reload;
        if self.forcing.pending.is_some() {
            let _ = done.send(Err(
                "a forced transition or stop is under way: read the configuration again once it has ended".into(),
            ));
            return;
        }
        forcing.pending = None;
        let now = self.clock.now_ms();
        let carried = self.engine.carry_over();
        let alarms = carried.alarms.len();
        let steps = engine.take_over(carried, now);
        self.engine = engine;
        self.forcing = forcing;
        self.timers = timers;
        self.max_shelve = max_shelve;
        for step in steps {
            self.dispatch(now, Input::Reloaded, step, 0).await;
        }
        let _ = done.send(Ok(alarms));
    }
}
