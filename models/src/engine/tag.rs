//! A tag as the engine knows it and a value as it holds one: shared by
//! the engine and its flight recorder, imported by both.

use std::sync::Arc;

use crate::signal::Signal;
use crate::value::Num;

/// A PLC tag as the engine knows it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Tag {
    /// The name used in the plant (`y_overtravel`).
    pub name: String,
    /// The PLC address the models use (`X0.06`).
    pub address: Signal,
}

/// A tag's value as the engine holds it.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// A contact.
    Bool(bool),
    /// A number.
    Num(Num),
    /// A string.
    Text(Arc<str>),
}

impl std::fmt::Display for Value {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Value::Bool(b) => write!(f, "{}", u8::from(*b)),
            Value::Num(n) => write!(f, "{n}"),
            Value::Text(t) => write!(f, "{t:?}"),
        }
    }
}
