//! IEC 61131-3 programs: matiec's Annex F examples and XML tests, Beremiz's
//! projects (an action's ladder, a chart's drawn conditions) and OpenPLC
//! Editor's ladders.

use super::*;

// --- matiec: IEC 61131-3 Annex F ----------------------------------------

#[test]
fn annex_f_cmd_monitor() {
    let p = program("matiec-annexf-cmd_monitor.il");
    // CMD_TMR is a TON and ALRM_FF an SR: their inputs are not coils.
    pinned(
        &p,
        &[
            (
                "CMD",
                "(AUTO_CMD * AUTO_MODE) + (MAN_CMD * -AUTO_MODE * -MAN_CMD_CHK)",
            ),
            ("ALRM", "ALRM_FF.Q1"),
        ],
    );
    let warned: Vec<usize> = p.warnings().iter().map(|w| w.at.line).collect();
    assert_eq!(warned, [20, 28, 31, 33]);
    // The declarations' comments are the comment database.
    assert_eq!(
        p.documentation().get(&Signal::new("AUTO_CMD")),
        Some("Automated command")
    );
    assert_eq!(
        p.documentation().get(&Signal::new("MAN_CMD_CHK")),
        Some("Negated MAN_CMD to debounce")
    );

    // By hand: in automatic mode the automated command drops. SSF1 =
    // AUTO_CMD·AUTO_MODE = 0·1 = 0; SSF2 = MAN_CMD·¬AUTO_MODE·¬MAN_CMD_CHK =
    // 0·0·1 = 0; CMD = SSF3 = SSF1 + SSF2 = 0. The command is missing
    // (fault when off); the lowest step on the fault's paths is SSF1, where
    // AUTO_CMD is the contact that changed; AUTO_MODE = 1 is what keeps
    // the manual path (SSF2) from carrying the command.
    let before = values(&[
        ("AUTO_CMD", true),
        ("AUTO_MODE", true),
        ("MAN_CMD", false),
        ("MAN_CMD_CHK", false),
    ]);
    let mut now = before.clone();
    now.set(Signal::new("AUTO_CMD"), false);
    let e = explained(&p, "CMD", &before, &now, Polarity::Off);
    assert!(e.is_fault());
    assert_eq!(e.steps, [false, false, false]);
    assert_eq!(e.fault_step, Some(1));
    assert_eq!(
        culprits(&e)[0],
        "AUTO_CMD = 0 (expected 1): Automated command"
    );
    assert!(e.culprits[0].trigger);
}

#[test]
fn annex_f_fwd_rev_mon() {
    let p = program("matiec-annexf-fwd_rev_mon.il");
    // FWD_MON and REV_MON are instances of CMD_MONITOR (declared in
    // another file, known as a block because they are CALled): their
    // inputs are not coils.
    pinned(
        &p,
        &[
            ("FWD_REV_ALRM", "FWD_REV_FF.Q"),
            ("FWD_CMD", "FWD_MON.CMD * -FWD_REV_FF.Q"),
            ("FWD_ALRM", "FWD_MON.ALRM"),
            ("REV_CMD", "REV_MON.CMD * -FWD_REV_FF.Q"),
            ("REV_ALRM", "REV_MON.ALRM"),
            ("KLAXON", "REV_MON.ALRM + FWD_MON.ALRM + FWD_REV_FF.Q"),
        ],
    );
    assert_eq!(p.warnings().len(), 18);
    assert_eq!(
        p.documentation().get(&Signal::new("KLAXON")),
        Some("Any alarm active")
    );

    // By hand: KLAXON = REV_MON.ALRM + FWD_MON.ALRM + FWD_REV_FF.Q, one
    // OR block. The forward monitor's alarm comes on: KLAXON = 0 + 1 + 0;
    // the fault (on) is at step 1 and FWD_MON.ALRM alone is to blame.
    let before = values(&[
        ("REV_MON.ALRM", false),
        ("FWD_MON.ALRM", false),
        ("FWD_REV_FF.Q", false),
    ]);
    let mut now = before.clone();
    now.set(Signal::new("FWD_MON.ALRM"), true);
    let e = explained(&p, "KLAXON", &before, &now, Polarity::On);
    assert_eq!(e.fault_step, Some(1));
    assert_eq!(culprits(&e), ["FWD_MON.ALRM = 1 (expected 0)"]);
}

