//! The cell's state as OPC UA for Machinery says a machine's
//! (OPC 40001-1): a `MachineryItemState` object under the cell's, whose
//! `CurrentState` (and its `Id`, the node of the state in the Machinery
//! namespace) follows the agent's machine state, so that a SCADA or MES
//! reading machines the Machinery way reads the cell too. The namespace
//! holds the state machine's type and its four states with their
//! `StateNumber`s, as the Machinery NodeSet has them.
//!
//! Running is `Executing`, idle `NotExecuting`, a fault `OutOfService`
//! ("not functional … e.g. error, blocked"), no link to the PLC
//! `NotAvailable` (nothing is known of it), as is the state before the
//! first one arrives.

use std::sync::Arc;

use cellwatch_models::engine::StateName;
use cellwatch_models::machinery::StateMachine;
use opcua::server::address_space::{ObjectBuilder, ObjectTypeBuilder, VariableBuilder};
use opcua::server::node_manager::memory::SimpleNodeManager;
use opcua::server::SubscriptionCache;
use opcua::sync::Mutex;
use opcua::types::{
    DataTypeId, DataValue, LocalizedText, NodeId, ObjectTypeId, QualifiedName, VariableTypeId,
    Variant,
};

/// The node manager of the Machinery namespace.
pub(super) const MACHINERY: &str = "machinery";

/// `MachineryItemState_StateMachineType`'s numeric id in the namespace.
const ITEM_STATE_TYPE: u32 = 1002;

/// The state number of the agent's machine state `s`.
pub(super) fn item_state(s: Option<StateName>) -> u32 {
    match s {
        Some(StateName::Running) => 3,
        Some(StateName::Idle) => 2,
        Some(StateName::Fault) => 1,
        Some(StateName::Offline) | None => 0,
    }
}

/// The cell's `MachineryItemState`, kept as the machine state changes.
pub(super) struct ItemState {
    /// The cell's namespace's manager, where the object is.
    nodes: Arc<SimpleNodeManager>,
    subscriptions: Arc<SubscriptionCache>,
    /// The Machinery namespace's index.
    machinery_ns: u16,
    current: NodeId,
    current_id: NodeId,
    /// The state last set.
    last: Mutex<Option<StateName>>,
}

impl ItemState {
    /// Declares the Machinery namespace's type and states in `machinery`
    /// (namespace `machinery_ns`) and the cell's object under `cell_node`
    /// in `nodes` (namespace `ns`), `NotAvailable` for now.
    pub(super) fn declare(
        machinery: &SimpleNodeManager,
        machinery_ns: u16,
        nodes: Arc<SimpleNodeManager>,
        ns: u16,
        cell: &str,
        cell_node: &NodeId,
        subscriptions: Arc<SubscriptionCache>,
    ) -> ItemState {
        let ty = NodeId::new(machinery_ns, ITEM_STATE_TYPE);
        {
            let space = machinery.address_space();
            let mut space = space.write();
            ObjectTypeBuilder::new(
                &ty,
                QualifiedName::new(machinery_ns, "MachineryItemState_StateMachineType"),
                "MachineryItemState_StateMachineType",
            )
            .subtype_of(ObjectTypeId::FiniteStateMachineType)
            .insert(&mut *space);
            for (id, number, name) in StateMachine::ItemState.states() {
                let state = NodeId::new(machinery_ns, *id);
                ObjectBuilder::new(&state, QualifiedName::new(machinery_ns, *name), *name)
                    .has_type_definition(ObjectTypeId::StateType)
                    .component_of(ty.clone())
                    .insert(&mut *space);
                VariableBuilder::new(
                    &NodeId::new(machinery_ns, format!("{name}.StateNumber")),
                    "StateNumber",
                    "StateNumber",
                )
                .data_type(DataTypeId::UInt32)
                .value(*number)
                .property_of(state)
                .has_type_definition(VariableTypeId::PropertyType)
                .insert(&mut *space);
            }
        }
        let object = NodeId::new(ns, format!("{cell}.MachineryItemState"));
        let current = NodeId::new(ns, format!("{cell}.MachineryItemState.CurrentState"));
        let current_id = NodeId::new(ns, format!("{cell}.MachineryItemState.CurrentState.Id"));
        let (name, id) = Self::state(machinery_ns, None);
        {
            let space = nodes.address_space();
            let mut space = space.write();
            ObjectBuilder::new(
                &object,
                QualifiedName::new(machinery_ns, "MachineryItemState"),
                "MachineryItemState",
            )
            .has_type_definition(ty)
            .component_of(cell_node.clone())
            .insert(&mut *space);
            VariableBuilder::new(&current, "CurrentState", "CurrentState")
                .data_type(DataTypeId::LocalizedText)
                .value(Variant::from(LocalizedText::from(name)))
                .component_of(object.clone())
                .has_type_definition(VariableTypeId::FiniteStateVariableType)
                .insert(&mut *space);
            VariableBuilder::new(&current_id, "Id", "Id")
                .data_type(DataTypeId::NodeId)
                .value(id)
                .property_of(current.clone())
                .has_type_definition(VariableTypeId::PropertyType)
                .insert(&mut *space);
        }
        ItemState {
            nodes,
            subscriptions,
            machinery_ns,
            current,
            current_id,
            last: Mutex::new(None),
        }
    }

    /// The name and node of the state for machine state `s`.
    fn state(machinery_ns: u16, s: Option<StateName>) -> (&'static str, NodeId) {
        let number = item_state(s);
        let (id, _, name) = StateMachine::ItemState
            .states()
            .iter()
            .find(|(_, n, _)| *n == number)
            .copied()
            .unwrap_or((5005, 0, "NotAvailable"));
        (name, NodeId::new(machinery_ns, id))
    }

    /// The machine state is `s` now.
    pub(super) fn set(&self, s: StateName) {
        {
            let mut last = self.last.lock();
            if *last == Some(s) {
                return;
            }
            *last = Some(s);
        }
        let (name, id) = Self::state(self.machinery_ns, Some(s));
        let values = [
            (&self.current, DataValue::new_now(LocalizedText::from(name))),
            (&self.current_id, DataValue::new_now(id)),
        ];
        if let Err(e) = self.nodes.set_values(
            &self.subscriptions,
            values.iter().map(|(n, v)| (*n, None, v.clone())),
        ) {
            tracing::warn!(error = %e, "alarm server: the cell's MachineryItemState not updated");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_machine_state_is_the_machinery_item_state_that_describes_it() {
        let names: Vec<&str> = [
            Some(StateName::Running),
            Some(StateName::Idle),
            Some(StateName::Fault),
            Some(StateName::Offline),
            None,
        ]
        .into_iter()
        .map(|s| ItemState::state(3, s).0)
        .collect();
        assert_eq!(
            names,
            [
                "Executing",
                "NotExecuting",
                "OutOfService",
                "NotAvailable",
                "NotAvailable"
            ]
        );
        assert_eq!(
            ItemState::state(3, Some(StateName::Running)).1,
            NodeId::new(3, 5006u32)
        );
    }
}
