//! Tags that are a state machine of OPC UA for Machinery (`states` in a
//! tag's configuration): the node is the machine's `CurrentState/Id`, whose
//! value is the node id of the state it is in; the engine reads the state's
//! number (`Executing` 3). The state objects are in the Machinery
//! namespace, whose index each server gives: learnt from its namespace
//! array when the subscription is made.

use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::Arc;

use cellwatch_models::engine::Reading;
use cellwatch_models::machinery::{StateMachine, NAMESPACE};
use cellwatch_models::value::{Num, ValueType};
use opcua::types::{Identifier, Variant};

/// The index of the Machinery namespace on the server, shared by every tag
/// that reads a state machine; `u32::MAX` while not known or absent.
#[derive(Debug, Clone)]
pub(super) struct MachineryNamespace(Arc<AtomicU32>);

impl Default for MachineryNamespace {
    fn default() -> MachineryNamespace {
        MachineryNamespace(Arc::new(AtomicU32::new(u32::MAX)))
    }
}

impl MachineryNamespace {
    /// The server's namespace array is `namespaces`.
    pub(super) fn learn(&self, namespaces: &[String]) {
        let index = namespaces
            .iter()
            .position(|u| u == NAMESPACE)
            .and_then(|i| u32::try_from(i).ok())
            .unwrap_or(u32::MAX);
        self.0.store(index, Ordering::Relaxed);
    }

    /// The reading of value `v` of a `machine`'s `CurrentState/Id`: its
    /// state's number; a node id of no state of that machine is a wrong
    /// value, as a value of another type is.
    pub(super) fn reading(&self, machine: StateMachine, v: &Variant) -> Reading {
        let wrong = || Reading::WrongType {
            expected: ValueType::UInt32,
            received: None,
        };
        let Variant::NodeId(id) = v else {
            return wrong();
        };
        let ns = self.0.load(Ordering::Relaxed);
        match &id.identifier {
            Identifier::Numeric(n) if u32::from(id.namespace) == ns => machine
                .number(*n)
                .map_or_else(wrong, |s| Reading::Number(Num::UInt(u64::from(s)))),
            _ => wrong(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use opcua::types::NodeId;

    #[test]
    fn a_state_node_of_the_machinery_namespace_reads_as_its_number() {
        let ns = MachineryNamespace::default();
        let executing = Variant::from(NodeId::new(3, 5006u32));
        // Before the namespace array is known: nothing is believed.
        assert!(matches!(
            ns.reading(StateMachine::ItemState, &executing),
            Reading::WrongType { .. }
        ));
        ns.learn(&[
            "http://opcfoundation.org/UA/".into(),
            "urn:plc".into(),
            "http://opcfoundation.org/UA/DI/".into(),
            NAMESPACE.into(),
        ]);
        assert_eq!(
            ns.reading(StateMachine::ItemState, &executing),
            Reading::Number(Num::UInt(3))
        );
        let setup = Variant::from(NodeId::new(3, 5027u32));
        assert_eq!(
            ns.reading(StateMachine::OperationMode, &setup),
            Reading::Number(Num::UInt(2))
        );
        // The same number in another namespace, a state of the other
        // machine, a value that is no node id: wrong, not a state.
        for (machine, v) in [
            (
                StateMachine::ItemState,
                Variant::from(NodeId::new(1, 5006u32)),
            ),
            (StateMachine::ItemState, setup.clone()),
            (StateMachine::ItemState, Variant::from(3u32)),
        ] {
            assert!(
                matches!(ns.reading(machine, &v), Reading::WrongType { .. }),
                "{v:?}"
            );
        }
    }
}
