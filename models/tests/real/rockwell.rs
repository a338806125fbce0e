//! Rockwell Studio 5000 exports (L5X): l5x2c's examples and L5Sharp's
//! exports, an Add-On Instruction's logic run where a rung calls it.

use super::*;

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
