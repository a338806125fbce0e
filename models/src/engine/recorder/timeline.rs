//! A recording drawn as a timing chart, the way a logic analyser shows
//! signals ([`Recording::timeline`]): what `cellwatch explain --alarm ID
//! --timeline` prints. It owns the drawing only; the recording is the
//! recorder's.
//!
//! Time runs left to right in columns of equal length, from the window's
//! start to its end, on an axis relative to the raise (`-10 s`, `0`,
//! `+5 s`; the raise marked `▼`). One row per signal, named by its
//! address and its tag's name:
//! - a contact is a trace: `▔` high (1), `▁` low (0), `╱` a rise, `╲` a
//!   fall; a column holding several changes shows how many (`2` to `9`,
//!   `+` for more), so that a short pulse is never lost;
//! - a number or a string is its value written where it changes, then `─`
//!   while it holds (`50 ─── 70 ─── 2×90 ─`); `n×v` says that `n` changes
//!   fell in that column and the last left `v`; a value with no room is cut
//!   (`…`) or only marked (`•`);
//! - `░` is unknown (bad quality, connection lost), `·` a time the
//!   recording does not hold (cut short: a note under the chart says why).

use super::{Cut, RecordedSignal, Recording, Sample};

/// The longest row label, in characters.
const LABEL: usize = 28;

impl Recording {
    /// The recording as a timing chart `width` columns wide (at least 10),
    /// plus the row labels; lines end with `\n`. Times are read from the
    /// raise (its date is the caller's to say: the models know no
    /// calendar).
    pub fn timeline(&self, width: usize) -> String {
        let width = width.max(10);
        let span = self.to.saturating_sub(self.from).max(1);
        let step = span.div_ceil(width as u64).max(1);
        let grid = Grid {
            from: self.from,
            step,
            width,
            holds: (self.holds_from, self.holds_to),
        };
        let labels: Vec<String> = self.signals.iter().map(label).collect();
        let pad = labels.iter().map(|l| l.chars().count()).max().unwrap_or(0);
        let mut out = format!(
            "{}: {} signal{}, {} ms a column\n",
            self.alarm,
            self.signals.len(),
            if self.signals.len() == 1 { "" } else { "s" },
            step
        );
        let raise = grid.column(self.raised_at);
        out.push_str(&format!("{:pad$} {}\n", "", self.axis(&grid, raise)));
        let mut ruler: Vec<char> = vec!['─'; width];
        ruler[0] = '├';
        ruler[width - 1] = '┤';
        ruler[raise] = '▼';
        out.push_str(&format!(
            "{:pad$} {}\n",
            "",
            ruler.into_iter().collect::<String>()
        ));
        for (s, l) in self.signals.iter().zip(&labels) {
            let row = if is_contact(s) {
                grid.trace(s)
            } else {
                grid.values(s)
            };
            let fill = pad - l.chars().count();
            out.push_str(&format!("{l}{:fill$} {row}\n", ""));
        }
        out.push_str(
            "▔ 1  ▁ 0  ╱ rise  ╲ fall  2-9 changes in a column (+ more)  \
             n×v n changes, the last to v  ░ unknown  · not recorded\n",
        );
        let at = |t: u64| seconds(t as i64 - self.raised_at as i64);
        match self.truncated.start {
            Some(Cut::Ring) => out.push_str(&format!(
                "recorded from {} only: the ring had dropped older changes\n",
                at(self.holds_from)
            )),
            Some(Cut::Changes) => out.push_str(&format!(
                "recorded from {} only: the recording's bound on changes before the raise\n",
                at(self.holds_from)
            )),
            _ => {}
        }
        match self.truncated.end {
            Some(Cut::Changes) => out.push_str(&format!(
                "recorded up to {} only: the recording's bound on changes after the raise\n",
                at(self.holds_to)
            )),
            Some(Cut::Busy) => out.push_str(&format!(
                "recorded up to {} only: as many recordings were under way as may be\n",
                at(self.holds_to)
            )),
            Some(Cut::Stopped) => out.push_str(&format!(
                "recorded up to {} only: the agent stopped or read its configuration again\n",
                at(self.holds_to)
            )),
            _ => {}
        }
        out
    }

