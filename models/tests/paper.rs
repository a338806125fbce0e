//! Paper 000's worked examples, reproduced: Fig. 6, ESE (eqs. 6, 8-13) and
//! CSD (eqs. 7, 14-23), from the programs shipped in `config/cnc/`.

#![allow(clippy::unwrap_used)] // test helpers fail loudly by design

use cellwatch_models::comments::CommentDb;
use cellwatch_models::explain::{explain, Polarity};
use cellwatch_models::expr::Expr;
use cellwatch_models::program::Program;
use cellwatch_models::signal::{pmc_address, Observability, Signal};
use cellwatch_models::switching::SwitchingFunction;
use cellwatch_models::values::Values;

mod kit;
use kit::{
    rename, step_expr, switching_function as sf, tags_to_paper, CSD, ESE, ESE_NORMAL, FIG6_FBD_L5X,
    FIG6_PLCOPEN, FIG6_TIA_FBD, FIG6_TIA_LAD,
};

const FIG6: &str =
    "RD X1\nANDN X2\nRDNS X3\nORS\nANDN Y1\nWR R1\nRD X4\nANDN Y2\nAND R1\nWR G0.00\n";
const ESE_COMMENTS: &str = include_str!("../../config/cnc/ese-comments.csv");
const CSD_COMMENTS: &str = include_str!("../../config/cnc/csd-comments.csv");
const ESE_STL: &str = include_str!("../../tests/data/paper000/ese.awl");
const FIG6_STL: &str = include_str!("../../tests/data/paper000/fig6.awl");
const ESE_LD: &str = include_str!("../../tests/data/paper000/ese.xml");
const FIG6_TIA_TAGS: &str = include_str!("../../tests/data/paper000/fig6.tags.SimaticML.xml");

/// `e` with the IEC direct addresses of the ladders renamed to the STL
/// addresses of the same map (`%IX20.4` → `E20.4`, or `I20.4` for the
/// English Fig. 6), then to the paper's.
fn ladder_to_paper(e: &Expr, english: bool) -> Expr {
    let stl = |s: &Signal| {
        let name = s.name();
        let (input, output) = if english { ("I", "Q") } else { ("E", "A") };
        let renamed = if let Some(a) = name.strip_prefix("%IX") {
            format!("{input}{a}")
        } else if let Some(a) = name.strip_prefix("%QX") {
            format!("{output}{a}")
        } else if let Some(a) = name.strip_prefix("%MX") {
            format!("M{a}")
        } else {
            name.to_string()
        };
        Signal::new(&renamed)
    };
    to_paper(&rename(e, &stl))
}

/// The S7 addresses the STL versions use for the paper's PMC addresses.
const STL_ADDRESSES: &[(&str, &str)] = &[
    ("E20.4", "X200.04"),
    ("E20.0", "X200.00"),
    ("E20.3", "X200.03"),
    ("E0.4", "X0.04"),
    ("E0.5", "X0.05"),
    ("E0.6", "X0.06"),
    ("E0.7", "X0.07"),
    ("E1.0", "X0.08"),
    ("E1.2", "X0.0A"),
    ("E1.7", "X0.0F"),
    ("E30.0", "F0.00"),
    ("E30.1", "F0.01"),
    ("E31.0", "F28.00"),
    ("E31.1", "F28.01"),
    ("E31.2", "F28.02"),
    ("E31.3", "F28.03"),
    ("A0.0", "Y0.00"),
    ("A10.0", "G0.00"),
    ("A8.2", "G8.02"),
    ("M102.0", "R1024.00"),
    ("M101.0", "R1023.00"),
    ("M101.1", "R1023.01"),
    ("M90.0", "R900.00"),
    ("I0.1", "X1"),
    ("I0.2", "X2"),
    ("I0.3", "X3"),
    ("I0.4", "X4"),
    ("Q0.1", "Y1"),
    ("Q0.2", "Y2"),
    ("M1.0", "R1"),
    ("Q10.0", "G0.00"),
];

/// `e` with its STL addresses renamed to the paper's.
fn to_paper(e: &Expr) -> Expr {
    let name = |s: &Signal| {
        if s.name().starts_with("SSF") {
            return s.clone();
        }
        let (_, paper) = STL_ADDRESSES
            .iter()
            .find(|(stl, _)| *stl == s.name())
            .unwrap_or_else(|| panic!("no paper address for {s}"));
        Signal::new(paper)
    };
    rename(e, &name)
}

