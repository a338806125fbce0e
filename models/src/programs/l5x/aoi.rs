//! Add-On Instructions expanded where a rung calls them: the definition's
//! `Logic` routine run in place, its parameters and local tags bound to
//! the call's operands, and the names its logic uses resolved through
//! those bindings. What each instruction of the logic does is
//! `instructions.rs`'s; the routines and rungs are `l5x/mod.rs`'s.
//!
//! A call `Permissive(Perm1,Guard_Closed,Air_OK,Perm_OK)` names the
//! instance tag and then one operand per required parameter, in the
//! definition's order. Inside the logic an input given an operand reads
//! that operand (the caller's tag, `Guard_Closed`, or a number) until the
//! logic writes it; an `InOut` is the caller's tag itself; every other
//! parameter and local tag is a member of the instance (`Perm1.Out`,
//! `Perm1.LocalBool`). After the logic each required output is copied to
//! its operand, as the controller does. `EnableIn` reads true in the
//! logic, which runs only on a true rung: a call on a rung that may be
//! false makes what its logic writes not derivable, as a conditional
//! `JSR` does. The rung goes on with the call's rung condition, or with
//! `EnableOut` where the logic writes it.

use std::cell::RefCell;
use std::collections::{HashMap, HashSet};
use std::rc::Rc;

use roxmltree::Node;

use super::names::{number, split, NotSignal};
use super::scope::{Access, Argument, Binding, Scope};
use super::{Frame, Ins, Reader, RungCtx, MAX_CALL_DEPTH};
use crate::programs::plcopen::{emit, Flow};
use crate::programs::{Instruction, Operand, Operation, Outside};
use crate::signal::Signal;

/// A parameter of a definition, as declared.
struct Parameter<'d> {
    name: &'d str,
    usage: &'d str,
    required: bool,
    alias_for: Option<&'d str>,
}

impl Scope {
    /// Whether `signal` is a member of this call's instance.
    pub(super) fn holds_member(&self, signal: &str) -> bool {
        signal
            .get(..self.instance.len() + 1)
            .is_some_and(|head| head.eq_ignore_ascii_case(&format!("{}.", self.instance)))
    }
}

