//! Simulated cells, served over real OPC UA, for the demo and the tests.

pub mod cnc;
pub mod line;
pub mod server;
