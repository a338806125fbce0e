//! A validated cell configuration: everything an agent needs to start.

use std::collections::HashMap;
use std::fmt;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use cellwatch_models::engine::{PartCounting, StateRules, SwitchingCheck, Tag};
use cellwatch_models::limit::LimitCheck;
use cellwatch_models::signal::Signal;
use cellwatch_models::value::Counter;

use crate::config::at_bus::AtBusConfig;
use crate::config::{
    Addressing, AlertmanagerConfig, OpcUaConfig, SfcCheck, TagConfig, TimerCheck, ZenohConfig,
};
use crate::journal::config::JournalConfig;
use crate::services::plant_operators::{OperatorsSetup, PlantOperatorsConfig};
use crate::sinks::metrics::MetricsSetup;
use crate::sinks::sparkplug::SparkplugCell;

/// The longest shelf unless the configuration says (`commands.max_shelve`).
pub const DEFAULT_MAX_SHELVE: Duration = Duration::from_secs(8 * 3600);

/// The longest `commands.max_shelve` accepted: one year.
pub const MAX_SHELVE_LIMIT: Duration = Duration::from_secs(365 * 24 * 3600);

/// A validated cell configuration.
#[derive(Clone)]
pub struct CellConfig {
    /// Cell id.
    pub cell: String,
    /// Free text.
    pub description: String,
    /// How the tags' addresses and the conditions over them are written
    /// (`cell.dialect`).
    pub addressing: Addressing,
    /// OPC UA connection.
    pub opcua: Option<OpcUaConfig>,
    /// The `@` bus of legacy units (paper 002), when the cell is read from
    /// one instead of an OPC UA server.
    pub legacy: Option<AtBusConfig>,
    /// Tags, in file order.
    pub tags: Vec<TagConfig>,
    /// Switching-function checks, compiled.
    pub switching: Vec<SwitchingCheck>,
    /// Transition-timer checks: id, model, severity.
    pub timers: Vec<TimerCheck>,
    /// Machine-state rules.
    pub state: StateRules,
    /// How often the state is published even without change.
    pub state_interval: Duration,
    /// Zenoh.
    pub zenoh: ZenohConfig,
    /// Journal.
    pub journal: JournalConfig,
    /// Prometheus `/metrics` address; `None` disables it.
    pub metrics: Option<SocketAddr>,
    /// The operators' public keys and permissions (`commands.operators_file`).
    pub operators_file: Option<PathBuf>,
    /// The plant operators list (`commands.plant_key`, `plant_list`): the
    /// plant administrator's public key, and where the newest list taken
    /// is kept; its operators replace the operators file's once one is held.
    pub plant_operators: Option<PlantOperatorsConfig>,
    /// The longest an operator may shelve an alarm (`commands.max_shelve`).
    pub max_shelve: Duration,
    /// The tag whose rising edge is one part done (index into `tags`).
    pub part_done: Option<usize>,
    /// The integer tags counting parts (indices into `tags`).
    pub part_counters: Vec<usize>,
    /// The tag giving the item (mould, product) code being made.
    pub order_item: Option<usize>,
    /// The tag giving the target quantity.
    pub order_target: Option<usize>,
    /// Limit checks on numeric tags.
    pub limits: Vec<LimitCheck>,
    /// Step supervision of charts.
    pub sfc: Vec<SfcCheck>,
    /// Alarm delays: alarm id, on-delay and off-delay, ms.
    pub delays: Vec<(String, u64, u64)>,
    /// Where alarms are pushed for people (`[alertmanager]`).
    pub alertmanager: Option<AlertmanagerConfig>,
    /// The alarms served to SCADA clients over OPC UA (`[alarm_server]`).
    pub alarm_server: Option<crate::config::AlarmServerConfig>,
    /// The cell as a Sparkplug B edge node (`[sparkplug]`); `None`: off.
    pub sparkplug: Option<crate::config::sparkplug::SparkplugConfig>,
    /// How OEE is judged (`[oee]`); `None`: off.
    pub oee: Option<crate::config::oee::OeeConfig>,
    /// The alarm-performance rules (`[kpi]`): flood, chattering, stale.
    pub kpi: cellwatch_models::kpi::KpiRules,
    /// Alarms that follow from others (`[alarms.consequences]`).
    pub consequences: crate::config::Consequences,
    /// The cell's master alarm database (`alarms.database`): the file and
    /// its rows, each alarm's rationalised priority and guidance.
    pub database: Option<(PathBuf, cellwatch_models::madb::Database)>,
    /// The flight recorder around every alarm (`[recorder]`); `None`: off.
    pub recorder: Option<cellwatch_models::engine::RecorderConfig>,
    /// Things worth saying at start (security off, ...).
    pub warnings: Vec<String>,
    /// SHA-256 (hex) of the configuration's text: what `about` tells
    /// `cellwatch plant check`.
    pub source_sha256: String,
}

/// The parts of a configuration a reload compares
/// ([`CellConfig::fixed_parts`]): what the cell is, where it keeps and
/// says things, whom it talks to, what it reads. The tags and the source's
/// settings are taken by starting a source of their own; the others only
/// by a restart.
pub const FIXED_PARTS: [&str; 13] = [
    "cell.id",
    "journal.path",
    "[opcua]",
    "[legacy]",
    "[zenoh]",
    "[metrics]",
    "[alertmanager]",
    "[alarm_server]",
    "[sparkplug]",
    "[oee]",
    "[kpi]",
    "state.publish_interval",
    "the tags",
];

