//! What a program's `VAR` ... `END_VAR` declarations say ([`Declarations`]):
//! each variable's type, the function blocks and functions of the file
//! and of IEC 61131-3, and from them which operands are contacts, which
//! are function-block instances and their inputs, and which are not
//! boolean. It owns the declarations, not the lexing of the instructions
//! that use them (`mod.rs`).

use std::collections::{HashMap, HashSet};

/// The standard function blocks, with their outputs (the rest of their
/// members are inputs).
const STANDARD_FBS: &[(&str, &[&str])] = &[
    ("TON", &["Q", "ET"]),
    ("TOF", &["Q", "ET"]),
    ("TP", &["Q", "ET"]),
    ("CTU", &["Q", "CV"]),
    ("CTD", &["Q", "CV"]),
    ("CTUD", &["QU", "QD", "CV"]),
    ("SR", &["Q1"]),
    ("RS", &["Q1"]),
    ("R_TRIG", &["Q"]),
    ("F_TRIG", &["Q"]),
    ("RTC", &["Q", "CDT"]),
];

/// Non-boolean outputs of the standard function blocks.
const NUMERIC_OUTPUTS: &[&str] = &["ET", "CV", "CDT"];

/// Standard functions usable as IL operators (IEC 61131-3, 2.5.1.5).
fn is_standard_function(upper: &str) -> bool {
    upper.contains("_TO_")
        || upper.starts_with("TRUNC")
        || matches!(
            upper,
            "ABS"
                | "SQRT"
                | "LN"
                | "LOG"
                | "EXP"
                | "SIN"
                | "COS"
                | "TAN"
                | "ASIN"
                | "ACOS"
                | "ATAN"
                | "EXPT"
                | "MOVE"
                | "SHL"
                | "SHR"
                | "ROL"
                | "ROR"
                | "SEL"
                | "MAX"
                | "MIN"
                | "LIMIT"
                | "MUX"
                | "LEN"
                | "LEFT"
                | "RIGHT"
                | "MID"
                | "CONCAT"
                | "INSERT"
                | "DELETE"
                | "REPLACE"
                | "FIND"
                | "BCD_TO_INT"
                | "INT_TO_BCD"
                | "NEG"
                | "ADD_TIME"
                | "SUB_TIME"
                | "MUL_TIME"
                | "DIV_TIME"
                | "CONCAT_DATE_TOD"
        )
}

/// The declaration blocks: read for their types, never as instructions.
pub(super) const SKIPPED_BLOCKS: &[&str] = &[
    "VAR",
    "VAR_INPUT",
    "VAR_OUTPUT",
    "VAR_IN_OUT",
    "VAR_GLOBAL",
    "VAR_EXTERNAL",
    "VAR_TEMP",
];

/// What the file declares: variables' types, its function blocks and
/// functions (upper case).
#[derive(Debug, Default, Clone)]
pub(crate) struct Declarations {
    pub(super) vars: HashMap<String, String>,
    pub(super) blocks: HashSet<String>,
    pub(super) functions: HashSet<String>,
}

impl Declarations {
    /// Reads every `VAR...END_VAR` line `a, b : TYPE := init;` and every
    /// `FUNCTION_BLOCK name` and `FUNCTION name : type` of `clean` (the
    /// source with comments blanked).
    pub(crate) fn read(clean: &str) -> Declarations {
        let mut d = Declarations::default();
        let mut in_var = false;
        for line in clean.lines() {
            let mut w = line.split_whitespace();
            let Some(first) = w.next() else { continue };
            let upper = first.to_ascii_uppercase();
            if in_var {
                if upper.starts_with("END_VAR") {
                    in_var = false;
                    continue;
                }
                d.declare(line);
                continue;
            }
            if SKIPPED_BLOCKS.contains(&upper.as_str()) {
                in_var = true;
                // `VAR_INPUT AUTO_CMD : BOOL;` on the keyword's line.
                let rest = line.trim_start()[first.len()..].trim_start();
                if rest.contains(':') && !rest.to_ascii_uppercase().starts_with("END_VAR") {
                    d.declare(rest);
                }
                continue;
            }
            let name = w.next().map(|n| {
                n.trim_end_matches(':')
                    .trim_end_matches(';')
                    .to_ascii_uppercase()
            });
            match (upper.as_str(), name) {
                ("FUNCTION_BLOCK", Some(n)) => {
                    d.blocks.insert(n);
                }
                ("FUNCTION", Some(n)) => {
                    d.functions.insert(n);
                }
                // `CAL FWD_MON` on a variable of a type declared elsewhere:
                // that type is a function block.
                ("CAL" | "CALC" | "CALCN", Some(n)) => {
                    let instance = n.split('(').next().unwrap_or("");
                    if let Some(ty) = d.vars.get(instance) {
                        if ty != "BOOL" {
                            d.blocks.insert(ty.clone());
                        }
                    }
                }
                _ => {}
            }
        }
        d
    }

