//! Charts from PLCopen XML (IEC 61131-3 TC6 XML 2.01): every POU whose
//! body is SFC is one chart, named after the POU.
//!
//! A TC6 SFC body is a graph of elements joined by `connectionPointIn`
//! / `connection refLocalId` (each element names what comes before it):
//! `step` (`initialStep="true"`), `transition`, `selectionDivergence` and
//! `selectionConvergence`, `simultaneousDivergence` and
//! `simultaneousConvergence`, `jumpStep` (`targetName`, a step of the same
//! POU; `CHART.STEP` jumps to another POU's chart). A transition leaves the
//! steps found walking back from it (through a selection divergence to its
//! step, through a simultaneous convergence to each of its steps) and goes
//! to the steps found walking on (through a simultaneous divergence to each
//! branch, through a selection convergence to the step after it, through a
//! jump to its target). Actions are not read: supervision needs the steps
//! and transitions only.
//!
//! A transition's id is its `name` attribute, else the name of the
//! transition it references (`<condition><reference name="…"/>`; with its
//! `localId` appended, `STOP_t12`, when several transitions reference the
//! same one), else `t` and its `localId`. Its condition is an ST expression, inline
//! (`<condition><inline><ST>`) or in the referenced named transition of
//! the POU (`<transitions><transition name="…"><body><ST>`): `AND`, `&`,
//! `OR`, `NOT`, parentheses, `TRUE`/`FALSE` and comparisons (`=`, `<>`,
//! `<`, `<=`, `>`, `>=`); or drawn: an LD or FBD named transition (the
//! logic of its coil or output variable of the transition's name), or
//! contacts and boxes in the chart wired to the transition's condition,
//! read by the PLCopen ladder reader. A step's flag is the IEC step flag `NAME.X`;
//! `documentation` becomes the comment of a step or transition, and that
//! of a declared variable (`T1`, `rSpindleSpeed`) the comment of the
//! operands that read it ([`super::Sfc::variables`]).
//!
//! The result goes through the same checks as the TOML form: every
//! problem is `FILE:LINE:COL: what`, at the XML element that is wrong: a
//! jump to a step that does not exist at its `jumpStep`, a connection to a
//! `localId` that does not exist at its `connection`.

use std::collections::HashMap;

use roxmltree::{Document, Node};
use toml::Spanned;

use super::text::{build, Errors, OneOrMany, RawChart, RawFile, RawStep, RawTransition};
use super::Sfc;
use crate::comments::CommentDb;
use crate::expr::{Expr, ExprError};
use crate::signal::Signal;

/// Parses the SFC bodies of the PLCopen XML project `text` (the file
/// `file`); `known` says whether a signal is one of the cell's tags.
///
/// # Errors
/// Every problem found, each `FILE:LINE:COL: what`.
pub fn parse(file: &str, text: &str, known: &dyn Fn(&Signal) -> bool) -> Result<Sfc, Vec<String>> {
    let mut errors = Errors::new(file, text);
    // No DTD (so no entity expansion); a bounded number of nodes.
    let options = roxmltree::ParsingOptions {
        allow_dtd: false,
        nodes_limit: 1_000_000,
        ..roxmltree::ParsingOptions::default()
    };
    let doc = match Document::parse_with_options(text, options) {
        Ok(d) => d,
        Err(e) => {
            let pos = e.pos();
            let line_start: usize = text
                .split_inclusive('\n')
                .take(pos.row.saturating_sub(1) as usize)
                .map(str::len)
                .sum();
            let col: usize = text[line_start..]
                .char_indices()
                .nth(pos.col.saturating_sub(1) as usize)
                .map_or(0, |(i, _)| i);
            errors.at(line_start + col, format!("not well-formed XML: {e}"));
            return Err(errors.finish());
        }
    };
    let mut raw = RawFile { chart: Vec::new() };
    for pou in doc.descendants().filter(|n| n.has_tag_name("pou")) {
        let Some(body) = child(pou, "body") else {
            continue;
        };
        let Some(sfc) = child(body, "SFC") else {
            continue;
        };
        let name = pou.attribute("name").unwrap_or_default();
        raw.chart.push(chart(pou, sfc, name, &mut errors));
    }
    if raw.chart.is_empty() && doc.root_element().has_tag_name("project") {
        errors.at(
            doc.root_element().range().start,
            "no POU with an SFC body in this PLCopen XML project".into(),
        );
        return Err(errors.finish());
    }
    let mut sfc = build(errors, &raw, known, &st_condition)?;
    sfc.variables = variables(&doc);
    Ok(sfc)
}

