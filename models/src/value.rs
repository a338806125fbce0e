//! Typed tag values: the OPC UA scalar types a tag may have, numbers as the
//! PLC gave them, comparisons of numbers used as contacts, and production
//! counters that wrap and reset.
//!
//! Booleans stay plain `bool` everywhere (the engine's fast path); numbers
//! travel as [`Num`], which keeps integers exact (a 64-bit part counter is
//! not rounded through `f64`).

use std::fmt;
use std::str::FromStr;

use crate::signal::Signal;

/// The scalar data types of OPC UA (Part 6) a tag may carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ValueType {
    /// `Boolean`.
    Boolean,
    /// `SByte`, 8-bit signed.
    SByte,
    /// `Byte`, 8-bit unsigned.
    Byte,
    /// `Int16`.
    Int16,
    /// `UInt16`.
    UInt16,
    /// `Int32`.
    Int32,
    /// `UInt32`.
    UInt32,
    /// `Int64`.
    Int64,
    /// `UInt64`.
    UInt64,
    /// `Float`, 32-bit IEEE 754.
    Float,
    /// `Double`, 64-bit IEEE 754.
    Double,
    /// `String`.
    String,
    /// `DateTime` (carried as ms since the Unix epoch).
    DateTime,
}

impl ValueType {
    /// Every type, in OPC UA's order.
    pub const ALL: [ValueType; 13] = [
        ValueType::Boolean,
        ValueType::SByte,
        ValueType::Byte,
        ValueType::Int16,
        ValueType::UInt16,
        ValueType::Int32,
        ValueType::UInt32,
        ValueType::Int64,
        ValueType::UInt64,
        ValueType::Float,
        ValueType::Double,
        ValueType::String,
        ValueType::DateTime,
    ];

    /// The OPC UA name (`UInt16`).
    pub fn as_str(self) -> &'static str {
        match self {
            ValueType::Boolean => "Boolean",
            ValueType::SByte => "SByte",
            ValueType::Byte => "Byte",
            ValueType::Int16 => "Int16",
            ValueType::UInt16 => "UInt16",
            ValueType::Int32 => "Int32",
            ValueType::UInt32 => "UInt32",
            ValueType::Int64 => "Int64",
            ValueType::UInt64 => "UInt64",
            ValueType::Float => "Float",
            ValueType::Double => "Double",
            ValueType::String => "String",
            ValueType::DateTime => "DateTime",
        }
    }

    /// Integers of any width and sign.
    pub fn is_integer(self) -> bool {
        self.bits().is_some()
    }

    /// Integers and floating point numbers (and times, which compare as
    /// numbers).
    pub fn is_numeric(self) -> bool {
        self.is_integer() || matches!(self, ValueType::Float | ValueType::Double)
    }

    /// The width of an integer type.
    pub fn bits(self) -> Option<u32> {
        match self {
            ValueType::SByte | ValueType::Byte => Some(8),
            ValueType::Int16 | ValueType::UInt16 => Some(16),
            ValueType::Int32 | ValueType::UInt32 => Some(32),
            ValueType::Int64 | ValueType::UInt64 => Some(64),
            _ => None,
        }
    }

    /// The largest value of an integer type: where a counter wraps.
    pub fn max(self) -> Option<u64> {
        Some(match self {
            ValueType::SByte => i8::MAX as u64,
            ValueType::Byte => u8::MAX as u64,
            ValueType::Int16 => i16::MAX as u64,
            ValueType::UInt16 => u16::MAX as u64,
            ValueType::Int32 => i32::MAX as u64,
            ValueType::UInt32 => u32::MAX as u64,
            ValueType::Int64 => i64::MAX as u64,
            ValueType::UInt64 => u64::MAX,
            _ => return None,
        })
    }
}

impl fmt::Display for ValueType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A value type's name that is none of [`ValueType::ALL`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown type '{text}': use one of {}", ValueType::ALL.map(ValueType::as_str).join(", "))]
pub struct UnknownValueType {
    /// The name as given.
    pub text: String,
}

impl FromStr for ValueType {
    type Err = UnknownValueType;

    fn from_str(s: &str) -> Result<Self, UnknownValueType> {
        ValueType::ALL
            .into_iter()
            .find(|t| t.as_str().eq_ignore_ascii_case(s))
            .ok_or_else(|| UnknownValueType { text: s.into() })
    }
}

/// A number as the PLC gave it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Num {
    /// A signed integer (and `DateTime`, as ms since the epoch).
    Int(i64),
    /// An unsigned integer.
    UInt(u64),
    /// A floating point number.
    Float(f64),
}