impl CellConfig {
    /// The tags marked `export`: index and name.
    pub fn exported_tags(&self) -> Vec<(usize, String)> {
        self.tags
            .iter()
            .enumerate()
            .filter(|(_, t)| t.export)
            .map(|(i, t)| (i, t.name.clone()))
            .collect()
    }

    /// What the Sparkplug edge node reads of the configuration.
    pub fn sparkplug_cell(&self) -> SparkplugCell<'_> {
        SparkplugCell {
            exported: self.exported_tags(),
            counts_parts: self.part_done.is_some() || !self.part_counters.is_empty(),
            journal: &self.journal.path,
        }
    }

    /// What the metrics sink reads of the configuration.
    pub fn metrics_setup(&self) -> MetricsSetup {
        MetricsSetup {
            tags: self.tags.len(),
            exported: self.exported_tags(),
            modes: self.state.modes.iter().map(|m| m.id.clone()).collect(),
            windows: self
                .timers
                .iter()
                .flat_map(|t| {
                    t.model
                        .transitions
                        .iter()
                        .map(|tr| (format!("{}-{:03}", t.id, tr.id), tr.window_ms))
                })
                .collect(),
            steps: self.step_flags(),
            kpi: self.kpi,
        }
    }

    /// What the operators' list reads of the configuration.
    pub fn operators_setup(&self) -> OperatorsSetup<'_> {
        OperatorsSetup {
            cell: &self.cell,
            prefix: &self.zenoh.prefix,
            operators_file: self.operators_file.as_deref(),
            plant: self.plant_operators.as_ref(),
        }
    }

    /// A fingerprint of each of [`FIXED_PARTS`], in that order: compared
    /// between the running configuration and one read again, it names what
    /// changed beyond the checks. (Hashes of the parts' debug forms: the tags
    /// of a 100,000-tag cell are not kept twice for it.)
    pub fn fixed_parts(&self) -> [u64; 13] {
        use std::hash::{Hash, Hasher};
        let hash = |part: &dyn fmt::Debug| {
            let mut h = std::collections::hash_map::DefaultHasher::new();
            format!("{part:?}").hash(&mut h);
            h.finish()
        };
        // The tags, and which of them are the charts' switches (the
        // source writes those only).
        let mut tags = std::collections::hash_map::DefaultHasher::new();
        for t in &self.tags {
            format!("{t:?}").hash(&mut tags);
        }
        for s in &self.sfc {
            (s.force_switch, s.stop_switch).hash(&mut tags);
        }
        [
            hash(&self.cell),
            hash(&self.journal.path),
            hash(&self.opcua),
            hash(&self.legacy),
            hash(&self.zenoh),
            hash(&self.metrics),
            hash(&self.alertmanager),
            hash(&self.alarm_server),
            hash(&self.sparkplug),
            hash(&self.oee),
            hash(&self.kpi),
            hash(&self.state_interval),
            tags.finish(),
        ]
    }

    /// The tags that are the flags of supervised steps: per tag index,
    /// (check, chart, step) of each step it flags. A step told by a
    /// step-number comparison (`D300 == 2`) has no flag tag and is not here.
    pub fn step_flags(&self) -> HashMap<usize, Vec<[String; 3]>> {
        let by_address: HashMap<&Signal, usize> = self
            .tags
            .iter()
            .enumerate()
            .map(|(i, t)| (&t.address, i))
            .collect();
        let mut out: HashMap<usize, Vec<[String; 3]>> = HashMap::new();
        for check in &self.sfc {
            for (r, step) in check.sfc.steps() {
                let Some(&tag) = by_address.get(&step.flag) else {
                    continue;
                };
                out.entry(tag).or_default().push([
                    check.id.clone(),
                    check.sfc.charts[r.chart].name.clone(),
                    step.name.clone(),
                ]);
            }
        }
        out
    }

    /// The engine's view of the tags.
    pub fn engine_tags(&self) -> Vec<Tag> {
        self.tags
            .iter()
            .map(|t| Tag {
                name: t.name.clone(),
                address: t.address.clone(),
            })
            .collect()
    }

    /// How the engine counts parts.
    pub fn part_counting(&self) -> PartCounting {
        match self.part_done {
            Some(t) => PartCounting::Edge(t),
            None if self.part_counters.is_empty() => PartCounting::None,
            None => PartCounting::Counters(
                self.part_counters
                    .iter()
                    .map(|&t| {
                        let max = self.tags[t].max.or(self.tags[t].value_type.max());
                        (t, Counter::new(max.unwrap_or(u64::MAX)))
                    })
                    .collect(),
            ),
        }
    }
}

impl CellConfig {
    /// How the engine counts rejects (`[oee]`'s reject signal or counter).
    pub fn reject_counting(&self) -> PartCounting {
        use crate::config::oee::RejectTag;
        match self.oee.as_ref().and_then(|o| o.rejects) {
            None => PartCounting::None,
            Some(RejectTag::Signal(t)) => PartCounting::Edge(t),
            Some(RejectTag::Counter(t)) => {
                let max = self.tags[t].max.or(self.tags[t].value_type.max());
                PartCounting::Counters(vec![(t, Counter::new(max.unwrap_or(u64::MAX)))])
            }
        }
    }
}

impl fmt::Debug for CellConfig {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("CellConfig")
            .field("cell", &self.cell)
            .field("tags", &self.tags.len())
            .finish_non_exhaustive()
    }
}
