//! Programs from Rockwell Studio 5000 Logix Designer exports (`.L5X`,
//! root `RSLogix5000Content`): the ladder (RLL) routines of every program,
//! as IEC instructions, and the tags' descriptions as comments.
//!
//! A rung's neutral text (`XIC(a)[XIO(b),XIC(c)]OTE(d);`, read by
//! `rung.rs`) is power flow, as in a PLCopen ladder: series is AND,
//! branches are OR, and an output instruction (`OTE`, `OTL`, `OTU`,
//! `TON`, `MOV`, `JSR`, ...) passes its rung condition on, so a branch may
//! end in one and the rung go on. Each coil's flow becomes the
//! instructions that compute and write it (the same ones the PLCopen
//! reader makes), located at the instruction inside the rung text.
//!
//! Read as logic: `XIC`/`XIO` contacts, `OTE`/`OTL`/`OTU` coils, `AFI`,
//! comparisons `EQU` `NEQ` `GRT` `GEQ` `LES` `LEQ` of a tag with a number
//! or a tag (the comparison contact `Temp > 80` the numeric tags define)
//! and `LIM` with number limits, the `.DN`/`.TT`/`.EN` bits of timers and
//! counters as contacts, `MCR` zones (exact: a zone ANDs its condition
//! into every output in it). `JSR` runs the routine it names right there;
//! called only when its rung is true, what that routine writes is not
//! derivable. After a `JMP` (up to its `LBL`), an early `RET` or a `TND`
//! the rungs may not run every scan: their coils are not derivable.
//! Timers, counters (`TON`, `CTU`, ...) take the rung as an input;
//! `MOV` and other word instructions leave it as it is. An Add-On
//! Instruction defined in the export runs its `Logic` routine in place,
//! its parameters bound to the call's operands and the instance's members
//! (`aoi.rs`): a contact on its output is the logic inside, over the
//! caller's tags. One-shots (`ONS`, `OSR`, `OSF`), `CMP` and any
//! instruction not named here make what follows them on the rung not
//! derivable, each with a warning at its place. FBD routines are read by
//! `fbd.rs`: each output reference (`ORef`) a coil, the blocks `BAND`,
//! `BOR`, `BXOR` and `BNOT` logic. ST and SFC routines are warnings.
//! Malformed rung text is an error at the character.
//!
//! Signals (see `names.rs`): a controller tag is its name as declared
//! (`Start`, `Local:1:I.Data.3`, `Timer1.DN`); a program tag is
//! `Program:<program>.<tag>`, the name RSLinx and Logix OPC UA servers
//! give it (`Program:MainProgram.Start`). An address that an alias tag
//! names is named by the alias (`Start`, not `Local:1:I.Data.3`), so
//! that the alias and its base are one signal. Logix names ignore case:
//! each name is spelt as first seen. Indexes must be numbers (`Arr[3]`);
//! `Arr[Idx]` is an indirect address. Programs are read in the order the
//! controller runs them: each task's scheduled programs, task by task
//! (file order in an export without tasks), each from its main routine
//! and then the routines its `JSR`s call where they call them, so that a
//! coil two routines write ends with the last writer's value; a routine
//! no `JSR` reaches, a fault routine, a disabled program, one no task
//! schedules and an inhibited task's are warnings, not read.

mod aoi;
mod names;
mod rung;
mod scope;

use std::collections::{HashMap, HashSet};
use std::rc::Rc;

use roxmltree::{Document, Node};

use super::plcopen::{Flow, Parsed};
use super::{Instruction, Operation, Outside};
use crate::source::{Location, SourceError, SourceErrors};
use names::Names;
use rung::{Element, Ins};

pub(crate) use names::is_tag_name;

/// How deep `JSR`s may nest.
const MAX_CALL_DEPTH: usize = 32;

/// Whether a text is an L5X export: XML whose root is `RSLogix5000Content`.
pub(crate) fn is_l5x(text: &str) -> bool {
    let head: String = text.chars().take(2048).collect();
    head.contains("<RSLogix5000Content")
}

