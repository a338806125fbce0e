//! The cell's OEE as it runs: each step's state changes, modes entered and
//! left, parts, rejects and order changes fed to the models'
//! [`LiveOee`], and the current shift's figures set in the metrics
//! (`cellwatch_oee_*`) on every tick. The rules are `[oee]`'s
//! ([`config`]); the reports compute the same figures from the journal.

pub use crate::config::oee as config;

use std::sync::Arc;

use cellwatch_models::oee::LiveOee;
use cellwatch_models::report::StopCauses;
use futures_util::future::BoxFuture;
use futures_util::FutureExt;

use crate::metrics::Metrics;
use crate::sinks::Sink;
use crate::step::{CellStep, Input};

/// Feeds the live OEE and sets its metrics.
pub struct OeeSink {
    metrics: Arc<Metrics>,
    live: LiveOee,
}

/// The sink for `config`, if `[oee]` is there.
pub fn sink(config: Option<&config::OeeConfig>, metrics: &Arc<Metrics>) -> Option<Box<dyn Sink>> {
    config.map(|c| Box::new(OeeSink::new(metrics.clone(), c)) as Box<dyn Sink>)
}

impl OeeSink {
    /// A sink judging by `config`.
    pub fn new(metrics: Arc<Metrics>, config: &config::OeeConfig) -> OeeSink {
        OeeSink {
            metrics,
            live: LiveOee::new(config.rules.clone(), StopCauses::default()),
        }
    }

    fn step(&mut self, step: &CellStep) {
        let e = &step.engine;
        for (state, _, at) in e.states() {
            let fault_type = match state {
                cellwatch_models::engine::MachineState::Fault { fault_type, .. } => {
                    Some(fault_type.as_str())
                }
                _ => None,
            };
            self.live.on_state(at, state.name(), fault_type);
        }
        for (mode, entered, at) in e.modes() {
            self.live.on_mode(at, mode, entered);
        }
        for &(at, n) in &e.parts {
            self.live.on_parts(at, n);
        }
        for &(at, n) in &e.rejects {
            self.live.on_rejects(at, n);
        }
        if let Some(o) = &e.order {
            self.live.on_order(step.at, o.item.as_deref());
        }
        if step.input == Input::Tick {
            if let Some((_, figures)) = self.live.figures(step.at) {
                self.metrics.oee.set(&figures);
            }
        }
    }
}

impl Sink for OeeSink {
    fn name(&self) -> &'static str {
        "oee"
    }

    fn handle<'a>(&'a mut self, step: &'a CellStep) -> BoxFuture<'a, ()> {
        self.step(step);
        async {}.boxed()
    }
}
