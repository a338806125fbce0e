//! The criteria analysis of a stuck step over every kind of operand a
//! transition reads: comparisons (`rSpindleSpeed >= 1800`, `iMode == 3`),
//! negated contacts, timer and counter bits (`T1.Q`, `C1.Q`) and a function
//! block's output (`fbClamp.Done`). One machining chart, in the TOML form
//! with an I/O list and in PLCopen XML with its variables documented, run
//! through the engine in virtual time: each stuck message names every
//! operand that keeps its transitions false, with its value and comment,
//! and none that holds.

#![allow(clippy::unwrap_used)] // test helpers fail loudly by design

use cellwatch_models::comments::CommentDb;
use cellwatch_models::engine::{CellEngine, Reading};
use cellwatch_models::sfc::SfcChecks;
use cellwatch_models::signal::Signal;
use cellwatch_models::value::Num;
use proptest::prelude::*;

mod kit;
use kit::read;

/// The machining cell: wait for start in automatic (S0), run the spindle
/// up with the door shut (S1), clamp and let it settle (S2; or abort),
/// machine (S3).
const CHART: &str = r#"
[[chart]]
name = "M1"
initial = "S0"

[[chart.step]]
name = "S0"
flag = "S0.X"
supervision = "5s"
comment = "Waiting for start"

[[chart.step]]
name = "S1"
flag = "S1.X"
supervision = "5s"
comment = "Spindle run-up"

[[chart.step]]
name = "S2"
flag = "S2.X"
supervision = "5s"
comment = "Clamp and settle"

[[chart.step]]
name = "S3"
flag = "S3.X"

[[chart.transition]]
id = "t1"
from = "S0"
to = "S1"
condition = "bStart * iMode == 3"
comment = "Start in automatic"

[[chart.transition]]
id = "t2"
from = "S1"
to = "S2"
condition = "rSpindleSpeed >= 1800 * -bDoorOpen"
comment = "Spindle at speed, door shut"

[[chart.transition]]
id = "t3"
from = "S2"
to = "S3"
condition = "T1.Q * fbClamp.Done * C1.Q"
comment = "Clamped and settled"

[[chart.transition]]
id = "t4"
from = "S2"
to = "S0"
condition = "bAbort"
comment = "Aborted"

[[chart.transition]]
id = "t5"
from = "S3"
to = "S0"
condition = "-bStart"
"#;

