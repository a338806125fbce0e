//! Programs from public projects (`tests/data/real/`, sources and licences
//! in its README): each file's outcome is pinned — which coils, which
//! switching functions, how many warnings, which errors — and on four of
//! them a fault is explained and checked against values worked out by hand.

#![allow(clippy::unwrap_used)] // test helpers fail loudly by design

use std::path::PathBuf;

use cellwatch_models::explain::{explain, Explanation, Polarity};
use cellwatch_models::program::Program;
use cellwatch_models::signal::{Observability, Signal};
use cellwatch_models::source;
use cellwatch_models::switching::SwitchingFunction;
use cellwatch_models::values::Values;

fn path(file: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/data/real")
        .join(file)
}

fn compile(file: &str) -> Result<Program, String> {
    let bytes = std::fs::read(path(file)).unwrap();
    let text = source::text(file, &bytes, None).map_err(|e| e.to_string())?;
    Program::compile(file, &text, None).map_err(|e| e.to_string())
}

fn program(file: &str) -> Program {
    compile(file).unwrap_or_else(|e| panic!("{e}"))
}

/// Every coil with its SF (internal relays replaced by their logic, as
/// `cellwatch sf` prints it), or `!` and the line the reason points at.
fn outcome(p: &Program) -> Vec<(String, String)> {
    p.coils()
        .iter()
        .map(|c| {
            let sf =
                SwitchingFunction::expand(p, &c.signal, &Observability::default_for(p.dialect()));
            let shown = match sf {
                Ok(sf) => sf.notation(),
                Err(e) => {
                    let e = e.to_string();
                    let line = e.split(':').nth(1).unwrap_or("?").to_string();
                    format!("! line {line}")
                }
            };
            (c.signal.name().to_string(), shown)
        })
        .collect()
}

fn pinned(p: &Program, expected: &[(&str, &str)]) {
    let got = outcome(p);
    let want: Vec<(String, String)> = expected
        .iter()
        .map(|(c, s)| ((*c).to_string(), (*s).to_string()))
        .collect();
    assert_eq!(got, want, "{}", p.origin());
}

fn sf(p: &Program, coil: &str) -> SwitchingFunction {
    SwitchingFunction::expand(
        p,
        &Signal::new(coil),
        &Observability::default_for(p.dialect()),
    )
    .unwrap()
}

fn values(pairs: &[(&str, bool)]) -> Values {
    let mut v = Values::new();
    for (s, b) in pairs {
        v.set(Signal::new(s), *b);
    }
    v
}

fn explained(
    p: &Program,
    coil: &str,
    before: &Values,
    now: &Values,
    polarity: Polarity,
) -> Explanation {
    let b = |s: &Signal| before.get(s);
    explain(
        &sf(p, coil),
        |s| now.get(s),
        Some(&b),
        polarity,
        p.documentation(),
    )
    .unwrap()
}

fn culprits(e: &Explanation) -> Vec<String> {
    e.culprits.iter().map(ToString::to_string).collect()
}

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

// --- awlsim: Siemens STL -------------------------------------------------

#[test]
fn awlsim_garage_counter() {
    let p = program("awlsim-garagecounter.awl");
    pinned(
        &p,
        &[
            ("M4.0", "-((-E0.1 * -E0.2) + (-((-E0.1 * -E0.2) + M4.0) * ((-E0.1 * E0.2) + M4.1))) * ((E0.1 * -E0.2) + M4.0)"),
            ("A0.0", "-((-E0.1 * -E0.2) + (-((-E0.1 * -E0.2) + M4.0) * ((-E0.1 * E0.2) + M4.1))) * ((E0.1 * -E0.2) + M4.0) * -E0.1 * E0.2"),
            ("M4.1", "-((-E0.1 * -E0.2) + (-((-E0.1 * -E0.2) + M4.1) * ((E0.1 * -E0.2) + M4.0))) * ((-E0.1 * E0.2) + M4.1)"),
            ("A0.1", "-((-E0.1 * -E0.2) + (-((-E0.1 * -E0.2) + M4.1) * ((E0.1 * -E0.2) + M4.0))) * ((-E0.1 * E0.2) + M4.1) * E0.1 * -E0.2"),
            ("A0.2", "Z0"),
        ],
    );
    assert_eq!(p.warnings().len(), 17);
}

