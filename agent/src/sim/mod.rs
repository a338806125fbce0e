//! Simulated cells for the demo and the tests: served over real OPC UA
//! (the CNC, the line, the robot of paper 004), or polled over the `@` protocol (moulding units).

pub mod cnc;
pub mod line;
pub mod moulding;
pub mod robot;
pub mod server;
