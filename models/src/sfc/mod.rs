//! Sequential function charts (IEC 61131-3 SFC) and their supervision,
//! after paper 004.
//!
//! A [`Sfc`] is one or more charts (the paper's F1 and F2): steps, and
//! transitions from one or more steps to one or more steps under a
//! condition. Single, select and parallel sequences are all this graph:
//! several transitions leaving one step are a *selection divergence*,
//! several arriving at one a *selection convergence*; a transition to
//! several steps is a *simultaneous divergence* ("sync"), one from several
//! steps a *simultaneous convergence* ("resync"). A transition to a step of
//! another chart is a *jump*.
//!
//! Which steps are active comes from the PLC: each step has a flag (a
//! boolean tag such as the step's `S2.X`, or a comparison `D300 == 2` on a
//! step-number word). [`SfcChecks`] supervises them: a step active longer
//! than its supervision time is *stuck*, and its alarm carries the
//! criteria analysis of every transition leaving it — the operands that
//! keep it from firing, with values, expected values and comments (a
//! comparison with the number it compares and the limit it needs).
//!
//! Charts are read from a TOML text form ([`text::parse`]) or from the SFC
//! bodies of a PLCopen XML project ([`plcopen::parse`]); [`read`] picks. [`run::Runner`]
//! runs them as a PLC does, force switch included (eq. (1)-(4) of paper
//! 004), for the simulated cell.

pub mod force;
pub mod learn;
pub mod patch;
pub mod plant;
pub mod plcopen;
pub mod run;
pub mod supervise;
pub mod text;

mod chart;

pub(crate) use chart::{about, and, culprit_list};
pub use chart::{Chart, Sfc, SfcTransition, Step, StepRef};
pub use supervise::SfcChecks;

use crate::signal::Signal;

/// Reads a chart file: PLCopen XML when it is XML (it begins with `<`),
/// the TOML form otherwise; `known` says whether a signal is one of the
/// cell's tags.
///
/// # Errors
/// Every problem found, each `FILE:LINE:COL: what`.
pub fn read(file: &str, text: &str, known: &dyn Fn(&Signal) -> bool) -> Result<Sfc, Vec<String>> {
    if text
        .trim_start_matches('\u{feff}')
        .trim_start()
        .starts_with('<')
    {
        plcopen::parse(file, text, known)
    } else {
        text::parse(file, text, known)
    }
}

