//! cellwatch: a monitoring agent, one per manufacturing cell, that names the
//! step and the contact behind every fault of its PLC.
//!
//! This crate is the glue: command line, files, and (as they land) the OPC UA
//! source, the engine task and the Zenoh, SQLite and Prometheus sinks.
//! Everything that compiles, learns or explains lives in
//! [`cellwatch_models`], which does no I/O.
//!
//! # Layout
//! - [`cli`]: the command line (clap) and exit statuses.
//! - `commands/`: one module per command (`sf`, `explain`).
//! - `inputs`: reading programs, comment databases and snapshots from
//!   files, with errors that name the file, line and column.
//! - [`config`]: the cell configuration file, parsed and validated.
//! - [`sources`]: the OPC UA client that feeds the engine, and PKI helpers.
//! - [`sinks`]: the SQLite journal and Zenoh.
//! - [`sim`]: simulated cells served over OPC UA.
//! - [`clock`]: wall-clock time in the models' unit.

pub mod cell;
pub mod cli;
pub mod clock;
mod commands;
pub mod config;
mod inputs;
pub mod metrics;
pub mod operator;
pub mod payload;
pub mod sim;
pub mod sinks;
pub mod sources;