/// Reads every RLL routine of an export as instructions.
///
/// # Errors
/// XML that is not well-formed, an export with no controller, malformed
/// rung text or tag names, each at its line and column.
pub(crate) fn lex(origin: &str, text: &str) -> Result<Parsed, SourceErrors> {
    let options = roxmltree::ParsingOptions {
        allow_dtd: false,
        nodes_limit: 1_000_000,
        ..roxmltree::ParsingOptions::default()
    };
    let doc = Document::parse_with_options(text, options).map_err(|e| {
        let pos = e.pos();
        SourceError::new(
            origin,
            Location {
                line: pos.row as usize,
                col: pos.col as usize,
            },
            format!("not well-formed XML: {e}"),
        )
    })?;
    let root = doc.root_element();
    let Some(controller) = root.children().find(|c| c.has_tag_name("Controller")) else {
        return Err(SourceError::new(
            origin,
            at(&doc, root.range().start),
            "no <Controller> in this L5X export: nothing to read",
        )
        .into());
    };
    let mut names = Names::read(controller);
    let documentation = names.documentation(controller);
    let aois: HashMap<String, Node> = controller
        .descendants()
        .filter(|d| d.has_tag_name("AddOnInstructionDefinition"))
        .filter_map(|d| Some((d.attribute("Name")?.to_ascii_uppercase(), d)))
        .collect();
    let mut reader = Reader {
        origin,
        doc: &doc,
        names,
        aois,
        called: HashSet::new(),
        out: Vec::new(),
        errors: Vec::new(),
        cut: None,
        words: Vec::new(),
        compared: HashSet::new(),
        ids: 0,
    };
    for program in reader.in_task_order(controller) {
        reader.program(program);
    }
    reader.mark_word_writes();
    // Definitions no rung called, said first, where they are.
    let read = std::mem::take(&mut reader.out);
    for aoi in controller
        .descendants()
        .filter(|d| d.has_tag_name("AddOnInstructionDefinition"))
    {
        let name = aoi.attribute("Name").unwrap_or("?");
        if !reader.called.contains(&name.to_ascii_uppercase()) {
            reader.note(
                aoi,
                format!("Add-On Instruction '{name}' is called by no ladder rung read: its logic is not read"),
            );
        }
    }
    reader.out.extend(read);
    let Reader {
        out, mut errors, ..
    } = reader;
    errors.sort_by_key(|e| e.at);
    SourceErrors::or_ok(
        Parsed {
            instructions: out,
            documentation,
        },
        errors,
    )
}

fn at(doc: &Document<'_>, offset: usize) -> Location {
    let pos = doc.text_pos_at(offset);
    Location {
        line: pos.row as usize,
        col: pos.col as usize,
    }
}

/// A rung's text and where its characters are in the file.
struct RungText<'d> {
    text: String,
    /// Byte offset of the text's first character in the file, when the
    /// text is the file's characters as they are (CDATA, or no entities).
    base: Option<usize>,
    /// The `<Text>` element, where a position is not exact.
    node: Node<'d, 'd>,
}

/// A routine being run: its name, its program, and what holds around it.
#[derive(Clone)]
struct Frame<'d> {
    program: &'d str,
    routines: Rc<HashMap<String, Node<'d, 'd>>>,
    routine: String,
    /// The call chain, for recursion.
    calls: Vec<String>,
    /// ANDed into every output: a conditional call's reason.
    guard: Flow,
    /// The bindings of the Add-On Instruction whose logic this is.
    aoi: Option<Rc<scope::Scope>>,
}

struct Reader<'a, 'd> {
    origin: &'a str,
    doc: &'d Document<'d>,
    names: Names,
    /// Add-On Instructions defined in the export, by upper-case name.
    aois: HashMap<String, Node<'d, 'd>>,
    /// Add-On Instructions a rung called, upper case.
    called: HashSet<String>,
    out: Vec<Instruction>,
    errors: Vec<SourceError>,
    /// After a `TND`: the rest of the scan may not run.
    cut: Option<Flow>,
    /// Word instructions emitted: index in `out`, the tag written, and
    /// whether it is a member of an Add-On Instruction's instance.
    words: Vec<(usize, String, bool)>,
    /// Tags a comparison reads.
    compared: HashSet<String>,
    /// The last contact's identity (parallel legs share a start by it).
    ids: u64,
}