impl Num {
    /// The value as `f64`, for comparisons and gauges.
    pub fn as_f64(self) -> f64 {
        match self {
            Num::Int(v) => v as f64,
            Num::UInt(v) => v as f64,
            Num::Float(v) => v,
        }
    }

    /// The value as an unsigned count, if it is a non-negative integer.
    pub fn as_count(self) -> Option<u64> {
        match self {
            Num::Int(v) => u64::try_from(v).ok(),
            Num::UInt(v) => Some(v),
            Num::Float(_) => None,
        }
    }
}

impl fmt::Display for Num {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Num::Int(v) => write!(f, "{v}"),
            Num::UInt(v) => write!(f, "{v}"),
            Num::Float(v) => write!(f, "{v}"),
        }
    }
}

/// A comparison operator.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CmpOp {
    /// `>`.
    Gt,
    /// `>=`.
    Ge,
    /// `<`.
    Lt,
    /// `<=`.
    Le,
    /// `==`.
    Eq,
    /// `!=`.
    Ne,
}

impl CmpOp {
    /// How it is written.
    pub fn as_str(self) -> &'static str {
        match self {
            CmpOp::Gt => ">",
            CmpOp::Ge => ">=",
            CmpOp::Lt => "<",
            CmpOp::Le => "<=",
            CmpOp::Eq => "==",
            CmpOp::Ne => "!=",
        }
    }

    /// Reads an operator written as in [`CmpOp::as_str`].
    pub fn parse(s: &str) -> Option<CmpOp> {
        Some(match s {
            ">" => CmpOp::Gt,
            ">=" => CmpOp::Ge,
            "<" => CmpOp::Lt,
            "<=" => CmpOp::Le,
            "==" => CmpOp::Eq,
            "!=" => CmpOp::Ne,
            _ => return None,
        })
    }

    /// Applies the operator. Integers compare exactly; anything with a
    /// floating point number compares as `f64`.
    pub fn holds(self, a: Num, b: Num) -> bool {
        use std::cmp::Ordering;
        let ord = match (a, b) {
            (Num::Int(x), Num::Int(y)) => Some(x.cmp(&y)),
            (Num::UInt(x), Num::UInt(y)) => Some(x.cmp(&y)),
            (Num::Int(x), Num::UInt(y)) => Some(i128::from(x).cmp(&i128::from(y))),
            (Num::UInt(x), Num::Int(y)) => Some(i128::from(x).cmp(&i128::from(y))),
            _ => a.as_f64().partial_cmp(&b.as_f64()),
        };
        // NaN compares unequal to everything.
        let Some(ord) = ord else {
            return self == CmpOp::Ne;
        };
        match self {
            CmpOp::Gt => ord == Ordering::Greater,
            CmpOp::Ge => ord != Ordering::Less,
            CmpOp::Lt => ord == Ordering::Less,
            CmpOp::Le => ord != Ordering::Greater,
            CmpOp::Eq => ord == Ordering::Equal,
            CmpOp::Ne => ord != Ordering::Equal,
        }
    }
}

/// The right-hand side of a comparison.
#[derive(Debug, Clone, PartialEq)]
pub enum CmpOperand {
    /// A constant.
    Const(Num),
    /// Another tag, by address.
    Tag(Signal),
}

/// A comparison of a numeric tag with a constant or another tag
/// (`TEMP > 80.5`, `MODE == 3`, `P1 >= P2`): a contact wherever a condition
/// is written. It travels through conditions as one [`Signal`] whose name is
/// its canonical text ([`Comparison::signal`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Comparison {
    /// The tag compared, by address.
    pub lhs: Signal,
    /// The operator.
    pub op: CmpOp,
    /// What it is compared with.
    pub rhs: CmpOperand,
}

impl Comparison {
    /// The signal standing for the comparison: `LHS OP RHS`, single spaces.
    pub fn signal(&self) -> Signal {
        let rhs = match &self.rhs {
            CmpOperand::Const(n) => n.to_string(),
            CmpOperand::Tag(s) => s.to_string(),
        };
        Signal::new(&format!("{} {} {rhs}", self.lhs, self.op.as_str()))
    }

    /// The comparison a signal stands for, if it is one.
    pub fn of_signal(signal: &Signal) -> Option<Comparison> {
        let mut parts = signal.name().split(' ');
        let (lhs, op, rhs) = (parts.next()?, parts.next()?, parts.next()?);
        if parts.next().is_some() {
            return None;
        }
        Some(Comparison {
            lhs: Signal::new(lhs),
            op: CmpOp::parse(op)?,
            rhs: operand(rhs),
        })
    }