/// Whether two expressions agree on every assignment of their signals.
fn equal_by_truth_table(a: &Expr, b: &Expr) -> bool {
    let mut signals = a.signals();
    signals.extend(b.signals());
    let signals: Vec<Signal> = signals.into_iter().collect();
    assert!(signals.len() <= 22, "truth table too large");
    (0u64..1 << signals.len()).all(|bits| {
        let v = |s: &Signal| {
            let i = signals.iter().position(|x| x == s).unwrap();
            bits >> i & 1 == 1
        };
        a.eval(&v) == b.eval(&v)
    })
}

fn assert_steps(sf: &SwitchingFunction, paper: &[&str]) {
    assert_eq!(sf.steps.len(), paper.len(), "number of step blocks");
    for (i, eq) in paper.iter().enumerate() {
        let expected = Expr::parse(eq).unwrap();
        // Same terms, same operator; order within a block does not matter.
        let sort = |e: Expr| match e {
            Expr::And(mut t) => {
                t.sort();
                Expr::And(t)
            }
            Expr::Or(mut t) => {
                t.sort();
                Expr::Or(t)
            }
            other => other,
        };
        assert_eq!(
            sort(step_expr(sf, i + 1)),
            sort(expected),
            "step {} differs from the paper's SSF{}",
            i + 1,
            i + 1
        );
    }
}

#[test]
fn fig6_relay_and_fault_coil() {
    let r1 = sf("fig6.il", FIG6, "R1");
    assert_eq!(r1.notation(), "((X1 * -X2) + -X3) * -Y1");
    let g = sf("fig6.il", FIG6, "G0.00");
    assert_eq!(g.notation(), "X4 * -Y2 * ((X1 * -X2) + -X3) * -Y1");
    // Eq. (5) as the paper prints it.
    let eq5 = Expr::parse("(X4) * (-Y2) * (((X1)*(-X2)) + (-X3)) * (-Y1)").unwrap();
    assert!(equal_by_truth_table(&g.to_expr(), &eq5));
}

#[test]
fn fig6_and_ese_in_stl_give_the_paper_s_functions_and_step_blocks() {
    // Fig. 6, English mnemonics.
    let p = Program::compile("fig6.awl", FIG6_STL, None).unwrap();
    assert_eq!(p.dialect(), cellwatch_models::programs::Dialect::Stl);
    let g = sf("fig6.awl", FIG6_STL, "Q10.0");
    let il = sf("fig6.il", FIG6, "G0.00");
    assert!(equal_by_truth_table(&to_paper(&g.to_expr()), &il.to_expr()));
    assert_eq!(g.steps.len(), il.steps.len());
    for i in 1..=il.steps.len() {
        assert_eq!(
            to_paper(&step_expr(&g, i)),
            step_expr(&il, i),
            "Fig. 6 step {i}"
        );
    }
    // ESE, German mnemonics, blocks and networks: eq. (6) and the six step
    // blocks of eqs. (8)-(13).
    let ese = sf("ese.awl", ESE_STL, "A8.2");
    let il = sf("ese.il", ESE, "G8.02");
    assert!(equal_by_truth_table(
        &to_paper(&ese.to_expr()),
        &il.to_expr()
    ));
    assert_eq!(ese.steps.len(), 6);
    for i in 1..=6 {
        assert_eq!(
            to_paper(&step_expr(&ese, i)),
            step_expr(&il, i),
            "ESE step {i}"
        );
    }
}

#[test]
fn fig6_and_ese_drawn_as_plcopen_ladders_give_the_paper_s_functions_and_step_blocks() {
    let g = sf("fig6.xml", FIG6_PLCOPEN, "%QX10.0");
    let il = sf("fig6.il", FIG6, "G0.00");
    assert!(equal_by_truth_table(
        &ladder_to_paper(&g.to_expr(), true),
        &il.to_expr()
    ));
    assert_eq!(g.steps.len(), il.steps.len());
    for i in 1..=il.steps.len() {
        assert_eq!(
            ladder_to_paper(&step_expr(&g, i), true),
            step_expr(&il, i),
            "Fig. 6 step {i}"
        );
    }
    let ese = sf("ese.xml", ESE_LD, "%QX8.2");
    let il = sf("ese.il", ESE, "G8.02");
    assert!(equal_by_truth_table(
        &ladder_to_paper(&ese.to_expr(), false),
        &il.to_expr()
    ));
    assert_eq!(ese.steps.len(), 6);
    for i in 1..=6 {
        assert_eq!(
            ladder_to_paper(&step_expr(&ese, i), false),
            step_expr(&il, i),
            "ESE step {i}"
        );
    }
}

