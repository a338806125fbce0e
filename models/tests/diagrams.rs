//! Drawn programs read as the IL reads them: a box whose output feeds
//! several inputs is one step block read twice (issue #69), and a wire
//! naming a part the diagram does not have is an error at that wire.
//!
//! Paper 000's CSD (`tests/data/paper000/csd-ese.il`) drawn as a function
//! block diagram in the three exports the readers take: TIA Portal
//! (SimaticML), PLCopen XML and Studio 5000 (L5X). Step 5 feeds steps 6
//! and 7, as the IL's internal relay R900.01 does.

#![allow(clippy::unwrap_used)] // test helpers fail loudly by design

use cellwatch_models::comments::CommentDb;
use cellwatch_models::explain::{explain, Polarity};
use cellwatch_models::program::Program;
use cellwatch_models::signal::Signal;
use cellwatch_models::switching::SwitchingFunction;
use cellwatch_models::values::Values;

mod kit;
use kit::{
    step_expr, switching_function as sf, tags_to_paper, CSD_ESE, FIG6_FBD_L5X, FIG6_PLCOPEN,
    FIG6_TIA_FBD, FIG6_TIA_LAD,
};

const CSD_TIA: &str = include_str!("../../tests/data/paper000/csd.fbd.SimaticML.xml");
const CSD_PLCOPEN: &str = include_str!("../../tests/data/paper000/csd.fbd.xml");
const CSD_L5X: &str = include_str!("../../tests/data/paper000/csd.fbd.L5X");

/// The CSD exports: file name, text, the coil G9.00 as each names it.
const EXPORTS: [(&str, &str, &str); 3] = [
    ("csd.fbd.SimaticML.xml", CSD_TIA, "G9_00"),
    ("csd.fbd.xml", CSD_PLCOPEN, "G9_00"),
    ("csd.fbd.L5X", CSD_L5X, "G9_00"),
];

#[test]
fn csd_drawn_as_fbd_has_the_il_s_nine_step_blocks_step_5_read_twice() {
    let il = sf("csd-ese.il", CSD_ESE, "G9.00");
    assert_eq!(il.steps.len(), 9);
    // Read inline at each input it feeds, step 5 and the four below it
    // were counted twice: fourteen blocks.
    let counts: Vec<(&str, usize)> = EXPORTS
        .iter()
        .map(|(origin, text, coil)| (*origin, sf(origin, text, coil).steps.len()))
        .collect();
    assert_eq!(
        counts,
        EXPORTS.map(|(origin, _, _)| (origin, 9)),
        "step blocks per export"
    );
    for (origin, text, coil) in EXPORTS {
        let g = sf(origin, text, coil);
        for i in 1..=9 {
            assert_eq!(
                tags_to_paper(&step_expr(&g, i)),
                step_expr(&il, i),
                "{origin}: step {i}"
            );
        }
        assert_eq!(tags_to_paper(&g.to_expr()), il.to_expr(), "{origin}");
        // Steps 6 and 7 both read step 5, as they read R900.01.
        assert_eq!(g.step_notation(7), "SSF5 + -X201_03", "{origin}");
        // The box's relay is expanded like R900.01: never a leaf.
        assert!(
            g.leaves().iter().all(|s| !s.name().starts_with('#')),
            "{origin}: {:?}",
            g.leaves()
        );
    }
}

#[test]
fn a_shared_box_is_an_internal_relay_named_after_the_box() {
    let coils = |origin: &str, text: &str| -> Vec<String> {
        let p = Program::compile(origin, text, None).unwrap();
        assert!(p.warnings().is_empty(), "{origin}: {:?}", p.warnings());
        p.coils().iter().map(|c| c.signal.to_string()).collect()
    };
    // The block, network and part (TIA), the POU and block (PLCopen), the
    // program, routine, sheet and block (L5X): each box its own relay.
    assert_eq!(coils(EXPORTS[0].0, CSD_TIA), ["#CSD_FBD.NW1.A25", "G9_00"]);
    assert_eq!(coils(EXPORTS[1].0, CSD_PLCOPEN), ["#csd.AND28", "G9_00"]);
    assert_eq!(
        coils(EXPORTS[2].0, CSD_L5X),
        ["#MainProgram.MainRoutine.1.BAND_03", "G9_00"]
    );
}

#[test]
fn a_plcopen_box_read_by_name_and_by_default_is_written_once() {
    // Step 7 reads step 5's box as its first output, step 6 as `OUT`.
    let text = CSD_PLCOPEN.replacen(
        r#"refLocalId="28" formalParameter="OUT""#,
        r#"refLocalId="28""#,
        1,
    );
    let p = Program::compile("csd.fbd.xml", &text, None).unwrap();
    let relay = p.coil(&Signal::new("#csd.AND28")).unwrap();
    assert_eq!(relay.writes.len(), 1);
    assert_eq!(sf("csd.fbd.xml", &text, "G9_00").steps.len(), 9);
}

