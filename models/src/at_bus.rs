//! The `@`-framed ASCII protocol of paper 002: a control computer polling
//! injection-moulding units on an RS-485 multidrop bus by unit number.
//!
//! A frame is `'@'`, the unit number (2 upper-case hex digits), the header
//! code (2 characters), the text, the FCS (2 upper-case hex digits: the XOR
//! of every character before it, `'@'` included), then `'*'` and CR. Bytes
//! between a terminator and the next `'@'` are ignored.
//!
//! The paper leaves the texts open; cellwatch fixes them ([`Header`]):
//!
//! | header | request text | answer text |
//! |---|---|---|
//! | `RJ` / `WJ` item code | — / 8 characters | 8 characters: `A`–`Z`, `0`–`9`, `-`, space-padded on the right |
//! | `RT` / `WT` target quantity | — / 6 digits | 6 decimal digits, zero-padded |
//! | `RP` / `WP` production quantity | — / 6 digits | 6 decimal digits (wraps after 999999) |
//! | `RI` / `WI` stock-in quantity | — / 6 digits | 6 decimal digits |
//! | `RW` / `WW` password | — / 4 digits | 4 decimal digits |
//! | `RC` / `WC` cycle increment | — / 2 digits | 2 decimal digits (parts per cycle) |
//! | `RO` / `WO` outputs | — / 4 hex digits | 4 hex digits, bit 0 first output |
//! | `R?` machine status | — | 4 hex digits of input bits ([`Status`]) then 6 digits of production |
//! | `AC` / `NC` acknowledge | 2 digits: end code | — |
//!
//! A read is answered with the same header code and the value; a write
//! with `AC10`, or `NC14` (format error: bad `'@'`, unit number, FCS or
//! terminator) or `NC15` (data error: wrong text for the header code).
//! Pure: no I/O, no clock.

use std::fmt;

/// End code: normal end.
pub const END_NORMAL: u8 = 10;
/// End code: format error (bad `'@'`, unit number, FCS or terminator).
pub const END_FORMAT: u8 = 14;
/// End code: data error (wrong data size for the header code).
pub const END_DATA: u8 = 15;

/// The longest text any header code carries, plus slack: a frame longer
/// than this is a format error, so a stream of garbage never grows a
/// buffer.
pub const MAX_FRAME: usize = 64;

/// The header codes of the paper's Table 2.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Header {
    /// `RJ`: read the item (product) code.
    ReadItem,
    /// `WJ`: write the item code.
    WriteItem,
    /// `RT`: read the target quantity.
    ReadTarget,
    /// `WT`: write the target quantity.
    WriteTarget,
    /// `RP`: read the production quantity.
    ReadProduction,
    /// `WP`: write (correct) the production quantity.
    WriteProduction,
    /// `RI`: read the stock-in quantity.
    ReadStockIn,
    /// `WI`: write the stock-in quantity.
    WriteStockIn,
    /// `RW`: read the password.
    ReadPassword,
    /// `WW`: write the password.
    WritePassword,
    /// `RC`: read the cycle increment.
    ReadCycleIncrement,
    /// `WC`: write the cycle increment.
    WriteCycleIncrement,
    /// `RO`: read the outputs.
    ReadOutputs,
    /// `WO`: write the outputs.
    WriteOutputs,
    /// `R?`: read the machine status (I/O state and production count).
    ReadStatus,
    /// `AC`: acknowledge, normal.
    Ack,
    /// `NC`: acknowledge, abnormal.
    Nak,
}

impl Header {
    /// Every header code.
    pub const ALL: [Header; 17] = [
        Header::ReadItem,
        Header::WriteItem,
        Header::ReadTarget,
        Header::WriteTarget,
        Header::ReadProduction,
        Header::WriteProduction,
        Header::ReadStockIn,
        Header::WriteStockIn,
        Header::ReadPassword,
        Header::WritePassword,
        Header::ReadCycleIncrement,
        Header::WriteCycleIncrement,
        Header::ReadOutputs,
        Header::WriteOutputs,
        Header::ReadStatus,
        Header::Ack,
        Header::Nak,
    ];