#[test]
fn fig6_exported_from_tia_portal_in_lad_and_fbd_gives_the_il_s_functions_steps_and_culprits() {
    let il = sf("fig6.il", FIG6, "G0.00");
    // LAD by tag (`"X1"`...), FBD by absolute address (`%I0.1`...).
    let lad = sf("fig6.lad.SimaticML.xml", FIG6_TIA_LAD, "G0_00");
    let fbd = sf("fig6.fbd.SimaticML.xml", FIG6_TIA_FBD, "Q10.0");
    let renamings: [fn(&Expr) -> Expr; 2] = [tags_to_paper, to_paper];
    for (g, to_paper) in [&lad, &fbd].into_iter().zip(renamings) {
        assert_eq!(to_paper(&g.to_expr()), il.to_expr());
        assert_eq!(g.steps.len(), il.steps.len());
        for i in 1..=il.steps.len() {
            assert_eq!(to_paper(&step_expr(g, i)), step_expr(&il, i), "step {i}");
        }
    }
    // The same culprits for every state of the six contacts.
    let inputs = ["X1", "X2", "X3", "X4", "Y1", "Y2"];
    let lad_names = |s: &Signal| Signal::new(s.name());
    let fbd_names = |s: &Signal| {
        let (stl, _) = STL_ADDRESSES[STL_ADDRESSES.len() - 8..]
            .iter()
            .find(|(_, paper)| *paper == s.name())
            .unwrap();
        Signal::new(stl)
    };
    for bits in 0u32..1 << inputs.len() {
        let value = |s: &Signal| {
            let i = inputs.iter().position(|x| *x == s.name())?;
            Some(bits >> i & 1 == 1)
        };
        let culprits = |g: &SwitchingFunction, named: &dyn Fn(&Signal) -> Signal| {
            let now = |s: &Signal| {
                inputs.iter().find_map(|x| {
                    (named(&Signal::new(x)) == *s)
                        .then(|| value(&Signal::new(x)))
                        .flatten()
                })
            };
            let e = explain(g, now, None, Polarity::On, &CommentDb::default()).unwrap();
            let names: Vec<String> = e
                .culprits
                .iter()
                .map(|c| {
                    let back = inputs
                        .iter()
                        .find(|x| named(&Signal::new(x)) == c.address)
                        .unwrap();
                    format!("{back}={}", u8::from(c.value))
                })
                .collect();
            (e.value, e.fault_step, names)
        };
        let want = culprits(&il, &|s| s.clone());
        assert_eq!(culprits(&lad, &lad_names), want, "bits {bits:06b}");
        assert_eq!(culprits(&fbd, &fbd_names), want, "bits {bits:06b}");
    }
    // The tag table names both the tags and their addresses.
    let p = Program::compile("fig6.lad.SimaticML.xml", FIG6_TIA_LAD, None).unwrap();
    let q = Program::compile("fig6.fbd.SimaticML.xml", FIG6_TIA_FBD, None).unwrap();
    for (p, stop) in [(&p, "X2"), (&q, "I0.2")] {
        let tags =
            CommentDb::parse("fig6.tags.SimaticML.xml", FIG6_TIA_TAGS, |a| p.resolve(a)).unwrap();
        assert_eq!(tags.get(&Signal::new(stop)), Some("Stop push button (B)"));
        assert_eq!(tags.len(), 16);
    }
    // The interface's comment, in en-US.
    assert_eq!(
        p.documentation().get(&Signal::new("Fig6_LAD.#Enable")),
        Some("Cell enabled")
    );
    assert!(p.warnings().is_empty(), "{:?}", p.warnings());
    assert!(q.warnings().is_empty(), "{:?}", q.warnings());
}