impl<'a, 'd> Reader<'a, 'd> {
    fn at(&self, offset: usize) -> Location {
        at(self.doc, offset)
    }

    /// A located warning (an instruction not read).
    fn note(&mut self, node: Node<'_, '_>, message: String) {
        let at = self.at(node.range().start);
        self.note_at(at, message);
    }

    fn note_at(&mut self, at: Location, message: String) {
        self.out.push(Instruction::bare(
            at,
            message,
            String::new(),
            Operation::Outside(Outside::Unread),
        ));
    }

    /// The programs in the order the controller runs them: each task's
    /// scheduled programs, task by task, as the export lists them; a
    /// program no task schedules, and an inhibited task's, said and left
    /// out. An export without tasks (a program or routine export) is read
    /// in file order.
    fn in_task_order(&mut self, controller: Node<'d, 'd>) -> Vec<Node<'d, 'd>> {
        let programs: Vec<Node> = controller
            .children()
            .filter(|c| c.has_tag_name("Programs"))
            .flat_map(|p| p.children())
            .filter(|p| p.has_tag_name("Program"))
            .collect();
        let tasks: Vec<Node> = controller
            .children()
            .filter(|c| c.has_tag_name("Tasks"))
            .flat_map(|t| t.children())
            .filter(|t| t.has_tag_name("Task"))
            .collect();
        if tasks.is_empty() {
            return programs;
        }
        let by_name: HashMap<String, Node> = programs
            .iter()
            .filter_map(|p| Some((p.attribute("Name")?.to_ascii_lowercase(), *p)))
            .collect();
        let mut order: Vec<Node> = Vec::new();
        let mut scheduled: HashSet<String> = HashSet::new();
        for task in tasks {
            let name = task.attribute("Name").unwrap_or("?");
            let inhibited = task.attribute("InhibitTask") == Some("true");
            let mut held: Vec<&str> = Vec::new();
            for s in task
                .descendants()
                .filter(|s| s.has_tag_name("ScheduledProgram"))
            {
                let Some(program) = s.attribute("Name") else {
                    continue;
                };
                scheduled.insert(program.to_ascii_lowercase());
                match by_name.get(&program.to_ascii_lowercase()) {
                    Some(_) if inhibited => held.push(program),
                    Some(p) if !order.contains(p) => order.push(*p),
                    _ => {}
                }
            }
            if !held.is_empty() {
                self.note(
                    task,
                    format!(
                        "task '{name}' is inhibited (InhibitTask=\"true\"): its programs {} are not read",
                        held.join(", ")
                    ),
                );
            }
        }
        for p in &programs {
            let name = p.attribute("Name").unwrap_or("?");
            let has_routines = p.children().any(|c| c.has_tag_name("Routines"));
            if has_routines && !scheduled.contains(&name.to_ascii_lowercase()) {
                self.note(
                    *p,
                    format!("program '{name}' is scheduled in no task, so the controller never runs it: not read"),
                );
            }
        }
        order
    }