    /// The two characters on the wire.
    pub fn code(self) -> &'static str {
        match self {
            Header::ReadItem => "RJ",
            Header::WriteItem => "WJ",
            Header::ReadTarget => "RT",
            Header::WriteTarget => "WT",
            Header::ReadProduction => "RP",
            Header::WriteProduction => "WP",
            Header::ReadStockIn => "RI",
            Header::WriteStockIn => "WI",
            Header::ReadPassword => "RW",
            Header::WritePassword => "WW",
            Header::ReadCycleIncrement => "RC",
            Header::WriteCycleIncrement => "WC",
            Header::ReadOutputs => "RO",
            Header::WriteOutputs => "WO",
            Header::ReadStatus => "R?",
            Header::Ack => "AC",
            Header::Nak => "NC",
        }
    }

    /// The header with this code.
    pub fn from_code(code: &[u8]) -> Option<Header> {
        Header::ALL
            .into_iter()
            .find(|h| h.code().as_bytes() == code)
    }

    /// The value's format this header's writes carry and its reads are
    /// answered with (`None` for the status and the acknowledgements).
    pub fn value(self) -> Option<Field> {
        Some(match self {
            Header::ReadItem | Header::WriteItem => Field::Item,
            Header::ReadTarget
            | Header::WriteTarget
            | Header::ReadProduction
            | Header::WriteProduction
            | Header::ReadStockIn
            | Header::WriteStockIn => Field::Quantity,
            Header::ReadPassword | Header::WritePassword => Field::Password,
            Header::ReadCycleIncrement | Header::WriteCycleIncrement => Field::CycleIncrement,
            Header::ReadOutputs | Header::WriteOutputs => Field::Outputs,
            Header::ReadStatus | Header::Ack | Header::Nak => return None,
        })
    }

    /// A read (answered with a value).
    pub fn is_read(self) -> bool {
        self.code().starts_with('R')
    }

    /// A write (answered with `AC`/`NC`).
    pub fn is_write(self) -> bool {
        self.code().starts_with('W')
    }

    /// The read that answers with what this write sets.
    pub fn read_of(self) -> Option<Header> {
        let code = self.code();
        if !code.starts_with('W') {
            return None;
        }
        Header::from_code(format!("R{}", &code[1..]).as_bytes())
    }
}

impl fmt::Display for Header {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.code())
    }
}

/// The format of a value field.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Field {
    /// 8 characters `A`–`Z`, `0`–`9`, `-`, space-padded on the right.
    Item,
    /// 6 decimal digits.
    Quantity,
    /// 4 decimal digits.
    Password,
    /// 2 decimal digits.
    CycleIncrement,
    /// 4 hex digits.
    Outputs,
}

impl Field {
    /// Its width on the wire.
    pub fn width(self) -> usize {
        match self {
            Field::Item => 8,
            Field::Quantity => 6,
            Field::Password | Field::Outputs => 4,
            Field::CycleIncrement => 2,
        }
    }

    /// Whether `text` is a well-formed value.
    pub fn accepts(self, text: &[u8]) -> bool {
        if text.len() != self.width() {
            return false;
        }
        match self {
            Field::Item => {
                let end = text.iter().rposition(|&c| c != b' ').map_or(0, |i| i + 1);
                end > 0
                    && text[..end]
                        .iter()
                        .all(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || *c == b'-')
            }
            Field::Quantity | Field::Password | Field::CycleIncrement => {
                text.iter().all(u8::is_ascii_digit)
            }
            Field::Outputs => text
                .iter()
                .all(|c| c.is_ascii_digit() || (b'A'..=b'F').contains(c)),
        }
    }