/// The documentation of every variable the project declares (a POU's
/// interface, a resource's or configuration's global variables), by name:
/// `<localVars><variable name="T1">…<documentation>`.
fn variables(doc: &Document<'_>) -> CommentDb {
    doc.descendants()
        .filter(|n| n.has_tag_name("variable"))
        .filter(|n| {
            n.parent_element()
                .is_some_and(|p| p.tag_name().name().ends_with("Vars"))
        })
        .filter_map(|n| Some((Signal::new(n.attribute("name")?), documentation(n)?)))
        .collect()
}

fn child<'a, 'i>(node: Node<'a, 'i>, name: &str) -> Option<Node<'a, 'i>> {
    node.children().find(|n| n.has_tag_name(name))
}

fn spanned<T>(node: Node<'_, '_>, value: T) -> Spanned<T> {
    let start = node.range().start;
    Spanned::new(start..start, value)
}

/// The text of a `documentation` (or any formatted text) child, trimmed.
fn documentation(node: Node<'_, '_>) -> Option<String> {
    let doc = child(node, "documentation")?;
    let text: String = doc
        .descendants()
        .filter(|n| n.is_text())
        .filter_map(|n| n.text())
        .collect::<Vec<_>>()
        .join(" ");
    let text = text.split_whitespace().collect::<Vec<_>>().join(" ");
    (!text.is_empty()).then_some(text)
}

/// Every `connection` element into `node`.
fn connections<'a, 'i>(node: Node<'a, 'i>) -> impl Iterator<Item = Node<'a, 'i>> {
    node.children()
        .filter(|n| n.has_tag_name("connectionPointIn"))
        .flat_map(|c| c.children().filter(|n| n.has_tag_name("connection")))
}

/// The `refLocalId`s of every connection into `node`.
fn inputs(node: Node<'_, '_>) -> Vec<String> {
    connections(node)
        .filter_map(|c| c.attribute("refLocalId").map(str::to_string))
        .collect()
}

/// The elements of an SFC body that are joined by connections (actions
/// and drawn conditions are not: their wiring is read elsewhere).
const SEQUENCE_ELEMENTS: [&str; 8] = [
    "step",
    "macroStep",
    "transition",
    "jumpStep",
    "selectionDivergence",
    "selectionConvergence",
    "simultaneousDivergence",
    "simultaneousConvergence",
];

/// An ST body's text: `<ST><xhtml:p>…</xhtml:p></ST>` or `<ST>…</ST>`.
fn st_text(st: Node<'_, '_>) -> String {
    st.descendants()
        .filter(|n| n.is_text())
        .filter_map(|n| n.text())
        .collect::<String>()
        .trim()
        .trim_end_matches(';')
        .trim()
        .to_string()
}