    fn program(&mut self, program: Node<'d, 'd>) {
        let name = program.attribute("Name").unwrap_or("?");
        let routines: Vec<Node> = program
            .children()
            .filter(|c| c.has_tag_name("Routines"))
            .flat_map(|r| r.children())
            .filter(|r| r.has_tag_name("Routine"))
            .collect();
        if routines.is_empty() {
            return;
        }
        if program.attribute("Disabled") == Some("true") {
            self.note(
                program,
                format!("program '{name}' is disabled (Disabled=\"true\"): not read"),
            );
            return;
        }
        let by_name: HashMap<String, Node> = routines
            .iter()
            .filter_map(|r| Some((r.attribute("Name")?.to_ascii_uppercase(), *r)))
            .collect();
        let by_name = Rc::new(by_name);
        let frame = |routine: &str| Frame {
            program: name,
            routines: Rc::clone(&by_name),
            routine: routine.to_string(),
            calls: vec![routine.to_ascii_uppercase()],
            guard: Flow::True,
            aoi: None,
        };
        let mut reached: HashSet<String> = HashSet::new();
        match program.attribute("MainRoutineName") {
            Some(main) => match by_name.get(&main.to_ascii_uppercase()) {
                Some(&node) => self.routine(node, &frame(main), &mut reached),
                None => self.note(
                    program,
                    format!("program '{name}': main routine '{main}' is not in this export"),
                ),
            },
            None => {
                self.note(
                    program,
                    format!("program '{name}' names no main routine (a partial export): each routine is read as if it ran every scan"),
                );
                for r in &routines {
                    let routine = r.attribute("Name").unwrap_or("?");
                    if !reached.contains(&routine.to_ascii_uppercase()) {
                        self.routine(*r, &frame(routine), &mut reached);
                    }
                }
            }
        }
        let fault = program
            .attribute("FaultRoutineName")
            .map(str::to_ascii_uppercase);
        for r in &routines {
            let routine = r.attribute("Name").unwrap_or("?");
            let upper = routine.to_ascii_uppercase();
            if reached.contains(&upper) {
                continue;
            }
            let why = if fault.as_deref() == Some(upper.as_str()) {
                format!("program '{name}': fault routine '{routine}' runs only on a major fault: not read")
            } else {
                format!("program '{name}': routine '{routine}' is not called from the main routine by a JSR: not read")
            };
            self.note(*r, why);
        }
        let end = self.at(program.range().end);
        self.out.push(Instruction::bare(
            end,
            format!("end of program '{name}'"),
            String::new(),
            Operation::EndBlock,
        ));
    }

    fn routine(&mut self, node: Node<'d, 'd>, frame: &Frame<'d>, reached: &mut HashSet<String>) {
        reached.insert(frame.routine.to_ascii_uppercase());
        let ty = node.attribute("Type").unwrap_or("RLL");
        let name = &frame.routine;
        if node.attribute("Use") == Some("Reference") {
            self.note(
                node,
                format!("routine {name}: only referenced by this export (Use=\"Reference\"), its logic is not in it: not read"),
            );
            return;
        }
        if node.children().any(|c| c.has_tag_name("EncodedData")) {
            self.note(
                node,
                format!("routine {name}: protected (encoded), not read"),
            );
            return;
        }
        if ty == "FBD" {
            return self.fbd(node, frame, reached);
        }
        if ty != "RLL" {
            self.note(
                node,
                format!("routine {name}: {ty} routine not read (ladder and FBD routines are)"),
            );
            return;
        }
        let rungs: Vec<Node> = node
            .children()
            .filter(|c| c.has_tag_name("RLLContent"))
            .flat_map(|c| c.children())
            .filter(|r| r.has_tag_name("Rung"))
            .collect();
        let mut parsed: Vec<(String, RungText, Vec<Element>)> = Vec::new();
        for (i, r) in rungs.iter().enumerate() {
            let number = r
                .attribute("Number")
                .map_or_else(|| i.to_string(), str::to_string);
            let Some(text) = rung_text(self.doc, *r) else {
                continue;
            };
            match rung::parse(&text.text) {
                Ok(elements) => parsed.push((number, text, elements)),
                Err((offset, message)) => {
                    let at = self.place(&text, offset);
                    self.errors.push(SourceError::new(
                        self.origin,
                        at,
                        format!("routine {name}, rung {number}: {message}"),
                    ));
                }
            }
        }
        let guards = self.region_guards(frame, &parsed);
        let mut zone = Flow::True;
        for (k, (number, text, elements)) in parsed.iter().enumerate() {
            let mut rung = RungCtx {
                frame,
                number,
                text,
                zone: zone.clone(),
                guard: guards[k].clone(),
            };
            self.sequence(elements, Flow::True, &mut rung, reached);
            zone = rung.zone;
        }
    }

