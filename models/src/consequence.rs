//! Consequence alarms and first-out, derived from the PLC's logic and the
//! cell's checks.
//!
//! When one fault makes others follow, the later alarms are *consequences*
//! (ISA-18.2's "designed suppression", which other alarm systems make
//! engineers write by hand). cellwatch reads the relation off what it has
//! compiled: every alarm's check says which signals its fault *holds* at
//! their fault value (its effects) and which signals it *reads*; alarm B
//! may follow from alarm A when B's check reads a signal A's fault holds:
//!
//! - a switching check holds its fault coil, and every output the program
//!   derives from that coil or from such an output in turn (its forced
//!   outputs): on many machines the emergency-stop coil is a contact of
//!   the cycle-start logic, so an emergency stop also makes cycle start
//!   impossible (paper 000's ESE and CSD); a hydraulic fault drops a
//!   ready relay, which drops the ram's enable (a permissive chain);
//! - a discrete alarm holds its contact (an over-travel switch open is a
//!   culprit of the emergency stop that reads it);
//! - a stuck step holds the operands its leaving transitions wait for
//!   (paper 004): a transition timer waiting for one of them follows;
//! - a lost connection makes every tag unknown: everything raised under a
//!   `communication` alarm follows from it, and an alarm whose culprits
//!   are all tags of bad quality follows from `tag-quality` (the engine
//!   applies both; they are no edges here).
//!
//! The relation only says what *may* follow. At run time an alarm raised
//! while one of its causes is active is that cause's consequence when its
//! fault would not hold with what the cause's fault holds taken back to
//! its values without it ([`crate::engine::CheckSet::would_hold`]): a
//! switching check's function; a transition timer's event, which would
//! have come (its signal, or the request starting its timer, held by the
//! fault: [`crate::timer::awaits`]); a stuck step's leaving transition,
//! which could fire, or an output driven from its flag, which the fault
//! took back ([`crate::sfc::SfcChecks::driving`]). Where a check cannot
//! say, every one of its culprits must be explained by the cause: a signal
//! the cause's fault holds, or one of the cause's own culprits. An edge
//! written in the configuration explains whatever its effect names.

use std::collections::{BTreeMap, HashMap};
use std::fmt::Write;

use crate::alarm::Alarm;
use crate::explain::Culprit;
use crate::program::Program;
use crate::programs::Observability;
use crate::signal::Signal;
use crate::switching::SwitchingFunction;

/// What one alarm's check reads and what its fault holds.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AlarmFacts {
    /// The alarm id.
    pub id: String,
    /// Signals its fault holds at their fault value.
    pub effects: Vec<Signal>,
    /// Signals its check reads.
    pub reads: Vec<Signal>,
}

/// Why one alarm may follow from another.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub enum Link {
    /// The effect's check reads these signals, which the cause's fault
    /// holds: every one, in the order the effect reads them.
    Reads(Vec<Signal>),
    /// Written in the cell's configuration.
    Configured,
}

/// One edge of the relation: `effect` may follow from `cause`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Edge {
    /// The alarm that comes first.
    pub cause: String,
    /// The alarm that follows from it.
    pub effect: String,
    /// Why.
    pub link: Link,
}

/// Which alarms of a cell may follow from which.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Relation {
    /// Per effect: its causes, each with its link.
    causes: BTreeMap<String, Vec<(String, Link)>>,
    /// Per alarm: the signals its fault holds.
    effects: HashMap<String, Vec<Signal>>,
}

impl Relation {
    /// The relation among alarms with `facts`: B follows from A when B
    /// reads a signal A holds (A ≠ B). Costs one look per signal read.
    pub fn derive(facts: &[AlarmFacts]) -> Relation {
        let mut held: HashMap<&Signal, Vec<&str>> = HashMap::new();
        for f in facts {
            for s in &f.effects {
                let by = held.entry(s).or_default();
                if !by.contains(&f.id.as_str()) {
                    by.push(&f.id);
                }
            }
        }
        let mut causes: BTreeMap<String, Vec<(String, Link)>> = BTreeMap::new();
        for f in facts {
            for s in &f.reads {
                for &cause in held.get(s).into_iter().flatten() {
                    if cause == f.id {
                        continue;
                    }
                    let list = causes.entry(f.id.clone()).or_default();
                    match list.iter_mut().find(|(c, _)| c == cause) {
                        Some((_, Link::Reads(through))) => {
                            if !through.contains(s) {
                                through.push(s.clone());
                            }
                        }
                        Some((_, Link::Configured)) => {}
                        None => list.push((cause.to_string(), Link::Reads(vec![s.clone()]))),
                    }
                }
            }
        }
        for list in causes.values_mut() {
            list.sort();
        }
        Relation {
            causes,
            effects: facts
                .iter()
                .filter(|f| !f.effects.is_empty())
                .map(|f| (f.id.clone(), f.effects.clone()))
                .collect(),
        }
    }

