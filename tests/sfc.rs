//! `cellwatch sfc check|patch` on chart files.

use crate::util::{cellwatch, root, Dir};

#[test]
fn check_lists_the_robot_charts_and_refuses_a_bad_one_with_its_place() {
    let robot = root().join("config/robot/robot.sfc.toml");
    let r = cellwatch(&["sfc", "check", robot.to_str().unwrap()]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stdout
            .contains("chart F2 (initial step none (entered by jumps))"),
        "{}",
        r.stdout
    );
    assert!(
        r.stdout
            .contains("transition t3    F1.S2 -> F2.S5 + F2.S8 + F2.S11  when %IX0.0.3"),
        "{}",
        r.stdout
    );
    let d = Dir::new();
    let bad = d.file(
        "bad.sfc.toml",
        "[[chart]]\nname = \"F1\"\ninitial = \"S0\"\n[[chart.step]]\nname = \"S0\"\nflag = \"S0.X\"\n[[chart.transition]]\nid = \"t1\"\nfrom = \"S0\"\nto = \"F2.S5\"\ncondition = \"X1\"\n",
    );
    let r = cellwatch(&["sfc", "check", &bad]);
    assert_eq!(r.code, 2);
    assert!(
        r.stderr
            .contains("bad.sfc.toml:10:6: transition t1 jumps to 'F2.S5': no chart 'F2'"),
        "{}",
        r.stderr
    );
}

#[test]
fn patch_prints_the_force_term_in_st_and_il() {
    let robot = root().join("config/robot/robot.sfc.toml");
    let r = cellwatch(&[
        "sfc",
        "patch",
        robot.to_str().unwrap(),
        "--force-switch",
        "%IX0.3.1",
        "--transition",
        "F1.t3",
        "--transition",
        "F2.t18",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(r
        .stdout
        .contains("F1_t3_FIRE := (S2.X AND %IX0.0.3) OR (%IX0.3.1 AND %IX0.0.3);"));
    assert!(r
        .stdout
        .contains("F2_t18_FIRE := (S15.X AND %IX0.2.2) OR (%IX0.3.1 AND %IX0.2.2);"));
    assert!(r
        .stdout
        .contains("OR(  %IX0.3.1\nAND  %IX0.2.2\n)\nST   F2_t18_FIRE"));
    let r = cellwatch(&[
        "sfc",
        "patch",
        robot.to_str().unwrap(),
        "--force-switch",
        "%IX0.3.1",
        "--transition",
        "F1.t9",
    ]);
    assert_eq!(r.code, 2);
    assert!(r.stderr.contains("--transition 'F1.t9'"), "{}", r.stderr);
}
