//! Transition timers (paper 001): learn `δ(A, E | Δt) = B` from the signal
//! logs of normal runs, and check at run time that each event comes neither
//! too early nor too late.
//!
//! - [`log`]: run logs (CSV and the paper's numeric form);
//! - [`learn`]: the learner (the paper's full-state method) and the model
//!   file it writes;
//! - [`monitor`]: the runtime monitor, fed changes and the passing of time;
//! - [`line`]: a simulated body-shop line that writes runs, normal or faulty;
//! - [`checks`]: timers as engine checks, with latched alarms;
//! - [`awaits`]: what a transition's alarm waits for, and whether it would
//!   have come without another alarm's fault;
//! - [`drift`]: each transition's recent durations in fixed memory, and
//!   the warning when they drift towards a limit;
//! - [`st`]: the diagnosis functions as IEC 61131-3 Structured Text.

pub mod awaits;
pub mod checks;
pub mod drift;
pub mod learn;
pub mod line;
pub mod log;
pub mod monitor;
pub mod st;