    /// The axis labels: the window's start, the raise and its end.
    fn axis(&self, grid: &Grid, raise: usize) -> String {
        let width = grid.width;
        let mut line: Vec<char> = vec![' '; width];
        let start = seconds(self.from as i64 - self.raised_at as i64);
        let end = seconds(self.to as i64 - self.raised_at as i64);
        let mut put = |text: &str, at: usize| {
            for (k, c) in text.chars().enumerate() {
                if let Some(slot) = line.get_mut(at + k) {
                    *slot = c;
                }
            }
        };
        let (start_len, end_len) = (start.chars().count(), end.chars().count());
        let end_at = width.saturating_sub(end_len);
        if raise > start_len && raise + 1 < end_at {
            put("0", raise);
        }
        put(&start, 0);
        if end_at > start_len {
            put(&end, end_at);
        }
        line.into_iter().collect::<String>().trim_end().to_string()
    }
}

/// `X0.06 x0.06`: the address and the tag's name, cut to [`LABEL`].
fn label(s: &RecordedSignal) -> String {
    let full = match &s.name {
        Some(name) => format!("{} {name}", s.address),
        None => s.address.clone(),
    };
    if full.chars().count() <= LABEL {
        return full;
    }
    let mut cut: String = full.chars().take(LABEL - 1).collect();
    cut.push('…');
    cut
}

/// Whether every known value of `s` is a contact's.
fn is_contact(s: &RecordedSignal) -> bool {
    std::iter::once(&s.start)
        .chain(s.changes.iter().map(|(_, v)| v))
        .flatten()
        .all(|v| matches!(v, Sample::Bool(_)))
}

/// `-10 s`, `+2.5 s`, `0`.
fn seconds(ms: i64) -> String {
    if ms == 0 {
        return "0".into();
    }
    let sign = if ms < 0 { '-' } else { '+' };
    let (s, frac) = (ms.abs() / 1000, ms.abs() % 1000);
    if frac == 0 {
        format!("{sign}{s} s")
    } else {
        let frac = format!("{frac:03}");
        format!("{sign}{s}.{} s", frac.trim_end_matches('0'))
    }
}

/// The chart's columns.
struct Grid {
    from: u64,
    /// Each column's length, ms.
    step: u64,
    width: usize,
    /// What the recording holds, ms (inclusive).
    holds: (u64, u64),
}

impl Grid {
    /// The column of time `t`.
    fn column(&self, t: u64) -> usize {
        (((t.saturating_sub(self.from)) / self.step) as usize).min(self.width - 1)
    }

    /// Whether column `c` lies wholly outside what the recording holds.
    fn unheld(&self, c: usize) -> bool {
        let start = self.from + c as u64 * self.step;
        let end = start + self.step - 1;
        end < self.holds.0 || start > self.holds.1
    }