#[test]
fn a_german_tag_table_meets_the_block_s_english_addresses() {
    // The same tag table as a project with German mnemonics exports it:
    // inputs `%E`, outputs `%A`. A block's absolute addresses are always
    // English (`I0.2`), so `%E0.2`'s comment must reach `I0.2`.
    let german = FIG6_TIA_TAGS
        .replace("<LogicalAddress>%I", "<LogicalAddress>%E")
        .replace("<LogicalAddress>%Q", "<LogicalAddress>%A");
    assert!(german.contains("<LogicalAddress>%E0.2<") && !german.contains("%I0."));
    let p = Program::compile("fig6.fbd.SimaticML.xml", FIG6_TIA_FBD, None).unwrap();
    let tags = CommentDb::parse("fig6.tags.SimaticML.xml", &german, |a| p.resolve(a)).unwrap();
    for (address, comment) in [
        ("I0.2", "Stop push button (B)"),
        ("I0.4", "Cycle start"),
        ("Q0.2", "Alarm lamp"),
        ("Q10.0", "PLC run (fault coil)"),
        ("M1.0", "Ready relay"),
        // As written, for a German STL source.
        ("E0.2", "Stop push button (B)"),
        ("A0.2", "Alarm lamp"),
    ] {
        assert_eq!(tags.get(&Signal::new(address)), Some(comment), "{address}");
    }
    let german_texts =
        CommentDb::parse_in("t.xml", &german, |a| p.resolve(a), Some("de-DE")).unwrap();
    assert_eq!(
        german_texts.get(&Signal::new("I0.2")),
        Some("Stopptaster (B)")
    );
    // A fault coil explained with the table: the culprit, an input the
    // block addresses as I0.x, carries its comment.
    let g = SwitchingFunction::expand(
        &p,
        &Signal::new("Q10.0"),
        &Observability::default_for(p.dialect()),
    )
    .unwrap();
    // X1 (I0.1) drops while X3 (I0.3) is on: the fault coil falls.
    let mut before = Values::new();
    for (s, v) in [
        ("I0.1", true),
        ("I0.2", false),
        ("I0.3", true),
        ("I0.4", true),
        ("Q0.1", false),
        ("Q0.2", false),
    ] {
        before.set(Signal::new(s), v);
    }
    let mut now = before.clone();
    now.set(Signal::new("I0.1"), false);
    let was = |s: &Signal| before.get(s);
    let e = explain(&g, |s| now.get(s), Some(&was), Polarity::Off, &tags).unwrap();
    let culprits: Vec<String> = e.culprits.iter().map(ToString::to_string).collect();
    assert_eq!(culprits[0], "I0.1 = 0 (expected 1): Start push button");
}

#[test]
fn stl_ors_and_groups_as_s7_does() {
    // `O` alone ORs AND groups; `O x` ORs into the result so far, and a
    // later `U` ANDs with all of it (no precedence), as an S7 CPU computes.
    let q = |src: &str| sf("t.awl", src, "A4.0").to_expr();
    let e = |text: &str| Expr::parse(text).unwrap();
    assert!(equal_by_truth_table(
        &q("U E 0.0\nU E 0.1\nO\nU E 0.2\nU E 0.3\n= A 4.0\n"),
        &e("(E0.0 * E0.1) + (E0.2 * E0.3)")
    ));
    assert!(equal_by_truth_table(
        &q("U E 0.0\nO E 0.1\nU E 0.2\n= A 4.0\n"),
        &e("(E0.0 + E0.1) * E0.2")
    ));
    assert!(equal_by_truth_table(
        &q("UN( \nO E 0.0\nO E 0.1\n)\nX E 0.2\n= A 4.0\n"),
        &e("(-E0.0 * -E0.1 * -E0.2) + ((E0.0 + E0.1) * E0.2)")
    ));
    // SET / CLR, and a first check after an assignment starts afresh.
    assert!(equal_by_truth_table(
        &q("U E 1.0\n= M 0.0\nSET\n= M 0.1\nU E 0.0\nUN E 0.1\n= A 4.0\n"),
        &e("E0.0 * -E0.1")
    ));
    // A timer's bit is a leaf; loading its preset is a warning, not an error.
    let p = Program::compile("t.awl", "U E 0.0\nL S5T#5S\nSE T 1\nU T 1\n= A 4.0\n", None).unwrap();
    assert_eq!(
        p.warnings().iter().map(|w| w.at.line).collect::<Vec<_>>(),
        [2, 3]
    );
    let t = SwitchingFunction::expand(
        &p,
        &Signal::new("A4.0"),
        &Observability::default_for(p.dialect()),
    )
    .unwrap();
    assert_eq!(t.notation(), "T1");
}

#[test]
fn ese_switching_function_is_eq_6() {
    let g = sf("ese.il", ESE, "G8.02");
    let eq6 = Expr::parse(
        "((((-R1024.00)+(-G0.00)+(-F0.00)+(-X200.04)) · (-X200.00)) · ((-R1023.00)+(-R1023.01)) · (-F0.01))
         + (-X0.07) + (-X0.05) + (-Y0.00) + (-F28.03) + (-F28.02) + (-F28.01) + (-F28.00)
         + (X200.03) + (-X0.0F) + (-X0.0A) + (-X0.08) + (-X0.06) + (-X0.04)",
    )
    .unwrap();
    assert_eq!(g.to_expr().canonical(), eq6.canonical());
}

