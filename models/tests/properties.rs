//! Model-based property tests:
//! - random PMC programs: every output's switching function, evaluated as a
//!   re-assembled tree, step by step, and compiled, equals running the
//!   instruction list directly;
//! - random expression trees written as IEC IL (parentheses, NOT, XOR):
//!   compiled evaluation equals naive tree evaluation;
//! - incremental evaluation equals full re-evaluation after every change;
//! - three-valued evaluation with unknown contacts: Kleene logic is never
//!   wrong, and [`SwitchingFunction::certain`] equals "all completions of
//!   the unknowns agree";
//! - mutated TIA Portal exports (SimaticML: wires pointed elsewhere, loops,
//!   parts renamed, text cut out) give a program or located errors, never
//!   a panic;
//! - mutated Studio 5000 FBD exports (wire ends and pins pointed elsewhere,
//!   blocks retyped, feedback wires, text cut out): the same.

#![allow(clippy::unwrap_used)] // test helpers fail loudly by design

use std::collections::HashMap;

use cellwatch_models::compiled::CompiledCell;
use cellwatch_models::expr::Expr;
use cellwatch_models::program::Program;
use cellwatch_models::signal::{Observability, Signal};
use cellwatch_models::switching::SwitchingFunction;
use proptest::prelude::*;

mod kit;
use kit::{FIG6_FBD_L5X, FIG6_TIA_FBD, FIG6_TIA_LAD};

const INPUTS: usize = 8;

fn input(i: usize) -> Signal {
    Signal::new(&format!("X{i}"))
}

/// A random tree over inputs `X0..X7` and relays `R0..R(relays-1)`.
fn tree(relays: usize) -> impl Strategy<Value = Expr> {
    let leaf = (0..INPUTS + relays, any::<bool>()).prop_map(move |(i, n)| {
        let s = if i < INPUTS {
            input(i)
        } else {
            Signal::new(&format!("R{}", i - INPUTS))
        };
        Expr::Lit(s, n)
    });
    leaf.prop_recursive(4, 24, 4, |inner| {
        prop_oneof![
            prop::collection::vec(inner.clone(), 2..4).prop_map(Expr::And),
            prop::collection::vec(inner, 2..4).prop_map(Expr::Or),
        ]
    })
}

/// Writes `e` as PMC IL: same-operator literals extend, sub-trees go
/// through the stack.
fn pmc(e: &Expr, out: &mut Vec<String>) {
    match e {
        Expr::Lit(s, n) => out.push(format!("{} {s}", if *n { "RD.NOT" } else { "RD" })),
        Expr::And(cs) | Expr::Or(cs) => {
            let (word, stk) = if matches!(e, Expr::And(_)) {
                ("AND", "AND.STK")
            } else {
                ("OR", "OR.STK")
            };
            pmc(&cs[0], out);
            for c in &cs[1..] {
                match c {
                    Expr::Lit(s, n) => {
                        out.push(format!("{word}{} {s}", if *n { ".NOT" } else { "" }))
                    }
                    _ => {
                        let mut inner = Vec::new();
                        pmc(c, &mut inner);
                        inner[0] = inner[0]
                            .replacen("RD.NOT", "RD.NOT.STK", 1)
                            .replacen("RD ", "RD.STK ", 1);
                        out.extend(inner);
                        out.push(stk.to_string());
                    }
                }
            }
        }
        Expr::Not(_) | Expr::Const(_) => unreachable!("not generated for pmc"),
    }
}

