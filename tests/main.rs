//! Integration tests of the `cellwatch` binary, run as a user would: the
//! built binary, real files in temporary directories, exit statuses and
//! output compared exactly.
//!
//! One test binary with shared helpers in `util`.

#![allow(clippy::unwrap_used)] // test helpers fail loudly by design

mod agent;
mod alarm_day;
mod alarm_management;
mod alarm_server;
mod alertmanager;
mod anchor;
mod asyncua;
mod at_bus;
mod bad_input;
mod binding;
mod bounded;
mod browser;
mod cell_loop;
mod commands;
mod console;
mod cycle;
mod dashboards;
mod docs;
mod durability;
mod explain;
mod force;
mod hardening;
mod house;
mod installed;
mod interop;
mod liveness;
mod machinery;
mod mad;
mod network_cut;
mod nodes_back;
mod oee;
mod opcua;
mod operations;
mod operators;
mod papercuts;
mod plant;
mod plc_alarms;
mod quickstart;
mod real_programs;
mod recorder;
mod redundancy;
mod report;
mod restart;
mod reverse;
mod robust;
mod scheduling;
mod sf;
mod sfc;
mod sparkplug;
mod spawned;
mod stacks;
mod timers;
mod trust;
mod typed;
mod util;
