//! The engine's side of the flight recorder (`recorder.rs`): built over the
//! tags the checks read, fed each change at the time its alarms are stamped
//! with, started when an alarm is raised, ended when the engine stops, and
//! emptied into each step. The ring and the recordings themselves are
//! `recorder.rs`'s.

use super::recorder::{Read, Recorder};
use super::{CellEngine, EngineStep, RecorderConfig, RecorderFill, Tag};
use crate::alarm::Transition;

/// The engine's side: the recorder is built over the tags the checks read,
/// fed by `set_value`/`set_other`, started by `announce` and emptied into
/// each [`EngineStep`].
impl CellEngine {
    /// Keeps, for every alarm raised whose check reads signals, the changes
    /// of those signals around its raise, by `config` (the recorder is off
    /// until this is called); each is handed out in
    /// [`Step::recordings`] once its window is over.
    #[must_use]
    pub fn recording(mut self, config: RecorderConfig) -> Self {
        let watched = (0..self.tags.len())
            .map(|t| !self.readers.of(t).is_empty() || !self.number_readers.of(t).is_empty())
            .collect();
        self.recorder = Some(Box::new(Recorder::new(config, watched)));
        self
    }

    /// Ends every flight recording under way at `now` — the agent stops,
    /// or a reload replaces this engine — so that none is lost: each holds
    /// what came until then (`truncated.end` [`Cut::Stopped`](super::Cut::Stopped)).
    pub fn end_recordings(&mut self, now: u64) -> EngineStep {
        let mut step = EngineStep::default();
        if let Some(recorder) = &mut self.recorder {
            recorder.finish_all(now);
            recorder.take_done(&mut step.recordings);
        }
        step
    }

    /// What the flight recorder's ring holds now, if it is on.
    pub fn recorder_fill(&self) -> Option<RecorderFill> {
        self.recorder.as_ref().map(|r| r.fill())
    }

    /// Starts the flight recording of alarm `id` if `transition` raised
    /// it: the signals its check reads, around `now`.
    pub(super) fn recording_starts(&mut self, id: &str, transition: Transition, now: u64) {
        if transition != Transition::Raised || self.recorder.is_none() {
            return;
        }
        let mut signals = Vec::new();
        for set in &self.sets {
            set.reads(id, &mut signals);
        }
        let mut reads: Vec<Read> = Vec::new();
        for s in signals {
            let Some(t) = self.tag_index(&s) else {
                continue;
            };
            if reads.iter().any(|r| r.tag == t) {
                continue;
            }
            let Tag { name, address } = &self.tags[t];
            let address = address.to_string();
            reads.push(Read {
                tag: t,
                name: (*name != address).then(|| name.clone()),
                address,
                value: self.value(t),
            });
        }
        if let Some(r) = &mut self.recorder {
            r.start(id, now, reads);
        }
    }

    /// The time the flight recorder keeps a change sampled at `at` with:
    /// the time an alarm judged on it is stamped with.
    pub(super) fn ring_time(&self, at: u64) -> u64 {
        if self.clock == 0 {
            at
        } else {
            self.stamp(at, self.clock)
        }
    }
}
