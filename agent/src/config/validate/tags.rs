//! Validating the configuration: tags.

use std::collections::{BTreeMap, HashSet};
use std::ops::Range;
use std::path::Path;
use std::str::FromStr;
use std::time::Duration;

use cellwatch_models::machinery::StateMachine;
use cellwatch_models::value::ValueType;
use toml::Spanned;

use super::Validator;
use crate::config::at_bus::BusNode;
use crate::config::node::TagNode;
use crate::config::raw;
use crate::config::{Deadband, TagConfig};

impl Validator<'_> {
    pub(super) fn tags(&mut self, mut raw: impl raw::TagRows) -> Vec<TagConfig> {
        // Indices written with `opcua.namespace_uri` (each with its first
        // tag), and a tag whose index is trusted blindly.
        let mut indices: BTreeMap<u16, usize> = BTreeMap::new();
        let mut blind: Option<(u16, String)> = None;
        // Room for every tag at once (a tags file's rows are counted by
        // its lines), not grown by doubling.
        let (least, most) = raw.size_hint();
        let mut out = Vec::with_capacity(most.unwrap_or(least));
        let mut names = HashSet::new();
        let mut addresses = HashSet::new();
        for (i, t) in raw.by_ref().enumerate() {
            let key = format!("tags[{i}]");
            if !names.insert(t.name.get_ref().clone()) {
                self.problem(
                    t.name.span(),
                    &format!("{key}.name"),
                    format!("'{}' is used by another tag", t.name.get_ref()),
                );
            }
            let uri = self.namespace_uri.as_ref().map(|(_, u)| u.as_str());
            if self.bus {
                if let Err(e) = BusNode::parse(t.node_id.get_ref()) {
                    self.problem(t.node_id.span(), &format!("{key}.node_id"), e);
                }
            } else {
                match TagNode::parse(t.node_id.get_ref(), uri) {
                    Ok(node) => {
                        if let Some(index) = written_index(t.node_id.get_ref()) {
                            indices.entry(index).or_insert(i);
                        }
                        if let Some(index) = node.bare_index().filter(|&i| i > 0) {
                            blind.get_or_insert((index, t.name.get_ref().clone()));
                        }
                    }
                    Err(e) => self.problem(t.node_id.span(), &format!("{key}.node_id"), e),
                }
            }
            let address = match self.addressing.signal(t.address.get_ref()) {
                Ok(a) => a,
                Err(e) => {
                    self.problem(t.address.span(), &format!("{key}.address"), e);
                    continue;
                }
            };
            if !addresses.insert(address.clone()) {
                self.problem(
                    t.address.span(),
                    &format!("{key}.address"),
                    format!("{address} is used by another tag"),
                );
            }
            let states =
                t.states
                    .as_ref()
                    .and_then(|s| match s.get_ref().parse::<StateMachine>() {
                        Ok(m) => Some(m),
                        Err(e) => {
                            self.problem(s.span(), &format!("{key}.states"), e);
                            None
                        }
                    });
            // A state machine's state is read as its number.
            let value_type = self.parsed(
                t.value_type.clone(),
                &format!("{key}.type"),
                if t.states.is_some() {
                    ValueType::UInt32
                } else {
                    ValueType::Boolean
                },
            );
            if let (Some(machine), Some(s)) = (states, &t.states) {
                let wrong = if self.bus {
                    Some("a tag of the `@` bus has no OPC UA state machine".to_string())
                } else if value_type != ValueType::UInt32 {
                    Some(format!(
                        "a {machine} is read as its state's number, a UInt32: leave `type` out"
                    ))
                } else if t.bit.is_some() {
                    Some(format!(
                        "a {machine} is read as its state's number: leave `bit` out"
                    ))
                } else {
                    None
                };
                if let Some(why) = wrong {
                    self.problem(s.span(), &format!("{key}.states"), why);
                }
            }
            let bit = t.bit.as_ref().and_then(|b| {
                let Some(width) = value_type.bits() else {
                    self.problem(
                        b.span(),
                        &format!("{key}.bit"),
                        format!("a bit needs an integer type; this tag is {value_type}: add type = \"Byte\" (or another integer type)"),
                    );
                    return None;
                };
                match u8::try_from(*b.get_ref()) {
                    Ok(n) if u32::from(n) < width => Some(n),
                    _ => {
                        self.problem(
                            b.span(),
                            &format!("{key}.bit"),
                            format!("{} is not a bit of a {value_type} (0..{})", b.get_ref(), width - 1),
                        );
                        None
                    }
                }
            });
            let sampling_interval = t.sampling_interval.map(|v| {
                if v.get_ref().trim() == "0" {
                    Duration::ZERO
                } else {
                    self.duration(Some(v), &format!("{key}.sampling_interval"), Duration::ZERO)
                }
            });
            let deadband = match (t.deadband, t.deadband_percent) {
                (Some(a), Some(_)) => {
                    self.problem(
                        a.span(),
                        &format!("{key}.deadband"),
                        "give deadband or deadband_percent, not both",
                    );
                    None
                }
                (Some(a), None) => self
                    .deadband(a, &format!("{key}.deadband"), value_type, 0.0..=f64::MAX)
                    .map(Deadband::Absolute),
                (None, Some(p)) => self
                    .deadband(
                        p,
                        &format!("{key}.deadband_percent"),
                        value_type,
                        0.0..=100.0,
                    )
                    .map(Deadband::Percent),
                (None, None) => None,
            };
            if t.export && !value_type.is_numeric() && value_type != ValueType::Boolean {
                self.problem(
                    t.name.span(),
                    &format!("{key}.export"),
                    format!("a {value_type} cannot be a gauge: export numbers and booleans only"),
                );
            }
            let max = t.max.and_then(|m| match value_type.max() {
                Some(top) if *m.get_ref() >= 1 && *m.get_ref() <= top => Some(*m.get_ref()),
                Some(top) => {
                    self.problem(
                        m.span(),
                        &format!("{key}.max"),
                        format!(
                            "{} is not between 1 and {top}, the largest {value_type}",
                            m.get_ref()
                        ),
                    );
                    None
                }
                None => {
                    self.problem(
                        m.span(),
                        &format!("{key}.max"),
                        format!(
                            "a counter's maximum needs an integer type; this tag is {value_type}"
                        ),
                    );
                    None
                }
            });
            out.push(TagConfig {
                name: t.name.into_inner(),
                node_id: t.node_id.into_inner(),
                address,
                comment: t.comment,
                value_type,
                bit,
                sampling_interval,
                deadband,
                export: t.export,
                max,
                states,
            });
        }
        for (offset, key, message) in raw.problems() {
            self.problem(offset..offset, &key, message);
        }
        // What follows is about the configuration file again.
        self.tags_file = None;
        if let Some((span, uri)) = self.namespace_uri.clone() {
            if indices.len() > 1 {
                let list: Vec<String> = indices.keys().map(|i| format!("ns={i}")).collect();
                self.problem(
                    span,
                    "opcua.namespace_uri",
                    format!(
                        "names one namespace ('{uri}') but the tags use {}: write their node ids as nsu=<namespace uri>;...",
                        list.join(" and ")
                    ),
                );
            } else if indices.is_empty() {
                self.warnings.push(format!(
                    "opcua.namespace_uri '{uri}' is not used: no tag is written ns=<index>;..."
                ));
            }
        }
        if let Some((index, name)) = blind {
            self.warnings.push(format!(
                "tag '{name}' (and maybe others) is written ns={index};... without opcua.namespace_uri: the index is trusted as is, and a server that renumbers its namespaces would be misread; write nsu=<namespace uri>;... or set opcua.namespace_uri"
            ));
        }
        out
    }

    /// The tags of `tags_file`: a CSV file with a header row naming its
    /// columns as the keys of a `[[tags]]` table (`name`, `node_id`,
    /// `address` required; `type`, `comment`, `bit`, `sampling_interval`,
    /// `deadband`, `deadband_percent`, `export`, `max`), one tag a row, an
    /// empty cell meaning the key is not given. Read row by row, without a
    /// document tree: a 100,000-tag cell is read in a fraction of what
    /// 100,000 TOML tables take. Problems name the file and the row's line.
    pub(super) fn tags_in_file(&mut self, file: Spanned<String>) -> Vec<TagConfig> {
        let path = self.path(file.get_ref());
        let Some(text) = self.read_text(file.span(), "tags_file", &path, "the tags file") else {
            return Vec::new();
        };
        let origin = path.display().to_string();
        // The validator places problems in the file's text; the rows are
        // read from a copy of it as they are validated.
        self.tags_file = Some((origin, text.clone()));
        self.tags(raw::CsvTags::new(&text))
    }

    pub(super) fn read_text(
        &mut self,
        span: Range<usize>,
        key: &str,
        path: &Path,
        what: &str,
    ) -> Option<String> {
        match self.files.read(path) {
            Ok(bytes) => {
                match cellwatch_models::source::text(&path.display().to_string(), &bytes, None) {
                    Ok(t) => Some(t.to_string()),
                    Err(e) => {
                        self.problems.push(e.to_string());
                        None
                    }
                }
            }
            Err(e) => {
                self.problem(
                    span,
                    key,
                    format!("cannot read {what} '{}': {e}", path.display()),
                );
                None
            }
        }
    }
}

/// The namespace index a node id is written with, when it is not 0 and not
/// given by URI.
fn written_index(node_id: &str) -> Option<u16> {
    if node_id.starts_with("nsu=") {
        return None;
    }
    opcua::types::NodeId::from_str(node_id)
        .ok()
        .map(|n| n.namespace)
        .filter(|&n| n > 0)
}
