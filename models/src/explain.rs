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
//!
//! A culprit that is a comparison (`rSpindleSpeed >= 1800`) is shown with
//! the number compared once [`read_comparisons`] is given the numbers:
//! `rSpindleSpeed = 1650.0 (needs >= 1800)`, with the variable's comment;
//! a contact as `X2 = 0 (expected 1)`.

use std::collections::HashSet;
use std::fmt;
use std::str::FromStr;

use crate::comments::CommentDb;
use crate::logic::Term;
use crate::programs::Op;
use crate::signal::Signal;
use crate::switching::SwitchingFunction;
use crate::value::{CmpOp, CmpOperand, Comparison, Num};

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

/// A polarity's name that is neither `on` nor `off`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown polarity '{text}': use on or off")]
pub struct UnknownPolarity {
    /// The name as read, lower case.
    pub text: String,
}

impl FromStr for Polarity {
    type Err = UnknownPolarity;

    fn from_str(s: &str) -> Result<Self, UnknownPolarity> {
        match s.to_ascii_lowercase().as_str() {
            "on" => Ok(Polarity::On),
            "off" => Ok(Polarity::Off),
            other => Err(UnknownPolarity { text: other.into() }),
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
    /// For a comparison, the number compared and what it needs
    /// ([`read_comparisons`]); `None` for a contact, or while the numbers
    /// are not known.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub compared: Option<Compared>,
}

/// What a comparison culprit compared: `rSpindleSpeed = 1650.0 (needs >= 1800)`.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct Compared {
    /// The variable compared (`rSpindleSpeed`).
    pub variable: Signal,
    /// Its value at the fault, as the PLC gave it (`1650.0`).
    pub value: String,
    /// What it would need to take the fault away: `>= 1800`; against
    /// another variable, `>= P2, P2 = 12`.
    pub needs: String,
}

impl fmt::Display for Culprit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.compared {
            Some(c) => write!(f, "{} = {} (needs {})", c.variable, c.value, c.needs)?,
            None => write!(
                f,
                "{} = {} (expected {})",
                self.address,
                u8::from(self.value),
                u8::from(self.expected)
            )?,
        }
        if let Some(c) = &self.comment {
            write!(f, ": {c}")?;
        }
        Ok(())
    }
}

/// A number as a culprit shows it: integers as they are, floating point
/// numbers with their point (`1650.0`).
pub fn show_number(n: Num) -> String {
    match n {
        Num::Float(v) => format!("{v:?}"),
        other => other.to_string(),
    }
}

/// Gives every culprit that is a comparison the number of the variable it
/// compares (`number`) and what it needs; its comment becomes the
/// variable's comment in `comments`, when it has one. A culprit whose
/// variable has no known number is left as it is.
pub fn read_comparisons(
    culprits: &mut [Culprit],
    number: impl Fn(&Signal) -> Option<Num>,
    comments: &CommentDb,
) {
    for c in culprits {
        if c.compared.is_some() {
            continue;
        }
        let Some(cmp) = Comparison::of_signal(&c.address) else {
            continue;
        };
        let Some(value) = number(&cmp.lhs) else {
            continue;
        };
        // The comparison must hold to take the fault away, or fail.
        let op = if c.expected { cmp.op } else { negated(cmp.op) };
        let needs = match &cmp.rhs {
            CmpOperand::Const(n) => format!("{} {n}", op.as_str()),
            CmpOperand::Tag(t) => match number(t) {
                Some(v) => format!("{} {t}, {t} = {}", op.as_str(), show_number(v)),
                None => format!("{} {t}", op.as_str()),
            },
        };
        if let Some(comment) = comments.get(&cmp.lhs) {
            c.comment = Some(comment.to_string());
        }
        c.compared = Some(Compared {
            variable: cmp.lhs,
            value: show_number(value),
            needs,
        });
    }
}

/// The operator that holds exactly when `op` does not.
fn negated(op: CmpOp) -> CmpOp {
    match op {
        CmpOp::Gt => CmpOp::Le,
        CmpOp::Ge => CmpOp::Lt,
        CmpOp::Lt => CmpOp::Ge,
        CmpOp::Le => CmpOp::Gt,
        CmpOp::Eq => CmpOp::Ne,
        CmpOp::Ne => CmpOp::Eq,
    }
}

