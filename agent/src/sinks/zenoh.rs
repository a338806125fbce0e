//! Zenoh: alarms, state, history and snapshot services, commands, liveliness.
