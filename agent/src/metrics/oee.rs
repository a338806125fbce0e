//! The metrics of overall equipment effectiveness for the current shift
//! (`[oee]`): availability, performance, quality and OEE as fractions, and
//! the seconds (or parts) lost to each of the six big losses. Registered
//! by [`super::Metrics::new`]; set by the OEE sink on every tick. A ratio
//! with nothing to be judged on (no planned time, no run, no part) is NaN.

use cellwatch_models::oee::Figures;
use prometheus::{Gauge, GaugeVec, Registry};

use super::labels::opts;

/// The current shift's OEE.
#[derive(Clone)]
pub struct OeeMetrics {
    /// availability, performance, quality, oee: each its gauge.
    ratios: [Gauge; 4],
    /// Loss in seconds by loss.
    loss_seconds: GaugeVec,
    /// Rejects by loss (start-up, production).
    rejects: GaugeVec,
}

/// The six big losses as labelled.
const LOSSES: [&str; 6] = [
    "breakdowns",
    "setup",
    "small_stops",
    "reduced_speed",
    "startup_rejects",
    "production_rejects",
];

impl OeeMetrics {
    /// Registers them for `cell` in `registry`.
    pub(super) fn register(registry: &Registry, cell: &str) -> OeeMetrics {
        let ratio = |name: &str, help: &str| {
            let g = Gauge::with_opts(opts(name, help, cell)).expect("valid metric");
            registry
                .register(Box::new(g.clone()))
                .expect("unique metric");
            g
        };
        let ratios = [
            ratio(
                "cellwatch_oee_availability",
                "The current shift's availability: run time / planned production time (0-1).",
            ),
            ratio(
                "cellwatch_oee_performance",
                "The current shift's performance: ideal cycle time x parts / run time (0-1, above 1 when the ideal cycle times are too long).",
            ),
            ratio(
                "cellwatch_oee_quality",
                "The current shift's quality: good parts / parts (0-1).",
            ),
            ratio(
                "cellwatch_oee_oee",
                "The current shift's OEE: availability x performance x quality (0-1).",
            ),
        ];
        let loss_seconds = GaugeVec::new(
            opts(
                "cellwatch_oee_loss_seconds",
                "The current shift's planned time lost, by loss of the six big losses (rejects priced at their ideal cycle time).",
                cell,
            ),
            &["loss"],
        )
        .expect("valid metric");
        let rejects = GaugeVec::new(
            opts(
                "cellwatch_oee_rejects",
                "The current shift's rejected parts, by loss (startup_rejects, production_rejects).",
                cell,
            ),
            &["loss"],
        )
        .expect("valid metric");
        for m in [&loss_seconds, &rejects] {
            registry
                .register(Box::new(m.clone()))
                .expect("unique metric");
        }
        for loss in LOSSES {
            loss_seconds.with_label_values(&[loss]).set(0.0);
        }
        for loss in &LOSSES[4..] {
            rejects.with_label_values(&[loss]).set(0.0);
        }
        OeeMetrics {
            ratios,
            loss_seconds,
            rejects,
        }
    }

    /// Sets the current shift's `figures`.
    pub fn set(&self, f: &Figures) {
        for (gauge, value) in
            self.ratios
                .iter()
                .zip([f.availability, f.performance, f.quality, f.oee])
        {
            gauge.set(value.unwrap_or(f64::NAN));
        }
        let l = &f.losses;
        let ms = [
            l.breakdowns_ms,
            l.setup_ms,
            l.small_stops_ms,
            l.reduced_speed_ms,
            l.startup_rejects_ms,
            l.production_rejects_ms,
        ];
        for (loss, ms) in LOSSES.iter().zip(ms) {
            self.loss_seconds
                .with_label_values(&[loss])
                .set(ms as f64 / 1000.0);
        }
        for (loss, n) in [
            ("startup_rejects", l.startup_rejects),
            ("production_rejects", l.production_rejects),
        ] {
            self.rejects.with_label_values(&[loss]).set(n as f64);
        }
    }
}
