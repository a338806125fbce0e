//! The state machines of OPC UA for Machinery (OPC 40001-1) a machine
//! exposes: `MachineryItemState` (is it producing?) and
//! `MachineryOperationMode` (what is it set up for?). A server says a
//! machine's state as the node id of the state object in its
//! `CurrentState/Id`; cellwatch reads it as the state's `StateNumber`, so
//! that a mode's condition or the machine-state history compares numbers.

use std::fmt;
use std::str::FromStr;

/// The namespace of OPC UA for Machinery, where the states' nodes are.
pub const NAMESPACE: &str = "http://opcfoundation.org/UA/Machinery/";

/// One of Machinery's state machines.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum StateMachine {
    /// `MachineryItemState_StateMachineType`: `NotAvailable` 0,
    /// `OutOfService` 1, `NotExecuting` 2, `Executing` 3.
    ItemState,
    /// `MachineryOperationMode_StateMachineType`: `None` 0, `Maintenance`
    /// 1, `Setup` 2, `Processing` 3.
    OperationMode,
}

impl StateMachine {
    /// Both, as configured.
    pub const ALL: [StateMachine; 2] = [StateMachine::ItemState, StateMachine::OperationMode];

    /// The states: the numeric id of each state object in [`NAMESPACE`]
    /// (from the Machinery NodeSet), its `StateNumber` and its name.
    pub fn states(self) -> &'static [(u32, u32, &'static str)] {
        match self {
            StateMachine::ItemState => &[
                (5005, 0, "NotAvailable"),
                (5004, 1, "OutOfService"),
                (5007, 2, "NotExecuting"),
                (5006, 3, "Executing"),
            ],
            StateMachine::OperationMode => &[
                (5024, 0, "None"),
                (5025, 1, "Maintenance"),
                (5027, 2, "Setup"),
                (5026, 3, "Processing"),
            ],
        }
    }

    /// The `StateNumber` of the state whose node is `i=id` in
    /// [`NAMESPACE`]; `None` for a node that is none of this machine's.
    pub fn number(self, id: u32) -> Option<u32> {
        self.states()
            .iter()
            .find(|(node, _, _)| *node == id)
            .map(|(_, n, _)| *n)
    }

    /// The name of state number `n`.
    pub fn name_of(self, n: u32) -> Option<&'static str> {
        self.states()
            .iter()
            .find(|(_, number, _)| *number == n)
            .map(|(_, _, name)| *name)
    }

    /// The name as configured (`MachineryItemState`).
    pub fn as_str(self) -> &'static str {
        match self {
            StateMachine::ItemState => "MachineryItemState",
            StateMachine::OperationMode => "MachineryOperationMode",
        }
    }
}

impl fmt::Display for StateMachine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A name that is none of Machinery's state machines.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("'{0}' is not a state machine of OPC UA for Machinery: MachineryItemState or MachineryOperationMode")]
pub struct NotAStateMachine(pub String);

impl FromStr for StateMachine {
    type Err = NotAStateMachine;

    fn from_str(s: &str) -> Result<StateMachine, NotAStateMachine> {
        StateMachine::ALL
            .into_iter()
            .find(|m| m.as_str() == s)
            .ok_or_else(|| NotAStateMachine(s.into()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_state_node_reads_as_its_state_number_and_only_its_machines() {
        assert_eq!(StateMachine::ItemState.number(5004), Some(1));
        assert_eq!(StateMachine::ItemState.number(5006), Some(3));
        assert_eq!(StateMachine::OperationMode.number(5027), Some(2));
        // A node of the other machine is none of this one's.
        assert_eq!(StateMachine::ItemState.number(5027), None);
        assert_eq!(StateMachine::OperationMode.name_of(1), Some("Maintenance"));
        assert_eq!(
            "MachineryOperationMode".parse(),
            Ok(StateMachine::OperationMode)
        );
        assert!("MachineryState".parse::<StateMachine>().is_err());
        // Numbers 0..3, each once.
        for m in StateMachine::ALL {
            let mut numbers: Vec<u32> = m.states().iter().map(|s| s.1).collect();
            numbers.sort_unstable();
            assert_eq!(numbers, [0, 1, 2, 3]);
        }
    }
}