    /// A number written as this field (`Quantity`: `000120`), if it fits.
    pub fn number(self, n: u64) -> Option<String> {
        let text = match self {
            Field::Outputs => format!("{n:04X}"),
            Field::Item => return None,
            _ => format!("{n:0width$}", width = self.width()),
        };
        (text.len() == self.width()).then_some(text)
    }

    /// An item code written as this field, if it is one.
    pub fn item(self, code: &str) -> Option<String> {
        let text = format!("{code:<8}");
        (self == Field::Item && self.accepts(text.as_bytes())).then_some(text)
    }
}

/// The machine status bits of an `R?` answer (the paper's Table 4 stop
/// causes, and running).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Status {
    /// The input bits.
    pub bits: u16,
    /// The production count.
    pub production: u32,
}

impl Status {
    /// Bit 0: the machine is running.
    pub const RUNNING: u16 = 1 << 0;
    /// Bit 1: front door open (stop cause 01).
    pub const FRONT_DOOR_OPEN: u16 = 1 << 1;
    /// Bit 2: rear door open (stop cause 02).
    pub const REAR_DOOR_OPEN: u16 = 1 << 2;
    /// Bit 3: mould clamp abnormal (stop cause 03).
    pub const MOULD_CLAMP_ABNORMAL: u16 = 1 << 3;
    /// Bit 4: mould change (stop cause 04).
    pub const MOULD_CHANGE: u16 = 1 << 4;
    /// Bit 5: stopped (stop cause 05).
    pub const STOPPED: u16 = 1 << 5;
    /// Bit 6: take-out robot abnormal (stop cause 06).
    pub const ROBOT_ABNORMAL: u16 = 1 << 6;

    /// The named bits: name, bit, the paper's stop-cause code.
    pub const NAMED: [(&'static str, u16, Option<&'static str>); 7] = [
        ("running", Status::RUNNING, None),
        ("front_door_open", Status::FRONT_DOOR_OPEN, Some("01")),
        ("rear_door_open", Status::REAR_DOOR_OPEN, Some("02")),
        (
            "mould_clamp_abnormal",
            Status::MOULD_CLAMP_ABNORMAL,
            Some("03"),
        ),
        ("mould_change", Status::MOULD_CHANGE, Some("04")),
        ("stopped", Status::STOPPED, Some("05")),
        ("robot_abnormal", Status::ROBOT_ABNORMAL, Some("06")),
    ];

    /// The status text: 4 hex digits of bits, 6 decimal digits of
    /// production (modulo 1,000,000).
    pub fn text(&self) -> String {
        format!("{:04X}{:06}", self.bits, self.production % 1_000_000)
    }

    /// Reads a status text.
    pub fn parse(text: &[u8]) -> Option<Status> {
        if text.len() != 10
            || !Field::Outputs.accepts(&text[..4])
            || !Field::Quantity.accepts(&text[4..])
        {
            return None;
        }
        let s = std::str::from_utf8(text).ok()?;
        Some(Status {
            bits: u16::from_str_radix(&s[..4], 16).ok()?,
            production: s[4..].parse().ok()?,
        })
    }
}

/// One frame: unit, header code, text.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame {
    /// The unit number (0–255).
    pub unit: u8,
    /// The header code.
    pub header: Header,
    /// The text, as sent.
    pub text: String,
}

impl Frame {
    /// A frame.
    pub fn new(unit: u8, header: Header, text: impl Into<String>) -> Frame {
        Frame {
            unit,
            header,
            text: text.into(),
        }
    }

    /// A read request (empty text).
    pub fn read(unit: u8, header: Header) -> Frame {
        Frame::new(unit, header, "")
    }

    /// An acknowledgement with `end` (`AC10`, `NC14`, `NC15`).
    pub fn ack(unit: u8, end: u8) -> Frame {
        let header = if end == END_NORMAL {
            Header::Ack
        } else {
            Header::Nak
        };
        Frame::new(unit, header, format!("{end:02}"))
    }

