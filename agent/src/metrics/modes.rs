//! The metrics of machine modes and designed suppression (ISA-18.2):
//! which modes hold, how many active alarms they suppress, and the raises
//! they suppressed in the last 10 minutes, which no other alarm figure
//! counts. Registered by [`super::Metrics::new`]; set by the metrics sink.

use prometheus::{IntGauge, IntGaugeVec, Registry};

use super::labels::opts;

/// Machine modes and the alarms they suppress by design.
#[derive(Clone)]
pub struct ModeMetrics {
    /// 1 while a mode holds, by mode.
    active: IntGaugeVec,
    /// Active alarms suppressed by design now.
    pub suppressed_by_design: IntGauge,
    /// Raises suppressed by design in the last 10 minutes.
    pub rate_by_design_10m: IntGauge,
}

impl ModeMetrics {
    /// Registers them for `cell` in `registry`.
    pub(super) fn register(registry: &Registry, cell: &str) -> ModeMetrics {
        let active = IntGaugeVec::new(
            opts(
                "cellwatch_mode_active",
                "1 while a machine mode of [[state.modes]] holds, by mode.",
                cell,
            ),
            &["mode"],
        )
        .expect("valid metric");
        let suppressed_by_design = IntGauge::with_opts(opts(
            "cellwatch_alarms_suppressed_by_design",
            "Active alarms suppressed by design now: a machine mode in which they mean nothing holds (journaled and shown, never announced).",
            cell,
        ))
        .expect("valid metric");
        let rate_by_design_10m = IntGauge::with_opts(opts(
            "cellwatch_alarm_rate_by_design_10m",
            "Raises suppressed by design in the last 10 minutes: counted in no other alarm rate or flood (ISA-18.2 reports them apart).",
            cell,
        ))
        .expect("valid metric");
        for m in [&suppressed_by_design, &rate_by_design_10m] {
            registry
                .register(Box::new(m.clone()))
                .expect("unique metric");
        }
        registry
            .register(Box::new(active.clone()))
            .expect("unique metric");
        ModeMetrics {
            active,
            suppressed_by_design,
            rate_by_design_10m,
        }
    }

    /// Mode `mode` holds (`on`) or not.
    pub fn mode(&self, mode: &str, on: bool) {
        self.active.with_label_values(&[mode]).set(i64::from(on));
    }
}
