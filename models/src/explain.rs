//! The explanation at fault time: which step, which contacts.
//!
//! Given the values at the instant a fault coil reached its fault value (and
//! optionally the values just before), [`explain`] evaluates every step
//! block and walks from the coil down to the contacts responsible:
//! - for a node whose value *forces* its own value (a true OR, a false AND),
//!   only the children with that value are responsible;
//! - for a node whose value needs all its children (a true AND, a false OR),
//!   every child is responsible.
//!
//! For a check that faults when the coil is ON this gives the true children
//! of each true OR and all children of each true AND; for one that faults
//! when OFF, the mirror. Negated blocks flip the sense on the way down. The
//! *fault step* is the lowest-numbered step on those paths; the *culprits*
//! are the contacts reached, each with the value that would clear it, and
//! those that changed since the values before are the trigger, listed first.

use std::collections::HashSet;
use std::fmt;
use std::str::FromStr;

use crate::comments::CommentDb;
use crate::il::Op;
use crate::logic::Term;
use crate::signal::Signal;
use crate::switching::SwitchingFunction;

/// Which coil value is the fault.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Polarity {
    /// The fault is the coil being ON (an alarm coil such as ESE).
    On,
    /// The fault is the coil being OFF (an enable coil such as cycle start).
    Off,
}

impl Polarity {
    /// The coil value that is the fault.
    pub fn fault_value(self) -> bool {
        self == Polarity::On
    }
}

impl fmt::Display for Polarity {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Polarity::On => "on",
            Polarity::Off => "off",
        })
    }
}

impl FromStr for Polarity {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "on" => Ok(Polarity::On),
            "off" => Ok(Polarity::Off),
            other => Err(format!("unknown polarity '{other}': use on or off")),
        }
    }
}

/// A contact responsible for the fault.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct Culprit {
    /// Its address.
    pub address: Signal,
    /// Its value at the fault.
    pub value: bool,
    /// The value that would take the fault away.
    pub expected: bool,
    /// Its comment in the I/O database.
    pub comment: Option<String>,
    /// It changed between the values before and at the fault.
    pub trigger: bool,
}

impl fmt::Display for Culprit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} = {} (expected {})",
            self.address,
            u8::from(self.value),
            u8::from(self.expected)
        )?;
        if let Some(c) = &self.comment {
            write!(f, ": {c}")?;
        }
        Ok(())
    }
}

/// What the check found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Explanation {
    /// The coil.
    pub coil: Signal,
    /// Its value.
    pub value: bool,
    /// Which value is the fault.
    pub polarity: Polarity,
    /// Every step's value, step 1 first.
    pub steps: Vec<bool>,
    /// The lowest step on the fault's paths (1-based); `None` when the coil
    /// is not at its fault value or is a single contact.
    pub fault_step: Option<usize>,
    /// Contacts responsible, triggers first; empty when there is no fault.
    pub culprits: Vec<Culprit>,
}

impl Explanation {
    /// Whether the coil is at its fault value.
    pub fn is_fault(&self) -> bool {
        self.value == self.polarity.fault_value()
    }
}

/// Signals the snapshot has no value for.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("no value for {} (read by {coil}); give every contact of the switching function", missing.iter().map(Signal::name).collect::<Vec<_>>().join(", "))]
pub struct MissingValues {
    /// The coil explained.
    pub coil: Signal,
    /// The signals with no value.
    pub missing: Vec<Signal>,
}

/// Looks up a signal's value in a snapshot; `None` if it has none.
pub type Lookup<'a> = &'a dyn Fn(&Signal) -> Option<bool>;

/// Explains `sf` at the values `now`, with the values `before` (if known)
/// marking triggers.
///
/// # Errors
/// [`MissingValues`] when `now` lacks a signal the SF reads.
pub fn explain(
    sf: &SwitchingFunction,
    now: impl Fn(&Signal) -> Option<bool>,
    before: Option<Lookup<'_>>,
    polarity: Polarity,
    comments: &CommentDb,
) -> Result<Explanation, MissingValues> {
    let missing: Vec<Signal> = sf
        .leaves()
        .into_iter()
        .filter(|s| now(s).is_none())
        .collect();
    if !missing.is_empty() {
        return Err(MissingValues {
            coil: sf.coil.clone(),
            missing,
        });
    }
    let (value, steps, fault_step, culprits) = walk(sf, &now, before, polarity, comments);
    let known = |v: Option<bool>| v.unwrap_or(false);
    Ok(Explanation {
        coil: sf.coil.clone(),
        value: known(value),
        polarity,
        steps: steps.into_iter().map(known).collect(),
        fault_step,
        culprits,
    })
}

