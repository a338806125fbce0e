//! `cellwatch sf`: switching functions and step blocks, text and JSON.

use crate::util::{cellwatch, Dir};

#[test]
fn fig6_in_both_notations() {
    let d = Dir::new();
    let p = d.file(
        "fig6.il",
        "RD X1\nANDN X2\nRDNS X3\nORS\nANDN Y1\nWR R1\nRD X4\nANDN Y2\nAND R1\nWR G0.00\n",
    );
    let r = cellwatch(&["sf", &p, "--coil", "G0.00"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stdout
            .contains("  SF:         G0.00 = X4 * -Y2 * ((X1 * -X2) + -X3) * -Y1\n"),
        "{}",
        r.stdout
    );
    assert!(r
        .stdout
        .contains("  in words:   X4 AND NOT Y2 AND ((X1 AND NOT X2) OR NOT X3) AND NOT Y1\n"));
    assert!(r.stdout.contains("  as written: G0.00 = X4 * -Y2 * R1\n"));
    assert!(
        r.stdout.contains("  SSF4   = X4 * -Y2 * SSF3 = G0.00\n"),
        "{}",
        r.stdout
    );
}

#[test]
fn json_lists_every_coil_with_steps_and_contacts() {
    let r = cellwatch(&[
        "sf",
        "config/cnc/csd.il",
        "--comments",
        "config/cnc/csd-comments.csv",
        "--json",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let v: serde_json::Value = serde_json::from_str(&r.stdout).unwrap();
    let coils: Vec<&str> = v
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["coil"].as_str().unwrap())
        .collect();
    assert_eq!(coils, ["R900.01", "G9.00"]);
    let g = &v[1];
    assert_eq!(g["steps"].as_array().unwrap().len(), 9);
    assert_eq!(g["steps"][2]["index"], 3);
    assert_eq!(g["steps"][2]["expr"], "X200.01 * X201.06");
    assert_eq!(g["steps"][8]["expr"], "SSF8 + -X200.01");
    let jog = g["contacts"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["address"] == "X201.06")
        .unwrap();
    assert_eq!(jog["comment"], "JOG Mode");
    assert!(g["sf"].as_str().unwrap().ends_with("+ -X200.01"));
}

#[test]
fn iec_program_with_function_block_output_and_a_jump() {
    let d = Dir::new();
    let p = d.file(
        "line.il",
        "(* station 1 *)\nPROGRAM station\nVAR\n  t1 : TON;\nEND_VAR\n\
         LD %IX0.0.3\nAND T1.Q\nOR( %IX0.0.4\nANDN Guard\n)\nST Alarm1\n\
         LD Alarm1\nST %QX0.1\nJMPC skip\nLD %IX0.1\nST %QX0.2\nskip:\nEND_PROGRAM\n",
    );
    let r = cellwatch(&["sf", &p, "--coil", "%qx0.1"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stdout
            .contains("SF:         %QX0.1 = (%IX0.0.3 * T1.Q) + (%IX0.0.4 * -Guard)\n"),
        "{}",
        r.stdout
    );
    assert!(
        r.stderr
            .contains(":14:1: warning: 'JMPC skip': jump or conditional region"),
        "{}",
        r.stderr
    );
    // The coil written after the jump is reported, not guessed.
    let r = cellwatch(&["sf", &p, "--coil", "%QX0.2"]);
    assert_eq!(r.code, 2);
    assert!(
        r.stderr.ends_with(":14: %QX0.2 is not derivable: written after a jump or conditional region, so the write may not run every scan ('JMPC skip' at line 14)\n"),
        "{}",
        r.stderr
    );
    // Without --coil, every coil is listed, the underivable one with its reason.
    let r = cellwatch(&["sf", &p]);
    assert_eq!(r.code, 0);
    assert!(r.stdout.contains("%QX0.2: not derivable\n"), "{}", r.stdout);
}

#[test]
fn observable_list_keeps_relays_as_leaves() {
    let r = cellwatch(&[
        "sf",
        "config/cnc/ese.il",
        "--coil",
        "G8.02",
        "--observable",
        "X,Y,F,G,R",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stdout.contains(
            "SF:         G8.02 = R900.00 + X200.03 + -X0.0F + -X0.0A + -X0.08 + -X0.06 + -X0.04\n"
        ),
        "{}",
        r.stdout
    );
}

#[test]
fn help_explains_the_commands() {
    let r = cellwatch(&["--help"]);
    assert_eq!(r.code, 0);
    assert!(r.stdout.contains("sf") && r.stdout.contains("explain"));
    // What the program is now, not its first version: every program format
    // it reads and every way its alarms leave the cell.
    let text = r.stdout.split_whitespace().collect::<Vec<_>>().join(" ");
    for said in [
        "FANUC PMC",
        "IEC 61131-3 IL",
        "Siemens STL",
        "PLCopen XML",
        "(.L5X)",
        "(SimaticML)",
        "OPC UA Alarms & Conditions server",
        "`@` serial bus",
        "Prometheus Alertmanager",
        "operators' web console",
    ] {
        assert!(
            text.contains(said),
            "--help does not say {said:?}:\n{}",
            r.stdout
        );
    }
    let r = cellwatch(&["-h"]);
    assert!(
        r.stdout
            .starts_with("cellwatch — one agent per manufacturing cell"),
        "{}",
        r.stdout
    );
    let r = cellwatch(&["explain", "--help"]);
    assert_eq!(r.code, 0);
    assert!(r.stdout.contains("--fault-when <on|off>"), "{}", r.stdout);
}

#[test]
fn a_tia_portal_block_gets_the_comments_of_the_tag_table_exported_beside_it() {
    // TIA Portal exports one object per file: the block and its tag table
    // side by side, and no --comments.
    let d = Dir::new();
    let block = d.file(
        "Fig6.xml",
        include_str!("data/paper000/fig6.lad.SimaticML.xml"),
    );
    let table = d.file(
        "PLC tags.xml",
        include_str!("data/paper000/fig6.tags.SimaticML.xml"),
    );
    // Another export of the folder that is no tag table is passed over.
    d.file(
        "Other.xml",
        include_str!("data/paper000/fig6.fbd.SimaticML.xml"),
    );
    let r = cellwatch(&["sf", &block, "--coil", "G0_00"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert_eq!(
        r.stderr,
        format!("{table}:1:1: note: the program's comments are read from this tag table, exported beside it\n")
    );
    assert!(
        r.stdout.contains("    X3  Door closed switch\n"),
        "{}",
        r.stdout
    );
    assert!(r.stdout.contains("    Y2  Alarm lamp\n"), "{}", r.stdout);
    // The project's comments in the language asked for.
    let r = cellwatch(&["sf", &block, "--coil", "G0_00", "--language", "de-DE"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stdout.contains("    X3  Tür geschlossen\n"),
        "{}",
        r.stdout
    );
    // Without it, only the block's own interface comments are left.
    std::fs::remove_file(&table).unwrap();
    let r = cellwatch(&["sf", &block, "--coil", "G0_00"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(r.stderr.is_empty(), "{}", r.stderr);
    assert!(!r.stdout.contains("Door closed switch"), "{}", r.stdout);
}