/// Runs a PMC program once, as a PLC scan would, on boolean values.
fn interpret(program: &str, inputs: &HashMap<Signal, bool>) -> HashMap<Signal, bool> {
    let mut mem = inputs.clone();
    let mut acc = false;
    let mut stack = Vec::new();
    for line in program.lines() {
        let mut w = line.split_whitespace();
        let (m, a) = (w.next().unwrap(), w.next().map(Signal::new));
        let val = |a: &Option<Signal>, mem: &HashMap<Signal, bool>| {
            mem.get(a.as_ref().unwrap()).copied().unwrap_or(false)
        };
        match m {
            "RD" => acc = val(&a, &mem),
            "RD.NOT" => acc = !val(&a, &mem),
            "RD.STK" => {
                stack.push(acc);
                acc = val(&a, &mem);
            }
            "RD.NOT.STK" => {
                stack.push(acc);
                acc = !val(&a, &mem);
            }
            "AND" => acc &= val(&a, &mem),
            "AND.NOT" => acc &= !val(&a, &mem),
            "OR" => acc |= val(&a, &mem),
            "OR.NOT" => acc |= !val(&a, &mem),
            "AND.STK" => acc &= stack.pop().unwrap(),
            "OR.STK" => acc |= stack.pop().unwrap(),
            "WRT" => {
                mem.insert(a.unwrap(), acc);
            }
            other => panic!("interpreter: {other}"),
        }
    }
    mem
}