/// A verdict reached with some contacts unknown ([`explain_partial`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PartialExplanation {
    /// Whether the coil is at its fault value, whatever the unknown
    /// contacts hold; `None` when they could change it.
    pub fault: Option<bool>,
    /// The lowest step on the fault's paths, for a certain fault.
    pub fault_step: Option<usize>,
    /// Contacts responsible for a certain fault, all of known value,
    /// triggers first.
    pub culprits: Vec<Culprit>,
    /// The contacts whose value is unknown.
    pub unknown: Vec<Signal>,
}

/// Explains `sf` with some values unknown, in three-valued (Kleene) logic:
/// a fault is certain when every completion of the unknown contacts gives
/// it, and its culprits are then contacts of known value only (the walk
/// follows only the terms that decide a block).
pub fn explain_partial(
    sf: &SwitchingFunction,
    now: impl Fn(&Signal) -> Option<bool>,
    before: Option<Lookup<'_>>,
    polarity: Polarity,
    comments: &CommentDb,
) -> PartialExplanation {
    let unknown = sf
        .leaves()
        .into_iter()
        .filter(|s| now(s).is_none())
        .collect();
    let (value, _, fault_step, culprits) = walk(sf, &now, before, polarity, comments);
    PartialExplanation {
        fault: value.map(|v| v == polarity.fault_value()),
        fault_step,
        culprits,
        unknown,
    }
}

type Walked = (Option<bool>, Vec<Option<bool>>, Option<usize>, Vec<Culprit>);

/// Evaluates in Kleene logic and, for a certain fault, walks to the
/// culprits.
fn walk(
    sf: &SwitchingFunction,
    now: &impl Fn(&Signal) -> Option<bool>,
    before: Option<Lookup<'_>>,
    polarity: Polarity,
    comments: &CommentDb,
) -> Walked {
    let (value, steps) = sf.evaluate3(now);
    if value != Some(polarity.fault_value()) {
        return (value, steps, None, Vec::new());
    }
    let mut walk = Walk {
        sf,
        steps: &steps,
        value_of: now,
        seen_blocks: HashSet::new(),
        seen: HashSet::new(),
        found: Vec::new(),
    };
    walk.term(&sf.root);
    let fault_step = walk.seen_blocks.iter().min().map(|b| b + 1);
    let found = walk.found;
    let mut culprits: Vec<Culprit> = found
        .into_iter()
        .map(|(address, value)| {
            let trigger = before.is_some_and(|b| b(&address).is_some_and(|old| old != value));
            Culprit {
                comment: comments.get(&address).map(str::to_string),
                expected: !value,
                value,
                trigger,
                address,
            }
        })
        .collect();
    // Stable: triggers first, otherwise in order of the walk.
    culprits.sort_by_key(|c| !c.trigger);
    (value, steps, fault_step, culprits)
}

struct Walk<'a, F: Fn(&Signal) -> Option<bool>> {
    sf: &'a SwitchingFunction,
    steps: &'a [Option<bool>],
    value_of: &'a F,
    seen_blocks: HashSet<usize>,
    seen: HashSet<Signal>,
    found: Vec<(Signal, bool)>,
}