#[test]
fn awlsim_binary_divider() {
    let p = program("awlsim-binaeruntersetzer.awl");
    let got = outcome(&p);
    // b1_imp comes from an edge (FP); everything reading it is not
    // derivable, the set/reset latch MRUECK and the toggle M16.1 are.
    assert_eq!(got[0], ("b1_imp".into(), "! line 10".into()));
    assert_eq!(
        got[1],
        (
            "MRUECK".into(),
            "-(-A0 * -A1 * -A2) * ((A0 * A1 * A2) + MRUECK)".into()
        )
    );
    assert_eq!(
        got[9],
        ("M16.1".into(), "(T1 * -M16.1) + (-T1 * M16.1)".into())
    );
    assert_eq!(got.len(), 11);
    assert_eq!(got.iter().filter(|(_, s)| s.starts_with('!')).count(), 7);

    // By hand: S when A0·A1·A2, R when ¬A0·¬A1·¬A2, reset written last:
    // SSF1 = ¬A0·¬A1·¬A2, SSF2 = A0·A1·A2, SSF3 = SSF2 + MRUECK,
    // SSF4 = ¬SSF1·SSF3. All three outputs drop to 0 while MRUECK was on:
    // SSF1 = 1, so SSF4 = 0 — MRUECK is off (fault when off), the lowest
    // step on the fault's path is the reset condition SSF1, and each of A0,
    // A1, A2 at 0 (expected 1) is a cause.
    let before = values(&[("A0", true), ("A1", false), ("A2", false), ("MRUECK", true)]);
    let now = values(&[
        ("A0", false),
        ("A1", false),
        ("A2", false),
        ("MRUECK", true),
    ]);
    let e = explained(&p, "MRUECK", &before, &now, Polarity::Off);
    assert_eq!(e.steps, [true, false, true, false]);
    assert_eq!(e.fault_step, Some(1));
    assert_eq!(
        culprits(&e),
        [
            "A0 = 0 (expected 1)",
            "A1 = 0 (expected 1)",
            "A2 = 0 (expected 1)"
        ]
    );
    assert!(e.culprits[0].trigger && !e.culprits[1].trigger);
}

#[test]
fn awlsim_traffic_lights_and_step_chain() {
    let p = program("awlsim-trafficlights_1.awl");
    let got = outcome(&p);
    assert_eq!(
        got[1],
        (
            "M0.0".into(),
            "-(-T0 * M0.0) * ((-T0 * -M0.0 * E0.1) + M0.0)".into()
        )
    );
    // Outputs behind the jump list (SPL) at line 20 may not run every scan.
    assert!(got[2..].iter().all(|(_, s)| s == "! line 20"), "{got:?}");
    assert_eq!(got.len(), 7);
    assert_eq!(p.warnings().len(), 32);
    // The step chain counts in words: no boolean coil; its CALL parameter
    // list is skipped, not read as instructions.
    let p = program("awlsim-stepchain.awl");
    pinned(&p, &[]);
    assert_eq!(p.warnings().len(), 21);
    assert_eq!(
        p.documentation().get(&Signal::new("FB1.#SM")),
        Some("Schrittmerker")
    );
}