    /// Adds an edge the logic does not show (`effect` follows from
    /// `cause` whatever its culprits); an edge already there becomes a
    /// configured one.
    pub fn add(&mut self, cause: &str, effect: &str) {
        let list = self.causes.entry(effect.to_string()).or_default();
        list.retain(|(c, _)| c != cause);
        list.push((cause.to_string(), Link::Configured));
        list.sort();
    }

    /// Removes an edge; whether there was one.
    pub fn remove(&mut self, cause: &str, effect: &str) -> bool {
        let Some(list) = self.causes.get_mut(effect) else {
            return false;
        };
        let before = list.len();
        list.retain(|(c, _)| c != cause);
        let removed = list.len() < before;
        if list.is_empty() {
            self.causes.remove(effect);
        }
        removed
    }

    /// Whether there is no edge.
    pub fn is_empty(&self) -> bool {
        self.causes.is_empty()
    }

    /// Whether `effect` may follow from `cause`.
    pub fn has(&self, cause: &str, effect: &str) -> bool {
        self.causes_of(effect).iter().any(|(c, _)| c == cause)
    }

    /// The alarms `effect` may follow from, with why.
    pub fn causes_of(&self, effect: &str) -> &[(String, Link)] {
        self.causes.get(effect).map_or(&[], Vec::as_slice)
    }

    /// The signals alarm `id`'s fault holds.
    pub fn effects_of(&self, id: &str) -> &[Signal] {
        self.effects.get(id).map_or(&[], Vec::as_slice)
    }

    /// Every edge, by effect then cause.
    pub fn edges(&self) -> impl Iterator<Item = Edge> + '_ {
        self.causes.iter().flat_map(|(effect, list)| {
            list.iter().map(move |(cause, link)| Edge {
                cause: cause.clone(),
                effect: effect.clone(),
                link: link.clone(),
            })
        })
    }

    /// The cause of alarm `effect`, raised now with `culprits`, among the
    /// active alarms `active` gives: the earliest raised active cause
    /// without which the effect's fault would not hold. `still(cause)`
    /// says whether the effect's fault would still hold with what the
    /// cause's fault holds taken back to its normal values (the
    /// counterfactual, [`crate::engine::CheckSet::would_hold`]); where it
    /// cannot say (`None`), the cause must explain every culprit: each a
    /// signal its fault holds or one of its own culprits.
    pub fn cause_of<'a>(
        &self,
        effect: &str,
        culprits: &[Culprit],
        active: impl Fn(&str) -> Option<&'a Alarm>,
        still: impl Fn(&str) -> Option<bool>,
    ) -> Option<&'a Alarm> {
        self.causes_of(effect)
            .iter()
            .filter_map(|(cause, link)| {
                let a = active(cause).filter(|a| a.active)?;
                let explained = match link {
                    Link::Configured => true,
                    Link::Reads(_) => match still(cause) {
                        Some(still) => !still,
                        None => explains(self.effects_of(cause), a, culprits),
                    },
                };
                explained.then_some(a)
            })
            .min_by_key(|a| (a.raised_at, a.id.as_str()))
    }

    /// The relation for people: one edge a line, by cause, then the rules
    /// the engine applies to its own alarms.
    pub fn render(&self) -> String {
        let mut out = String::new();
        let mut edges: Vec<Edge> = self.edges().collect();
        edges.sort_by(|a, b| (&a.cause, &a.effect).cmp(&(&b.cause, &b.effect)));
        let width = edges
            .iter()
            .map(|e| e.cause.len() + e.effect.len() + 4)
            .max()
            .unwrap_or(0);
        if edges.is_empty() {
            out.push_str("no alarm of the cell's checks follows from another\n");
        }
        for e in &edges {
            let pair = format!("{} -> {}", e.cause, e.effect);
            let why = match &e.link {
                Link::Reads(through) => {
                    let signals: Vec<String> = through.iter().map(ToString::to_string).collect();
                    let them = if through.len() == 1 {
                        "which"
                    } else {
                        "each of which"
                    };
                    format!(
                        "{} reads {}, {them} {}'s fault holds",
                        e.effect,
                        signals.join(", "),
                        e.cause
                    )
                }
                Link::Configured => "written in the configuration".to_string(),
            };
            let _ = writeln!(out, "{pair:<width$}   {why}");
        }
        out.push_str("communication -> every alarm raised while the link is down\n");
        out.push_str("tag-quality -> an alarm whose culprits are all tags of bad quality\n");
        out
    }
}