/// The robot charts of paper 004 (`config/robot/robot.sfc.toml`), for
/// the tests.
#[cfg(test)]
pub(crate) fn robot() -> Sfc {
    text::parse(
        "robot.sfc.toml",
        include_str!("../../../config/robot/robot.sfc.toml"),
        &|_| true,
    )
    .unwrap()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::alarm::{AlarmKind, Severity};
    use crate::comments::CommentDb;
    use crate::engine::{CheckSet, Finding};
    use crate::expr::Expr;

    use super::robot;

    fn r(sfc: &Sfc, name: &str) -> StepRef {
        let (c, s) = name.split_once('.').unwrap();
        let chart = sfc.chart(c).unwrap();
        StepRef {
            chart,
            step: sfc.charts[chart]
                .steps
                .iter()
                .position(|x| x.name == s)
                .unwrap(),
        }
    }

    #[test]
    fn the_robot_charts_parse_into_sequences_and_jumps() {
        let sfc = robot();
        assert_eq!(
            sfc.charts
                .iter()
                .map(|c| c.name.as_str())
                .collect::<Vec<_>>(),
            ["F1", "F2"]
        );
        // Selection divergence at S1: automatic or manual.
        let leaving: Vec<&str> = sfc
            .leaving(r(&sfc, "F1.S1"))
            .map(|t| t.id.as_str())
            .collect();
        assert_eq!(leaving, ["t2", "t20"]);
        // t3 jumps to the other chart, starting three steps at once (sync).
        let (_, t3) = sfc.transition("F1", "t3").unwrap();
        assert_eq!(
            t3.to,
            [r(&sfc, "F2.S5"), r(&sfc, "F2.S8"), r(&sfc, "F2.S11")]
        );
        // Resync.
        let (_, t12) = sfc.transition("F2", "t12").unwrap();
        assert_eq!(
            t12.from,
            [r(&sfc, "F2.S6"), r(&sfc, "F2.S9"), r(&sfc, "F2.S12")]
        );
        assert_eq!(sfc.charts[1].initial, None);
        assert_eq!(sfc.step(r(&sfc, "F1.S2")).supervision_ms, Some(8000));
        assert_eq!(sfc.step(r(&sfc, "F1.S2")).flag, Signal::new("S2.X"));
    }

    /// The robot as PLCopen XML: the model of its TOML form, but for the
    /// supervision times XML has no place for.
    #[test]
    fn the_robot_in_plcopen_xml_is_the_robot_of_the_text_form() {
        let xml = read(
            "robot.sfc.xml",
            include_str!("../../../config/robot/robot.sfc.xml"),
            &|_| true,
        )
        .unwrap();
        let mut text = robot();
        for c in &mut text.charts {
            for s in &mut c.steps {
                s.supervision_ms = None;
            }
        }
        assert_eq!(xml, text);
    }

    #[test]
    fn bad_xml_charts_are_refused_at_their_element() {
        let head = "<project xmlns=\"http://www.plcopen.org/xml/tc6_0201\" xmlns:xhtml=\"http://www.w3.org/1999/xhtml\">\n<types><pous>\n<pou name=\"F1\" pouType=\"program\"><body><SFC>\n";
        let tail = "</SFC></body></pou>\n</pous></types></project>\n";
        let st = |c: &str| {
            format!(
                "<condition><inline name=\"\"><ST><xhtml:p>{c}</xhtml:p></ST></inline></condition>"
            )
        };
        let body = format!(
            "<step localId=\"1\" name=\"S0\" initialStep=\"true\"/>\n\
             <transition localId=\"2\" name=\"t1\">{}</transition>\n\
             <step localId=\"3\" name=\"S1\"><connectionPointIn><connection refLocalId=\"2\"/></connectionPointIn></step>\n\
             <transition localId=\"4\" name=\"t2\"><connectionPointIn><connection refLocalId=\"3\"/></connectionPointIn>{}</transition>\n\
             <jumpStep localId=\"5\" targetName=\"F9.S5\"><connectionPointIn><connection refLocalId=\"4\"/></connectionPointIn></jumpStep>\n\
             <step localId=\"6\" name=\"S7\"/>\n",
            st("X1"),
            st("X2 AND Y9")
        );
        let known = |s: &Signal| s.name() != "Y9";
        let errors = read("bad.xml", &format!("{head}{body}{tail}"), &known).unwrap_err();
        assert_eq!(
            errors,
            [
                "bad.xml:5:1: transition t1 has no source step",
                "bad.xml:8:1: transition t2 jumps to 'F9.S5': no chart 'F9'",
                "bad.xml:7:129: transition t2: unknown contact 'Y9': no tag has this address",
                "bad.xml:9:1: step F1.S7 is unreachable: it is not the initial step and no transition leads to it",
            ]
        );
        // A jump to a step of its own chart that is not there, and a
        // connection to an element that is not there: each at itself.
        let dangling = format!(
            "{head}<step localId=\"1\" name=\"S0\" initialStep=\"true\"/>\n\
             <transition localId=\"2\" name=\"t1\"><connectionPointIn><connection refLocalId=\"1\"/></connectionPointIn>{}</transition>\n\
             <jumpStep localId=\"3\" targetName=\"S9\"><connectionPointIn><connection refLocalId=\"2\"/></connectionPointIn></jumpStep>\n\
             <transition localId=\"4\" name=\"t2\"><connectionPointIn>\n<connection refLocalId=\"77\"/></connectionPointIn>{}</transition>\n\
             <jumpStep localId=\"5\" targetName=\"S0\"><connectionPointIn><connection refLocalId=\"4\"/></connectionPointIn></jumpStep>\n{tail}",
            st("X1"),
            st("X2")
        );
        let errors = read("dangling.xml", &dangling, &|_| true).unwrap_err();
        assert_eq!(
            errors,
            [
                "dangling.xml:8:1: connection to localId 77, which is not in this SFC",
                "dangling.xml:6:1: transition t1 goes to 'S9': no step 'S9' in chart F1",
                "dangling.xml:7:1: transition t2 has no source step",
            ]
        );
        // Not XML at all, and a condition in a language not read.
        let errors = read("x.xml", "<project>\n<pou></project>", &|_| true).unwrap_err();
        assert!(
            errors[0].starts_with("x.xml:2:6: not well-formed XML: expected 'pou' tag"),
            "{errors:?}"
        );
        let il = format!(
            "{head}<step localId=\"1\" name=\"S0\" initialStep=\"true\"/>\n<transition localId=\"2\" name=\"t1\"><connectionPointIn><connection refLocalId=\"1\"/></connectionPointIn><condition><inline name=\"\"><IL>LD X1</IL></inline></condition></transition>\n<jumpStep localId=\"3\" targetName=\"S0\"><connectionPointIn><connection refLocalId=\"2\"/></connectionPointIn></jumpStep>\n{tail}"
        );
        let errors = read("il.xml", &il, &|_| true).unwrap_err();
        assert_eq!(
            errors,
            ["il.xml:5:129: a transition condition in IL is not read; write it as an ST, LD or FBD body"]
        );
        // A condition drawn in the chart that is not boolean logic: the
        // output of an arithmetic box.
        let add = format!(
            "{head}<step localId=\"1\" name=\"S0\" initialStep=\"true\"/>\n\
             <inVariable localId=\"7\"><expression>A</expression></inVariable><block localId=\"8\" typeName=\"ADD\"><inputVariables><variable formalParameter=\"IN1\"><connectionPointIn><connection refLocalId=\"7\"/></connectionPointIn></variable></inputVariables><outputVariables><variable formalParameter=\"OUT\"><connectionPointOut/></variable></outputVariables></block>\n\
             <transition localId=\"2\" name=\"t1\"><connectionPointIn><connection refLocalId=\"1\"/></connectionPointIn><condition><connectionPointIn><connection refLocalId=\"8\" formalParameter=\"OUT\"/></connectionPointIn></condition></transition>\n\
             <jumpStep localId=\"3\" targetName=\"S0\"><connectionPointIn><connection refLocalId=\"2\"/></connectionPointIn></jumpStep>\n{tail}"
        );
        let errors = read("add.xml", &add, &|_| true).unwrap_err();
        assert_eq!(
            errors,
            ["add.xml:6:102: transition condition: the condition is not boolean logic: output of function 'ADD'"]
        );
        // ST operators map to the paper's.
        assert_eq!(
            plcopen::st_condition("(A AND NOT B) OR C & D300 = 2 OR P <> 3").unwrap(),
            Expr::parse("(A * -B) + C * D300 == 2 + P != 3").unwrap()
        );
    }

    #[test]
    fn bad_charts_are_refused_at_their_place() {
        let bad = r#"[[chart]]
name = "F1"
initial = "S0"

[[chart.step]]
name = "S0"
flag = "S0.X"

[[chart.step]]
name = "S1"
flag = "S1.X"

[[chart.step]]
name = "S7"
flag = "S7.X"

[[chart.transition]]
id = "t1"
from = []
to = "S1"
condition = "X1"

[[chart.transition]]
id = "t2"
from = "S1"
to = "F9.S5"
condition = "X2 * Y9"
"#;
        let known = |s: &Signal| s.name() != "Y9";
        let errors = text::parse("bad.sfc.toml", bad, &known).unwrap_err();
        assert_eq!(
            errors,
            [
                "bad.sfc.toml:19:8: transition t1 has no source step",
                "bad.sfc.toml:26:6: transition t2 jumps to 'F9.S5': no chart 'F9'",
                "bad.sfc.toml:27:13: transition t2: unknown contact 'Y9': no tag has this address",
                "bad.sfc.toml:14:8: step F1.S7 is unreachable: it is not the initial step and no transition leads to it",
            ]
        );
        let errors = text::parse(
            "x.sfc.toml",
            "[[chart]]\nname = \"F1\"\n[[chart.step]]\nname = \"S0\"\nflag = \"S0.X\"\nsupervision = \"8 parsecs\"\n",
            &|_| true,
        )
        .unwrap_err();
        assert_eq!(
            errors,
            [
                "x.sfc.toml:6:15: supervision: '8 parsecs': write a duration such as 500ms, 8s, 2m or 1h",
                "x.sfc.toml:4:8: step F1.S0 is unreachable: it is not the initial step and no transition leads to it",
            ]
        );
        let errors = text::parse("y.sfc.toml", "[[chart]]\nnam = 1\n", &|_| true).unwrap_err();
        assert!(
            errors[0].starts_with("y.sfc.toml:2:1: unknown field `nam`"),
            "{errors:?}"
        );
    }

    #[test]
    fn durations_and_st_conditions_say_what_is_wrong() {
        assert_eq!(text::duration_ms("1.5s"), Ok(1500));
        assert_eq!(
            text::duration_ms("0.1ms").unwrap_err().to_string(),
            "'0.1ms': between 1 ms and about 30 years"
        );
        assert_eq!(
            text::duration_ms("8 parsecs"),
            Err(text::DurationError::Malformed {
                text: "8 parsecs".into()
            })
        );
        let st = |t| plcopen::st_condition(t).unwrap_err().to_string();
        assert_eq!(
            st("a XOR b"),
            "XOR is not read in a condition: write (a AND NOT b) OR (NOT a AND b)"
        );
        assert_eq!(
            st("a | b"),
            "'|' is not read in a condition (ST: AND, OR, NOT, parentheses, comparisons)"
        );
        assert_eq!(st("(a AND b"), "'(a AND b': expected ')' at the end");
    }

    fn checks() -> SfcChecks {
        let comments: CommentDb = [(
            Signal::new("%IX0.0.3"),
            "Shuttle waiting-position sensor".to_string(),
        )]
        .into_iter()
        .collect();
        SfcChecks::new("sfc", robot(), Severity::High, comments)
    }

    fn set(c: &mut SfcChecks, s: &str, v: bool, before: Option<bool>, now: u64) -> Vec<Finding> {
        let mut out = Vec::new();
        c.on_change(&Signal::new(s), Some(v), before, now, &mut out);
        out
    }

    #[test]
    fn a_stuck_step_reads_its_flag_and_what_its_transitions_need() {
        let c = checks();
        let reads = |id: &str| {
            let mut out = Vec::new();
            c.reads(id, &mut out);
            out.iter().map(Signal::to_string).collect::<Vec<_>>()
        };
        assert_eq!(reads("sfc-F1-S2"), ["S2.X", "%IX0.0.3"]);
        assert!(reads("sfc-F1-S99").is_empty());
        // Every step's reads are among what the set reads.
        let inputs = c.inputs();
        for d in c.alarms() {
            let mut out = Vec::new();
            c.reads(&d.id, &mut out);
            assert!(!out.is_empty(), "{}", d.id);
            assert!(out.iter().all(|s| inputs.contains(s)), "{}: {out:?}", d.id);
        }
    }

    #[test]
    fn a_stuck_step_names_what_its_transitions_wait_for() {
        let mut c = checks();
        assert!(c
            .alarms()
            .iter()
            .any(|d| d.id == "sfc-F1-S2" && d.kind == AlarmKind::Step));
        set(&mut c, "%IX0.0.3", false, None, 0);
        set(&mut c, "S2.X", true, None, 1_000);
        let mut out = Vec::new();
        c.advance(8_999, &mut out);
        assert!(out.is_empty());
        c.advance(9_000, &mut out);
        assert_eq!(out.len(), 1);
        let f = &out[0];
        assert_eq!((f.id.as_str(), f.active), ("sfc-F1-S2", true));
        assert_eq!(f.fault_type, "STUCK F1.S2");
        assert_eq!(
            f.message,
            "F1.S2 (Shuttle to waiting position) stuck for 8.0 s (supervision 8.0 s): \
             t3 (Shuttle at waiting position) waits for %IX0.0.3 = 0 (expected 1): \
             Shuttle waiting-position sensor"
        );
        assert_eq!(f.culprits[0].address, Signal::new("%IX0.0.3"));
        assert!(!f.culprits[0].value && f.culprits[0].expected);
        // Raised once.
        out.clear();
        c.advance(20_000, &mut out);
        assert!(out.is_empty());
        // The sensor comes: the analysis follows.
        let out = set(&mut c, "%IX0.0.3", true, Some(false), 21_000);
        assert!(
            out[0].active
                && out[0]
                    .message
                    .ends_with("t3 (Shuttle at waiting position) can fire")
        );
        // The step is left: cleared.
        let out = set(&mut c, "S2.X", false, Some(true), 21_100);
        assert_eq!((out[0].id.as_str(), out[0].active), ("sfc-F1-S2", false));
        // Active again, left in time: nothing.
        set(&mut c, "S2.X", true, Some(false), 30_000);
        set(&mut c, "S2.X", false, Some(true), 37_999);
        let mut out = Vec::new();
        c.advance(60_000, &mut out);
        assert!(out.is_empty());
    }

    #[test]
    fn a_restored_stuck_step_clears_when_its_flag_is_seen_off() {
        let mut c = checks();
        c.restored(&crate::alarm::Alarm::active_since(
            "sfc-F1-S2",
            AlarmKind::Step,
            1_000,
        ));
        // Still active after the restart: no second raise when its
        // supervision runs out again.
        set(&mut c, "S2.X", true, None, 20_000);
        let mut out = Vec::new();
        c.advance(40_000, &mut out);
        assert!(out.is_empty(), "{out:?}");
        // Left: cleared.
        let out = set(&mut c, "S2.X", false, Some(true), 41_000);
        assert_eq!((out[0].id.as_str(), out[0].active), ("sfc-F1-S2", false));
        // Seen off at once after a restart: cleared too.
        let mut c = checks();
        c.restored(&crate::alarm::Alarm::active_since(
            "sfc-F1-S2",
            AlarmKind::Step,
            1_000,
        ));
        let out = set(&mut c, "S2.X", false, None, 20_000);
        assert_eq!((out[0].id.as_str(), out[0].active), ("sfc-F1-S2", false));
    }

    #[test]
    fn a_convergence_waits_for_every_source_step() {
        let mut c = checks();
        for (s, v) in [
            ("S6.X", true),
            ("S9.X", false),
            ("S12.X", true),
            ("%IX0.1.3", true),
        ] {
            set(&mut c, s, v, None, 0);
        }
        let (chart, _) = c.sfc().transition("F2", "t12").unwrap();
        let i = c.sfc().charts[chart]
            .transitions
            .iter()
            .position(|t| t.id == "t12")
            .unwrap();
        let waits: Vec<String> = c.criteria(chart, i).iter().map(|k| k.to_string()).collect();
        assert_eq!(waits, ["S9.X = 0 (expected 1)"]);
    }

    #[test]
    fn through_the_engine_a_stuck_step_is_a_fault_with_its_values_captured() {
        use crate::engine::{CellEngine, EngineEvent, MachineState, Reading, StateRules, Tag};
        let sfc = robot();
        let mut signals = std::collections::BTreeSet::new();
        for (_, s) in sfc.steps() {
            signals.insert(s.flag.clone());
        }
        for c in &sfc.charts {
            for t in &c.transitions {
                signals.extend(t.condition.signals());
            }
        }
        let tags: Vec<Tag> = signals
            .iter()
            .map(|s| Tag {
                name: s.name().to_string(),
                address: s.clone(),
            })
            .collect();
        let index = |name: &str| tags.iter().position(|t| t.address.name() == name).unwrap();
        let (s2, t3) = (index("S2.X"), index("%IX0.0.3"));
        let mut e = CellEngine::new(
            "robot",
            tags.clone(),
            vec![Box::new(checks())],
            StateRules::default(),
        )
        .unwrap();
        e.on_connection(true, 0);
        for i in 0..tags.len() {
            e.on_reading(i, Reading::Good(i == s2), 1_000, 1_000);
        }
        assert_eq!(e.next_deadline(), Some(9_000), "S2's supervision runs out");
        assert!(e.advance(8_999).events.is_empty());
        let step = e.advance(9_000);
        let raised = step.events.iter().any(|ev| {
            matches!(ev, EngineEvent::Alarm { alarm, .. } if alarm.id == "sfc-F1-S2" && alarm.active)
        });
        assert!(raised, "{:?}", step.events);
        assert_eq!(
            e.state(),
            &MachineState::Fault {
                fault_type: "STUCK F1.S2".into(),
                element: Some("%IX0.0.3".into())
            }
        );
        let captured = e.last_fault().unwrap();
        assert_eq!(captured.alarm, "sfc-F1-S2");
        assert_eq!(captured.values[s2], Some(crate::engine::Value::Bool(true)));
        // The shuttle arrives and the PLC moves on: cleared.
        e.on_reading(t3, Reading::Good(true), 9_500, 9_500);
        let ev = e.on_reading(s2, Reading::Good(false), 9_600, 9_600).events;
        assert!(ev.iter().any(|ev| matches!(ev, EngineEvent::Alarm { alarm, .. } if alarm.id == "sfc-F1-S2" && !alarm.active)));
    }
}