    /// Declares `name` of type `ty` (any case).
    pub(crate) fn variable(&mut self, name: &str, ty: &str) {
        self.vars
            .insert(name.to_ascii_uppercase(), ty.to_ascii_uppercase());
    }

    /// Declares a function block type or a function of the project.
    pub(crate) fn unit(&mut self, name: &str, function: bool) {
        let name = name.to_ascii_uppercase();
        if function {
            self.functions.insert(name);
        } else {
            self.blocks.insert(name);
        }
    }

    fn declare(&mut self, line: &str) {
        let Some((names, ty)) = line.split_once(':') else {
            return;
        };
        if ty.starts_with('=') {
            return;
        }
        let ty = ty
            .split(":=")
            .next()
            .unwrap_or("")
            .trim()
            .trim_end_matches(';');
        let ty = ty.trim().to_ascii_uppercase();
        let ty = if ty.starts_with("ARRAY") {
            "ARRAY".to_string()
        } else {
            ty
        };
        // `name AT %IX0.0`
        for name in names.split(',') {
            let Some(name) = name.split_whitespace().next() else {
                continue;
            };
            self.vars.insert(name.to_ascii_uppercase(), ty.clone());
        }
    }

    /// The declared type of `name`, upper case.
    fn type_of(&self, name: &str) -> Option<&str> {
        self.vars
            .get(&name.to_ascii_uppercase())
            .map(String::as_str)
    }

    /// Whether `ty` is a function block's type.
    fn is_block_type(&self, ty: &str) -> bool {
        STANDARD_FBS.iter().any(|(n, _)| *n == ty) || self.blocks.contains(ty)
    }

    /// Whether `name` is a function-block instance.
    pub(super) fn is_instance(&self, name: &str) -> bool {
        self.type_of(name).is_some_and(|t| self.is_block_type(t))
    }

    /// Whether an operand is known not to be a boolean: a variable of
    /// another type, an instance itself, a numeric output of a standard
    /// block, an array element.
    pub(crate) fn not_boolean(&self, operand: &str) -> bool {
        if operand.contains('[') {
            return true;
        }
        match operand.split_once('.') {
            None => self.type_of(operand).is_some_and(|t| t != "BOOL"),
            Some((base, member)) => {
                let member = member.to_ascii_uppercase();
                self.type_of(base).is_some_and(|t| {
                    STANDARD_FBS.iter().any(|(n, _)| *n == t)
                        && NUMERIC_OUTPUTS.contains(&member.as_str())
                })
            }
        }
    }

    /// Whether a write target is a function block's input (`T1.PT`,
    /// `FF.S1`) rather than a coil.
    pub(super) fn is_block_input(&self, target: &str) -> bool {
        let Some((base, member)) = target.split_once('.') else {
            return false;
        };
        let Some(ty) = self.type_of(base) else {
            return false;
        };
        let member = member.to_ascii_uppercase();
        match STANDARD_FBS.iter().find(|(n, _)| *n == ty) {
            Some((_, outputs)) => !outputs.contains(&member.as_str()),
            // A user block's member: an input unless we know better.
            None => self.blocks.contains(ty),
        }
    }

    pub(super) fn is_function(&self, upper: &str) -> bool {
        is_standard_function(upper) || self.functions.contains(upper)
    }
}