#[test]
fn ese_step_blocks_are_eqs_8_to_13() {
    assert_steps(
        &sf("ese.il", ESE, "G8.02"),
        &[
            "(-R1024.00)+(-G0.00)+(-F0.00)+(-X200.04)",
            "SSF1 · (-X200.00)",
            "(-R1023.00)+(-R1023.01)",
            "SSF2 · SSF3 · (-F0.01)",
            "SSF4 + (-X0.07)+(-X0.05)+(-Y0.00)+(-F28.03)+(-F28.02)+(-F28.01)+(-F28.00)",
            "SSF5 + X200.03 + (-X0.0F)+(-X0.0A)+(-X0.08)+(-X0.06)+(-X0.04)",
        ],
    );
}

#[test]
fn csd_switching_function_and_step_blocks_are_eqs_14_to_22() {
    let g = sf("csd.il", CSD, "G9.00");
    assert_steps(
        &g,
        &[
            "(-F17.00)+(-F17.01)+(-F17.02)+(-F17.03)+(-F18.00)+(-F18.01)+(-F18.02)+(-F18.03)",
            "SSF1 · R35.00",
            "X200.01 · X201.06",
            "SSF2 + SSF3",
            "SSF4 · G0.00 · R0.00",
            "SSF5 + (-X0.0E)+(-X0.0D)+(-X201.02)+(-F17.03)+(-F17.02)+(-F17.01)+(-F17.00)",
            "SSF5 + (-X201.03)",
            "SSF6 · SSF7",
            "SSF8 + (-X200.01)",
        ],
    );
}

fn ese_comments() -> CommentDb {
    CommentDb::parse("ese-comments.csv", ESE_COMMENTS, pmc_address).unwrap()
}

#[test]
fn ese_with_y_over_travel_open_names_x0_06_at_step_6() {
    let g = sf("ese.il", ESE, "G8.02");
    let before = Values::parse_file("ese-normal.values", ESE_NORMAL, pmc_address).unwrap();
    let mut now = before.clone();
    now.set(Signal::new("X0.06"), false);
    let b = |s: &Signal| before.get(s);
    let e = explain(&g, |s| now.get(s), Some(&b), Polarity::On, &ese_comments()).unwrap();
    assert!(e.value);
    assert_eq!(e.fault_step, Some(6));
    assert_eq!(e.culprits.len(), 1);
    let c = &e.culprits[0];
    assert_eq!(
        c.to_string(),
        "X0.06 = 0 (expected 1): Y Over Travel Limit SW (B)"
    );
    assert!(c.trigger);
    // The machine as it runs normally is not in ESE.
    let ok = explain(&g, |s| before.get(s), None, Polarity::On, &ese_comments()).unwrap();
    assert!(!ok.is_fault());
}

#[test]
fn csd_cycle_start_in_jog_mode_is_step_3() {
    let g = sf("csd.il", CSD, "G9.00");
    let comments = CommentDb::parse("csd-comments.csv", CSD_COMMENTS, pmc_address).unwrap();
    let mut now = Values::new();
    // Axes referenced, PLC running, both spindles in auto, JOG mode.
    for s in [
        "F17.00", "F17.01", "F17.02", "F17.03", "F18.00", "F18.01", "F18.02", "F18.03",
    ] {
        now.set(Signal::new(s), true);
    }
    for (s, v) in [
        ("R35.00", true),
        ("G0.00", true),
        ("R0.00", true),
        ("X0.0D", true),
        ("X0.0E", true),
        ("X201.02", false),
        ("X201.03", false),
        ("X201.06", true),
        ("X200.01", false),
    ] {
        now.set(Signal::new(s), v);
    }
    let before = now.clone();
    now.set(Signal::new("X200.01"), true); // cycle start pressed
    let b = |s: &Signal| before.get(s);
    let e = explain(&g, |s| now.get(s), Some(&b), Polarity::On, &comments).unwrap();
    assert!(e.is_fault());
    assert_eq!(e.fault_step, Some(3));
    let names: Vec<&str> = e.culprits.iter().map(|c| c.address.name()).collect();
    assert!(
        names.contains(&"X200.01") && names.contains(&"X201.06"),
        "{names:?}"
    );
    assert_eq!(
        e.culprits[0].to_string(),
        "X200.01 = 1 (expected 0): Cycle Start"
    );
    assert!(e.culprits[0].trigger);
    let jog = e
        .culprits
        .iter()
        .find(|c| c.address.name() == "X201.06")
        .unwrap();
    assert_eq!(jog.to_string(), "X201.06 = 1 (expected 0): JOG Mode");
    // Reference-return contacts are all fine: none is blamed.
    assert!(!names
        .iter()
        .any(|n| n.starts_with("F17") || n.starts_with("F18")));
}

