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

pub mod cli;
mod commands;
pub mod config;
mod inputs;