/// Whether every culprit of an alarm is a signal `cause`'s fault holds or
/// one of `cause`'s own culprits. No culprit: nothing to explain by.
fn explains(held: &[Signal], cause: &Alarm, culprits: &[Culprit]) -> bool {
    !culprits.is_empty()
        && culprits.iter().all(|c| {
            held.contains(&c.address) || cause.culprits.iter().any(|k| k.address == c.address)
        })
}

/// The outputs `program` derives from `coil` (its forced outputs), each
/// with its switching function: the coils `is_tag` accepts whose switching
/// function over `observable` reads `coil` or an output forced already (a
/// permissive chain: a ready relay the fault drops, a valve the relay
/// enables), each after the forced outputs it reads, so that they can be
/// re-derived in order. A coil that is not derivable forces nothing.
pub fn forced_outputs(
    program: &Program,
    coil: &Signal,
    observable: &Observability,
    is_tag: impl Fn(&Signal) -> bool,
) -> Vec<SwitchingFunction> {
    let mut candidates: Vec<SwitchingFunction> = program
        .coils()
        .iter()
        .filter(|c| c.signal != *coil && is_tag(&c.signal))
        .filter_map(|c| SwitchingFunction::expand(program, &c.signal, observable).ok())
        .collect();
    // Forced: reads the coil or a forced output; to a fixed point.
    let mut forced: Vec<SwitchingFunction> = Vec::new();
    loop {
        let reads_forced = |sf: &SwitchingFunction| {
            sf.leaves()
                .iter()
                .any(|l| l == coil || forced.iter().any(|f| f.coil == *l))
        };
        let (now, rest): (Vec<_>, Vec<_>) = candidates.into_iter().partition(reads_forced);
        candidates = rest;
        if now.is_empty() {
            break;
        }
        forced.extend(now);
    }
    // Each after the forced outputs it reads (as written where they read
    // each other round).
    let mut ordered: Vec<SwitchingFunction> = Vec::with_capacity(forced.len());
    while !forced.is_empty() {
        let ready = forced
            .iter()
            .position(|sf| {
                let leaves = sf.leaves();
                !forced
                    .iter()
                    .any(|f| f.coil != sf.coil && leaves.contains(&f.coil))
            })
            .unwrap_or(0);
        ordered.push(forced.remove(ready));
    }
    ordered
}

