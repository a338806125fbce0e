//! How a cell reaches its `@` bus (paper 002) and where each tag is on
//! it, as the configuration says: the transport, the serial line, the
//! poll timing, and a tag's `@<unit>/<item>`. Read by the `@` bus source
//! (`sources/at_bus`). The table as written ([`RawLegacy`]) and its check
//! (`validate`).

use std::time::Duration;

use serde::Deserialize;
use toml::Spanned;

use crate::table::Table;

use cellwatch_models::at_bus::Header;
use cellwatch_models::value::ValueType;

/// How the bus is reached.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Transport {
    /// A serial device server's raw socket, `host:port`.
    Tcp(String),
    /// A serial port.
    Serial(SerialLine),
}

impl Transport {
    /// The address or the device: what two cells on one bus have alike.
    pub fn place(&self) -> &str {
        match self {
            Transport::Tcp(a) => a,
            Transport::Serial(s) => &s.path,
        }
    }
}

/// Serial line settings (paper 002: 9600 bit/s, 7 data bits, even parity,
/// 2 stop bits).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SerialLine {
    /// The device (`/dev/ttyUSB0`).
    pub path: String,
    /// Bits per second.
    pub baud: u32,
    /// 5 to 8.
    pub data_bits: u8,
    /// `none`, `even`, `odd`.
    pub parity: Parity,
    /// 1 or 2.
    pub stop_bits: u8,
}

/// Serial parity.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Parity {
    /// No parity bit.
    None,
    /// Even.
    Even,
    /// Odd.
    Odd,
}

/// The `[legacy]` section: the bus and how it is polled.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AtBusConfig {
    /// Where the bus is.
    pub transport: Transport,
    /// How often every unit is polled.
    pub poll_interval: Duration,
    /// How long a unit has to answer one request.
    pub response_timeout: Duration,
    /// Requests asked again after a bad or missing answer, per request.
    pub retries: u32,
}

impl AtBusConfig {
    /// What it connects to, for logs.
    pub fn describe(&self) -> String {
        match &self.transport {
            Transport::Tcp(a) => format!("@ bus tcp://{a}"),
            Transport::Serial(s) => format!(
                "@ bus {} {} {}{}{}",
                s.path,
                s.baud,
                s.data_bits,
                match s.parity {
                    Parity::None => 'N',
                    Parity::Even => 'E',
                    Parity::Odd => 'O',
                },
                s.stop_bits
            ),
        }
    }

    /// The bus and every polling setting, to tell two apart.
    pub fn settings(&self) -> String {
        format!(
            "{}, poll every {:?}, response timeout {:?}, {} retries",
            self.describe(),
            self.poll_interval,
            self.response_timeout,
            self.retries
        )
    }
}

/// What of a unit a tag reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Item {
    /// The `R?` status bits (a `UInt16`; tags take one `bit` each).
    Status,
    /// The production count of the `R?` answer (`UInt32`, wraps after
    /// 999,999).
    Production,
    /// `RT` target quantity.
    Target,
    /// `RJ` item code (`String`).
    ItemCode,
    /// `RI` stock-in quantity.
    StockIn,
    /// `RC` cycle increment.
    CycleIncrement,
    /// `RO` output bits (`UInt16`).
    Outputs,
}

impl Item {
    const NAMES: [(&'static str, Item); 7] = [
        ("status", Item::Status),
        ("production", Item::Production),
        ("target", Item::Target),
        ("item", Item::ItemCode),
        ("stock_in", Item::StockIn),
        ("cycle_increment", Item::CycleIncrement),
        ("outputs", Item::Outputs),
    ];

    /// The request that reads it.
    pub(crate) fn request(self) -> Header {
        match self {
            Item::Status | Item::Production => Header::ReadStatus,
            Item::Target => Header::ReadTarget,
            Item::ItemCode => Header::ReadItem,
            Item::StockIn => Header::ReadStockIn,
            Item::CycleIncrement => Header::ReadCycleIncrement,
            Item::Outputs => Header::ReadOutputs,
        }
    }

    /// The type its values have.
    pub fn value_type(self) -> ValueType {
        match self {
            Item::Status | Item::Outputs => ValueType::UInt16,
            Item::Production | Item::Target | Item::StockIn => ValueType::UInt32,
            Item::CycleIncrement => ValueType::Byte,
            Item::ItemCode => ValueType::String,
        }
    }
}

/// A tag's place on the bus: `@<unit>/<item>`, unit in hex (`@02/status`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct BusNode {
    /// The unit number.
    pub unit: u8,
    /// What of it.
    pub item: Item,
}