#[test]
fn annex_f_stack_and_weigh_are_jumps_and_arithmetic() {
    let p = program("matiec-annexf-stack_int.il");
    pinned(&p, &[("OFLO", "! line 17"), ("EMPTY", "! line 17")]);
    assert_eq!(p.warnings().len(), 20);
    let p = program("matiec-annexf-weigh.il");
    pinned(&p, &[("ENO", "! line 9"), ("WEIGH", "! line 9")]);
    assert_eq!(p.warnings().len(), 5);
    assert!(p
        .warnings()
        .iter()
        .any(|w| w.message.starts_with("'BCD_TO_INT'")));
}

#[test]
fn matiec_xml_tests() {
    // An SFC body is the chart reader's; nothing here writes a coil.
    let p = program("matiec-SFC_TEST.xml");
    pinned(&p, &[]);
    let warned: Vec<&str> = p.warnings().iter().map(|w| w.message.as_str()).collect();
    assert_eq!(
        warned,
        [
            "POU 'MAIN_TEST, action ONSTEP1': ST body not read (ladder and IL bodies are)",
            "POU 'MAIN_TEST': SFC body, read as a chart by [[checks.sfc]], not here",
        ]
    );
    // An empty ladder body is an error that says so.
    assert_eq!(
        compile("matiec-LD_TEST.xml").unwrap_err(),
        "matiec-LD_TEST.xml:1:1: no ladder (LD), IL, ST, FBD or SFC body with anything in it in this XML file"
    );
}

// --- Beremiz -------------------------------------------------------------

#[test]
fn beremiz_first_steps() {
    // Counters in five languages: the IL, LD and FBD ones count in INT
    // (declared in the XML interface), so nothing is a boolean coil; the
    // ST and SFC bodies are named in warnings.
    let p = program("beremiz-first_steps.xml");
    pinned(&p, &[]);
    let lines: Vec<usize> = p.warnings().iter().map(|w| w.at.line).collect();
    assert_eq!(lines, [67, 483, 690, 944, 948, 949, 957, 958]);
    assert!(p.warnings()[6]
        .message
        .starts_with("'ST Cnt': word instruction"));
}

#[test]
fn beremiz_traffic_light_action_ladder() {
    let p = program("beremiz-svghmi_traffic_light.xml");
    // The LD action BLINK_ORANGE_LIGHT: reset coil first, then set coil;
    // the FBD transition STOP: a NOT box. (The FBD main program's outputs
    // are of the HMI's own types, not BOOL: data flow, not coils.)
    pinned(
        &p,
        &[
            ("ORANGE_LIGHT", "R_TRIG1.Q + (-R_TRIG0.Q * ORANGE_LIGHT)"),
            ("STOP", "-SWITCH_BUTTON"),
        ],
    );
    let warnings: Vec<&str> = p.warnings().iter().map(|w| w.message.as_str()).collect();
    assert_eq!(
        warnings,
        ["POU 'traffic_light_sequence': SFC body, read as a chart by [[checks.sfc]], not here"]
    );

    // By hand: SSF1 = ¬R_TRIG0.Q·ORANGE_LIGHT, SSF2 = R_TRIG1.Q + SSF1.
    // The light is on and stays on although the reset edge came: with
    // R_TRIG0.Q = 1, SSF1 = 0, so the light is on only because the set
    // edge R_TRIG1.Q is 1 in the same scan — step 2, R_TRIG1.Q to blame.
    let before = values(&[
        ("R_TRIG0.Q", false),
        ("R_TRIG1.Q", false),
        ("ORANGE_LIGHT", true),
    ]);
    let now = values(&[
        ("R_TRIG0.Q", true),
        ("R_TRIG1.Q", true),
        ("ORANGE_LIGHT", true),
    ]);
    let e = explained(&p, "ORANGE_LIGHT", &before, &now, Polarity::On);
    assert_eq!(e.steps, [false, true]);
    assert_eq!(e.fault_step, Some(2));
    assert_eq!(culprits(&e), ["R_TRIG1.Q = 1 (expected 0)"]);
}