/// `forced` (as [`forced_outputs`] gives them for `coil`) without the
/// fault coils of other alarms (`is_fault`) and what the chain reaches
/// only through one: what follows from another alarm's fault is that
/// alarm's, and the relation chains the two alarms (the hydraulic fault
/// holds the clamp valve; the clamp fault's coil, which reads the valve,
/// and the cycle-start fault's, which reads that coil, are the clamp's and
/// the cycle start's).
pub(crate) fn short_of_faults(
    forced: Vec<SwitchingFunction>,
    coil: &Signal,
    is_fault: impl Fn(&Signal) -> bool,
) -> Vec<SwitchingFunction> {
    let mut kept: Vec<SwitchingFunction> = Vec::with_capacity(forced.len());
    for f in forced {
        let leaves = f.leaves();
        if !is_fault(&f.coil)
            && (leaves.contains(coil) || kept.iter().any(|k| leaves.contains(&k.coil)))
        {
            kept.push(f);
        }
    }
    kept
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::alarm::AlarmKind;

    fn facts(id: &str, effects: &[&str], reads: &[&str]) -> AlarmFacts {
        AlarmFacts {
            id: id.into(),
            effects: effects.iter().map(|s| Signal::new(s)).collect(),
            reads: reads.iter().map(|s| Signal::new(s)).collect(),
        }
    }

    fn culprit(address: &str) -> Culprit {
        Culprit {
            address: Signal::new(address),
            value: true,
            expected: false,
            comment: None,
            trigger: true,
            compared: None,
        }
    }

    fn coils(forced: &[SwitchingFunction]) -> Vec<&str> {
        forced.iter().map(|f| f.coil.name()).collect()
    }

    #[test]
    fn forced_outputs_follow_a_permissive_chain_each_after_what_it_reads() {
        // The fault drops the ready relay Y2.01, which drops the ram
        // enable Y2.02: both forced, the relay first even where the enable
        // is written above it; Y2.03 reads neither, R1 is no tag.
        for enable_first in [false, true] {
            let relay = "RD X1.00\nAND.NOT G10.00\nWRT Y2.01\n";
            let enable = "RD Y2.01\nAND X1.07\nWRT Y2.02\n";
            let (a, b) = if enable_first {
                (enable, relay)
            } else {
                (relay, enable)
            };
            let rest = "RD X1.01\nWRT Y2.03\nRD Y2.02\nWRT R1.00\nRD.NOT X1.00\nWRT G10.00\n";
            let p = Program::compile("chain.il", &format!("{a}{b}{rest}"), None).unwrap();
            let forced = forced_outputs(
                &p,
                &Signal::new("G10.00"),
                &Observability::default_for(p.dialect()),
                |s| s.name() != "R1.00",
            );
            assert_eq!(
                coils(&forced),
                ["Y2.01", "Y2.02"],
                "enable first: {enable_first}"
            );
        }
    }

    #[test]
    fn a_chain_of_forced_outputs_stops_at_another_alarms_fault_coil() {
        // The valve Y2.00 is forced; the clamp fault G10.01 reads it, the
        // cycle-start fault G10.02 reads that, the lamp Y2.04 reads G10.02:
        // all three another alarm's to hold. The ready relay Y2.01 and the
        // enable Y2.02 it drives stay.
        let p = Program::compile(
            "press.il",
            "RD X1.00\nAND.NOT X1.01\nWRT G10.00\nRD X1.03\nAND.NOT G10.00\nWRT Y2.00\n\
             RD.NOT Y2.00\nWRT G10.01\nRD X1.04\nAND G10.01\nWRT G10.02\nRD G10.02\nWRT Y2.04\n\
             RD X1.00\nAND.NOT G10.00\nWRT Y2.01\nRD Y2.01\nAND X1.07\nWRT Y2.02\n",
            None,
        )
        .unwrap();
        let coil = Signal::new("G10.00");
        let forced = forced_outputs(&p, &coil, &Observability::default_for(p.dialect()), |_| {
            true
        });
        assert_eq!(
            coils(&forced),
            ["Y2.00", "Y2.01", "G10.01", "Y2.02", "G10.02", "Y2.04"]
        );
        let faults = [Signal::new("G10.01"), Signal::new("G10.02")];
        let kept = short_of_faults(forced, &coil, |s| faults.contains(s));
        assert_eq!(coils(&kept), ["Y2.00", "Y2.01", "Y2.02"]);
    }

    #[test]
    fn an_edge_names_every_held_signal_it_runs_through() {
        // The clamp reads the pump contactor and the valve, both held by
        // the hydraulic fault; the coolant reads the contactor only.
        let r = Relation::derive(&[
            facts("hydraulic", &["K1", "Y2.00"], &["X1.00"]),
            facts("clamp", &[], &["Y2.00", "X1.02", "K1"]),
            facts("coolant", &[], &["K1"]),
        ]);
        assert_eq!(
            r.causes_of("clamp"),
            [(
                "hydraulic".to_string(),
                Link::Reads(vec![Signal::new("Y2.00"), Signal::new("K1")])
            )]
        );
        assert_eq!(
            r.render().lines().take(2).collect::<Vec<_>>(),
            [
                "hydraulic -> clamp     clamp reads Y2.00, K1, each of which hydraulic's fault holds",
                "hydraulic -> coolant   coolant reads K1, which hydraulic's fault holds",
            ]
        );
    }

    #[test]
    fn an_alarm_follows_from_one_whose_held_signal_its_check_reads() {
        let r = Relation::derive(&[
            facts("ese", &["G8.02"], &["X0.06", "G0.00"]),
            facts("csd", &["G9.00"], &["X200.01", "G8.02", "G0.00"]),
            facts("z2", &["X0.0A"], &["X0.0A"]),
            facts("ese2", &["G8.03"], &["X0.0A"]),
        ]);
        let edges: Vec<(String, String)> = r.edges().map(|e| (e.cause, e.effect)).collect();
        assert_eq!(
            edges,
            [("ese".into(), "csd".into()), ("z2".into(), "ese2".into())]
        );
        // A signal both read (G0.00) relates nothing; nor does an alarm
        // reading what it holds itself.
        assert!(!r.has("csd", "ese"));
        assert!(!r.has("z2", "z2"));
    }

    #[test]
    fn without_a_counterfactual_a_consequence_needs_a_cause_that_explains_every_culprit() {
        let r = Relation::derive(&[
            facts("ese", &["G8.02"], &["X0.06"]),
            facts("csd", &["G9.00"], &["X200.01", "G8.02", "X201.06"]),
        ]);
        let mut ese = Alarm::active_since("ese", AlarmKind::Switching, 1_000);
        ese.culprits = vec![culprit("X0.06")];
        let active = |id: &str| (id == "ese").then_some(&ese);
        let unknown = |_: &str| None;
        assert_eq!(
            r.cause_of("csd", &[culprit("G8.02")], active, unknown)
                .map(|a| a.id.as_str()),
            Some("ese")
        );
        // The cause's own culprit explains too.
        assert!(r
            .cause_of("csd", &[culprit("X0.06")], active, unknown)
            .is_some());
        // A culprit of its own: not a consequence.
        assert!(r
            .cause_of(
                "csd",
                &[culprit("G8.02"), culprit("X201.06")],
                active,
                unknown
            )
            .is_none());
        // Nothing to explain by.
        assert!(r.cause_of("csd", &[], active, unknown).is_none());
        // The cause cleared: not a consequence.
        let mut cleared = ese.clone();
        cleared.active = false;
        assert!(r
            .cause_of(
                "csd",
                &[culprit("G8.02")],
                |id: &str| (id == "ese").then_some(&cleared),
                unknown
            )
            .is_none());
    }

    #[test]
    fn the_counterfactual_decides_whatever_the_culprits() {
        let r = Relation::derive(&[
            facts("ese", &["G8.02"], &["X0.06"]),
            facts("csd", &["G9.00"], &["X200.01", "G8.02", "X201.06"]),
        ]);
        let ese = Alarm::active_since("ese", AlarmKind::Switching, 1_000);
        let active = |id: &str| (id == "ese").then_some(&ese);
        // A request among the culprits: still a consequence when the fault
        // would not hold without the cause.
        let culprits = [culprit("G8.02"), culprit("X201.06")];
        assert!(r
            .cause_of("csd", &culprits, active, |_: &str| Some(false))
            .is_some());
        // Every culprit held by the cause, but the fault would hold anyway.
        assert!(r
            .cause_of("csd", &[culprit("G8.02")], active, |_: &str| Some(true))
            .is_none());
    }

    #[test]
    fn a_configured_edge_explains_whatever_its_effect_names_and_edges_can_be_removed() {
        let mut r = Relation::derive(&[
            facts("ese", &["G8.02"], &["X0.06"]),
            facts("csd", &["G9.00"], &["G8.02"]),
        ]);
        let ese = Alarm::active_since("ese", AlarmKind::Switching, 1_000);
        r.add("ese", "door");
        assert!(r
            .cause_of(
                "door",
                &[],
                |id: &str| (id == "ese").then_some(&ese),
                |_: &str| Some(true)
            )
            .is_some());
        assert!(r.remove("ese", "csd"));
        assert!(!r.remove("ese", "csd"));
        assert!(!r.has("ese", "csd"));
        assert_eq!(
            r.render(),
            "ese -> door   written in the configuration\n\
             communication -> every alarm raised while the link is down\n\
             tag-quality -> an alarm whose culprits are all tags of bad quality\n"
        );
    }
}
