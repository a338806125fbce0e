//! Validating the configuration: legacy.

use std::time::Duration;

use super::Validator;
use crate::config::legacy::{LegacyConfig, Parity, SerialLine, Transport};
use crate::config::raw;

impl Validator<'_> {
    pub(super) fn legacy(&mut self, raw: raw::RawLegacy) -> Option<LegacyConfig> {
        self.bus = true;
        let transport = match (raw.tcp, raw.serial) {
            (Some(t), None) => {
                if t.get_ref()
                    .rsplit_once(':')
                    .and_then(|(_, p)| p.parse::<u16>().ok())
                    .is_none()
                {
                    self.problem(
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
                    Some(b) => self.count(b, "legacy.baud", 50..=4_000_000, 9600),
                };
                let data_bits = match raw.data_bits {
                    None => 7,
                    Some(b) => self.count(b, "legacy.data_bits", 5..=8, 7) as u8,
                };
                let stop_bits = match raw.stop_bits {
                    None => 2,
                    Some(b) => self.count(b, "legacy.stop_bits", 1..=2, 2) as u8,
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
                        self.problem(
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
                self.problem(t.span(), "legacy.tcp", "give tcp or serial, not both");
                return None;
            }
            (None, None) => {
                self.problem(
                    0..0,
                    "legacy",
                    "give the bus: tcp = \"host:port\" or serial = \"/dev/ttyUSB0\"",
                );
                return None;
            }
        };
        let poll_interval = self.duration(
            raw.poll_interval,
            "legacy.poll_interval",
            Duration::from_secs(1),
        );
        let response_timeout = self.duration(
            raw.response_timeout,
            "legacy.response_timeout",
            Duration::from_millis(300),
        );
        let retries = match raw.retries {
            None => 2,
            Some(r) => self.count(r, "legacy.retries", 0..=10, 2),
        };
        Some(LegacyConfig {
            transport,
            poll_interval,
            response_timeout,
            retries,
        })
    }
}
