//! Pure models of cellwatch: everything that compiles, learns, evaluates or
//! explains, with no I/O and no clock (time, where needed, is passed in).
//!
//! # Layout
//! - [`source`]: locations in input text and the `FILE:LINE:COL` error.
//! - [`signal`]: PLC addresses in both dialects, and observability.
//! - [`programs`]: the readers of PLC programs in every format (instruction
//!   lists in the `pmc`, `iec` and `stl` dialects, PLCopen XML, Rockwell L5X,
//!   TIA Portal SimaticML) into one instruction set.
//! - [`logic`]: step blocks (n-ary AND/OR nodes) and their terms.
//! - [`program`]: the compiler from instructions to each coil's logic.
//! - [`switching`]: a coil's switching function in observable signals,
//!   its step blocks, and printing in the paper's notation.
//! - [`explain`]: the fault step and the culprit contacts at fault time.
//! - [`comments`]: the address → comment database.
//! - [`value`]: typed tag values, comparisons used as contacts, counters.
//! - [`values`]: snapshots of signal values.
//! - [`compiled`]: many switching functions over one bitset, re-evaluated
//!   incrementally.
//! - [`expr`]: naive expression trees, the reference for tests.
//! - [`alarm`]: alarms and their ISA-18.2 lifecycle.
//! - [`engine`]: the per-cell engine: tags, check sets, alarms, machine state.
//! - [`at_bus`]: the `@`-framed serial protocol of paper 002 (frames, FCS, end codes).
//! - [`limit`]: limit alarms (HH/H/L/LL) on numbers, with deadband and delays.
//! - [`machinery`]: the state machines of OPC UA for Machinery
//!   (`MachineryItemState`, `MachineryOperationMode`) read as numbers.
//! - [`madb`]: the master alarm database a plant's team gives back: each
//!   alarm's priority, class and guidance.
//! - [`oee`]: overall equipment effectiveness per shift and day, the six
//!   big losses, from state history and a shift calendar.
//! - [`report`]: daily and monthly production reports from state history.
//! - [`timer`]: transition timers: run logs, the learner, the runtime monitor,
//!   drift warnings.

pub mod alarm;
pub mod at_bus;
pub mod comments;
pub mod compiled;
pub mod consequence;
pub mod engine;
pub mod explain;
pub mod expr;
pub mod kpi;
pub mod limit;
pub mod logic;
pub mod machinery;
pub mod madb;
pub mod oee;
pub mod program;
pub mod programs;
pub mod report;
pub mod sfc;
pub mod signal;
pub mod source;
pub mod switching;
pub mod timer;
pub mod value;
pub mod values;