#[test]
fn csd_drawn_as_fbd_blames_what_the_il_blames() {
    // Cycle start pressed in JOG mode (paper 000, eq. 23): step 3, the
    // cycle start button and the JOG mode switch.
    let il = sf("csd-ese.il", CSD_ESE, "G9.00");
    let culprits = |g: &SwitchingFunction, name: &dyn Fn(&str) -> String| {
        let mut now = Values::new();
        for s in [
            "F17.00", "F17.01", "F17.02", "F17.03", "F18.00", "F18.01", "F18.02", "F18.03",
            "R35.00", "G0.00", "R0.00", "X0.0D", "X0.0E", "X201.06",
        ] {
            now.set(Signal::new(&name(s)), true);
        }
        for s in ["X201.02", "X201.03", "X200.01", "G8.02"] {
            now.set(Signal::new(&name(s)), false);
        }
        let before = now.clone();
        now.set(Signal::new(&name("X200.01")), true);
        let was = |s: &Signal| before.get(s);
        let e = explain(
            g,
            |s| now.get(s),
            Some(&was),
            Polarity::On,
            &CommentDb::default(),
        )
        .unwrap();
        let named: Vec<String> = e
            .culprits
            .iter()
            .map(|c| c.to_string().replace('_', "."))
            .collect();
        (e.fault_step, named)
    };
    let want = culprits(&il, &|s| s.to_string());
    assert_eq!(want.0, Some(3));
    for (origin, text, coil) in EXPORTS {
        let g = sf(origin, text, coil);
        assert_eq!(culprits(&g, &|s| s.replace('.', "_")), want, "{origin}");
    }
}

/// `text` with the first `from` replaced by `to`; `from` must be there.
fn broken(text: &str, from: &str, to: &str) -> String {
    assert!(text.contains(from), "{from}");
    text.replacen(from, to, 1)
}

/// The errors compiling `text` gives, one a line.
fn errors(origin: &str, text: &str) -> String {
    match Program::compile(origin, text, None) {
        Ok(_) => panic!("{origin}: compiled"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn a_tia_portal_wire_naming_a_missing_part_is_an_error_at_the_wire() {
    // The operand of LAD contact 27 (X2): its contact was left without
    // one, a warning at the contact; now the wire is named where it is.
    let lad = broken(
        FIG6_TIA_LAD,
        r#"<IdentCon UId="22" />"#,
        r#"<IdentCon UId="99" />"#,
    );
    assert_eq!(
        errors("fig6.lad.SimaticML.xml", &lad),
        r#"fig6.lad.SimaticML.xml:123:7: block "Fig6_LAD" network 1: wire 35 names part 99, which is not in this network"#
    );
    // FBD: a wire from an operand that is not there, and a wire into a
    // box that is not there (box 27's in1).
    let fbd = broken(
        FIG6_TIA_FBD,
        r#"<IdentCon UId="22" />"#,
        r#"<IdentCon UId="99" />"#,
    );
    let fbd = broken(
        &fbd,
        r#"<NameCon UId="27" Name="in1" />"#,
        r#"<NameCon UId="98" Name="in1" />"#,
    );
    assert_eq!(
        errors("fig6.fbd.SimaticML.xml", &fbd),
        [
            r#"fig6.fbd.SimaticML.xml:103:7: block "Fig6_FBD" network 1: wire 31 names part 99, which is not in this network"#,
            r#"fig6.fbd.SimaticML.xml:108:7: block "Fig6_FBD" network 1: wire 32 names part 98, which is not in this network"#,
        ]
        .join("\n")
    );
}

#[test]
fn a_plcopen_connection_to_a_missing_element_is_an_error_at_the_connection() {
    // LD: contact 3 (X2) connected to nothing there.
    let ld = broken(
        FIG6_PLCOPEN,
        r#"<connection refLocalId="2"/>"#,
        r#"<connection refLocalId="99"/>"#,
    );
    assert_eq!(
        errors("fig6.xml", &ld),
        "fig6.xml:23:32: contact 3 is connected to element 99, which is not in POU 'fig6'"
    );
    // FBD: step 6's box reading step 5's from an element that is not there.
    let fbd = broken(CSD_PLCOPEN, r#"refLocalId="28""#, r#"refLocalId="77""#);
    assert_eq!(
        errors("csd.fbd.xml", &fbd),
        "csd.fbd.xml:93:66: block 29 input IN1 is connected to element 77, which is not in POU 'csd'"
    );
}

#[test]
fn a_studio_5000_wire_naming_a_missing_element_is_an_error_at_the_wire() {
    let from = broken(
        FIG6_FBD_L5X,
        r#"<Wire FromID="1" ToID="5" ToParam="In"/>"#,
        r#"<Wire FromID="99" ToID="5" ToParam="In"/>"#,
    );
    let both = broken(
        &from,
        r#"<Wire FromID="16" FromParam="Out" ToID="17" ToParam="In2"/>"#,
        r#"<Wire FromID="16" FromParam="Out" ToID="97" ToParam="In2"/>"#,
    );
    assert_eq!(
        errors("fig6.fbd.L5X", &both),
        [
            "fig6.fbd.L5X:229:1: routine MainRoutine, sheet 1: the wire from 99 to 5 names element 99, which is not on this sheet",
            "fig6.fbd.L5X:255:1: routine MainRoutine, sheet 2: the wire from 16 to 97 names element 97, which is not on this sheet",
        ]
        .join("\n")
    );
}
