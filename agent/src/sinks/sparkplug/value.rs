//! A value of one of the device's metrics, as the book keeps it and the
//! store writes it: what both share, importing neither.

use super::tahu::Value;

/// A metric's value.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum MetricValue {
    /// A Boolean.
    Boolean(bool),
    /// A string.
    Text(String),
    /// A count.
    UInt64(u64),
    /// A number.
    Double(f64),
}

impl MetricValue {
    pub(super) fn into_value(self) -> Value {
        match self {
            MetricValue::Boolean(b) => Value::BooleanValue(b),
            MetricValue::Text(s) => Value::StringValue(s),
            MetricValue::UInt64(n) => Value::LongValue(n),
            MetricValue::Double(x) => Value::DoubleValue(x),
        }
    }
}
