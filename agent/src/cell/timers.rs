//! The transition timers' recent measurements (paper 001), kept for the
//! snapshot: each transition's window, and its last [`RECENT`] measured
//! durations with when they ended, early ones included.

use std::collections::{HashMap, VecDeque};

use cellwatch_models::engine::Observation;

use crate::clock::rfc3339;
use crate::config::CellConfig;
use crate::payload::{MeasurementPayload, TimerPayload};

/// How many measurements of each transition are kept.
pub(crate) const RECENT: usize = 10;

/// Every timed transition of a cell and its recent measurements.
#[derive(Default)]
pub struct Timers {
    transitions: Vec<Timed>,
    /// By alarm id (`line-007`), as the observations name them.
    by_id: HashMap<String, usize>,
}

struct Timed {
    alarm: String,
    label: String,
    window_ms: [u64; 2],
    delta_ms: u64,
    /// (when it ended, ms; how long, ms), oldest first.
    recent: VecDeque<(u64, u64)>,
}

impl Timers {
    /// The transitions of `config`'s timer checks.
    pub fn of(config: &CellConfig) -> Timers {
        let transitions: Vec<Timed> = config
            .timers
            .iter()
            .flat_map(|c| {
                c.model.transitions.iter().map(|t| Timed {
                    alarm: format!("{}-{:03}", c.id, t.id),
                    label: cellwatch_models::timer::checks::label(t),
                    window_ms: t.window_ms,
                    delta_ms: t.delta_ms,
                    recent: VecDeque::with_capacity(RECENT),
                })
            })
            .collect();
        let by_id = transitions
            .iter()
            .enumerate()
            .map(|(i, t)| (t.alarm.clone(), i))
            .collect();
        Timers { transitions, by_id }
    }

    /// Keeps what was measured at `at`.
    pub fn observe(&mut self, at: u64, observations: &[Observation]) {
        for o in observations {
            if let Some(&i) = self.by_id.get(&o.check) {
                let recent = &mut self.transitions[i].recent;
                if recent.len() == RECENT {
                    recent.pop_front();
                }
                recent.push_back((at, o.ms));
            }
        }
    }

    /// Each transition with its window and recent measurements.
    pub fn payload(&self) -> Vec<TimerPayload> {
        self.transitions
            .iter()
            .map(|t| TimerPayload {
                alarm: t.alarm.clone(),
                label: t.label.clone(),
                window_ms: t.window_ms,
                delta_ms: t.delta_ms,
                recent: t
                    .recent
                    .iter()
                    .map(|&(at, ms)| MeasurementPayload {
                        at: rfc3339(at),
                        ms,
                    })
                    .collect(),
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_last_ten_measurements_of_each_transition_are_kept() {
        let mut t = Timers {
            transitions: vec![Timed {
                alarm: "line-007".into(),
                label: "+B in A".into(),
                window_ms: [900, 1100],
                delta_ms: 1000,
                recent: VecDeque::new(),
            }],
            by_id: HashMap::from([("line-007".to_string(), 0)]),
        };
        for i in 0..15 {
            t.observe(
                i,
                &[
                    Observation {
                        check: "line-007".into(),
                        ms: 1000 + i,
                    },
                    Observation {
                        check: "other-001".into(),
                        ms: 5,
                    },
                ],
            );
        }
        let p = t.payload();
        assert_eq!(p.len(), 1);
        let ms: Vec<u64> = p[0].recent.iter().map(|m| m.ms).collect();
        assert_eq!(ms, (1005..1015).collect::<Vec<_>>());
    }
}