/// The same chart as PLCopen XML: the variables' comments are their
/// documentation; conditions in ST.
const XML: &str = r#"<?xml version="1.0" encoding="utf-8"?>
<project xmlns="http://www.plcopen.org/xml/tc6_0201" xmlns:xhtml="http://www.w3.org/1999/xhtml">
<types><pous>
<pou name="M1" pouType="program">
  <interface>
    <inputVars>
      <variable name="bStart"><type><BOOL/></type></variable>
      <variable name="iMode"><type><INT/></type><documentation><xhtml:p>Operating mode</xhtml:p></documentation></variable>
      <variable name="rSpindleSpeed"><type><REAL/></type><documentation><xhtml:p>Spindle speed</xhtml:p></documentation></variable>
      <variable name="bDoorOpen"><type><BOOL/></type><documentation><xhtml:p>Door open</xhtml:p></documentation></variable>
      <variable name="bAbort"><type><BOOL/></type><documentation><xhtml:p>Abort pressed</xhtml:p></documentation></variable>
    </inputVars>
    <localVars>
      <variable name="T1"><type><derived name="TON"/></type><documentation><xhtml:p>Clamp settle time</xhtml:p></documentation></variable>
      <variable name="C1"><type><derived name="CTU"/></type><documentation><xhtml:p>Parts in the fixture</xhtml:p></documentation></variable>
      <variable name="fbClamp"><type><derived name="FB_Cylinder"/></type><documentation><xhtml:p>Clamp cylinder</xhtml:p></documentation></variable>
    </localVars>
  </interface>
  <body><SFC>
    <step localId="1" name="S0" initialStep="true"><connectionPointIn><connection refLocalId="11"/></connectionPointIn><documentation><xhtml:p>Waiting for start</xhtml:p></documentation></step>
    <transition localId="2" name="t1"><connectionPointIn><connection refLocalId="1"/></connectionPointIn><condition><inline name=""><ST><xhtml:p>bStart AND iMode = 3</xhtml:p></ST></inline></condition><documentation><xhtml:p>Start in automatic</xhtml:p></documentation></transition>
    <step localId="3" name="S1"><connectionPointIn><connection refLocalId="2"/></connectionPointIn><documentation><xhtml:p>Spindle run-up</xhtml:p></documentation></step>
    <transition localId="4" name="t2"><connectionPointIn><connection refLocalId="3"/></connectionPointIn><condition><inline name=""><ST><xhtml:p>rSpindleSpeed &gt;= 1800 AND NOT bDoorOpen</xhtml:p></ST></inline></condition><documentation><xhtml:p>Spindle at speed, door shut</xhtml:p></documentation></transition>
    <step localId="5" name="S2"><connectionPointIn><connection refLocalId="4"/></connectionPointIn><documentation><xhtml:p>Clamp and settle</xhtml:p></documentation></step>
    <selectionDivergence localId="6"><connectionPointIn><connection refLocalId="5"/></connectionPointIn></selectionDivergence>
    <transition localId="7" name="t3"><connectionPointIn><connection refLocalId="6"/></connectionPointIn><condition><inline name=""><ST><xhtml:p>T1.Q AND fbClamp.Done AND C1.Q</xhtml:p></ST></inline></condition><documentation><xhtml:p>Clamped and settled</xhtml:p></documentation></transition>
    <transition localId="8" name="t4"><connectionPointIn><connection refLocalId="6"/></connectionPointIn><condition><inline name=""><ST><xhtml:p>bAbort</xhtml:p></ST></inline></condition><documentation><xhtml:p>Aborted</xhtml:p></documentation></transition>
    <jumpStep localId="9" targetName="S0"><connectionPointIn><connection refLocalId="8"/></connectionPointIn></jumpStep>
    <step localId="10" name="S3"><connectionPointIn><connection refLocalId="7"/></connectionPointIn></step>
    <transition localId="11" name="t5"><connectionPointIn><connection refLocalId="10"/></connectionPointIn><condition><inline name=""><ST><xhtml:p>NOT bStart</xhtml:p></ST></inline></condition></transition>
  </SFC></body>
</pou>
</pous></types>
</project>
"#;

/// The I/O list of the TOML form: what the XML documents.
fn io_list() -> CommentDb {
    [
        ("iMode", "Operating mode"),
        ("rSpindleSpeed", "Spindle speed"),
        ("bDoorOpen", "Door open"),
        ("bAbort", "Abort pressed"),
        ("T1", "Clamp settle time"),
        ("C1", "Parts in the fixture"),
        ("fbClamp", "Clamp cylinder"),
    ]
    .into_iter()
    .map(|(a, c)| (Signal::new(a), c.to_string()))
    .collect()
}

/// The variables the cell reads (comparisons are the engine's own).
const TAGS: [&str; 12] = [
    "S0.X",
    "S1.X",
    "S2.X",
    "S3.X",
    "bStart",
    "iMode",
    "rSpindleSpeed",
    "bDoorOpen",
    "T1.Q",
    "fbClamp.Done",
    "C1.Q",
    "bAbort",
];

/// The two forms of the chart, each as its engine.
fn engines() -> Vec<(&'static str, CellEngine)> {
    let toml = kit::charts("m1.sfc.toml", CHART);
    let mut xml = kit::charts("m1.sfc.xml", XML);
    // XML has no place for supervision times.
    for c in &mut xml.charts {
        for s in c.steps.iter_mut().filter(|s| s.name != "S3") {
            s.supervision_ms = Some(5_000);
        }
    }
    assert_eq!(xml.charts, toml.charts, "the two forms are one chart");
    vec![
        ("toml", engine(kit::supervision(toml, io_list()))),
        ("xml", engine(kit::supervision(xml, CommentDb::default()))),
    ]
}