fn chart(pou: Node<'_, '_>, sfc: Node<'_, '_>, name: &str, errors: &mut Errors<'_>) -> RawChart {
    let by_id: HashMap<&str, Node<'_, '_>> = sfc
        .children()
        .filter(|n| n.is_element())
        .filter_map(|n| n.attribute("localId").map(|id| (id, n)))
        .collect();
    // What follows each element.
    let mut next: HashMap<String, Vec<Node<'_, '_>>> = HashMap::new();
    for n in sfc.children().filter(|n| n.is_element()) {
        for id in inputs(n) {
            next.entry(id).or_default().push(n);
        }
    }
    let named_conditions: HashMap<&str, Node<'_, '_>> = child(pou, "transitions")
        .into_iter()
        .flat_map(|ts| ts.children().filter(|n| n.has_tag_name("transition")))
        .filter_map(|t| t.attribute("name").map(|n| (n, t)))
        .collect();
    let mut out = RawChart {
        name: spanned(pou, name.to_string()),
        initial: None,
        step_word: None,
        step: Vec::new(),
        transition: Vec::new(),
    };
    // A named transition may be the condition of several transitions.
    let mut uses: HashMap<&str, usize> = HashMap::new();
    for r in sfc
        .children()
        .filter(|n| n.has_tag_name("transition"))
        .filter_map(|n| n.descendants().find(|c| c.has_tag_name("reference")))
        .filter_map(|r| r.attribute("name"))
    {
        *uses.entry(r).or_default() += 1;
    }
    for n in sfc.children().filter(|n| n.is_element()) {
        // A connection to nothing, at the connection.
        if SEQUENCE_ELEMENTS.contains(&n.tag_name().name()) {
            for c in connections(n) {
                let id = c.attribute("refLocalId").unwrap_or_default();
                if !by_id.contains_key(id) {
                    errors.at(
                        c.range().start,
                        format!("connection to localId {id}, which is not in this SFC"),
                    );
                }
            }
        }
        match n.tag_name().name() {
            "step" => {
                let step = n.attribute("name").unwrap_or_default().to_string();
                if n.attribute("initialStep") == Some("true") {
                    if let Some(first) = &out.initial {
                        errors.at(
                            n.range().start,
                            format!(
                                "chart {name}: a second initial step '{step}' (the first is '{}')",
                                first.get_ref()
                            ),
                        );
                    } else {
                        out.initial = Some(spanned(n, step.clone()));
                    }
                }
                out.step.push(RawStep {
                    name: spanned(n, step.clone()),
                    flag: Some(spanned(n, format!("{step}.X"))),
                    number: None,
                    supervision: None,
                    comment: documentation(n),
                });
            }
            "transition" => {
                let mut from = Vec::new();
                for i in inputs(n) {
                    back(&by_id, &i, &mut from, errors, n, 0);
                }
                let mut to = Vec::new();
                if let Some(id) = n.attribute("localId") {
                    on(&next, id, &mut to, errors, n, 0);
                }
                let (to, to_at): (Vec<String>, Vec<usize>) = to.into_iter().unzip();
                let reference = n
                    .descendants()
                    .find(|c| c.has_tag_name("reference"))
                    .and_then(|r| r.attribute("name"));
                let local = n.attribute("localId").unwrap_or("?");
                let id = match (n.attribute("name"), reference) {
                    (Some(own), _) => own.to_string(),
                    // `STOP` used at two places: `STOP_t12`, `STOP_t20`.
                    (None, Some(r)) if uses.get(r).copied().unwrap_or(0) > 1 => {
                        format!("{r}_t{local}")
                    }
                    (None, Some(r)) => r.to_string(),
                    (None, None) => format!("t{local}"),
                };
                let (condition, at) = condition(n, reference, &named_conditions, errors);
                out.transition.push(RawTransition {
                    id: spanned(n, id),
                    from: spanned(n, OneOrMany::Many(from)),
                    to: spanned(n, OneOrMany::Many(to)),
                    condition: spanned(at, condition),
                    comment: documentation(n),
                    to_at,
                });
            }
            "macroStep" => errors.at(
                n.range().start,
                format!("chart {name}: macro steps are not read; expand the macro into its steps"),
            ),
            _ => {}
        }
    }
    out
}

/// The condition of transition `t` as ST text, and the node it is in.
fn condition<'a, 'i>(
    t: Node<'a, 'i>,
    reference: Option<&str>,
    named: &HashMap<&str, Node<'a, 'i>>,
    errors: &mut Errors<'_>,
) -> (String, Node<'a, 'i>) {
    let Some(cond) = child(t, "condition") else {
        errors.at(t.range().start, "transition without a condition".into());
        return ("FALSE".into(), t);
    };
    let body = match reference {
        Some(r) => match named.get(r) {
            Some(n) => child(*n, "body").unwrap_or(*n),
            None => {
                errors.at(
                    cond.range().start,
                    format!("the condition names transition '{r}', which this POU does not define"),
                );
                return ("FALSE".into(), cond);
            }
        },
        None => cond,
    };
    if let Some(st) = body.descendants().find(|n| n.has_tag_name("ST")) {
        return (st_text(st), st);
    }
    // A ladder or function block diagram: the logic of the output named
    // after the transition (or its only one).
    if let Some(graphic) = body
        .descendants()
        .find(|n| n.has_tag_name("LD") || n.has_tag_name("FBD"))
    {
        let name = reference.or(t.attribute("name")).unwrap_or_default();
        match crate::programs::plcopen::graphical_condition(t.document(), graphic, name) {
            Ok(text) => return (text, graphic),
            Err((at, why)) => {
                errors.at(at, format!("transition condition: {why}"));
                return ("FALSE".into(), graphic);
            }
        }
    }
    // Contacts and boxes drawn in the chart itself, wired to the
    // condition.
    if body.children().any(|n| n.has_tag_name("connectionPointIn")) {
        if let Some(chart) = t.parent() {
            match crate::programs::plcopen::connected_condition(t.document(), chart, body) {
                Ok(text) => return (text, body),
                Err((at, why)) => {
                    errors.at(at, format!("transition condition: {why}"));
                    return ("FALSE".into(), body);
                }
            }
        }
    }
    let found = body.descendants().find(|n| n.has_tag_name("IL"));
    let language = found.map_or("this form", |n| n.tag_name().name());
    errors.at(
        found.unwrap_or(body).range().start,
        format!(
            "a transition condition in {language} is not read; write it as an ST, LD or FBD body"
        ),
    );
    ("FALSE".into(), body)
}

