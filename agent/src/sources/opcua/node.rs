//! Where a tag's node lives, and how that is found on the server.
//!
//! A namespace index is the server's choice and may change when the server
//! restarts (another namespace registered first, a new firmware): an index
//! read blindly can land on another namespace holding the same names. So a
//! tag names its namespace by URI — `nsu=<uri>;s=X0.06`, or `ns=2;s=X0.06`
//! with `opcua.namespace_uri` saying what index 2 meant — and the source
//! looks the URI up in the server's `NamespaceArray` at every connect.
//! `ns=<index>` without a URI is still read, trusted as is (the
//! configuration warns).

use std::str::FromStr;

use opcua::types::{Identifier, NodeId};

/// The OPC UA namespace every server has at index 0.
const STANDARD: &str = "http://opcfoundation.org/UA/";

/// A tag's namespace.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Namespace {
    /// Named by URI: resolved against the server's namespace array.
    Uri(String),
    /// A bare index, trusted as is.
    Index(u16),
}

/// A tag's node: its namespace and its identifier in it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TagNode {
    /// Which namespace.
    pub namespace: Namespace,
    /// The identifier (`s=X0.06`, `i=1001`, ...).
    pub identifier: Identifier,
}

/// Why a text is not a node id (the text).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NodeIdError {
    /// Not of a node id's form.
    #[error("'{0}' is not a node id like nsu=<namespace uri>;s=X0.06 or ns=2;s=X0.06")]
    NotANodeId(String),
    /// `nsu=` with nothing before the identifier.
    #[error("'{0}' names an empty namespace uri")]
    EmptyNamespaceUri(String),
}

impl TagNode {
    /// Reads `nsu=<uri>;<id>` or `ns=<index>;<id>` (or a bare `<id>`, in
    /// namespace 0). With `namespace_uri`, an index other than 0 stands for
    /// that URI. In a URI, `%3B` is a `;` and `%25` a `%`.
    ///
    /// # Errors
    /// The text is not a node id; the message says what was expected.
    pub fn parse(text: &str, namespace_uri: Option<&str>) -> Result<TagNode, NodeIdError> {
        let expected = || NodeIdError::NotANodeId(text.into());
        if let Some(rest) = text.strip_prefix("nsu=") {
            let split = [";s=", ";i=", ";g=", ";b="]
                .iter()
                .filter_map(|k| rest.find(k))
                .min()
                .ok_or_else(expected)?;
            let uri = unescape(&rest[..split]);
            if uri.is_empty() {
                return Err(NodeIdError::EmptyNamespaceUri(text.into()));
            }
            let id = NodeId::from_str(&format!("ns=1;{}", &rest[split + 1..]))
                .map_err(|_| expected())?;
            return Ok(TagNode {
                namespace: Namespace::Uri(uri),
                identifier: id.identifier,
            });
        }
        let id = NodeId::from_str(text).map_err(|_| expected())?;
        let namespace = match (id.namespace, namespace_uri) {
            (0, _) => Namespace::Uri(STANDARD.into()),
            (_, Some(uri)) => Namespace::Uri(uri.into()),
            (index, None) => Namespace::Index(index),
        };
        Ok(TagNode {
            namespace,
            identifier: id.identifier,
        })
    }

    /// The node id on a server whose namespace array is `namespaces`, or
    /// `None` when the server has no such namespace.
    pub fn resolve(&self, namespaces: &[String]) -> Option<NodeId> {
        let index = match &self.namespace {
            Namespace::Index(i) => *i,
            Namespace::Uri(uri) => u16::try_from(namespaces.iter().position(|n| n == uri)?).ok()?,
        };
        Some(NodeId::new(index, self.identifier.clone()))
    }

    /// The index written in the configuration, when it is a bare index.
    pub fn bare_index(&self) -> Option<u16> {
        match self.namespace {
            Namespace::Index(i) => Some(i),
            Namespace::Uri(_) => None,
        }
    }
}

fn unescape(uri: &str) -> String {
    uri.replace("%3B", ";")
        .replace("%3b", ";")
        .replace("%25", "%")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ns() -> Vec<String> {
        [
            "http://opcfoundation.org/UA/",
            "urn:server",
            "urn:decoy",
            "urn:plc;v2",
        ]
        .map(String::from)
        .to_vec()
    }

    #[test]
    fn uris_are_looked_up_and_indices_trusted() {
        let t = TagNode::parse("nsu=urn:plc%3Bv2;s=X0.06", None).unwrap();
        assert_eq!(t.namespace, Namespace::Uri("urn:plc;v2".into()));
        assert_eq!(t.resolve(&ns()), Some(NodeId::new(3, "X0.06")));
        let t = TagNode::parse("ns=2;s=X0.06", Some("urn:plc;v2")).unwrap();
        assert_eq!(t.resolve(&ns()), Some(NodeId::new(3, "X0.06")));
        let t = TagNode::parse("ns=2;i=1001", None).unwrap();
        assert_eq!(t.bare_index(), Some(2));
        assert_eq!(t.resolve(&ns()), Some(NodeId::new(2, 1001u32)));
        let t = TagNode::parse("i=2258", Some("urn:plc;v2")).unwrap();
        assert_eq!(t.resolve(&ns()), Some(NodeId::new(0, 2258u32)));
        // Identifiers may hold `;` and `=`.
        let t = TagNode::parse("nsu=urn:decoy;s=a;b=c", None).unwrap();
        assert_eq!(t.resolve(&ns()), Some(NodeId::new(2, "a;b=c")));
    }

    #[test]
    fn a_missing_namespace_resolves_to_nothing() {
        let t = TagNode::parse("nsu=urn:gone;s=X0.06", None).unwrap();
        assert_eq!(t.resolve(&ns()), None);
    }

    #[test]
    fn bad_node_ids_are_refused() {
        for bad in [
            "two;X1",
            "nsu=urn:x",
            "nsu=;s=X",
            "nsu=urn:x;q=1",
            "ns=x;s=1",
        ] {
            assert!(TagNode::parse(bad, None).is_err(), "{bad}");
        }
    }
}