fn engine(checks: SfcChecks) -> CellEngine {
    let tags = kit::tags_as_named(TAGS.map(Signal::new));
    let mut e = kit::cell("m1", tags, vec![Box::new(checks)]);
    e.on_connection(true, 0);
    e
}

/// A contact's value as the PLC gives it (`1`/`0`); a number is a
/// `Reading::Number`.
fn bit(v: bool) -> Reading {
    Reading::Good(v)
}

/// Every value at once, the active step's flag on and the others off.
fn load(e: &mut CellEngine, step: &str, values: &[(&str, Reading)], at: u64) {
    for flag in ["S0.X", "S1.X", "S2.X", "S3.X"] {
        read(e, flag, bit(flag == step), at);
    }
    for (a, v) in values {
        read(e, a, v.clone(), at);
    }
}

/// The message of alarm `id` now, if active.
fn message(e: &CellEngine, id: &str) -> Option<String> {
    e.alarms()
        .find(|a| a.id == id && a.active)
        .map(|a| a.message.clone())
}

#[test]
fn a_stuck_step_names_every_false_operand_with_its_value_and_comment() {
    for (form, mut e) in engines() {
        // S0: started, but in manual (mode 1).
        load(
            &mut e,
            "S0.X",
            &[
                ("bStart", bit(true)),
                ("iMode", Reading::Number(Num::Int(1))),
                ("rSpindleSpeed", Reading::Number(Num::Float(0.0))),
                ("bDoorOpen", bit(true)),
                ("T1.Q", bit(false)),
                ("fbClamp.Done", bit(false)),
                ("C1.Q", bit(false)),
                ("bAbort", bit(false)),
            ],
            1_000,
        );
        e.advance(6_000);
        assert_eq!(
            message(&e, "sfc-M1-S0").as_deref(),
            Some(
                "M1.S0 (Waiting for start) stuck for 5.0 s (supervision 5.0 s): \
                 t1 (Start in automatic) waits for iMode = 1 (needs == 3): Operating mode"
            ),
            "{form}"
        );
        // Automatic: t1 fires; S1 runs the spindle up with the door open.
        read(&mut e, "iMode", Reading::Number(Num::Int(3)), 6_100);
        read(&mut e, "S0.X", bit(false), 6_200);
        read(&mut e, "S1.X", bit(true), 6_200);
        assert_eq!(message(&e, "sfc-M1-S0"), None, "{form}");
        read(
            &mut e,
            "rSpindleSpeed",
            Reading::Number(Num::Float(1650.0)),
            6_300,
        );
        e.advance(11_200);
        assert_eq!(
            message(&e, "sfc-M1-S1").as_deref(),
            Some(
                "M1.S1 (Spindle run-up) stuck for 5.0 s (supervision 5.0 s): \
                 t2 (Spindle at speed, door shut) waits for \
                 rSpindleSpeed = 1650.0 (needs >= 1800): Spindle speed, \
                 bDoorOpen = 1 (expected 0): Door open"
            ),
            "{form}"
        );
        // The door shuts: the speed alone is named.
        read(&mut e, "bDoorOpen", bit(false), 12_000);
        let waits = message(&e, "sfc-M1-S1").unwrap();
        assert!(
            waits.ends_with("waits for rSpindleSpeed = 1650.0 (needs >= 1800): Spindle speed"),
            "{form}: {waits}"
        );
        // At speed: t2 can fire; the PLC moves to S2, where the clamp is
        // not done and the part not counted, the settle time is over.
        read(
            &mut e,
            "rSpindleSpeed",
            Reading::Number(Num::Float(1812.5)),
            12_100,
        );
        assert!(message(&e, "sfc-M1-S1")
            .unwrap()
            .ends_with("t2 (Spindle at speed, door shut) can fire"));
        read(&mut e, "S1.X", bit(false), 12_200);
        read(&mut e, "S2.X", bit(true), 12_200);
        read(&mut e, "T1.Q", bit(true), 12_300);
        e.advance(17_200);
        assert_eq!(
            message(&e, "sfc-M1-S2").as_deref(),
            Some(
                "M1.S2 (Clamp and settle) stuck for 5.0 s (supervision 5.0 s): \
                 t3 (Clamped and settled) waits for \
                 fbClamp.Done = 0 (expected 1): Clamp cylinder, \
                 C1.Q = 0 (expected 1): Parts in the fixture; \
                 t4 (Aborted) waits for bAbort = 0 (expected 1): Abort pressed"
            ),
            "{form}"
        );
        // The clamp is done, the timer restarts: the timer is named.
        read(&mut e, "fbClamp.Done", bit(true), 18_000);
        read(&mut e, "T1.Q", bit(false), 18_000);
        let waits = message(&e, "sfc-M1-S2").unwrap();
        assert!(
            waits.contains(
                "t3 (Clamped and settled) waits for T1.Q = 0 (expected 1): Clamp settle time, \
                 C1.Q = 0 (expected 1): Parts in the fixture; "
            ),
            "{form}: {waits}"
        );
    }
}