#[test]
fn awlsim_training_plant_export() {
    // A whole Step 7 export: several blocks, set/reset inside nesting
    // expressions, comparisons, indirect addressing.
    let p = program("awlsim-bnt_modell.awl");
    let got = outcome(&p);
    assert_eq!(got.len(), 169);
    assert_eq!(got.iter().filter(|(_, s)| !s.starts_with('!')).count(), 50);
    let find = |c: &str| got.iter().find(|(n, _)| n == c).map(|(_, s)| s.as_str());
    assert_eq!(
        find("Eingänge Schrittkette_3.#T14_15"),
        Some("(Eingänge Schrittkette_3.#Farbe_Rot * 4B4) + (-Eingänge Schrittkette_3.#Farbe_Rot * 4B5)")
    );
    assert_eq!(
        find("Betriebsarten.#STEU_EIN"),
        Some("-(-Betriebsarten.#STG_AUS + -Betriebsarten.#NOT_AUS) * (Betriebsarten.#STG_EIN + Betriebsarten.#STEU_EIN)")
    );
    assert_eq!(
        find("Programmzyklus.#TEMP_Aktor_vor"),
        Some("Handbetrieb * -AktorRück_Hand * AktorVor_Hand")
    );
    // Three blocks write a local `#T1_2` of their own: three coils, each
    // with its block's logic (read as one signal, the last block's write
    // hid the others').
    assert_eq!(
        find("Eingaenge_Schrittkette_1.#T1_2"),
        Some("1B3 * 1S2 * 1S2 * 2B5")
    );
    assert_eq!(find("Eingänge Schrittkette_3.#T1_2"), Some("4B6"));
    assert_eq!(got.iter().filter(|(n, _)| n.ends_with(".#T1_2")).count(), 3);
    assert_eq!(p.warnings().len(), 567);
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

// --- Studio 5000 exports (L5X) -------------------------------------------

#[test]
fn l5x2c_examples() {
    // A routine export with no main routine: read as if it ran every
    // scan; five rungs write D, the last one wins. Empty branches `[,]`
    // are shorts.
    let p = program("l5x2c-ex1.L5X");
    pinned(&p, &[("D", "A")]);
    let warned: Vec<&str> = p.warnings().iter().map(|w| w.message.as_str()).collect();
    assert_eq!(
        warned,
        ["program 'MainProgram' names no main routine (a partial export): each routine is read as if it ran every scan"]
    );
    assert_eq!(p.documentation().get(&Signal::new("A")), Some("BOOL 1"));

    // A belt conveyor: timers in branches, failure bits (BIT members of a
    // SINT) set all at once by a MOV of -1 and unlatched by OTU, outputs
    // at the ends of nested branches.
    let p = program("l5x2c-belt_conveyor.L5X");
    let got = outcome(&p);
    let names: Vec<&str> = got.iter().map(|(c, _)| c.as_str()).collect();
    let bits = [
        "Conveyor_Failures.Break_Jammed",
        "Conveyor_Failures.Contactor_Failure",
        "Conveyor_Failures.Emergency_Stop",
        "Conveyor_Failures.Misalignment",
        "Conveyor_Failures.Overload",
    ];
    assert_eq!(names[..5], bits);
    assert_eq!(
        names[5..],
        [
            "Failure_Summary",
            "Ready_to_Start",
            "Ready_to_Run",
            "Started",
            "Horn",
            "Contactor",
            "Open_Break",
        ]
    );
    // The MOV writes the failure bits as a number: never read as if only
    // the OTUs wrote them.
    for (coil, shown) in &got[..5] {
        assert_eq!(shown, "! line 258", "{coil}");
    }
    assert_eq!(got[6].1, "TRUE");
    let lines: Vec<usize> = p.warnings().iter().map(|w| w.at.line).collect();
    assert_eq!(lines, [258, 258, 258, 258, 258, 258, 265, 272, 328, 328]);
    assert_eq!(
        p.warnings()[0].message,
        "'MOV(-1,Conveyor_Failures.Failures)': word instruction, not boolean logic: the boolean result is left as it is"
    );
    assert_eq!(
        p.warnings()[5].message,
        "'MOV(-1,Conveyor_Failures.Failures) → Conveyor_Failures.Overload': a word instruction writes this coil as a bit of a number: it is not derivable"
    );
    assert_eq!(
        p.documentation().get(&Signal::new("Horn")),
        Some("Motor's Horn Output")
    );

    // By hand, with the failure bits observed (they are the PLC's tags):
    // the summary is the AND of the five; the overload bit falls, step 1,
    // the overload bit to blame.
    let observable = Observability::parse(p.dialect(), &bits.join(",")).unwrap();
    let summary =
        SwitchingFunction::expand(&p, &Signal::new("Failure_Summary"), &observable).unwrap();
    assert_eq!(
        summary.notation(),
        "Conveyor_Failures.Emergency_Stop * Conveyor_Failures.Misalignment * Conveyor_Failures.Overload * Conveyor_Failures.Break_Jammed * Conveyor_Failures.Contactor_Failure"
    );
    let before = values(&bits.map(|b| (b, true)));
    let mut now = before.clone();
    now.set(Signal::new("Conveyor_Failures.Overload"), false);
    let b = |s: &Signal| before.get(s);
    let e = explain(
        &summary,
        |s| now.get(s),
        Some(&b),
        Polarity::Off,
        p.documentation(),
    )
    .unwrap();
    assert_eq!(e.fault_step, Some(1));
    assert_eq!(
        culprits(&e),
        ["Conveyor_Failures.Overload = 0 (expected 1)"]
    );
}

#[test]
fn l5sharp_exports_say_what_they_do_not_read() {
    // A program export whose only logic is an Add-On Instruction's, never
    // called: nothing runs it.
    let p = program("l5sharp-TestProgram.L5X");
    pinned(&p, &[]);
    let never =
        "Add-On Instruction 'aoi_Test' is called by no ladder rung read: its logic is not read";
    assert_eq!(warnings(&p), [format!("134:13: {never}")]);
    // A structured-text routine: named, not read.
    let p = program("l5sharp-ST.L5X");
    pinned(&p, &[]);
    let warned: Vec<String> = p
        .warnings()
        .iter()
        .map(|w| format!("{}: {}", w.at, w.message))
        .collect();
    assert_eq!(
        warned,
        [
            "113:1: Add-On Instruction 'aoi_Test' is called by no ladder rung read: its logic is not read",
            "452:1: program 'MainProgram' names no main routine (a partial export): each routine is read as if it ran every scan",
            "454:1: routine ST: ST routine not read (ladder and FBD routines are)",
        ]
    );
    // An FBD routine: BAND__F of SimpleBool and BNOT__F of it wired to the
    // one ORef; a SEL block feeding itself, a DEDT, a TOFR, an Add-On
    // Instruction and two JSRs to a routine the export only references,
    // all wired to no ORef.
    let p = program("l5sharp-FBD.L5X");
    pinned(
        &p,
        &[(
            "TestComplexTag.SimpleMember.BoolMember",
            "SimpleBool * -SimpleBool",
        )],
    );
    // One AND node: one step block, located at the ORef.
    let bool_member = sf(&p, "TestComplexTag.SimpleMember.BoolMember");
    assert_eq!(bool_member.steps.len(), 1);
    assert_eq!(
        warnings(&p),
        [
            "113:1: Add-On Instruction 'aoi_Test' is called by no ladder rung read: its logic is not read",
            "463:1: program 'MainProgram' names no main routine (a partial export): each routine is read as if it ran every scan",
            "670:1: routine ST: only referenced by this export (Use=\"Reference\"), its logic is not in it: not read",
        ]
    );
}

#[test]
fn l5sharp_rung_calling_an_add_on_instruction_runs_its_logic() {
    // `aoi_Test(aoiTestInstance,TestSimpleTag,SimpleInt,RealArray,0)`: the
    // instance, then the four required parameters (InOutTest, Config,
    // InOutArray, New). Its Logic: `OTE(InputTest)`, a latch of a local
    // on the InOut's member, a comparison of the input Config with a local
    // array element, MOVs.
    let p = program("l5sharp-Rung2_from_Main.L5X");
    pinned(
        &p,
        &[
            ("aoiTestInstance.InputTest", "TRUE"),
            (
                "aoiTestInstance.LocalBool",
                "TestSimpleTag.BoolMember + aoiTestInstance.LocalBool",
            ),
        ],
    );
    assert_eq!(
        warnings(&p),
        [
            "248:1: program 'MainProgram' names no main routine (a partial export): each routine is read as if it ran every scan",
            "174:35: 'MOV(Config,InOutArray[0])': word instruction, not boolean logic: the boolean result is left as it is",
            "179:10: 'MOV(100,LocalArray[2])': word instruction, not boolean logic: the boolean result is left as it is",
        ]
    );
}

// --- TIA Portal exports (SimaticML) ----------------------------------------

/// Every warning as `LINE:COL: message`.
fn warnings(p: &Program) -> Vec<String> {
    p.warnings()
        .iter()
        .map(|w| format!("{}: {}", w.at, w.message))
        .collect()
}

#[test]
fn tia_portal_exports_give_their_latches_and_say_which_networks_are_not_read() {
    // An FB in LAD: a valve opened by an S coil and closed by an R coil,
    // its state copied to an output. Locals are the block's own.
    let p = program("codegeneratoropenness-LAD_Valve_V0.1.xml");
    let latch = "-(Valve.#CloseValve * Valve.#Release) * ((Valve.#OpenValve * Valve.#Release) + Valve.#StateValve)";
    pinned(&p, &[("Valve.#StateValve", latch), ("Valve.#Valve", latch)]);
    assert!(warnings(&p).is_empty(), "{:?}", warnings(&p));
    // A contact on a global tag beside locals.
    let p = program("codegeneratoropenness-plcBlock_LAD_Block_Logic.xml");
    pinned(
        &p,
        &[
            ("Block_Logic.#MyValue", "Block_Logic.#A1"),
            ("Block_Logic.#Out1", "Block_Logic.#A1 * Tag_5"),
        ],
    );
    // Calls of an FB: said where they are, the coils around them read.
    let p = program("codegeneratoropenness-LAD_TemplateValve_V0.3.xml");
    pinned(
        &p,
        &[
            ("GenerateValve.#Release", "AlwaysOFF"),
            ("GenerateValve.#OpenValve", "AlwaysON * AlwaysOFF"),
            ("GenerateValve.#CloseValve", "AlwaysON * AlwaysOFF"),
            // Both calls write their output Valve into Valve_0: the last
            // one's instance member.
            ("Valve_0", "GenerateValve.#Valve_Instance_1.Valve"),
        ],
    );
    assert_eq!(
        warnings(&p),
        [
            "296:5: block \"GenerateValve\" network 3: call of Valve is not read",
            "578:5: block \"GenerateValve\" network 6: call of Valve is not read",
        ]
    );
    // A GRAPH sequence: no coil, one located warning per network.
    let p = program("codegeneratoropenness-GraphBranch.xml");
    pinned(&p, &[]);
    assert_eq!(
        warnings(&p),
        ["723:13: block \"FB_SEQ_One\" network 1: GRAPH network not read (LAD and FBD networks are)"]
    );
}

#[test]
fn tia_portal_exports_of_other_projects() {
    // A V21 LAD FC of a pump starter (Portuguese names): global tags with
    // hyphens, members of a DB whose name has a space, R coils without an
    // S coil, a negated coil, two empty networks (comments only). Calls of
    // FBs and MOVEs are said where they are; what they write reads as inputs.
    let p = program("tia-portal-cli-BombaTemplateFc.xml");
    let motor = "DB GLOBAL.AREA_01.AREA_01_MOTORES.MOTOR_S-01A";
    // The FB calls' Bool outputs are written into the tags wired to them,
    // each the instance's member: a leaf named with the instance (#69).
    let falha = "FB FALHA_S-01A";
    let partida = "FB CONDIÇÃO DE PARTIDA_S-01A";
    let reset_liga = format!("({partida}.RESET_CMD_LIGA + -CCM-1_STS_PAINEL_OK)");
    pinned(
        &p,
        &[
            ("S-01A_STS_MODO_LOCAL", "S-01A_STS_MOTOR_MODO_LOCAL_1"),
            ("S-01A_STS_MODO_REMOTO", "S-01A_STS_MOTOR_MODO_REMOTO_1"),
            ("S-01A_CMD_BOTAO_RESET_FALHA", "QA-01_CMD_RESET_REMOTA"),
            ("S-01A_FALHA", &format!("{falha}.FALHA")),
            (
                "S-01A_CMD_RESET_FALHA_PROFINET",
                &format!("{falha}.RESET_FALHA_INVERSOR"),
            ),
            (
                "S-01A_STS_FALHA_NAO_LIGOU",
                &format!("{falha}.FALHA_NÃO_LIGOU"),
            ),
            ("S-01A_CMD_LIGA_BOMBA", &format!("{partida}.LIGA_BOMBA")),
            (
                "S-01A_STS_REMOTO_AUTO",
                &format!("{partida}.OUTPUT_REMOTO_AUTO"),
            ),
            ("S-01A_CMD_RESET_LIGA", &format!("{partida}.RESET_CMD_LIGA")),
            (
                &format!("{motor}.STS_INTERTRAVAMENTO_AUTOMATICO"),
                &format!("{partida}.STS_INTERTRAVAMENTO_AUTOMATICO"),
            ),
            // Network 7's OR box feeds both coils below: one relay, as
            // the IL writes an internal relay (issue #69). Their
            // functions are what they were when the box was read twice.
            (
                "#PARTIDA_MOTOR_1 (S-01A).NW7.O28",
                &format!("{partida}.RESET_CMD_LIGA + -CCM-1_STS_PAINEL_OK"),
            ),
            (
                &format!("{motor}.CMD_LIGA"),
                &format!("-(S-01A_STS_MOTOR_MODO_LOCAL_1 + -S-01A_STS_MOTOR_MODO_REMOTO_1) * -{reset_liga} * {motor}.CMD_LIGA"),
            ),
            (
                &format!("{motor}.CMD_MODO_OPERACAO"),
                &format!("-({reset_liga} * {partida}.OUTPUT_REMOTO_AUTO) * {motor}.CMD_MODO_OPERACAO"),
            ),
            (
                &format!("{motor}.CMD_INTERTRAVAMENTO_LIGA"),
                &format!("-(-S-01A_STS_MOTOR_MODO_LOCAL_1 * -S-01A_STS_LOCAL_AUTO * -S-01A_STS_LOCAL_MANUAL * S-01A_STS_MOTOR_MODO_REMOTO_1 * S-01A_STS_REMOTO_MANUAL * -{falha}.FALHA)"),
            ),
            (
                "S-01A_STS_LIGADO_PROFINET",
                "SINA_SPEED_TLG20_S-01A.axisEnabled",
            ),
            ("S-01A_STS_FALHA_PROFINET", "SINA_SPEED_TLG20_S-01A.error"),
            ("S-01A_CMD_LIGA_PROFINET", &format!("{partida}.LIGA_BOMBA")),
        ],
    );
    let block = "block \"PARTIDA_MOTOR_1 (S-01A)\"";
    assert_eq!(
        warnings(&p),
        [
            format!("349:17: {block} network 2: call of FB FALHA is not read"),
            format!("724:17: {block} network 5: call of FB CONDIÇÃO DE PARTIDA is not read"),
            format!("1022:17: {block} network 6: part 'Move' is not read"),
            format!("1025:17: {block} network 6: part 'Move' is not read"),
            format!("1028:17: {block} network 6: call of FB SETPOINT ESCALONAMENTO is not read"),
            format!("1706:17: {block} network 10: call of SINA_SPEED_TLG20 is not read"),
        ]
    );

    // A V16 FBD FB stepping a sequence: every S coil is fed by a call's
    // ENO, every coil by a comparison of a local of a block whose name has
    // a space ("Program Logic"), which a comparison signal cannot carry:
    // no coil derivable, each saying where.
    let p = program("tia-xml-modcheck-Program_Logic.xml");
    pinned(
        &p,
        &[
            ("Program Logic.#StepDone", "! line 2037"),
            ("DB_ProgramLogic.VlvDrn_Open", "! line 2285"),
            ("DB_ProgramLogic.VlvLiq1_Open", "! line 2298"),
            ("DB_ProgramLogic.VlvLiq2_Open", "! line 2302"),
        ],
    );
    let w = warnings(&p);
    assert_eq!(w.len(), 31, "{w:?}");
    assert_eq!(
        w[0],
        "161:5: block \"Program Logic\" network 1: call of fcStepChooser is not read"
    );
    assert_eq!(
        w[30],
        "2302:5: 'block \"Program Logic\" network 22: comparator 'Eq' of 'Program Logic.#CurrentStep', a name with a space, which a comparison contact cannot name': a call, timer, counter, edge or function, not boolean logic: the coils it feeds are not derivable"
    );

    // V16 safety FBD (F_FBD): a muting FC read whole, the negated AND
    // output as its De Morgan form.
    let p = program("block-diagram-z3-Demo.xml");
    let scanners = "(Demo.#left_clear + (Demo.#is_slow * Demo.#mute_req)) * (Demo.#right_clear + Demo.#mute_req)";
    pinned(
        &p,
        &[
            ("Demo.#mute_granted", "Demo.#is_slow * Demo.#mute_req"),
            ("Demo.#scanners_ok", scanners),
            ("Demo.#stop", &format!("-({scanners}) + -Demo.#estop_clear")),
        ],
    );
    assert!(warnings(&p).is_empty(), "{:?}", warnings(&p));
    // A safety FB latching on edges (NBox resets, PBox sets) and a coil
    // chained after a coil: the edges are pulses, so nothing they reach is
    // derivable.
    let p = program("block-diagram-z3-Step2.xml");
    pinned(
        &p,
        &[
            ("Step2.#faults_clear", "! line 130"),
            ("DataFromSafety.running", "! line 130"),
            ("interlock", "! line 130"),
        ],
    );
    assert_eq!(
        warnings(&p),
        [
            "128:5: 'block \"Step2\" network 1: edge 'NBox' on 'Step2.#last_estop_clear' (a pulse, not a function of the signals)': a call, timer, counter, edge or function, not boolean logic: the coils it feeds are not derivable",
            "130:5: 'block \"Step2\" network 1: edge 'PBox' on 'Step2.#last_reset' (a pulse, not a function of the signals)': a call, timer, counter, edge or function, not boolean logic: the coils it feeds are not derivable",
        ]
    );
}