    /// The guard of each rung: after a `JMP` (up to its `LBL`, or to the
    /// end if the label comes first) or an early `RET`, a rung may not run
    /// every scan.
    fn region_guards(
        &self,
        frame: &Frame<'d>,
        rungs: &[(String, RungText, Vec<Element>)],
    ) -> Vec<Flow> {
        let mut labels: HashMap<String, usize> = HashMap::new();
        let mut jumps: Vec<(usize, String, Option<String>, Location)> = Vec::new();
        for (k, (_, text, elements)) in rungs.iter().enumerate() {
            visit(elements, &mut |i: &Ins| {
                let label = i.args.first().map(|(_, a)| a.to_ascii_uppercase());
                match i.name.to_ascii_uppercase().as_str() {
                    "LBL" => {
                        if let Some(l) = label {
                            labels.entry(l).or_insert(k);
                        }
                    }
                    "JMP" => jumps.push((k, i.text.clone(), label, self.place(text, i.at))),
                    "RET" if k + 1 < rungs.len() => {
                        jumps.push((k, i.text.clone(), None, self.place(text, i.at)))
                    }
                    _ => {}
                }
            });
        }
        let mut guards = vec![Vec::new(); rungs.len()];
        for (k, text, label, place) in jumps {
            let target = label.as_ref().and_then(|l| labels.get(l)).copied();
            let range = match target {
                Some(t) if t > k => k + 1..t,
                Some(t) => t..rungs.len(),
                None => k + 1..rungs.len(),
            };
            let why = format!(
                "routine {}, rung {}: after '{text}' the rungs may not run every scan",
                frame.routine, rungs[k].0
            );
            for g in &mut guards[range] {
                g.push(Flow::Opaque(why.clone(), place));
            }
        }
        guards.into_iter().map(Flow::and).collect()
    }

    /// Where byte `offset` of a rung's text is in the file.
    fn place(&self, text: &RungText<'_>, offset: usize) -> Location {
        match text.base {
            Some(base) => self.at(base + offset),
            None => self.at(text.node.range().start),
        }
    }

    /// Runs a series of elements on the flow `input`; returns what flows out.
    fn sequence(
        &mut self,
        elements: &[Element],
        input: Flow,
        rung: &mut RungCtx<'_, 'd>,
        reached: &mut HashSet<String>,
    ) -> Flow {
        let mut flow = input;
        for e in elements {
            flow = match e {
                Element::Ins(i) => self.instruction(i, flow, rung, reached),
                Element::Branch(_, legs) => {
                    let outs: Vec<Flow> = legs
                        .iter()
                        .map(|leg| self.sequence(leg, flow.clone(), rung, reached))
                        .collect();
                    Flow::or(outs)
                }
            };
        }
        flow
    }
}

/// The rung being run.
struct RungCtx<'r, 'd> {
    frame: &'r Frame<'d>,
    number: &'r str,
    text: &'r RungText<'d>,
    /// The `MCR` zone's condition (`True` outside a zone).
    zone: Flow,
    /// `JMP`/`RET` regions this rung is in.
    guard: Flow,
}

impl RungCtx<'_, '_> {
    /// What every output on this rung is ANDed with.
    fn prefix(&self, cut: Option<&Flow>) -> Flow {
        let mut parts = vec![
            self.frame.guard.clone(),
            self.guard.clone(),
            self.zone.clone(),
        ];
        parts.extend(cut.cloned());
        Flow::and(parts)
    }
}

/// Calls `f` on every instruction, branches included.
fn visit(elements: &[Element], f: &mut dyn FnMut(&Ins)) {
    for e in elements {
        match e {
            Element::Ins(i) => f(i),
            Element::Branch(_, legs) => legs.iter().for_each(|l| visit(l, f)),
        }
    }
}

/// A rung's `<Text>`: its CDATA section's characters, located exactly, or
/// its text.
fn rung_text<'d>(doc: &'d Document<'d>, rung: Node<'d, 'd>) -> Option<RungText<'d>> {
    let node = rung.children().find(|c| c.has_tag_name("Text"))?;
    let range = node.range();
    let raw = doc.input_text().get(range.clone())?;
    if let Some(open) = raw.find("<![CDATA[") {
        let start = open + "<![CDATA[".len();
        if let Some(len) = raw[start..].find("]]>") {
            return Some(RungText {
                text: raw[start..start + len].to_string(),
                base: Some(range.start + start),
                node,
            });
        }
    }
    let first = node.children().find(|c| c.is_text())?;
    let text = first.text().unwrap_or("").to_string();
    let base = first.range().start;
    let exact = doc.input_text().get(base..base + text.len()) == Some(text.as_str());
    Some(RungText {
        text,
        base: exact.then_some(base),
        node,
    })
}

mod fbd;
mod instructions;

#[cfg(test)]
mod tests;