/// The comment of `signal` in `comments`; for an instance's output with
/// none of its own (`T1.Q`, `Fb1.Done`), the instance's (`T1`).
pub fn comment_of(comments: &CommentDb, signal: &Signal) -> Option<String> {
    if let Some(c) = comments.get(signal) {
        return Some(c.to_string());
    }
    let (instance, output) = signal.name().rsplit_once('.')?;
    let is_output = output.starts_with(|c: char| c.is_ascii_alphabetic())
        && output
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_');
    if !is_output || instance.is_empty() {
        return None;
    }
    comments.get(&Signal::new(instance)).map(str::to_string)
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
                compared: None,
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

    #[test]
    fn a_comparison_culprit_shows_its_variable_and_what_it_needs() {
        // Enable = speed reached * door shut * P1 below P2 * not in mode 3.
        let sf = SwitchingFunction::from_expr(
            Signal::new("Enable"),
            &crate::expr::Expr::parse(
                "rSpindleSpeed >= 1800 * -bDoorOpen * P1 < P2 * -(iMode == 3) * bReady",
            )
            .unwrap(),
        );
        let bits = |s: &Signal| {
            Some(match s.name() {
                "rSpindleSpeed >= 1800" | "P1 < P2" => false,
                "bDoorOpen" | "iMode == 3" | "bReady" => true,
                other => panic!("{other}"),
            })
        };
        let numbers = |s: &Signal| match s.name() {
            "rSpindleSpeed" => Some(Num::Float(1650.0)),
            "P1" => Some(Num::Int(12)),
            "P2" => Some(Num::Int(10)),
            "iMode" => Some(Num::UInt(3)),
            _ => None,
        };
        let comments: CommentDb = [
            ("rSpindleSpeed", "Spindle speed"),
            ("bDoorOpen", "Door open"),
            ("iMode", "Operating mode"),
        ]
        .into_iter()
        .map(|(a, c)| (Signal::new(a), c.to_string()))
        .collect();
        let mut e = explain(&sf, bits, None, Polarity::Off, &comments).unwrap();
        let before: Vec<String> = e.culprits.iter().map(ToString::to_string).collect();
        assert_eq!(
            before,
            [
                "rSpindleSpeed >= 1800 = 0 (expected 1)",
                "bDoorOpen = 1 (expected 0): Door open",
                "P1 < P2 = 0 (expected 1)",
                "iMode == 3 = 1 (expected 0)",
            ],
            "without numbers a comparison is a contact"
        );
        read_comparisons(&mut e.culprits, numbers, &comments);
        let after: Vec<String> = e.culprits.iter().map(ToString::to_string).collect();
        assert_eq!(
            after,
            [
                "rSpindleSpeed = 1650.0 (needs >= 1800): Spindle speed",
                "bDoorOpen = 1 (expected 0): Door open",
                "P1 = 12 (needs < P2, P2 = 10)",
                "iMode = 3 (needs != 3): Operating mode",
            ]
        );
        // The address stays the comparison's; the culprit says what it is.
        assert_eq!(e.culprits[0].address.name(), "rSpindleSpeed >= 1800");
        assert!(!e.culprits[0].value && e.culprits[0].expected);
        assert_eq!(
            serde_json::to_value(&e.culprits[0]).unwrap()["compared"],
            serde_json::json!({"variable": "rSpindleSpeed", "value": "1650.0", "needs": ">= 1800"})
        );
        assert!(serde_json::to_value(&e.culprits[1])
            .unwrap()
            .get("compared")
            .is_none());
    }

    #[test]
    fn an_instance_output_without_a_comment_of_its_own_has_its_instance_s() {
        let comments: CommentDb = [
            (Signal::new("T1"), "Clamp settle time".to_string()),
            (Signal::new("X0"), "Input byte 0".to_string()),
        ]
        .into_iter()
        .collect();
        let of = |s: &str| comment_of(&comments, &Signal::new(s));
        assert_eq!(of("T1.Q").as_deref(), Some("Clamp settle time"));
        assert_eq!(of("T1"), of("T1.Q"));
        assert_eq!(of("X0.07"), None, "a bit of a byte is no output");
        assert_eq!(of("C1.Q"), None);
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