    /// Whether it holds for these values.
    pub fn holds(&self, lhs: Num, rhs: Num) -> bool {
        self.op.holds(lhs, rhs)
    }
}

/// A constant if the text is a number, else a tag address.
pub fn operand(text: &str) -> CmpOperand {
    if let Ok(v) = text.parse::<i64>() {
        return CmpOperand::Const(Num::Int(v));
    }
    if let Ok(v) = text.parse::<u64>() {
        return CmpOperand::Const(Num::UInt(v));
    }
    match text.parse::<f64>() {
        Ok(v) if text.starts_with(|c: char| c.is_ascii_digit() || c == '-' || c == '.') => {
            CmpOperand::Const(Num::Float(v))
        }
        _ => CmpOperand::Tag(Signal::new(text)),
    }
}

/// A production counter read from the PLC: counts increments, recognising
/// wrap-around at the type's maximum and resets.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Counter {
    /// The largest value before it wraps to 0.
    pub max: u64,
    last: Option<u64>,
}

impl Counter {
    /// A counter of an integer type wrapping after `max`.
    pub fn new(max: u64) -> Counter {
        Counter { max, last: None }
    }

    /// The counter now reads `value` (`None`: unknown, the next known value
    /// starts afresh against the last one seen). Returns the parts made
    /// since the last value:
    /// - up: the difference;
    /// - down, by less than half the range to wrap: a wrap-around
    ///   (`65535 → 2` is 3 parts);
    /// - down otherwise: a reset (to zero or a small value): the value
    ///   itself, the parts made since the reset.
    ///
    /// The first value ever seen counts nothing.
    pub fn next(&mut self, value: u64) -> u64 {
        let Some(last) = self.last.replace(value) else {
            return 0;
        };
        if value >= last {
            return value - last;
        }
        // Down: over the top (wrap) or back to the bottom (reset).
        let wrapped = (self.max - last).saturating_add(value).saturating_add(1);
        if wrapped <= self.max / 2 {
            wrapped
        } else {
            value
        }
    }

    /// The last value seen.
    pub fn last(&self) -> Option<u64> {
        self.last
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unknown_type_is_named_with_the_known_ones() {
        assert_eq!("int16".parse(), Ok(ValueType::Int16));
        assert_eq!(
            "Int12".parse::<ValueType>().unwrap_err().to_string(),
            "unknown type 'Int12': use one of Boolean, SByte, Byte, Int16, UInt16, Int32, UInt32, Int64, UInt64, Float, Double, String, DateTime"
        );
    }

    #[test]
    fn a_counter_counts_increments_wraps_and_resets() {
        let mut c = Counter::new(u16::MAX as u64);
        let mut parts = 0;
        for v in 0..=65535u64 {
            parts += c.next(v);
        }
        assert_eq!(parts, 65535);
        parts += c.next(0);
        assert_eq!(parts, 65536, "65535 → 0 is one part");
        for v in 1..=120u64 {
            parts += c.next(v);
        }
        assert_eq!(parts, 65656);
        assert_eq!(c.next(0), 0, "a reset to zero is not a part");
        assert_eq!(c.next(3), 3);
        assert_eq!(c.next(65534), 65531, "a jump up counts");
        assert_eq!(c.next(2), 4, "wrap with a jump");
        assert_eq!(
            c.next(1),
            1,
            "down by little and far from the top: a reset to 1"
        );
    }

    #[test]
    fn comparisons_round_trip_through_their_signal() {
        let c = Comparison {
            lhs: Signal::new("TEMP"),
            op: CmpOp::Ge,
            rhs: CmpOperand::Const(Num::Float(80.5)),
        };
        assert_eq!(c.signal().name(), "TEMP >= 80.5");
        assert_eq!(Comparison::of_signal(&c.signal()), Some(c));
        let c = Comparison::of_signal(&Signal::new("P1 != P2")).unwrap();
        assert_eq!(c.rhs, CmpOperand::Tag(Signal::new("P2")));
        assert!(Comparison::of_signal(&Signal::new("X0.06")).is_none());
        assert!(CmpOp::Eq.holds(Num::Int(3), Num::UInt(3)));
        assert!(CmpOp::Gt.holds(Num::Float(85.2), Num::Float(80.5)));
        assert!(!CmpOp::Gt.holds(Num::Int(-1), Num::UInt(0)));
        assert!(CmpOp::Ne.holds(Num::Float(f64::NAN), Num::Float(f64::NAN)));
        assert!(CmpOp::Gt.holds(Num::UInt(u64::MAX), Num::Int(i64::MAX)));
    }
}
