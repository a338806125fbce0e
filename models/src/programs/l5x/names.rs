//! Logix tag names as signals: scopes, aliases, spelling, and the
//! descriptions and I/O comments that become the program's comments. It
//! reads the `<Tags>` and `<Modules>` of an export; it knows nothing of
//! rungs.

use std::collections::HashMap;

use roxmltree::Node;

/// How many aliases may chain (an alias of an alias).
const MAX_ALIAS_DEPTH: usize = 8;

/// A declared tag.
struct Tag {
    /// As declared.
    name: String,
    /// `AliasFor`, as written.
    alias_for: Option<String>,
}

/// Every declared tag by scope, and what aliases name.
pub(super) struct Names {
    /// Lower-case name → tag.
    controller: HashMap<String, Tag>,
    /// Lower-case program name → (program as declared, its tags).
    programs: HashMap<String, (String, HashMap<String, Tag>)>,
    /// Lower-case resolved address → the alias tag that names it.
    aliased: HashMap<String, String>,
    /// Lower-case signal name → its first spelling: Logix names ignore case.
    spelling: HashMap<String, String>,
}

/// Why a tag reference is not a signal.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) enum NotSignal {
    /// An index or bit number that is a tag (`Bits[Idx]`, `Word.[Bit]`).
    Indirect(String),
    /// Not a tag name at all.
    Malformed(String),
    /// A number, given as an Add-On Instruction's input (`1` for a BOOL).
    Number(String),
}

impl Names {
    /// The tags of a `<Controller>`: its own, and each program's.
    pub(super) fn read(controller: Node<'_, '_>) -> Names {
        let mut names = Names {
            controller: tags(controller),
            programs: HashMap::new(),
            aliased: HashMap::new(),
            spelling: HashMap::new(),
        };
        for program in programs(controller) {
            let name = program.attribute("Name").unwrap_or("?").to_string();
            names
                .programs
                .insert(name.to_ascii_lowercase(), (name, tags(program)));
        }
        // Each aliased address is named by its alias (the first one).
        let mut aliases: Vec<(Option<String>, String, String)> = Vec::new();
        for t in names.controller.values() {
            if let Some(a) = &t.alias_for {
                aliases.push((None, t.name.clone(), a.clone()));
            }
        }
        for (program, (_, tags)) in &names.programs {
            for t in tags.values() {
                if let Some(a) = &t.alias_for {
                    aliases.push((Some(program.clone()), t.name.clone(), a.clone()));
                }
            }
        }
        aliases.sort();
        for (program, alias, target) in aliases {
            if let Ok(address) = names.address(program.as_deref(), &target, 0) {
                let name = names.scoped(program.as_deref(), &alias);
                names
                    .aliased
                    .entry(address.to_ascii_lowercase())
                    .or_insert(name);
            }
        }
        names
    }

    /// A declared program's name as declared.
    fn program_name(&self, program: &str) -> String {
        self.programs
            .get(&program.to_ascii_lowercase())
            .map_or_else(|| program.to_string(), |(n, _)| n.clone())
    }

    /// A program tag's signal name: `Program:Main.Start`.
    fn scoped(&self, program: Option<&str>, tag: &str) -> String {
        match program {
            Some(p) => format!("Program:{}.{tag}", self.program_name(p)),
            None => tag.to_string(),
        }
    }

    /// The address a reference stands for: scope resolved, aliases
    /// followed, base spelt as declared.
    fn address(
        &self,
        program: Option<&str>,
        text: &str,
        depth: usize,
    ) -> Result<String, NotSignal> {
        let (base, rest) = split(text)?;
        let lower = base.to_ascii_lowercase();
        let local = program
            .and_then(|p| self.programs.get(&p.to_ascii_lowercase()))
            .and_then(|(_, tags)| tags.get(&lower));
        let (tag, scope) = match local {
            Some(t) => (Some(t), program),
            None => (self.controller.get(&lower), None),
        };
        let Some(tag) = tag else {
            return Ok(format!("{base}{rest}"));
        };
        match &tag.alias_for {
            Some(target) if depth < MAX_ALIAS_DEPTH => {
                Ok(format!("{}{rest}", self.address(scope, target, depth + 1)?))
            }
            Some(_) => Err(NotSignal::Malformed(format!(
                "alias '{text}' chains through more than {MAX_ALIAS_DEPTH} aliases"
            ))),
            None => Ok(format!("{}{rest}", self.scoped(scope, &tag.name))),
        }
    }

    /// The signal name of a tag reference in `program` (`None`: a
    /// controller-scoped reference): see the module doc of `l5x`.
    pub(super) fn signal(
        &mut self,
        program: Option<&str>,
        text: &str,
    ) -> Result<String, NotSignal> {
        let address = self.address(program, text, 0)?;
        Ok(self.named(address))
    }

    /// The signal name of a resolved address (a scope and aliases already
    /// followed): named by an alias of it or of a part of it, spelt as
    /// first seen.
    pub(super) fn named(&mut self, address: String) -> String {
        let named = self.aliased_name(&address).unwrap_or(address);
        self.spelling
            .entry(named.to_ascii_lowercase())
            .or_insert(named)
            .clone()
    }

