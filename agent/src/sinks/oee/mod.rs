//! The cell's OEE as it runs: each step's state changes, modes entered and
//! left, parts, rejects and order changes fed to the models'
//! [`LiveOee`], and on every tick the current shift's figures set in the
//! metrics (`cellwatch_oee_*`) and handed to whoever watches them (the
//! snapshot, the Sparkplug B node) as an [`OeeNow`]. The rules are
//! `[oee]`'s ([`config`]); the reports compute the same figures from the
//! journal, and a restarted agent takes the current shift's facts back
//! from it, so that the live figures go on where they were.

pub mod config;

use std::path::Path;
use std::sync::Arc;

use cellwatch_models::oee::LiveOee;
use cellwatch_models::report::StopCauses;
use futures_util::future::BoxFuture;
use futures_util::FutureExt;
use tokio::sync::watch;

use crate::journal::{JournalError, ReportInput};
use crate::metrics::Metrics;
use crate::sinks::Sink;
use crate::step::{CellStep, Input};
pub(crate) use crate::step::{OeeNow, OeeWatch};

/// Feeds the live OEE, sets its metrics and tells its watchers.
pub(crate) struct OeeSink {
    metrics: Arc<Metrics>,
    live: LiveOee,
    now: watch::Sender<Option<OeeNow>>,
    /// When the figures were last computed (they are, at most once per
    /// [`EVERY_MS`]: each computation reads the whole shift's facts).
    computed_at: Option<u64>,
}

/// How often the figures are computed, at most, ms.
const EVERY_MS: u64 = 1000;

impl OeeSink {
    /// The sink for `config`, with the current shift's facts taken back
    /// from the journal at `journal` (none yet is fine).
    ///
    /// # Errors
    /// The journal exists but cannot be read.
    pub(crate) fn start(
        config: &config::OeeConfig,
        metrics: &Arc<Metrics>,
        journal: &Path,
        now: u64,
    ) -> Result<OeeSink, JournalError> {
        let mut sink = OeeSink::new(metrics.clone(), config);
        if let Some(shift) = config.rules.calendar.current(now) {
            if journal.exists() {
                let conn = crate::journal::open_read(journal)?;
                let until = now.saturating_add(1);
                let input =
                    crate::journal::report_input(&conn, shift.start, until).map_err(|source| {
                        JournalError::Sqlite {
                            path: journal.to_path_buf(),
                            source,
                        }
                    })?;
                sink.take_back(&input);
            }
        }
        Ok(sink)
    }

    /// A watch of the figures as each tick computes them.
    pub(crate) fn watch(&self) -> OeeWatch {
        self.now.subscribe()
    }

    /// A sink judging by `config`, from nothing.
    pub(crate) fn new(metrics: Arc<Metrics>, config: &config::OeeConfig) -> OeeSink {
        OeeSink {
            metrics,
            live: LiveOee::new(config.rules.clone(), shipped_causes()),
            now: watch::channel(None).0,
            computed_at: None,
        }
    }

    /// Takes back the facts a journal kept (the current shift's, and the
    /// last state, order and modes before it).
    fn take_back(&mut self, input: &ReportInput) {
        for c in &input.changes {
            self.live.on_state(c.at, &c.state, c.fault_type.as_deref());
        }
        for m in &input.modes {
            self.live.on_mode(m.at, &m.mode, m.entered);
        }
        for &(at, n) in &input.parts {
            self.live.on_parts(at, n);
        }
        for &(at, n) in &input.rejects {
            self.live.on_rejects(at, n);
        }
        for o in &input.orders {
            self.live.on_order(o.at, o.item.as_deref());
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
        let due = self
            .computed_at
            .is_none_or(|t| step.at >= t.saturating_add(EVERY_MS) || step.at < t);
        if step.input == Input::Tick && due {
            self.computed_at = Some(step.at);
            if let Some((shift, figures)) = self.live.figures(step.at) {
                self.metrics.oee.set(&figures);
                self.now.send_replace(Some(OeeNow {
                    shift,
                    figures,
                    at: step.at,
                }));
            }
        }
    }
}

/// The shipped stop causes, as the reports classify stops without
/// `--causes`.
fn shipped_causes() -> StopCauses {
    config::shipped_stop_causes().unwrap_or_else(|e| {
        tracing::error!(error = %e, "the shipped stop causes do not read: breakdowns are not named by cause");
        StopCauses::default()
    })
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