    /// The bytes on the wire.
    pub fn encode(&self) -> Vec<u8> {
        let mut out = format!("@{:02X}{}{}", self.unit, self.header.code(), self.text).into_bytes();
        let fcs = checksum(&out);
        out.extend_from_slice(format!("{fcs:02X}*\r").as_bytes());
        out
    }

    /// Checks the text against the header code: the end code `15` (data
    /// error) and why, if it does not fit.
    ///
    /// # Errors
    /// [`TextMismatch`]: a text that does not fit the header code.
    pub fn check_text(&self, request: bool) -> Result<(), TextMismatch> {
        let t = self.text.as_bytes();
        let ok = match self.header {
            Header::Ack | Header::Nak => t.len() == 2 && t.iter().all(u8::is_ascii_digit),
            Header::ReadStatus if request => t.is_empty(),
            Header::ReadStatus => Status::parse(t).is_some(),
            h if h.is_read() && request => t.is_empty(),
            h => h.value().is_some_and(|f| f.accepts(t)),
        };
        if ok {
            Ok(())
        } else {
            Err(TextMismatch {
                text: self.text.clone(),
                header: self.header,
                request,
            })
        }
    }
}

/// A frame's text that does not fit its header code (end code `15`, data
/// error).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("'{text}' is not the text of a {header} {}", if *request { "request" } else { "answer" })]
pub struct TextMismatch {
    /// The text as received.
    pub text: String,
    /// The header code it came with.
    pub header: Header,
    /// Whether the frame is a request (else an answer).
    pub request: bool,
}

/// The paper's `CheckSum`: the XOR of every byte.
pub fn checksum(bytes: &[u8]) -> u8 {
    bytes.iter().fold(0, |c, b| c ^ b)
}

/// What the decoder found in the byte stream.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Decoded {
    /// A well-formed frame.
    Frame(Frame),
    /// The same frame again, with no request in between: dropped.
    Duplicate(Frame),
    /// A frame that is not well formed: the end code to answer with
    /// ([`END_FORMAT`] or [`END_DATA`]), the unit if it could be read, and
    /// why.
    Error {
        /// `14` or `15`.
        end: u8,
        /// The unit number, if readable.
        unit: Option<u8>,
        /// What is wrong.
        why: String,
    },
}

/// A streaming decoder: bytes in, frames out. Memory is bounded by
/// [`MAX_FRAME`] whatever arrives.
#[derive(Debug, Default)]
pub struct Decoder {
    buf: Vec<u8>,
    /// Inside a frame (an `'@'` was seen).
    in_frame: bool,
    last: Option<Frame>,
    /// Decode the texts as requests (a unit) or answers (the computer).
    requests: bool,
}

impl Decoder {
    /// A decoder of answers (the control computer's side).
    pub fn answers() -> Decoder {
        Decoder::default()
    }

    /// A decoder of requests (a unit's side).
    pub fn requests() -> Decoder {
        Decoder {
            requests: true,
            ..Decoder::default()
        }
    }

    /// A request was sent: the next frame is new even if it equals the
    /// last one.
    pub fn request_sent(&mut self) {
        self.last = None;
    }

    /// Feeds bytes; every frame or error completed by them is appended to
    /// `out`.
    pub fn push(&mut self, bytes: &[u8], out: &mut Vec<Decoded>) {
        for &b in bytes {
            if b == b'@' {
                if self.in_frame && !self.buf.is_empty() {
                    out.push(self.error(END_FORMAT, "a new '@' before the terminator".into()));
                }
                self.buf.clear();
                self.buf.push(b);
                self.in_frame = true;
                continue;
            }
            if !self.in_frame {
                // Between a terminator and the next '@': ignored.
                continue;
            }
            self.buf.push(b);
            if b == b'\r' {
                let frame = std::mem::take(&mut self.buf);
                self.in_frame = false;
                out.push(self.frame(&frame));
            } else if self.buf.len() > MAX_FRAME {
                self.buf.clear();
                self.in_frame = false;
                out.push(Decoded::Error {
                    end: END_FORMAT,
                    unit: None,
                    why: format!("no terminator within {MAX_FRAME} bytes"),
                });
            }
        }
    }