    /// Per column: how many changes, and the value after them.
    fn columns<'a>(&self, s: &'a RecordedSignal) -> Vec<(usize, Option<&'a Sample>)> {
        let mut value = s.start.as_ref();
        let mut out = Vec::with_capacity(self.width);
        let mut changes = s.changes.iter().peekable();
        for c in 0..self.width {
            let mut n = 0;
            while let Some((at, v)) = changes.peek() {
                if self.column(*at) != c {
                    break;
                }
                value = v.as_ref();
                n += 1;
                changes.next();
            }
            out.push((n, value));
        }
        out
    }

    /// A contact's trace.
    fn trace(&self, s: &RecordedSignal) -> String {
        let mut before = s.start.as_ref();
        let mut out = String::with_capacity(self.width * 3);
        for (c, (n, value)) in self.columns(s).into_iter().enumerate() {
            let level = |v: Option<&Sample>| match v {
                Some(Sample::Bool(true)) => '▔',
                Some(Sample::Bool(false)) => '▁',
                _ => '░',
            };
            out.push(match n {
                _ if self.unheld(c) => '·',
                0 => level(value),
                1 => match (before, value) {
                    (Some(Sample::Bool(false)), Some(Sample::Bool(true))) => '╱',
                    (Some(Sample::Bool(true)), Some(Sample::Bool(false))) => '╲',
                    _ => '░',
                },
                2..=9 => char::from_digit(n as u32, 10).unwrap_or('+'),
                _ => '+',
            });
            before = value;
        }
        out
    }

    /// A number's or a string's row: its values where they change.
    fn values(&self, s: &RecordedSignal) -> String {
        let columns = self.columns(s);
        let mut row: Vec<char> = columns
            .iter()
            .enumerate()
            .map(|(c, (_, v))| match v {
                _ if self.unheld(c) => '·',
                None => '░',
                Some(_) => '─',
            })
            .collect();
        // Where a value is written: the first column held, then each
        // column with changes that leave a known value.
        let first = (0..self.width).find(|&c| !self.unheld(c));
        let marks: Vec<(usize, String)> = columns
            .iter()
            .enumerate()
            .filter(|&(c, &(n, _))| !self.unheld(c) && (n > 0 || Some(c) == first))
            .filter_map(|(c, &(n, v))| {
                let v = v?;
                Some((
                    c,
                    if n > 1 {
                        format!("{n}×{v}")
                    } else {
                        v.to_string()
                    },
                ))
            })
            .collect();
        for (c, text) in marks {
            // Up to the next change (to a value or to unknown).
            let next = (c + 1..self.width)
                .find(|&k| columns[k].0 > 0)
                .unwrap_or(self.width);
            let (room, len) = (next - c, text.chars().count());
            let shown: Vec<char> = if len + 1 < room {
                text.chars().chain([' ']).collect()
            } else if len <= room {
                text.chars().collect()
            } else if room >= 2 {
                text.chars().take(room - 1).chain(['…']).collect()
            } else {
                vec!['•']
            };
            for (i, ch) in shown.into_iter().enumerate() {
                row[c + i] = ch;
            }
        }
        row.into_iter().collect()
    }
}

#[cfg(test)]
mod tests {
    use super::super::Truncated;
    use super::*;

    fn signal(address: &str, name: Option<&str>, start: Sample) -> RecordedSignal {
        RecordedSignal {
            address: address.into(),
            name: name.map(str::to_string),
            start: Some(start),
            changes: Vec::new(),
        }
    }

    #[test]
    fn a_recording_draws_as_a_timing_chart() {
        let b = |v: bool| Some(Sample::Bool(v));
        let mut x006 = signal("X0.06", Some("x0.06"), Sample::Bool(true));
        x006.changes = vec![(10_000, b(false)), (12_000, b(true)), (12_100, b(false))];
        let mut r1024 = signal("R1024.00", Some("machine ready"), Sample::Bool(true));
        r1024.changes = vec![(4_000, b(false)), (6_000, b(true)), (13_000, None)];
        let mut temp = signal("TEMP", Some("spindle temperature"), Sample::Float(50.0));
        temp.changes = vec![
            (3_000, Some(Sample::Float(70.0))),
            (10_000, Some(Sample::Float(85.0))),
            (10_400, Some(Sample::UInt(90))),
            (12_500, Some(Sample::Float(95.5))),
            (14_000, None),
        ];
        let r = Recording {
            alarm: "ese".into(),
            raised_at: 10_000,
            from: 0,
            to: 15_000,
            holds_from: 1_000,
            holds_to: 15_000,
            truncated: Truncated {
                start: Some(Cut::Ring),
                end: None,
            },
            signals: vec![x006, r1024, temp],
        };
        assert_eq!(
            r.timeline(30),
            "\
ese: 3 signals, 500 ms a column
                         -10 s               0     +5 s
                         ├───────────────────▼────────┤
X0.06 x0.06              ··▔▔▔▔▔▔▔▔▔▔▔▔▔▔▔▔▔▔╲▁▁▁2▁▁▁▁▁
R1024.00 machine ready   ··▔▔▔▔▔▔╲▁▁▁╱▔▔▔▔▔▔▔▔▔▔▔▔▔░░░░
TEMP spindle temperature ··50 ─70 ───────────2×90─95…░░
▔ 1  ▁ 0  ╱ rise  ╲ fall  2-9 changes in a column (+ more)  n×v n changes, the last to v  ░ unknown  · not recorded
recorded from -9 s only: the ring had dropped older changes
"
        );
    }

    #[test]
    fn times_read_as_seconds_from_the_raise() {
        assert_eq!(seconds(-10_000), "-10 s");
        assert_eq!(seconds(2_500), "+2.5 s");
        assert_eq!(seconds(-250), "-0.25 s");
        assert_eq!(seconds(0), "0");
    }
}