/// A program of rungs: relay `Rk` may read inputs and earlier relays; the
/// outputs `Y0..` read anything written before them.
fn programs() -> impl Strategy<Value = (String, usize)> {
    (1usize..4, 1usize..4).prop_flat_map(|(relays, outputs)| {
        let rungs: Vec<_> = (0..relays + outputs).map(|k| tree(k.min(relays))).collect();
        rungs.prop_map(move |trees| {
            let mut lines = Vec::new();
            for (k, t) in trees.iter().enumerate() {
                pmc(t, &mut lines);
                let coil = if k < relays {
                    format!("R{k}")
                } else {
                    format!("Y{}", k - relays)
                };
                lines.push(format!("WRT {coil}"));
            }
            (lines.join("\n"), outputs)
        })
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn switching_functions_equal_running_the_program((src, outputs) in programs(), bits in any::<u8>()) {
        let program = Program::compile("random.il", &src, None).unwrap();
        let observable = Observability::default_for(program.dialect());
        let sfs: Vec<SwitchingFunction> = (0..outputs)
            .map(|k| SwitchingFunction::expand(&program, &Signal::new(&format!("Y{k}")), &observable).unwrap())
            .collect();
        let inputs: HashMap<Signal, bool> = (0..INPUTS).map(|i| (input(i), bits >> i & 1 == 1)).collect();
        let scan = interpret(&src, &inputs);
        let mut cell = CompiledCell::new(&sfs);
        let mut changed = Vec::new();
        for (s, v) in &inputs {
            if let Some(i) = cell.signal_index(s) {
                cell.set(i, *v, &mut changed);
            }
        }
        let value = |s: &Signal| inputs[s];
        for (k, sf) in sfs.iter().enumerate() {
            let expected = scan[&Signal::new(&format!("Y{k}"))];
            prop_assert_eq!(sf.to_expr().eval(&value), expected, "re-assembled steps, {}", sf);
            prop_assert_eq!(sf.evaluate(value).0, expected, "step evaluation, {}", sf);
            prop_assert_eq!(cell.output(k), expected, "compiled, {}", sf);
            // Relays are gone: only inputs remain.
            prop_assert!(sf.leaves().iter().all(|s| s.name().starts_with('X')));
        }
    }
}

/// A random tree with NOT, XOR-free IEC spelling and constants.
fn iec_tree() -> impl Strategy<Value = Expr> {
    let leaf = prop_oneof![
        8 => (0..INPUTS, any::<bool>()).prop_map(|(i, n)| Expr::Lit(Signal::new(&format!("%IX0.{i}")), n)),
        1 => any::<bool>().prop_map(Expr::Const),
    ];
    leaf.prop_recursive(5, 40, 4, |inner| {
        prop_oneof![
            prop::collection::vec(inner.clone(), 2..5).prop_map(Expr::And),
            prop::collection::vec(inner.clone(), 2..5).prop_map(Expr::Or),
            inner.prop_map(|e| Expr::Not(Box::new(e))),
        ]
    })
}

fn iec(e: &Expr, out: &mut Vec<String>) {
    let operand = |e: &Expr| match e {
        Expr::Lit(s, n) => Some((s.to_string(), *n)),
        Expr::Const(v) => Some(((if *v { "TRUE" } else { "FALSE" }).to_string(), false)),
        _ => None,
    };
    match e {
        Expr::Lit(..) | Expr::Const(_) => {
            let (s, n) = operand(e).unwrap();
            out.push(format!("{} {s}", if n { "LDN" } else { "LD" }));
        }
        Expr::Not(inner) => {
            iec(inner, out);
            out.push("NOT".into());
        }
        Expr::And(cs) | Expr::Or(cs) => {
            let word = if matches!(e, Expr::And(_)) {
                "AND"
            } else {
                "OR"
            };
            iec(&cs[0], out);
            for c in &cs[1..] {
                match operand(c) {
                    Some((s, n)) => out.push(format!("{word}{} {s}", if n { "N" } else { "" })),
                    None => {
                        out.push(format!("{word}("));
                        iec(c, out);
                        out.push(")".into());
                    }
                }
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn compiled_equals_naive_tree(e in iec_tree(), states in prop::collection::vec(any::<u8>(), 1..8)) {
        let mut lines = Vec::new();
        iec(&e, &mut lines);
        lines.push("ST %QX0.0".into());
        let src = lines.join("\n");
        let program = Program::compile("random.il", &src, None).unwrap();
        let sf = SwitchingFunction::expand(&program, &Signal::new("%QX0.0"), &Observability::default_for(program.dialect())).unwrap();
        let mut cell = CompiledCell::new(std::slice::from_ref(&sf));
        let mut changed = Vec::new();
        for bits in states {
            let value = |s: &Signal| {
                let i: u32 = s.name().rsplit('.').next().unwrap().parse().unwrap();
                bits >> i & 1 == 1
            };
            for s in cell.signals().to_vec() {
                let i = cell.signal_index(&s).unwrap();
                cell.set(i, value(&s), &mut changed);
            }
            prop_assert_eq!(cell.output(0), e.eval(&value), "{}", src);
            prop_assert_eq!(sf.to_expr().eval(&value), e.eval(&value));
        }
    }

    #[test]
    fn incremental_equals_full_reevaluation(
        trees in prop::collection::vec(tree(0), 1..12),
        changes in prop::collection::vec((0..INPUTS, any::<bool>()), 1..64),
    ) {
        let mut lines = Vec::new();
        for (k, t) in trees.iter().enumerate() {
            pmc(t, &mut lines);
            lines.push(format!("WRT Y{k}"));
        }
        let program = Program::compile("random.il", &lines.join("\n"), None).unwrap();
        let observable = Observability::default_for(program.dialect());
        let sfs: Vec<_> = (0..trees.len())
            .map(|k| SwitchingFunction::expand(&program, &Signal::new(&format!("Y{k}")), &observable).unwrap())
            .collect();
        let mut cell = CompiledCell::new(&sfs);
        let mut changed = Vec::new();
        for (i, v) in changes {
            let Some(s) = cell.signal_index(&input(i)) else { continue };
            let before: Vec<bool> = (0..sfs.len()).map(|c| cell.output(c)).collect();
            changed.clear();
            cell.set(s, v, &mut changed);
            let mut full = cell.clone();
            let mut again = Vec::new();
            full.evaluate_all(&mut again);
            prop_assert!(again.is_empty(), "incremental missed checks {:?}", again);
            for (c, was) in before.iter().enumerate() {
                prop_assert_eq!(changed.contains(&c), *was != cell.output(c));
            }
        }
    }
}

/// Every completion of the unknown inputs (`None` in `values`) of `sf`.
fn completions(sf: &SwitchingFunction, values: &[Option<bool>]) -> Vec<bool> {
    let unknown: Vec<usize> = (0..INPUTS).filter(|&i| values[i].is_none()).collect();
    (0u32..1 << unknown.len())
        .map(|bits| {
            let value = |s: &Signal| {
                let i: usize = s.name()[1..].parse().unwrap();
                values[i].unwrap_or_else(|| {
                    let k = unknown.iter().position(|&u| u == i).unwrap();
                    bits >> k & 1 == 1
                })
            };
            sf.evaluate(value).0
        })
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn three_valued_evaluation_is_all_completions_agreeing(
        e in tree(0),
        values in prop::collection::vec(prop::option::of(any::<bool>()), INPUTS),
    ) {
        let sf = SwitchingFunction::from_expr(Signal::new("Y0"), &e);
        let lookup = |s: &Signal| {
            let i: usize = s.name()[1..].parse().unwrap();
            values[i]
        };
        let all = completions(&sf, &values);
        let agreed = if all.iter().all(|&v| v) {
            Some(true)
        } else if all.iter().all(|&v| !v) {
            Some(false)
        } else {
            None
        };
        prop_assert_eq!(sf.certain(lookup), agreed, "{}", sf);
        // Kleene alone may say less, never something else.
        if let Some(v) = sf.evaluate3(lookup).0 {
            prop_assert_eq!(Some(v), agreed, "kleene, {}", sf);
        }
    }
}

/// Part names a mutation may give a part.
const PART_NAMES: &[&str] = &[
    "Contact", "Coil", "SCoil", "RCoil", "Sr", "Rs", "O", "A", "X", "Not", "Gt", "Eq", "TON",
    "PBox", "PContact", "Move", "Calc", "",
];

/// One change to an export.
#[derive(Debug, Clone)]
enum Mutation {
    /// The `n`th UId reference (of a wire end or a part) becomes `to`.
    Rewire { n: usize, to: u32 },
    /// The `n`th part is renamed.
    Rename { n: usize, name: usize },
    /// The `n`th pin name becomes another part's pin name.
    Pin { n: usize, to: usize },
    /// Bytes `at..at+len` are cut out.
    Cut { at: usize, len: usize },
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        (0..64usize, 0..48u32).prop_map(|(n, to)| Mutation::Rewire { n, to }),
        (0..16usize, 0..PART_NAMES.len()).prop_map(|(n, name)| Mutation::Rename { n, name }),
        (0..64usize, 0..64usize).prop_map(|(n, to)| Mutation::Pin { n, to }),
        (0..20_000usize, 0..200usize).prop_map(|(at, len)| Mutation::Cut { at, len }),
    ]
}

/// `text` with its `n`th match of `pattern` (`UId="`, `Name="`) given the
/// value `value`.
fn replace_nth(text: &str, pattern: &str, n: usize, value: &str) -> String {
    let starts: Vec<usize> = text.match_indices(pattern).map(|(i, _)| i).collect();
    if starts.is_empty() {
        return text.to_string();
    }
    let start = starts[n % starts.len()] + pattern.len();
    let end = text[start..].find('"').map_or(text.len(), |e| start + e);
    format!("{}{value}{}", &text[..start], &text[end..])
}

fn mutate(text: &str, m: &Mutation) -> String {
    match m {
        Mutation::Rewire { n, to } => replace_nth(text, "UId=\"", *n, &to.to_string()),
        Mutation::Rename { n, name } => replace_nth(text, "<Part Name=\"", *n, PART_NAMES[*name]),
        Mutation::Pin { n, to } => {
            let pins: Vec<&str> = text
                .match_indices("NameCon UId=")
                .filter_map(|(i, _)| text[i..].split('"').nth(3))
                .collect();
            let pin = pins.get(to % pins.len().max(1)).copied().unwrap_or("in");
            replace_nth(text, "\" Name=\"", *n, pin)
        }
        Mutation::Cut { at, len } => {
            let at = (*at).min(text.len());
            let end = (at + len).min(text.len());
            match (text.get(..at), text.get(end..)) {
                (Some(a), Some(b)) => format!("{a}{b}"),
                _ => text.to_string(),
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn mutated_tia_exports_compile_or_fail_with_located_errors(
        fbd in any::<bool>(),
        mutations in prop::collection::vec(mutation(), 1..6),
    ) {
        let mut text = if fbd { FIG6_TIA_FBD } else { FIG6_TIA_LAD }.to_string();
        for m in &mutations {
            text = mutate(&text, m);
        }
        compiles_or_fails_located("m.xml", &text)?;
    }
}

/// Block types a mutation may give an L5X FBD block.
const BLOCK_TYPES: &[&str] = &[
    "BAND", "BOR", "BXOR", "BNOT", "BAND__F", "TONR", "CMP", "OSRI", "band", "",
];

/// Pin names a mutation may give an L5X wire's end.
const L5X_PINS: &[&str] = &[
    "In", "In1", "In2", "In3", "In8", "Out", "EnableIn", "DN", "",
];

/// One change to an L5X FBD export.
#[derive(Debug, Clone)]
enum FbdMutation {
    /// The `n`th `FromID` or `ToID` becomes `to`.
    Rewire { n: usize, to: u32, from: bool },
    /// The `n`th block's type becomes another.
    Retype { n: usize, to: usize },
    /// The `n`th `ToParam` or `FromParam` becomes another pin.
    Pin { n: usize, to: usize, from: bool },
    /// The `n`th wire becomes a feedback wire.
    Feedback { n: usize },
    /// Bytes `at..at+len` are cut out.
    Cut { at: usize, len: usize },
}

fn fbd_mutation() -> impl Strategy<Value = FbdMutation> {
    prop_oneof![
        (0..32usize, 0..24u32, any::<bool>()).prop_map(|(n, to, from)| FbdMutation::Rewire {
            n,
            to,
            from
        }),
        (0..16usize, 0..BLOCK_TYPES.len()).prop_map(|(n, to)| FbdMutation::Retype { n, to }),
        (0..32usize, 0..L5X_PINS.len(), any::<bool>()).prop_map(|(n, to, from)| FbdMutation::Pin {
            n,
            to,
            from
        }),
        (0..32usize).prop_map(|n| FbdMutation::Feedback { n }),
        (0..20_000usize, 0..200usize).prop_map(|(at, len)| FbdMutation::Cut { at, len }),
    ]
}

fn mutate_fbd(text: &str, m: &FbdMutation) -> String {
    match m {
        FbdMutation::Rewire { n, to, from } => {
            let end = if *from { "FromID=\"" } else { "ToID=\"" };
            replace_nth(text, end, *n, &to.to_string())
        }
        FbdMutation::Retype { n, to } => replace_nth(text, "<Block Type=\"", *n, BLOCK_TYPES[*to]),
        FbdMutation::Pin { n, to, from } => {
            let end = if *from { "FromParam=\"" } else { "ToParam=\"" };
            replace_nth(text, end, *n, L5X_PINS[*to])
        }
        FbdMutation::Feedback { n } => {
            let starts: Vec<usize> = text.match_indices("<Wire ").map(|(i, _)| i).collect();
            match starts.get(n % starts.len().max(1)) {
                Some(&i) => format!("{}<FeedbackWire {}", &text[..i], &text[i + 6..]),
                None => text.to_string(),
            }
        }
        FbdMutation::Cut { at, len } => mutate(text, &Mutation::Cut { at: *at, len: *len }),
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn mutated_l5x_fbd_exports_compile_or_fail_with_located_errors(
        mutations in prop::collection::vec(fbd_mutation(), 1..6),
    ) {
        let mut text = FIG6_FBD_L5X.to_string();
        for m in &mutations {
            text = mutate_fbd(&text, m);
        }
        compiles_or_fails_located("m.L5X", &text)?;
    }
}

/// A mutated export compiles (every coil expands and prints, every
/// warning has a line) or fails with every message located in `origin`.
fn compiles_or_fails_located(origin: &str, text: &str) -> Result<(), TestCaseError> {
    match Program::compile(origin, text, None) {
        Ok(p) => {
            let observable = Observability::default_for(p.dialect());
            for coil in p.coils() {
                if let Ok(sf) = SwitchingFunction::expand(&p, &coil.signal, &observable) {
                    let _ = sf.notation();
                }
            }
            for w in p.warnings() {
                prop_assert!(w.at.line >= 1, "{:?}", w);
            }
        }
        Err(e) => {
            for line in e.lines() {
                prop_assert!(
                    line.starts_with(&format!("{origin}:")) || line.starts_with("... and "),
                    "{}",
                    line
                );
            }
        }
    }
    Ok(())
}
