//! A cell's master alarm database (ISA-18.2 / IEC 62682): the rationalised
//! rows a plant's team gives back after `cellwatch mad export` — per alarm
//! its priority, class, the consequence of not acting, the operator's
//! corrective action and the time they have. Read from CSV text with every
//! mistake at its line and column; which ids are the cell's alarms is the
//! agent's to check (it knows the cell).

use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;

pub use crate::alarm::Guidance;
use crate::alarm::{AlarmPattern, Severity};
use crate::sfc::text::duration_ms;

/// The columns a rationalised file must have.
pub const REQUIRED: [&str; 6] = [
    "id",
    "priority",
    "class",
    "consequence_of_inaction",
    "corrective_action",
    "response_time",
];

/// One alarm's rationalisation as the engine applies it.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Rationalised {
    /// The priority it is raised with; `None`: as its check says.
    pub priority: Option<Severity>,
    /// What the operator is told.
    pub guidance: Arc<Guidance>,
}

/// The rationalised alarms: by id, and by pattern (`plc-*`, for the PLC's
/// own alarms, whose ids are not known beforehand).
#[derive(Debug, Clone, Default)]
pub struct Rationalisation {
    by_id: HashMap<String, Rationalised>,
    patterns: Vec<(AlarmPattern, Rationalised)>,
}

impl Rationalisation {
    /// The table of `rows` (alarm id, or a pattern with `*`, and its
    /// rationalisation).
    pub fn new(rows: impl IntoIterator<Item = (String, Rationalised)>) -> Rationalisation {
        let mut table = Rationalisation::default();
        for (id, r) in rows {
            if id.contains('*') {
                table.patterns.push((AlarmPattern::new(&id), r));
            } else {
                table.by_id.insert(id, r);
            }
        }
        table
    }

    /// Alarm `id`'s rationalisation: its row, or the first pattern's it
    /// matches.
    pub fn of(&self, id: &str) -> Option<&Rationalised> {
        self.by_id.get(id).or_else(|| {
            self.patterns
                .iter()
                .find(|(p, _)| p.matches(id))
                .map(|(_, r)| r)
        })
    }
}

/// One alarm's row of the database.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Rationale {
    /// The priority the cell gives it; `None`: as configured (an empty
    /// cell, or the PLC's own priority for a PLC's alarm).
    pub priority: Option<Severity>,
    /// The guidance.
    pub guidance: Guidance,
    /// The condition as the file has it (the draft's), to tell a changed
    /// alarm when the cell's logic changes.
    pub condition: Option<String>,
    /// The row's line in the file.
    pub line: u64,
}

/// A rationalised file, by alarm id.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Database {
    /// The rows by alarm id.
    pub rows: BTreeMap<String, Rationale>,
}

/// Why a file is not a rationalised database: each problem at its line
/// and column, as `file:line:col: column 'name': what`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{}", problems.join("\n"))]
pub struct DatabaseErrors {
    /// The problems, in the file's order.
    pub problems: Vec<String>,
}