    /// The alias naming `address` or a part of it (`InWord` for
    /// `Local:1:I.Data` names `Local:1:I.Data.3` `InWord.3`).
    fn aliased_name(&self, address: &str) -> Option<String> {
        let mut cut = address.len();
        loop {
            let head = &address[..cut];
            if let Some(alias) = self.aliased.get(&head.to_ascii_lowercase()) {
                return Some(format!("{alias}{}", &address[cut..]));
            }
            cut = head.rfind(['.', '['])?;
        }
    }

    /// Descriptions and comments, by signal name: a tag's description, a
    /// member's or I/O point's comment (`<Comment Operand=".DATA.3">`), and
    /// for an alias with no description of its own, what the point it
    /// names carries.
    pub(super) fn documentation(&mut self, controller: Node<'_, '_>) -> Vec<(String, String)> {
        // By lower-case address, before aliases rename them.
        let mut by_address: Vec<(Option<String>, String, String)> = Vec::new();
        let mut own: Vec<(Option<String>, String, String)> = Vec::new();
        let mut scopes: Vec<(Option<String>, Node)> = vec![(None, controller)];
        scopes.extend(programs(controller).map(|p| (p.attribute("Name").map(str::to_string), p)));
        for (scope, node) in scopes {
            for t in tag_nodes(node) {
                let Some(name) = t.attribute("Name") else {
                    continue;
                };
                if let Some(d) = text_of(t, "Description") {
                    if t.attribute("AliasFor").is_some() {
                        own.push((scope.clone(), name.to_string(), d));
                    } else {
                        by_address.push((scope.clone(), name.to_string(), d));
                    }
                }
                for (operand, c) in comments(t) {
                    by_address.push((scope.clone(), format!("{name}{operand}"), c));
                }
            }
        }
        for (tag, operand, c) in module_comments(controller) {
            by_address.push((None, format!("{tag}{operand}"), c));
        }
        let mut docs: HashMap<String, String> = HashMap::new();
        for (scope, text, comment) in by_address {
            if let Ok(s) = self.signal(scope.as_deref(), &text) {
                docs.entry(s).or_insert(comment);
            }
        }
        for (scope, text, comment) in own {
            if let Ok(s) = self.signal(scope.as_deref(), &text) {
                docs.insert(s, comment);
            }
        }
        let mut out: Vec<(String, String)> = docs.into_iter().collect();
        out.sort();
        out
    }
}

/// Splits a reference into its base tag (`Local:1:I`) and the members and
/// indexes after it (`.Data.3`, `[2].DN`), checking their spelling.
pub(super) fn split(text: &str) -> Result<(&str, &str), NotSignal> {
    let malformed = || NotSignal::Malformed(format!("'{text}' is not a tag name"));
    let base_len = text
        .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_' || c == ':'))
        .unwrap_or(text.len());
    let (base, rest) = text.split_at(base_len);
    if !base.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_') || base.ends_with(':') {
        return Err(malformed());
    }
    let mut r = rest;
    while !r.is_empty() {
        if let Some(after) = r.strip_prefix('.') {
            if after.starts_with('[') {
                return Err(NotSignal::Indirect(format!(
                    "'{text}': the bit number is a tag, so which bit is known only at run time"
                )));
            }
            let n = after
                .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                .unwrap_or(after.len());
            if n == 0 {
                return Err(malformed());
            }
            r = &after[n..];
        } else if let Some(after) = r.strip_prefix('[') {
            let close = after.find(']').ok_or_else(malformed)?;
            let index = &after[..close];
            if index.is_empty() {
                return Err(malformed());
            }
            if !index.split(',').all(|i| {
                let i = i.trim();
                !i.is_empty() && i.chars().all(|c| c.is_ascii_digit())
            }) {
                return Err(NotSignal::Indirect(format!(
                    "'{text}': the index is not a number, so which element is known only at run time"
                )));
            }
            r = &after[close + 1..];
        } else {
            return Err(malformed());
        }
    }
    if text.contains(char::is_whitespace) {
        return Err(malformed());
    }
    Ok((base, rest))
}

/// Whether `text` is spelt as a Logix tag reference (`Local:1:I.Data.3`,
/// `Program:Main.Start`, `Timer1.DN`, `Arr[2].0`), numbers for indexes.
pub(crate) fn is_tag_name(text: &str) -> bool {
    split(text).is_ok()
}

fn programs<'a, 'i>(controller: Node<'a, 'i>) -> impl Iterator<Item = Node<'a, 'i>> {
    controller
        .children()
        .filter(|c| c.has_tag_name("Programs"))
        .flat_map(|p| p.children())
        .filter(|p| p.has_tag_name("Program"))
}

fn tag_nodes<'a, 'i>(scope: Node<'a, 'i>) -> impl Iterator<Item = Node<'a, 'i>> {
    scope
        .children()
        .filter(|c| c.has_tag_name("Tags"))
        .flat_map(|t| t.children())
        .filter(|t| t.has_tag_name("Tag"))
}

