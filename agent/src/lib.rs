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
//! - [`cli`]: the command line: parses it (each command module owns its
//!   arguments), dispatches, and turns outcomes into exit statuses.
//! - `commands/`: one module per command, its clap arguments with it;
//!   `commands/inputs.rs` reads programs, comment databases and snapshots
//!   from files, with errors that name the file, line and column.
//! - [`config`]: the cell configuration file, parsed and validated.
//! - [`cell`]: the cell loop, the engine built from a configuration, and a
//!   running agent's wiring.
//! - [`sources`]: the [`sources::Source`] trait, the OPC UA client, a
//!   scripted source, PKI helpers.
//! - [`step`]: what one input to the cell loop caused, as every sink is
//!   given it (below both the loop and the sinks).
//! - [`sinks`]: the [`sinks::Sink`] trait, the SQLite journal, Zenoh
//!   (publication and services), the demo console.
//! - [`metrics`]: Prometheus metrics, their sink and `/metrics`.
//! - [`operator`]: signed operator commands and their gate.
//! - [`payload`]: the JSON payloads on the bus.
//! - [`sim`]: simulated cells served over OPC UA.
//! - [`clock`]: wall-clock time in the models' unit.

pub mod cell;
pub mod cli;
pub mod clock;
mod commands;
pub mod config;
pub mod metrics;
pub mod operator;
pub mod payload;
pub mod sim;
pub mod sinks;
pub mod sources;
pub mod step;