impl Database {
    /// Reads the CSV `text` of file `origin` (a header row naming at least
    /// the [`REQUIRED`] columns, in any order; other columns are kept by
    /// nobody and may be anything).
    ///
    /// # Errors
    /// [`DatabaseErrors`]: a missing column, a row that does not read, an
    /// id given twice or empty, a priority outside `low`, `medium`, `high`,
    /// `critical`, a response time that is no duration.
    pub fn parse(origin: &str, text: &str) -> Result<Database, DatabaseErrors> {
        let mut problems = Vec::new();
        let mut reader = csv::ReaderBuilder::new()
            .flexible(false)
            .from_reader(text.as_bytes());
        let header: Vec<String> = match reader.headers() {
            Ok(h) => h.iter().map(|c| c.trim().to_string()).collect(),
            Err(e) => {
                return Err(DatabaseErrors {
                    problems: vec![format!("{origin}:1:1: {e}")],
                })
            }
        };
        let missing: Vec<&str> = REQUIRED
            .iter()
            .copied()
            .filter(|c| !header.iter().any(|h| h == c))
            .collect();
        if !missing.is_empty() {
            return Err(DatabaseErrors {
                problems: vec![format!(
                    "{origin}:1:1: no column {} (the columns `cellwatch mad export` writes: {})",
                    missing
                        .iter()
                        .map(|c| format!("'{c}'"))
                        .collect::<Vec<_>>()
                        .join(", "),
                    REQUIRED.join(", ")
                )],
            });
        }
        let at = |name: &str| header.iter().position(|h| h == name);
        let column = |name: &str| at(name).unwrap_or(0);
        let mut rows = BTreeMap::new();
        for record in reader.records() {
            let record = match record {
                Ok(r) => r,
                Err(e) => {
                    let line = e.position().map_or(0, csv::Position::line);
                    let what = match e.kind() {
                        csv::ErrorKind::UnequalLengths {
                            expected_len, len, ..
                        } => {
                            format!("the row has {len} columns where the header has {expected_len}")
                        }
                        _ => e.to_string(),
                    };
                    problems.push(format!("{origin}:{line}:1: {what}"));
                    continue;
                }
            };
            let line = record.position().map_or(0, csv::Position::line);
            let field = |name: &str| record.get(column(name)).unwrap_or("").trim().to_string();
            let mut problem = |name: &str, what: String| {
                problems.push(format!(
                    "{origin}:{line}:{}: column '{name}': {what}",
                    column(name) + 1
                ));
            };
            let id = field("id");
            if id.is_empty() {
                problem("id", "is empty: every row names its alarm".into());
                continue;
            }
            let priority = match field("priority").as_str() {
                "" | "from the PLC" => None,
                p => match p.parse::<Severity>() {
                    Ok(s) => Some(s),
                    Err(_) => {
                        problem(
                            "priority",
                            format!("'{p}' is no priority: low, medium, high or critical"),
                        );
                        None
                    }
                },
            };
            let response_time_ms = match field("response_time").as_str() {
                "" => None,
                t => match duration_ms(t) {
                    Ok(ms) => Some(ms),
                    Err(e) => {
                        problem("response_time", e.to_string());
                        None
                    }
                },
            };
            let rationale = Rationale {
                priority,
                guidance: Guidance {
                    class: field("class"),
                    consequence_of_inaction: field("consequence_of_inaction"),
                    corrective_action: field("corrective_action"),
                    response_time_ms,
                },
                condition: at("condition").map(|_| field("condition")),
                line,
            };
            if let Some(first) = rows.insert(id.clone(), rationale) {
                problem(
                    "id",
                    format!("'{id}' is given twice (first on line {})", first.line),
                );
            }
        }
        if problems.is_empty() {
            Ok(Database { rows })
        } else {
            Err(DatabaseErrors { problems })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEADER: &str =
        "id,priority,class,condition,consequence_of_inaction,corrective_action,response_time\n";

    #[test]
    fn a_rationalised_file_gives_each_alarm_its_priority_and_guidance() {
        let text = format!(
            "{HEADER}ese,high,safety,\"fault while G8.02 is on\",machine stays stopped,\"Release the E-stop, then reset\",5m\nplc-*,from the PLC,plc,,,,\n"
        );
        let db = Database::parse("m.csv", &text).unwrap();
        let ese = &db.rows["ese"];
        assert_eq!(ese.priority, Some(Severity::High));
        assert_eq!(
            ese.guidance,
            Guidance {
                class: "safety".into(),
                consequence_of_inaction: "machine stays stopped".into(),
                corrective_action: "Release the E-stop, then reset".into(),
                response_time_ms: Some(300_000),
            }
        );
        assert_eq!(ese.condition.as_deref(), Some("fault while G8.02 is on"));
        assert_eq!(ese.line, 2);
        assert_eq!(db.rows["plc-*"].priority, None);
    }

    #[test]
    fn every_mistake_is_said_at_its_line_and_column() {
        let text = format!("{HEADER}ese,urgent,,,,,soon\n,high,,,,,\nese,low,,,,,\ncsd,high,,\n");
        assert_eq!(
            Database::parse("m.csv", &text).unwrap_err().to_string(),
            [
                "m.csv:2:2: column 'priority': 'urgent' is no priority: low, medium, high or critical",
                "m.csv:2:7: column 'response_time': 'soon': write a duration such as 500ms, 8s, 2m or 1h",
                "m.csv:3:1: column 'id': is empty: every row names its alarm",
                "m.csv:4:1: column 'id': 'ese' is given twice (first on line 2)",
                "m.csv:5:1: the row has 4 columns where the header has 7",
            ]
            .join("\n")
        );
        assert_eq!(
            Database::parse("m.csv", "id,priority\nese,high\n")
                .unwrap_err()
                .to_string(),
            "m.csv:1:1: no column 'class', 'consequence_of_inaction', 'corrective_action', 'response_time' (the columns `cellwatch mad export` writes: id, priority, class, consequence_of_inaction, corrective_action, response_time)"
        );
    }
}