fn tags(scope: Node<'_, '_>) -> HashMap<String, Tag> {
    let mut out = HashMap::new();
    for t in tag_nodes(scope) {
        let Some(name) = t.attribute("Name") else {
            continue;
        };
        out.entry(name.to_ascii_lowercase()).or_insert(Tag {
            name: name.to_string(),
            alias_for: t.attribute("AliasFor").map(|a| a.trim().to_string()),
        });
    }
    out
}

/// A child element's text (CDATA or not), whitespace collapsed; `None`
/// when empty.
pub(super) fn text_of(node: Node<'_, '_>, child: &str) -> Option<String> {
    let c = node.children().find(|c| c.has_tag_name(child))?;
    collapse(c)
}

fn collapse(node: Node<'_, '_>) -> Option<String> {
    let text: Vec<&str> = node
        .descendants()
        .filter(|n| n.is_text())
        .filter_map(|n| n.text())
        .collect();
    let joined = text.join(" ");
    let out = joined.split_whitespace().collect::<Vec<_>>().join(" ");
    (!out.is_empty()).then_some(out)
}

/// `<Comments><Comment Operand=".DATA.3">` of a tag or a module's tag.
fn comments(node: Node<'_, '_>) -> Vec<(String, String)> {
    node.children()
        .filter(|c| c.has_tag_name("Comments"))
        .flat_map(|c| c.children())
        .filter(|c| c.has_tag_name("Comment"))
        .filter_map(|c| Some((c.attribute("Operand")?.to_string(), collapse(c)?)))
        .collect()
}

/// The comments on modules' I/O points, by the tag Logix makes for the
/// connection: `Local:3:I` for a module in slot 3 of the controller's
/// chassis, `Rack1:3:I` in slot 3 of the chassis of adapter `Rack1`,
/// `Drive1:I` for a module on a network; `:O` outputs, `:C` configuration.
fn module_comments(controller: Node<'_, '_>) -> Vec<(String, String, String)> {
    let modules: Vec<Node> = controller
        .children()
        .filter(|c| c.has_tag_name("Modules"))
        .flat_map(|m| m.children())
        .filter(|m| m.has_tag_name("Module"))
        .collect();
    let mut out = Vec::new();
    for m in &modules {
        let Some(name) = m.attribute("Name") else {
            continue;
        };
        let parent = m.attribute("ParentModule").unwrap_or("");
        let slot = m
            .descendants()
            .find(|p| p.has_tag_name("Port") && p.attribute("Upstream") == Some("true"))
            .and_then(|p| Some((p.attribute("Address")?, p.attribute("Type").unwrap_or(""))));
        let prefix = match slot {
            Some((slot, _)) if parent == "Local" && name != "Local" => format!("Local:{slot}"),
            Some((slot, ty))
                if !parent.is_empty() && parent != name && !ty.contains("Ethernet") =>
            {
                format!("{parent}:{slot}")
            }
            _ => name.to_string(),
        };
        for (kind, suffix) in [("InputTag", "I"), ("OutputTag", "O"), ("ConfigTag", "C")] {
            for t in m.descendants().filter(|t| t.has_tag_name(kind)) {
                for (operand, c) in comments(t) {
                    out.push((format!("{prefix}:{suffix}"), operand, c));
                }
            }
        }
    }
    out
}

/// A Logix number: `12`, `-1`, `1.5`, `2.0e3`, `16#FF`, `2#0101_1010`, `8#17`.
pub(super) fn number(text: &str) -> Option<f64> {
    let t = text.replace('_', "");
    let (negative, t) = match t.strip_prefix('-') {
        Some(rest) => (true, rest.to_string()),
        None => (false, t),
    };
    let value = if let Some((radix, digits)) = t.split_once('#') {
        let radix: u32 = radix.parse().ok().filter(|r| matches!(r, 2 | 8 | 16))?;
        i64::from_str_radix(digits, radix).ok()? as f64
    } else if t.starts_with(|c: char| c.is_ascii_digit()) {
        t.parse::<f64>().ok().filter(|v| v.is_finite())?
    } else {
        return None;
    };
    Some(if negative { -value } else { value })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tag_names_split_and_refuse() {
        assert_eq!(split("Local:1:I.Data.3").unwrap(), ("Local:1:I", ".Data.3"));
        assert_eq!(split("Timer1.DN").unwrap(), ("Timer1", ".DN"));
        assert_eq!(split("Arr[1,2].3").unwrap(), ("Arr", "[1,2].3"));
        assert!(matches!(split("Bits[Idx]"), Err(NotSignal::Indirect(_))));
        assert!(matches!(split("Word.[Bit]"), Err(NotSignal::Indirect(_))));
        for bad in ["1abc", "a..b", "a b", "Local:", "a.", "a[", "?", ""] {
            assert!(matches!(split(bad), Err(NotSignal::Malformed(_))), "{bad}");
        }
    }
}