/// The operands of S1's and S2's transitions, as a case.
#[derive(Debug, Clone)]
struct Case {
    speed: f64,
    door: bool,
    timer: bool,
    clamp: bool,
    counted: bool,
    abort: bool,
}

fn case() -> impl Strategy<Value = Case> {
    (
        prop_oneof![Just(1800.0), Just(1799.5), 0.0..4000.0f64],
        any::<[bool; 5]>(),
    )
        .prop_map(|(speed, b)| Case {
            speed,
            door: b[0],
            timer: b[1],
            clamp: b[2],
            counted: b[3],
            abort: b[4],
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// For any values, a stuck step's message names exactly the operands
    /// that are false where the transition needs them true (or true
    /// where it needs them false), each with its value.
    #[test]
    fn every_blocking_operand_is_named_and_no_other(c in case()) {
        let (_, mut e) = engines().remove(0);
        let values = [
            ("bStart", bit(true)),
            ("iMode", Reading::Number(Num::Int(3))),
            ("rSpindleSpeed", Reading::Number(Num::Float(c.speed))),
            ("bDoorOpen", bit(c.door)),
            ("T1.Q", bit(c.timer)),
            ("fbClamp.Done", bit(c.clamp)),
            ("C1.Q", bit(c.counted)),
            ("bAbort", bit(c.abort)),
        ];
        for (at, step, id) in [(1_000, "S1.X", "sfc-M1-S1"), (100_000, "S2.X", "sfc-M1-S2")] {
            load(&mut e, step, &values, at);
            e.advance(at + 10_000);
            let text = message(&e, id).unwrap();
            let blocking: Vec<(&str, String, bool)> = if step == "S1.X" {
                vec![
                    ("rSpindleSpeed", format!("rSpindleSpeed = {:?} (needs >= 1800)", c.speed), c.speed < 1800.0),
                    ("bDoorOpen", "bDoorOpen = 1 (expected 0)".into(), c.door),
                ]
            } else {
                vec![
                    ("T1.Q", "T1.Q = 0 (expected 1)".into(), !c.timer),
                    ("fbClamp.Done", "fbClamp.Done = 0 (expected 1)".into(), !c.clamp),
                    ("C1.Q", "C1.Q = 0 (expected 1)".into(), !c.counted),
                    ("bAbort", "bAbort = 0 (expected 1)".into(), !c.abort),
                ]
            };
            for (name, named, blocks) in blocking {
                prop_assert_eq!(text.contains(name), blocks, "{}: {}", name, text);
                if blocks {
                    prop_assert!(text.contains(&named), "{}: {}", named, text);
                }
            }
        }
    }
}