#[test]
fn beremiz_traffic_light_chart_with_graphical_conditions() {
    // Every transition's condition is drawn: an FBD named transition
    // (STOP: a NOT box), contacts and an OR box wired to the transition in
    // the chart itself.
    let text = std::fs::read_to_string(path("beremiz-svghmi_traffic_light.xml")).unwrap();
    let sfc = cellwatch_models::sfc::read("tl.xml", &text, &|_| true).unwrap();
    let chart = &sfc.charts[0];
    let got: Vec<(String, String)> = chart
        .transitions
        .iter()
        .map(|t| {
            let sf = SwitchingFunction::from_expr(Signal::new(&t.id), &t.condition);
            (t.id.clone(), sf.notation())
        })
        .collect();
    let want = [
        ("t2", "SWITCH_BUTTON"),
        ("t6", "STOP_CARS"),
        ("t12", "ALLOW_PEDESTRIANS"),
        ("STOP_t16", "-SWITCH_BUTTON"),
        ("STOP_t4", "-SWITCH_BUTTON"),
        ("t20", "-SWITCH_BUTTON"),
        ("t23", "STOP_PEDESTRIANS"),
        ("t26", "-SWITCH_BUTTON"),
        ("t29", "ALLOW_CARS"),
        ("t37", "TON3.Q + WARN_CARS"),
        ("t39", "-SWITCH_BUTTON"),
    ];
    let want: Vec<(String, String)> = want
        .iter()
        .map(|(t, c)| ((*t).to_string(), (*c).to_string()))
        .collect();
    assert_eq!(got, want);
}

// --- OpenPLC Editor ladders ----------------------------------------------

#[test]
fn openplc_ladders_give_what_the_openplc_compiler_gives() {
    // Each as the project's own generated ST says (build/plc.st there).
    pinned(
        &program("openplc-tutorials-02_no_nc.xml"),
        &[("Coil_1", "NO_Contact"), ("Coil_2", "-NC_Contact")],
    );
    pinned(
        &program("openplc-tutorials-03_not_or_nor.xml"),
        &[
            ("Output_0", "-Input_0"),
            ("Output_1", "Input_1 + Input_2"),
            ("Output_2", "-Input_3 * -Input_4"),
        ],
    );
    let p = program("openplc-tutorials-05_xor_xnor.xml");
    pinned(
        &p,
        &[
            ("OUTPUT_0", "(INPUT_0 * -INPUT_1) + (INPUT_1 * -INPUT_0)"),
            ("OUTPUT_1", "(INPUT_2 * INPUT_3) + (-INPUT_2 * -INPUT_3)"),
        ],
    );
    assert!(p.warnings().is_empty());

    // By hand: XOR with both inputs on. SSF1 = INPUT_0·¬INPUT_1 = 1·0 = 0,
    // SSF2 = INPUT_1·¬INPUT_0 = 1·0 = 0, OUTPUT_0 = SSF3 = 0 (fault when
    // off); the lowest step on its paths is SSF1. INPUT_1 switching on
    // killed branch 1 (trigger); INPUT_0 = 1 blocks branch 2.
    let before = values(&[("INPUT_0", true), ("INPUT_1", false)]);
    let now = values(&[("INPUT_0", true), ("INPUT_1", true)]);
    let e = explained(&p, "OUTPUT_0", &before, &now, Polarity::Off);
    assert_eq!(e.steps, [false, false, false]);
    assert_eq!(e.fault_step, Some(1));
    assert_eq!(
        culprits(&e),
        ["INPUT_1 = 1 (expected 0)", "INPUT_0 = 1 (expected 0)"]
    );
    assert!(e.culprits[0].trigger && !e.culprits[1].trigger);
}