/// Walks back from element `id` to the steps a transition leaves.
fn back(
    by_id: &HashMap<&str, Node<'_, '_>>,
    id: &str,
    out: &mut Vec<String>,
    errors: &mut Errors<'_>,
    t: Node<'_, '_>,
    depth: usize,
) {
    // A connection to nothing is reported at the connection.
    let Some(n) = by_id.get(id) else {
        return;
    };
    if depth > 64 {
        errors.at(n.range().start, "connections loop without a step".into());
        return;
    }
    match n.tag_name().name() {
        "step" => out.push(n.attribute("name").unwrap_or_default().to_string()),
        "selectionDivergence" | "simultaneousConvergence" => {
            for i in inputs(*n) {
                back(by_id, &i, out, errors, t, depth + 1);
            }
        }
        other => errors.at(
            t.range().start,
            format!("a transition follows a {other} (localId {id}); it must follow a step, a selection divergence or a simultaneous convergence"),
        ),
    }
}

/// Walks on from element `id` to the steps a transition activates, each
/// with where it is written (the `step` or the `jumpStep`).
fn on(
    next: &HashMap<String, Vec<Node<'_, '_>>>,
    id: &str,
    out: &mut Vec<(String, usize)>,
    errors: &mut Errors<'_>,
    t: Node<'_, '_>,
    depth: usize,
) {
    if depth > 64 {
        errors.at(t.range().start, "connections loop without a step".into());
        return;
    }
    for n in next.get(id).into_iter().flatten() {
        match n.tag_name().name() {
            "step" => out.push((
                n.attribute("name").unwrap_or_default().to_string(),
                n.range().start,
            )),
            "jumpStep" => out.push((
                n.attribute("targetName").unwrap_or_default().to_string(),
                n.range().start,
            )),
            "simultaneousDivergence" | "selectionConvergence" => {
                if let Some(nid) = n.attribute("localId") {
                    on(next, nid, out, errors, t, depth + 1);
                }
            }
            "actionBlock" | "comment" => {}
            other => errors.at(
                n.range().start,
                format!(
                    "a {other} follows transition (localId {id}); it must be followed by a step, a jump, a simultaneous divergence or a selection convergence"
                ),
            ),
        }
    }
}

/// Why a transition's ST condition is not read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum StConditionError {
    /// `XOR`, which the notation has no operator for.
    #[error("XOR is not read in a condition: write (a AND NOT b) OR (NOT a AND b)")]
    Xor,
    /// A character that is no operand, operator or parenthesis.
    #[error("'{found}' is not read in a condition (ST: AND, OR, NOT, parentheses, comparisons)")]
    Unread {
        /// The character.
        found: char,
    },
    /// The condition, in the paper's notation, is no expression.
    #[error("'{text}': {cause}")]
    Expr {
        /// The condition as written in ST.
        text: String,
        /// What is wrong, at a character of the condition in the paper's
        /// notation.
        cause: ExprError,
    },
}

/// An ST boolean expression in the paper's notation, then read as the
/// TOML form's conditions are.
///
/// # Errors
/// [`StConditionError`]: an operator or character the notation has not,
/// or an expression that does not parse.
pub fn st_condition(text: &str) -> Result<Expr, StConditionError> {
    let mut paper = String::new();
    let chars: Vec<char> = text.chars().collect();
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        if c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '%') {
            let start = i;
            while i < chars.len()
                && (chars[i].is_ascii_alphanumeric() || matches!(chars[i], '.' | '_' | '%'))
            {
                i += 1;
            }
            let word: String = chars[start..i].iter().collect();
            match word.to_ascii_uppercase().as_str() {
                "AND" => paper.push_str(" * "),
                "OR" => paper.push_str(" + "),
                "NOT" => paper.push_str(" -"),
                "XOR" => return Err(StConditionError::Xor),
                _ => paper.push_str(&word),
            }
            continue;
        }
        match (c, chars.get(i + 1)) {
            ('&', _) => paper.push_str(" * "),
            ('<', Some('>')) => {
                paper.push_str(" != ");
                i += 1;
            }
            ('<' | '>', Some('=')) => {
                paper.push(c);
                paper.push_str("= ");
                i += 1;
            }
            ('=', _) => paper.push_str(" == "),
            ('(' | ')' | '<' | '>' | '-', _) => paper.push(c),
            (c, _) if c.is_whitespace() => paper.push(' '),
            (c, _) => return Err(StConditionError::Unread { found: c }),
        }
        i += 1;
    }
    Expr::parse(&paper).map_err(|cause| StConditionError::Expr {
        text: text.into(),
        cause,
    })
}