const FIG6_L5X: &str = include_str!("../../tests/data/paper000/fig6.L5X");

/// `e` with the Studio 5000 export's tag names renamed to the paper's.
fn l5x_to_paper(e: &Expr) -> Expr {
    rename(e, &|s: &Signal| {
        let paper = match s.name() {
            "Program:MainProgram.R1" => "R1",
            "G0_00" => "G0.00",
            other => other,
        };
        Signal::new(paper)
    })
}

#[test]
fn fig6_as_a_studio_5000_export_gives_the_paper_s_functions_step_blocks_and_culprits() {
    fig6_from_studio_5000("fig6.L5X", FIG6_L5X);
}

#[test]
fn fig6_as_a_studio_5000_function_block_diagram_gives_the_same() {
    // R1 on sheet 1 (BAND, BOR and BNOT blocks), G0_00 on sheet 2 reading
    // R1 through an IRef: the same coils, step blocks and culprits.
    fig6_from_studio_5000("fig6.fbd.L5X", FIG6_FBD_L5X);
}

/// The Fig. 6 export `text` gives the IL's switching functions, step
/// blocks and culprits, and the tags' comments.
fn fig6_from_studio_5000(origin: &str, text: &str) {
    let p = Program::compile(origin, text, None).unwrap();
    assert!(p.warnings().is_empty(), "{:?}", p.warnings());
    let names: Vec<&str> = p.coils().iter().map(|c| c.signal.name()).collect();
    assert_eq!(names, ["Program:MainProgram.R1", "G0_00"]);
    let g = sf(origin, text, "G0_00");
    let il = sf("fig6.il", FIG6, "G0.00");
    assert_eq!(l5x_to_paper(&g.to_expr()), il.to_expr());
    assert_eq!(g.steps.len(), il.steps.len());
    for i in 1..=il.steps.len() {
        assert_eq!(
            l5x_to_paper(&step_expr(&g, i)),
            step_expr(&il, i),
            "Fig. 6 step {i}"
        );
    }
    // The aliases' comments: X1's own description; X2 has none, so the
    // input card's comment on Local:1:I.Data.2 shows, as in Studio 5000.
    let docs = p.documentation();
    assert_eq!(
        docs.get(&Signal::new("X1")),
        Some("Cycle start push button")
    );
    assert_eq!(docs.get(&Signal::new("X2")), Some("X2: door open"));
    assert_eq!(docs.get(&Signal::new("Y1")), Some("Y1: spindle alarm lamp"));
    assert_eq!(
        docs.get(&Signal::new("Program:MainProgram.R1")),
        Some("Internal relay R1")
    );

    // The same fault, the same culprits: X1 drops while X3 is on (not
    // manual), so SSF1 = 0, SSF2 = 0 and the fault coil falls.
    let before = [
        ("X1", true),
        ("X2", false),
        ("X3", true),
        ("X4", true),
        ("Y1", false),
        ("Y2", false),
    ];
    let culprits_of = |sf: &SwitchingFunction, rename: &dyn Fn(&str) -> String| {
        let mut b = Values::new();
        for (s, v) in before {
            b.set(Signal::new(&rename(s)), v);
        }
        let mut now = b.clone();
        now.set(Signal::new(&rename("X1")), false);
        let was = |s: &Signal| b.get(s);
        let e = explain(
            sf,
            |s| now.get(s),
            Some(&was),
            Polarity::Off,
            &CommentDb::default(),
        )
        .unwrap();
        (
            e.fault_step,
            e.culprits
                .iter()
                .map(ToString::to_string)
                .collect::<Vec<_>>(),
        )
    };
    let from_l5x = culprits_of(&g, &|s| s.to_string());
    let from_il = culprits_of(&il, &|s| s.to_string());
    assert_eq!(from_l5x, from_il);
    assert_eq!(from_l5x.0, Some(1));
    assert_eq!(from_l5x.1[0], "X1 = 0 (expected 1)");
}