    fn error(&self, end: u8, why: String) -> Decoded {
        let unit = self
            .buf
            .get(1..3)
            .and_then(|u| std::str::from_utf8(u).ok())
            .and_then(|u| u8::from_str_radix(u, 16).ok());
        Decoded::Error { end, unit, why }
    }

    /// One complete frame, `'@'` to CR.
    fn frame(&mut self, f: &[u8]) -> Decoded {
        let fail = |end: u8, why: String| {
            let unit = f
                .get(1..3)
                .filter(|u| u.iter().all(u8::is_ascii_hexdigit))
                .and_then(|u| std::str::from_utf8(u).ok())
                .and_then(|u| u8::from_str_radix(u, 16).ok());
            Decoded::Error { end, unit, why }
        };
        // '@' unit(2) header(2) fcs(2) '*' CR at least.
        if f.len() < 9 {
            return fail(
                END_FORMAT,
                format!("{} bytes is too short for a frame", f.len()),
            );
        }
        let n = f.len();
        if f[n - 2] != b'*' {
            return fail(END_FORMAT, "no '*' before the CR".into());
        }
        let unit = &f[1..3];
        if !unit
            .iter()
            .all(|c| c.is_ascii_digit() || (b'A'..=b'F').contains(c))
        {
            return fail(
                END_FORMAT,
                format!(
                    "unit number '{}' is not 2 hex digits",
                    String::from_utf8_lossy(unit)
                ),
            );
        }
        let fcs = &f[n - 4..n - 2];
        let Some(fcs) = std::str::from_utf8(fcs)
            .ok()
            .filter(|s| {
                s.bytes()
                    .all(|c| c.is_ascii_digit() || (b'A'..=b'F').contains(&c))
            })
            .and_then(|s| u8::from_str_radix(s, 16).ok())
        else {
            return fail(END_FORMAT, "the FCS is not 2 hex digits".into());
        };
        let sum = checksum(&f[..n - 4]);
        if sum != fcs {
            return fail(
                END_FORMAT,
                format!("FCS {fcs:02X} does not match the frame's {sum:02X}"),
            );
        }
        let unit = u8::from_str_radix(std::str::from_utf8(unit).unwrap_or("00"), 16).unwrap_or(0);
        let Some(header) = Header::from_code(&f[3..5]) else {
            return fail(
                END_DATA,
                format!(
                    "unknown header code '{}'",
                    String::from_utf8_lossy(&f[3..5])
                ),
            );
        };
        let Ok(text) = std::str::from_utf8(&f[5..n - 4]) else {
            return fail(END_DATA, "the text is not ASCII".into());
        };
        let frame = Frame::new(unit, header, text);
        if let Err(why) = frame.check_text(self.requests) {
            return fail(END_DATA, why.to_string());
        }
        if self.last.as_ref() == Some(&frame) {
            return Decoded::Duplicate(frame);
        }
        self.last = Some(frame.clone());
        Decoded::Frame(frame)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn decode(bytes: &[u8]) -> Vec<Decoded> {
        let mut d = Decoder::answers();
        let mut out = Vec::new();
        d.push(bytes, &mut out);
        out
    }

    #[test]
    fn frames_are_as_the_papers_reference_code_writes_them() {
        // "@01RP" XOR: 0x40 ^ 0x30 ^ 0x31 ^ 0x52 ^ 0x50 = 0x43.
        assert_eq!(
            Frame::read(1, Header::ReadProduction).encode(),
            b"@01RP43*\r"
        );
        let f = Frame::new(0x1F, Header::WriteTarget, "001500");
        let bytes = f.encode();
        assert_eq!(&bytes[..11], b"@1FWT001500");
        assert_eq!(&bytes[13..], b"*\r");
        assert_eq!(decode(&bytes), [Decoded::Frame(f)]);
    }

    #[test]
    fn format_and_data_errors_get_their_end_codes() {
        let good = Frame::new(2, Header::ReadTarget, "000120").encode();
        let mut bad_fcs = good.clone();
        bad_fcs[good.len() - 3] ^= 1;
        let mut no_star = good.clone();
        let n = no_star.len();
        no_star[n - 2] = b'#';
        let mut lower_unit = good.clone();
        lower_unit[1] = b'g';
        let short_text = Frame::new(2, Header::ReadTarget, "0120").encode();
        let ends: Vec<u8> = [bad_fcs, no_star, lower_unit, short_text]
            .iter()
            .map(|b| match &decode(b)[..] {
                [Decoded::Error { end, .. }] => *end,
                other => panic!("{other:?}"),
            })
            .collect();
        assert_eq!(ends, [END_FORMAT, END_FORMAT, END_FORMAT, END_DATA]);
    }

    #[test]
    fn garbage_between_frames_is_skipped_and_duplicates_recognised() {
        let a = Frame::new(
            3,
            Header::ReadStatus,
            Status {
                bits: 0x22,
                production: 77,
            }
            .text(),
        );
        let mut bytes = b"\x00noise*\r".to_vec();
        bytes.extend(a.encode());
        bytes.extend(b"\xff\xfe junk ");
        bytes.extend(a.encode());
        let out = decode(&bytes);
        assert_eq!(out, [Decoded::Frame(a.clone()), Decoded::Duplicate(a)]);
    }

    #[test]
    fn a_missing_terminator_is_reported_and_memory_stays_bounded() {
        let mut d = Decoder::answers();
        let mut out = Vec::new();
        d.push(b"@01RT000", &mut out);
        assert!(out.is_empty());
        d.push(
            &Frame::new(1, Header::ReadTarget, "000120").encode(),
            &mut out,
        );
        assert!(matches!(
            out[0],
            Decoded::Error {
                end: END_FORMAT,
                ..
            }
        ));
        assert!(matches!(out[1], Decoded::Frame(_)));
        out.clear();
        d.push(&[b'@'; 1][..], &mut out);
        d.push(&vec![b'7'; 10_000], &mut out);
        assert_eq!(out.len(), 1);
        assert!(d.buf.len() <= MAX_FRAME);
    }

    #[test]
    fn texts_are_checked_per_header() {
        assert!(Field::Item.item("AB-12").is_some());
        assert_eq!(Field::Item.item("AB-12").unwrap(), "AB-12   ");
        assert!(Field::Item.item("ab").is_none());
        assert_eq!(Field::Quantity.number(120).unwrap(), "000120");
        assert!(Field::Quantity.number(1_000_000).is_none());
        assert_eq!(Field::Outputs.number(0xBEEF).unwrap(), "BEEF");
        assert_eq!(Header::WriteTarget.read_of(), Some(Header::ReadTarget));
        let s = Status {
            bits: Status::FRONT_DOOR_OPEN | Status::STOPPED,
            production: 1234,
        };
        assert_eq!(s.text(), "0022001234");
        assert_eq!(Status::parse(s.text().as_bytes()), Some(s));
        let mut requests = Decoder::requests();
        let mut out = Vec::new();
        requests.push(&Frame::read(4, Header::ReadStatus).encode(), &mut out);
        requests.push(&Frame::new(4, Header::ReadStatus, "x").encode(), &mut out);
        assert!(matches!(out[0], Decoded::Frame(_)));
        assert!(matches!(
            out[1],
            Decoded::Error {
                end: END_DATA,
                unit: Some(4),
                ..
            }
        ));
    }
}