impl<F: Fn(&Signal) -> Option<bool>> Walk<'_, F> {
    /// Visits a term that carries the fault; its value is known.
    fn term(&mut self, term: &Term) {
        match term {
            Term::Const(_) => {}
            Term::Signal { signal, .. } => {
                if let Some(v) = (self.value_of)(signal) {
                    if self.seen.insert(signal.clone()) {
                        self.found.push((signal.clone(), v));
                    }
                }
            }
            Term::Block { id, .. } => {
                if !self.seen_blocks.insert(*id) {
                    return;
                }
                let block = &self.sf.steps[*id];
                let Some(v) = self.steps[*id] else {
                    return;
                };
                let forcing = matches!((block.op, v), (Op::Or, true) | (Op::And, false));
                // A forcing block is decided by its terms of that value
                // (all known); a non-forcing one by all its terms, which
                // are then all known.
                for t in &block.terms {
                    if !forcing || t.value3(self.value_of, self.steps) == Some(v) {
                        self.term(t);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::program::Program;
    use crate::signal::Observability;
    use crate::values::Values;

    fn setup(src: &str, coil: &str) -> SwitchingFunction {
        let p = Program::compile("t.il", src, None).unwrap();
        SwitchingFunction::expand(
            &p,
            &Signal::new(coil),
            &Observability::default_for(p.dialect()),
        )
        .unwrap()
    }

    fn values(s: &str) -> Values {
        Values::parse_inline("v", s, crate::signal::pmc_address).unwrap()
    }

    #[test]
    fn true_or_names_its_true_children_and_trigger_first() {
        let sf = setup("RD X1\nOR X2\nOR X3\nWRT Y1", "Y1");
        let now = values("X1=1,X2=0,X3=1");
        let before = values("X1=1,X2=0,X3=0");
        let b = |s: &Signal| before.get(s);
        let e = explain(
            &sf,
            |s| now.get(s),
            Some(&b),
            Polarity::On,
            &CommentDb::default(),
        )
        .unwrap();
        assert!(e.is_fault());
        assert_eq!(e.fault_step, Some(1));
        let names: Vec<(&str, bool)> = e
            .culprits
            .iter()
            .map(|c| (c.address.name(), c.trigger))
            .collect();
        assert_eq!(names, [("X3", true), ("X1", false)]);
    }

    #[test]
    fn off_polarity_mirrors() {
        // Enable = X1 * X2 * -X3: faulted when OFF; X2 = 0 and X3 = 1 are to blame.
        let sf = setup("RD X1\nAND X2\nANDN X3\nWRT Y1", "Y1");
        let now = values("X1=1,X2=0,X3=1");
        let e = explain(
            &sf,
            |s| now.get(s),
            None,
            Polarity::Off,
            &CommentDb::default(),
        )
        .unwrap();
        let c: Vec<String> = e.culprits.iter().map(ToString::to_string).collect();
        assert_eq!(c, ["X2 = 0 (expected 1)", "X3 = 1 (expected 0)"]);
        let e = explain(
            &sf,
            |s| now.get(s),
            None,
            Polarity::On,
            &CommentDb::default(),
        )
        .unwrap();
        assert!(!e.is_fault());
        assert!(e.culprits.is_empty());
    }

    #[test]
    fn negated_block_flips_the_sense() {
        // Y1 = -(X1 * X2) + X3, built with IEC NOT.
        let p = Program::compile(
            "t.il",
            "LD %IX0.1\nAND %IX0.2\nNOT\nOR %IX0.3\nST %QX0.0",
            None,
        )
        .unwrap();
        let sf = SwitchingFunction::expand(
            &p,
            &Signal::new("%QX0.0"),
            &Observability::default_for(p.dialect()),
        )
        .unwrap();
        let now = values_iec("%IX0.1=1,%IX0.2=0,%IX0.3=0");
        let e = explain(
            &sf,
            |s| now.get(s),
            None,
            Polarity::On,
            &CommentDb::default(),
        )
        .unwrap();
        let c: Vec<&str> = e.culprits.iter().map(|c| c.address.name()).collect();
        assert_eq!(c, ["%IX0.2"]);
    }

    fn values_iec(s: &str) -> Values {
        Values::parse_inline("v", s, crate::signal::iec_direct_address).unwrap()
    }

    #[test]
    fn missing_values_are_named() {
        let sf = setup("RD X1\nOR X2\nWRT Y1", "Y1");
        let now = values("X1=1");
        let e = explain(
            &sf,
            |s| now.get(s),
            None,
            Polarity::On,
            &CommentDb::default(),
        )
        .unwrap_err();
        assert_eq!(
            e.to_string(),
            "no value for X2 (read by Y1); give every contact of the switching function"
        );
    }
}