impl<'d> Reader<'_, 'd> {
    /// A tag reference in `frame` as a signal name: through the bindings
    /// of the Add-On Instruction whose logic is running, if any.
    pub(super) fn signal(
        &mut self,
        frame: &Frame<'d>,
        text: &str,
        access: Access,
    ) -> Result<String, NotSignal> {
        self.signal_in(frame.program, frame.aoi.as_deref(), text, access)
    }

    /// [`Reader::signal`] given the frame's program and bindings.
    pub(super) fn signal_in(
        &mut self,
        program: &str,
        scope: Option<&Scope>,
        text: &str,
        access: Access,
    ) -> Result<String, NotSignal> {
        let Some(scope) = scope else {
            return self.names.signal(Some(program), text);
        };
        let (base, rest) = split(text)?;
        let lower = base.to_ascii_lowercase();
        let member = |m: &str| format!("{}.{m}{rest}", scope.instance);
        let address = match scope.bound.get(&lower) {
            None => return self.names.signal(Some(program), text),
            Some(Binding::Member(m)) => member(m),
            Some(Binding::Reference(r)) => format!("{r}{rest}"),
            Some(Binding::Input {
                member: m,
                argument,
            }) => {
                if access == Access::Write {
                    scope.written.borrow_mut().insert(lower);
                    member(m)
                } else if scope.written.borrow().contains(&lower) {
                    member(m)
                } else {
                    match argument {
                        Argument::Signal(s) => format!("{s}{rest}"),
                        Argument::Number(n) if rest.is_empty() => {
                            return Err(NotSignal::Number(n.clone()))
                        }
                        Argument::Number(_) => member(m),
                    }
                }
            }
        };
        Ok(self.names.named(address))
    }

    /// A call of the Add-On Instruction `definition`: its logic run here
    /// with the call's operands bound; returns what flows on the rung.
    pub(super) fn add_on(
        &mut self,
        i: &Ins,
        definition: Node<'d, 'd>,
        flow: Flow,
        rung: &mut RungCtx<'_, 'd>,
        reached: &mut HashSet<String>,
    ) -> Flow {
        let name = definition.attribute("Name").unwrap_or(&i.name);
        self.called.insert(name.to_ascii_uppercase());
        let place = self.place(rung.text, i.at);
        let parameters = parameters(definition);
        let required: Vec<&Parameter> = parameters.iter().filter(|p| p.required).collect();
        if i.args.len() != required.len() + 1 {
            let asked: Vec<&str> = required.iter().map(|p| p.name).collect();
            let why = format!(
                "'{}' gives {} operands, Add-On Instruction '{name}' takes {} (its instance, then {}): what follows it on the rung is not derivable",
                i.text,
                i.args.len(),
                required.len() + 1,
                if asked.is_empty() { "nothing".to_string() } else { asked.join(", ") }
            );
            return Flow::and(vec![flow, self.unread(i, rung, why)]);
        }
        let instance_text = &i.args[0].1;
        let instance = match self.signal(rung.frame, instance_text, Access::Write) {
            Ok(s) => s,
            Err(_) => {
                let why = format!(
                    "'{}': its instance '{instance_text}' is not a tag: what follows it on the rung is not derivable",
                    i.text
                );
                return Flow::and(vec![flow, self.unread(i, rung, why)]);
            }
        };
        let key = format!("AOI {}", name.to_ascii_uppercase());
        if rung.frame.calls.contains(&key) || rung.frame.calls.len() >= MAX_CALL_DEPTH {
            let why = format!(
                "'{}': Add-On Instruction '{name}' is already running (calls deeper than {MAX_CALL_DEPTH}): not run again",
                i.text
            );
            return Flow::and(vec![flow, self.unread(i, rung, why)]);
        }
        let Some(logic) = routines(definition).find(|r| r.attribute("Name") == Some("Logic"))
        else {
            let why = format!(
                "'{}': Add-On Instruction '{name}' has no Logic routine in this export: what follows it on the rung is not derivable",
                i.text
            );
            return Flow::and(vec![flow, self.unread(i, rung, why)]);
        };
        let mut bound: HashMap<String, Binding> = HashMap::new();
        let mut copies: Vec<(String, Signal)> = Vec::new();
        let mut operands = i.args[1..].iter();
        for p in &parameters {
            let lower = p.name.to_ascii_lowercase();
            let binding = if let Some(target) = p.alias_for {
                Binding::Member(target.to_string())
            } else if lower == "enablein" {
                Binding::Input {
                    member: p.name.to_string(),
                    argument: Argument::Number("1".into()),
                }
            } else if !p.required {
                Binding::Member(p.name.to_string())
            } else {
                let Some((_, text)) = operands.next() else {
                    continue;
                };
                match p.usage {
                    "InOut" => match self.signal(rung.frame, text, Access::Read) {
                        Ok(s) => Binding::Reference(s),
                        Err(_) => {
                            let why = format!(
                                "'{}': '{text}' given for InOut parameter {} is not a tag: what follows it on the rung is not derivable",
                                i.text, p.name
                            );
                            return Flow::and(vec![flow, self.unread(i, rung, why)]);
                        }
                    },
                    "Output" => {
                        match self.signal(rung.frame, text, Access::Write) {
                            Ok(s) => copies.push((p.name.to_string(), Signal::new(&s))),
                            Err(NotSignal::Indirect(_)) => {
                                self.outside(i, place, Outside::Indirect);
                            }
                            Err(_) => {}
                        }
                        Binding::Member(p.name.to_string())
                    }
                    _ => {
                        let argument = if number(text).is_some() {
                            Some(Argument::Number(text.clone()))
                        } else {
                            match self.signal(rung.frame, text, Access::Read) {
                                Ok(s) => Some(Argument::Signal(s)),
                                Err(NotSignal::Number(n)) => Some(Argument::Number(n)),
                                Err(_) => None,
                            }
                        };
                        match argument {
                            Some(argument) => Binding::Input {
                                member: p.name.to_string(),
                                argument,
                            },
                            None => Binding::Member(p.name.to_string()),
                        }
                    }
                }
            };
            bound.insert(lower, binding);
        }
        for local in local_tags(definition) {
            bound
                .entry(local.to_ascii_lowercase())
                .or_insert_with(|| Binding::Member(local.to_string()));
        }
        let guard = self.call_guard(
            i,
            &flow,
            rung,
            place,
            &format!("the logic of Add-On Instruction '{name}'"),
        );
        let scope = Rc::new(Scope {
            instance: instance.clone(),
            bound,
            written: RefCell::new(HashSet::new()),
        });
        let mut calls = rung.frame.calls.clone();
        calls.push(key);
        let by_name: HashMap<String, Node<'d, 'd>> = routines(definition)
            .filter_map(|r| Some((r.attribute("Name")?.to_ascii_uppercase(), r)))
            .collect();
        let frame = Frame {
            program: rung.frame.program,
            routines: Rc::new(by_name),
            routine: format!("Logic of {name}({instance_text})"),
            calls,
            guard: guard.clone(),
            aoi: Some(Rc::clone(&scope)),
        };
        self.routine(logic, &frame, reached);
        for (member, target) in copies {
            self.ids += 1;
            let from = Signal::new(&self.names.named(format!("{instance}.{member}")));
            let value = Flow::and(vec![guard.clone(), Flow::Lit(from, false, self.ids)]);
            emit(&value, place, &mut self.out);
            self.out.push(Instruction {
                at: place,
                text: format!("{}({target})", i.name),
                mnemonic: i.name.clone(),
                operation: Operation::Write { negated: false },
                operand: Some(Operand::Signal(target)),
                operand_at: place,
            });
        }
        if scope.written.borrow().contains("enableout") {
            self.ids += 1;
            let out = Signal::new(&self.names.named(format!("{instance}.EnableOut")));
            Flow::and(vec![flow, Flow::Lit(out, false, self.ids)])
        } else {
            flow
        }
    }
}

/// A definition's parameters, in order.
fn parameters<'d>(definition: Node<'d, 'd>) -> Vec<Parameter<'d>> {
    definition
        .children()
        .filter(|c| c.has_tag_name("Parameters"))
        .flat_map(|c| c.children())
        .filter(|p| p.has_tag_name("Parameter"))
        .filter_map(|p| {
            Some(Parameter {
                name: p.attribute("Name")?,
                usage: p.attribute("Usage").unwrap_or("Input"),
                required: p.attribute("Required") == Some("true"),
                alias_for: p
                    .attribute("AliasFor")
                    .filter(|_| p.attribute("TagType") == Some("Alias")),
            })
        })
        .collect()
}

fn local_tags<'d>(definition: Node<'d, 'd>) -> impl Iterator<Item = &'d str> {
    definition
        .children()
        .filter(|c| c.has_tag_name("LocalTags"))
        .flat_map(|c| c.children())
        .filter(|t| t.has_tag_name("LocalTag"))
        .filter_map(|t| t.attribute("Name"))
}

fn routines<'d>(definition: Node<'d, 'd>) -> impl Iterator<Item = Node<'d, 'd>> {
    definition
        .children()
        .filter(|c| c.has_tag_name("Routines"))
        .flat_map(|c| c.children())
        .filter(|r| r.has_tag_name("Routine"))
}
