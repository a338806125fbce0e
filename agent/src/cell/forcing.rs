//! What forcing a cell's charts needs between commands: each chart's
//! force and stop switches, and the forces under way (paper 004). The
//! handling itself is in `force.rs`.

use std::time::Duration;

use cellwatch_models::comments::CommentDb;
use cellwatch_models::sfc::Sfc;

use crate::config::CellConfig;
use crate::step::CommandOutcome;

/// The charts of one `[[checks.sfc]]` and their switches.
pub(crate) struct ForceSet {
    /// Alarm id prefix of its stuck steps.
    pub id: String,
    pub sfc: Sfc,
    pub comments: CommentDb,
    pub force_switch: Option<usize>,
    pub stop_switch: Option<usize>,
    pub forcible: Vec<(String, String)>,
    pub pulse: Duration,
    pub timeout: Duration,
}

/// What the loop needs to force and stop.
#[derive(Default)]
pub struct Forcing {
    pub(crate) sets: Vec<ForceSet>,
    /// The force under way or overdue, at most one per cell.
    pub(crate) pending: Option<Pending>,
}

impl Forcing {
    /// The switches and forcible transitions of `config`'s charts.
    pub fn of(config: &CellConfig) -> Forcing {
        let comments: CommentDb = config
            .tags
            .iter()
            .filter_map(|t| Some((t.address.clone(), t.comment.clone()?)))
            .collect();
        Forcing {
            sets: config
                .sfc
                .iter()
                .map(|s| ForceSet {
                    id: s.id.clone(),
                    sfc: s.sfc.clone(),
                    comments: comments.clone(),
                    force_switch: s.force_switch,
                    stop_switch: s.stop_switch,
                    forcible: s.forcible.clone(),
                    pulse: s.force_pulse,
                    timeout: s.force_timeout,
                })
                .collect(),
            pending: None,
        }
    }

    /// Until when the force under way waits for its target steps, while an
    /// operator waits for its outcome.
    pub(crate) fn deadline(&self) -> Option<u64> {
        self.pending
            .as_ref()
            .filter(|p| p.reply.is_some())
            .map(|p| p.deadline)
    }

    /// The set supervising chart `chart`.
    pub(crate) fn set_of(&self, chart: &str) -> Option<&ForceSet> {
        self.sets.iter().find(|s| s.sfc.chart(chart).is_some())
    }
}

/// A forced transition whose switch was pulsed, waiting for its target
/// steps.
pub(crate) struct Pending {
    pub operator: String,
    pub nonce: String,
    /// The command's digest, for its later rows.
    pub digest: Option<String>,
    /// `F1.t3`.
    pub transition: String,
    /// The steps it leads to: name and flag tag.
    pub targets: Vec<(String, usize)>,
    /// The flags of the steps it leaves.
    pub sources: Vec<usize>,
    /// When the switch was pulsed, ms.
    pub since: u64,
    /// Until when the targets may take, ms.
    pub deadline: u64,
    /// The operator waiting for the outcome (`None` while the switch is
    /// written, and once answered).
    pub reply: Option<tokio::sync::oneshot::Sender<CommandOutcome>>,
    /// The switch is being pulsed.
    pub writing: bool,
    /// Which targets have been seen active since the pulse began (a step
    /// may be left again before the pulse ends).
    pub seen: Vec<bool>,
    /// The overdue alarm is raised.
    pub overdue: bool,
}

impl Pending {
    /// The id of its overdue alarm.
    pub(crate) fn alarm(&self) -> String {
        format!("force-{}", self.transition.replace('.', "-"))
    }
}

impl Forcing {
    /// Marks the forced transition's targets that `readings` show active,
    /// even if a later reading of the same batch shows them left.
    pub(crate) fn seen_in(&mut self, readings: &[cellwatch_models::engine::TagReading]) {
        let Some(p) = self.pending.as_mut() else {
            return;
        };
        for r in readings {
            if r.reading != cellwatch_models::engine::Reading::Good(true) {
                continue;
            }
            for (seen, &(_, t)) in p.seen.iter_mut().zip(&p.targets) {
                *seen |= t == r.tag;
            }
        }
    }
}