/// A tag's node id that is not an `@` bus node (`@02/status`).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("'{text}' is not a bus node like @02/status (unit number in hex, then one of {items})")]
pub struct NotABusNode {
    /// The node id as written.
    pub text: String,
    /// The items a node can name, comma-separated.
    pub items: String,
}

impl BusNode {
    /// Reads `@02/status`, `@1F/production`, ...
    ///
    /// # Errors
    /// The text is not `@<unit in hex>/<item>`.
    pub fn parse(text: &str) -> Result<BusNode, NotABusNode> {
        let expected = || NotABusNode {
            text: text.to_string(),
            items: Item::NAMES
                .iter()
                .map(|(n, _)| *n)
                .collect::<Vec<_>>()
                .join(", "),
        };
        let rest = text.strip_prefix('@').ok_or_else(expected)?;
        let (unit, item) = rest.split_once('/').ok_or_else(expected)?;
        if unit.len() != 2 {
            return Err(expected());
        }
        let unit = u8::from_str_radix(unit, 16).map_err(|_| expected())?;
        let item = Item::NAMES
            .iter()
            .find(|(n, _)| *n == item)
            .map(|(_, i)| *i)
            .ok_or_else(expected)?;
        Ok(BusNode { unit, item })
    }
}

/// `[legacy]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawLegacy {
    pub(crate) tcp: Option<Spanned<String>>,
    pub(crate) serial: Option<Spanned<String>>,
    pub(crate) baud: Option<Spanned<i64>>,
    pub(crate) data_bits: Option<Spanned<i64>>,
    pub(crate) parity: Option<Spanned<String>>,
    pub(crate) stop_bits: Option<Spanned<i64>>,
    pub(crate) poll_interval: Option<Spanned<String>>,
    pub(crate) response_timeout: Option<Spanned<String>>,
    pub(crate) retries: Option<Spanned<i64>>,
}

pub(crate) fn validate(kit: &mut Table<'_>, raw: RawLegacy) -> Option<AtBusConfig> {
    let transport = match (raw.tcp, raw.serial) {
        (Some(t), None) => {
            if t.get_ref()
                .rsplit_once(':')
                .and_then(|(_, p)| p.parse::<u16>().ok())
                .is_none()
            {
                kit.problem(
                    t.span(),
                    "legacy.tcp",
                    format!(
                        "'{}' is not host:port (the serial device server's raw socket)",
                        t.get_ref()
                    ),
                );
            }
            Transport::Tcp(t.into_inner())
        }
        (None, Some(path)) => {
            let baud = match raw.baud {
                None => 9600,
                Some(b) => kit.count(b, "legacy.baud", 50..=4_000_000, 9600),
            };
            let data_bits = match raw.data_bits {
                None => 7,
                Some(b) => kit.count(b, "legacy.data_bits", 5..=8, 7) as u8,
            };
            let stop_bits = match raw.stop_bits {
                None => 2,
                Some(b) => kit.count(b, "legacy.stop_bits", 1..=2, 2) as u8,
            };
            let parity = match raw
                .parity
                .as_ref()
                .map(|p| (p.get_ref().as_str(), p.span()))
            {
                None | Some(("even", _)) => Parity::Even,
                Some(("odd", _)) => Parity::Odd,
                Some(("none", _)) => Parity::None,
                Some((p, span)) => {
                    kit.problem(
                        span,
                        "legacy.parity",
                        format!("unknown parity '{p}': use even, odd or none"),
                    );
                    Parity::Even
                }
            };
            Transport::Serial(SerialLine {
                path: path.into_inner(),
                baud,
                data_bits,
                parity,
                stop_bits,
            })
        }
        (Some(t), Some(_)) => {
            kit.problem(t.span(), "legacy.tcp", "give tcp or serial, not both");
            return None;
        }
        (None, None) => {
            kit.problem(
                0..0,
                "legacy",
                "give the bus: tcp = \"host:port\" or serial = \"/dev/ttyUSB0\"",
            );
            return None;
        }
    };
    let poll_interval = kit.duration(
        raw.poll_interval,
        "legacy.poll_interval",
        Duration::from_secs(1),
    );
    let response_timeout = kit.duration(
        raw.response_timeout,
        "legacy.response_timeout",
        Duration::from_millis(300),
    );
    let retries = match raw.retries {
        None => 2,
        Some(r) => kit.count(r, "legacy.retries", 0..=10, 2),
    };
    Some(AtBusConfig {
        transport,
        poll_interval,
        response_timeout,
        retries,
    })
}
