//! cellwatch: a monitoring agent, one per manufacturing cell, that names the
//! step and the contact behind every fault of its PLC.
//!
//! This crate is the glue: command line, files, sockets and tasks. A source
//! feeds the cell loop, which runs the engine and hands each step to its
//! sinks (journal, Zenoh, metrics, console); `ARCHITECTURE.md` has the
//! picture. Everything that compiles, learns or explains lives in
//! [`cellwatch_models`], which does no I/O.
//!
//! # Layout
//! Data flows one way: sources (and the query services, which are inputs
//! too) → the cell loop's step → sinks. Nothing imports what stands above
//! it (`tests/house.rs` checks it).
//! - [`cli`]: the command line: parses it (each command module owns its
//!   arguments), dispatches, and turns outcomes into exit statuses.
//! - `commands/`: one module per command, its clap arguments with it;
//!   `commands/inputs.rs` reads programs, comment databases and snapshots
//!   from files, with errors that name the file, line and column.
//! - [`agent`]: one running agent composed: source, journal, bus, services,
//!   sinks, metrics and the cell loop, started and stopped together.
//! - [`cell`]: the cell loop and the engine built from a configuration.
//! - [`sources`]: the [`sources::Source`] trait, the OPC UA client, the `@`
//!   bus, a scripted source, PKI helpers.
//! - [`services`]: the agent's query services on the bus (history,
//!   snapshot, command): inputs to the cell loop beside the sources.
//! - [`sinks`]: the [`sinks::Sink`] trait and the sinks: the journal's
//!   adapter, Zenoh publication, metrics, the demo console.
//! - [`step`]: what one input to the cell loop caused, as every sink is
//!   given it (below both the loop and the sinks).
//! - [`journal`]: the SQLite journal, a store: writes, restores, history
//!   pages, report inputs, the command rows' hash chain.
//! - [`console`]: the operators' web console (`cellwatch console`): the
//!   plant's cells and alarms live in a browser, commands signed there.
//! - [`client`]: the bus client (ask agents, believe only what the trust
//!   file verifies), for the CLI and any plant-side process.
//! - [`bus`]: the bus itself: key layout, signed envelope, sessions,
//!   certificates.
//! - [`metrics`]: the Prometheus registry and `/metrics`.
//! - [`operator`]: signed operator commands and their gate.
//! - [`payload`]: the JSON payloads on the bus.
//! - [`config`]: the cell configuration file as a whole: read, each table
//!   validated, assembled into a [`config::CellConfig`]. It stands above
//!   the components: each component owns its table (raw, validated, its
//!   check) in its own `config.rs` (`sources/opcua/`,
//!   `sources/at_bus/`, `bus/`, `journal/`, `sinks/alertmanager/`,
//!   `sinks/sparkplug/`, `sinks/oee/`, `services/alarm_server/`), and a
//!   component reads only its own part.
//! - [`tags`]: a cell's tags as configured (address, type, deadband,
//!   export), read by the sources, the engine and the sinks.
//! - [`table`]: a component's table checked: each problem at its place.
//! - [`sim`]: simulated cells served over OPC UA.
//! - [`clock`]: wall-clock time in the models' unit.
//! - [`backoff`]: the waits between tries, doubling up to a cap.
//! - [`archive`]: the plant archive: `cellwatch router` (Zenoh's router
//!   with its storage manager and a SQLite volume) and its readers.

pub mod agent;
pub mod archive;
mod backoff;
pub mod bus;
pub mod cell;
pub mod cli;
pub mod client;
pub mod clock;
mod commands;
pub mod config;
pub mod console;
mod health;
pub mod journal;
pub mod metrics;
pub mod operator;
pub mod payload;
pub mod plant;
pub mod services;
#[cfg(feature = "simulators")]
pub mod sim;
pub mod sinks;
pub mod sources;
pub mod step;
mod table;
mod tags;
