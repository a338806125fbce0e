//! Tests of the L5X reader: rungs, scopes and aliases, what is not read,
//! and the located errors.

use crate::program::Program;
use crate::signal::{Observability, Signal};
use crate::switching::SwitchingFunction;

/// An export with controller tags `tags`, and program `Main` with its own
/// tags `local` and routines `(name, type, rungs)`, `Main` the main one.
fn export(tags: &str, local: &str, routines: &[(&str, &str, &[&str])]) -> String {
    let routines: String = routines
        .iter()
        .map(|(name, ty, rungs)| {
            let rungs: String = rungs
                .iter()
                .enumerate()
                .map(|(k, r)| format!("<Rung Number=\"{k}\" Type=\"N\">\n<Text>\n<![CDATA[{r}]]>\n</Text>\n</Rung>\n"))
                .collect();
            format!("<Routine Name=\"{name}\" Type=\"{ty}\">\n<RLLContent>\n{rungs}</RLLContent>\n</Routine>\n")
        })
        .collect();
    format!(
        "<?xml version=\"1.0\" encoding=\"UTF-8\" standalone=\"yes\"?>\n\
         <RSLogix5000Content SchemaRevision=\"1.0\" SoftwareRevision=\"33.01\" TargetName=\"T\" TargetType=\"Controller\">\n\
         <Controller Use=\"Target\" Name=\"T\">\n<Tags>\n{tags}</Tags>\n<Programs>\n\
         <Program Name=\"Main\" MainRoutineName=\"Main\">\n<Tags>\n{local}</Tags>\n<Routines>\n{routines}</Routines>\n</Program>\n\
         </Programs>\n</Controller>\n</RSLogix5000Content>\n"
    )
}

fn compile(rungs: &[&str]) -> Program {
    Program::compile("t.L5X", &export("", "", &[("Main", "RLL", rungs)]), None)
        .unwrap_or_else(|e| panic!("{e}"))
}

fn sf(p: &Program, coil: &str) -> String {
    match SwitchingFunction::expand(
        p,
        &Signal::new(coil),
        &Observability::everything(p.dialect()),
    ) {
        Ok(sf) => sf.notation(),
        Err(e) => format!("! {e}"),
    }
}

fn warnings(p: &Program) -> Vec<String> {
    p.warnings()
        .iter()
        .map(|w| format!("{}: {}", w.at, w.message))
        .collect()
}

#[test]
fn branches_outputs_mid_rung_latches_and_timer_bits() {
    let p = compile(&[
        "XIC(a)[OTE(b),XIC(c)OTE(d)]XIC(e)OTE(f);",
        "[XIC(a),XIC(b)[XIO(c),XIC(T1.DN)]]OTL(g);",
        "XIC(stop)OTU(g);",
        "XIC(a)[,XIO(c)]OTE(h);",
        "XIC(run)TON(T1,?,?)XIC(t1.dn)OTE(late);",
        "AFI()OTE(never);",
    ]);
    assert_eq!(sf(&p, "b"), "a");
    assert_eq!(sf(&p, "d"), "a * c");
    // (a + a·c)·e: the branch that bypasses c makes the OR a.
    assert_eq!(sf(&p, "f"), "a * e");
    assert_eq!(sf(&p, "g"), "-stop * (a + (b * (-c + T1.DN)) + g)");
    assert_eq!(sf(&p, "h"), "a");
    // A timer passes the rung on; its bits are contacts, spelt as first seen.
    assert_eq!(sf(&p, "late"), "run * T1.DN");
    assert_eq!(sf(&p, "never"), "FALSE");
    assert_eq!(warnings(&p), ["35:18: 'TON(T1,?,?)': an input of a function block instance, not a coil: the boolean result is left as it is"]);
}

#[test]
fn comparisons_are_contacts_and_what_is_not_one_is_said() {
    let p = compile(&[
        "GRT(Temp,80)LES(100,Level)EQU(Mode,16#0A)OTE(hot);",
        "LIM(10,Speed,20)OTE(inside);",
        "LIM(20,Speed,10)OTE(outside);",
        "MOV(3,Mode)OTE(moved);",
        "EQU(A+B,3)OTE(sum);",
        "XIC(a)FFL(src,arr[0],ctl,10,0)OTE(fifo);",
    ]);
    assert_eq!(sf(&p, "hot"), "Temp > 80 * Level > 100 * Mode == 10");
    assert_eq!(sf(&p, "inside"), "Speed >= 10 * Speed <= 20");
    assert_eq!(sf(&p, "outside"), "Speed >= 20 + Speed <= 10");
    assert_eq!(sf(&p, "moved"), "TRUE");
    assert!(sf(&p, "sum").starts_with("! "), "{}", sf(&p, "sum"));
    assert!(sf(&p, "fifo").starts_with("! "), "{}", sf(&p, "fifo"));
    assert_eq!(
        warnings(&p),
        [
            "30:10: 'MOV(3,Mode) (writes 'Mode', which a comparison contact reads as the PLC holds it)': word instruction, not boolean logic: the boolean result is left as it is",
            "35:10: routine Main, rung 4: 'EQU(A+B,3)' compares something that is not a tag or a number: not a contact, what follows it is not derivable",
            "35:10: 'EQU(A+B,3)': a call, timer, counter, edge or function, not boolean logic: the coils it feeds are not derivable",
            "40:16: routine Main, rung 5: instruction 'FFL' is not read",
            "40:16: 'FFL(src,arr[0],ctl,10,0)': a call, timer, counter, edge or function, not boolean logic: the coils it feeds are not derivable",
        ]
    );
}

#[test]
fn scopes_aliases_and_comments() {
    let tags = "<Tag Name=\"Start\" TagType=\"Alias\" AliasFor=\"Local:1:I.Data.3\"><Description><![CDATA[Start button]]></Description></Tag>\n\
                <Tag Name=\"Local:1:I\" TagType=\"Base\" DataType=\"AB:1769_DI16:I:0\"><Comments><Comment Operand=\".DATA.4\"><![CDATA[Stop button]]></Comment></Comments></Tag>\n\
                <Tag Name=\"Stop\" TagType=\"Alias\" AliasFor=\"Local:1:I.Data.4\"/>\n\
                <Tag Name=\"Run\" TagType=\"Base\" DataType=\"BOOL\"><Description><![CDATA[Motor runs]]></Description></Tag>\n";
    let local = "<Tag Name=\"Seal\" TagType=\"Base\" DataType=\"BOOL\"><Description><![CDATA[seal-in]]></Description></Tag>\n";
    let text = export(
        tags,
        local,
        &[(
            "Main",
            "RLL",
            &[
                "[XIC(Local:1:I.Data.3),XIC(seal)]XIO(STOP)OTE(Seal);",
                "XIC(Seal)OTE(run);",
            ],
        )],
    );
    let p = Program::compile("t.L5X", &text, None).unwrap_or_else(|e| panic!("{e}"));
    let names: Vec<&str> = p.coils().iter().map(|c| c.signal.name()).collect();
    assert_eq!(names, ["Program:Main.Seal", "Run"]);
    assert_eq!(sf(&p, "Run"), "Program:Main.Seal");
    assert_eq!(
        sf(&p, "Program:Main.Seal"),
        "(Start + Program:Main.Seal) * -Stop"
    );
    let docs = p.documentation();
    assert_eq!(docs.get(&Signal::new("Start")), Some("Start button"));
    assert_eq!(docs.get(&Signal::new("Stop")), Some("Stop button"));
    assert_eq!(docs.get(&Signal::new("Run")), Some("Motor runs"));
    assert_eq!(docs.get(&Signal::new("Program:Main.Seal")), Some("seal-in"));
    // Names as a user types them resolve, in any case.
    assert_eq!(
        p.resolve("program:main.seal").unwrap().name(),
        "Program:Main.Seal"
    );
    assert_eq!(
        p.resolve("Local:1:I.Data.5").unwrap().name(),
        "Local:1:I.Data.5"
    );
}

#[test]
fn jsr_mcr_jumps_and_what_is_not_read() {
    let text = export(
        "",
        "",
        &[
            (
                "Main",
                "RLL",
                &[
                    "JSR(Sub,0);",
                    "XIC(c)JSR(Cond,0);",
                    "MCR()XIC(z)MCR();",
                    "XIC(a)OTE(inzone);",
                    "MCR();",
                    "XIC(a)OTE(out);",
                ],
            ),
            ("Sub", "RLL", &["XIC(a)OTE(fromsub);", "JSR(Sub,0);"]),
            (
                "Cond",
                "RLL",
                &[
                    "XIC(b)OTE(fromcond);",
                    "XIC(x)JMP(L1);",
                    "XIC(b)OTE(skipped);",
                    "LBL(L1)XIC(b)OTE(after);",
                ],
            ),
            ("Never", "RLL", &["XIC(b)OTE(nothing);"]),
            ("Text", "ST", &[]),
        ],
    );
    let p = Program::compile("t.L5X", &text, None).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(sf(&p, "fromsub"), "a");
    assert!(
        sf(&p, "fromcond").contains("runs routine Cond only when the rung is true"),
        "{}",
        sf(&p, "fromcond")
    );
    assert!(sf(&p, "skipped").starts_with("! "));
    // An MCR zone ANDs its condition into every output in it.
    assert_eq!(sf(&p, "inzone"), "z * a");
    assert_eq!(sf(&p, "out"), "a");
    assert!(p.coil(&Signal::new("nothing")).is_none());
    let w: Vec<String> = warnings(&p)
        .into_iter()
        .filter(|w| !w.contains("': a call"))
        .collect();
    assert_eq!(
        w,
        [
            "54:10: routine Sub, rung 1: 'JSR(Sub,0)': routine 'Sub' is already running (a JSR cycle, or calls deeper than 32): not run again",
            "83:1: program 'Main': routine 'Never' is not called from the main routine by a JSR: not read",
            "92:1: program 'Main': routine 'Text' is not called from the main routine by a JSR: not read",
        ]
    );
}

#[test]
fn malformed_rungs_and_names_are_errors_at_the_character() {
    let text = export(
        "",
        "",
        &[(
            "Main",
            "RLL",
            &["XIC(a)[XIO(b);", "XIC(1abc)OTE(c);", "XIC(a)OTE(c)"],
        )],
    );
    let e = Program::compile("t.L5X", &text, None).unwrap_err();
    assert_eq!(
        e.to_string(),
        "t.L5X:15:16: routine Main, rung 0: branch '[' is never closed with ']'\n\
         t.L5X:20:14: routine Main, rung 1: '1abc' is not a tag name\n\
         t.L5X:25:22: routine Main, rung 2: the rung text does not end with ';'"
    );
    let e = Program::compile("t.L5X", "<RSLogix5000Content>\n<Controller>\n", None).unwrap_err();
    assert_eq!(
        e.to_string(),
        "t.L5X:1:1: not well-formed XML: the root node was opened but never closed"
    );
    let e = Program::compile("t.L5X", &export("", "", &[]), None).unwrap_err();
    assert_eq!(
        e.to_string(),
        "t.L5X:1:1: no routine with any rung or output reference (ORef) in it in this L5X export"
    );
    let e = Program::compile(
        "t.L5X",
        &export("", "", &[]),
        Some(crate::programs::Dialect::Iec),
    )
    .unwrap_err();
    assert!(e.to_string().contains("leave --dialect out"), "{e}");
}

#[test]
fn mutated_exports_never_panic() {
    // Every prefix of an export, and every byte of it replaced by the
    // characters the rung and tag readers care about: an answer, never a
    // panic.
    let text = export(
        "<Tag Name=\"S\" TagType=\"Alias\" AliasFor=\"S\"/>\n",
        "",
        &[(
            "Main",
            "RLL",
            &["[XIC(a),XIO(b)[,XIC(T1.DN)]]GRT(t,16#1F)LIM(1,x,2)JSR(Main,0)MCR()OTE(S);"],
        )],
    );
    for cut in (0..text.len()).filter(|&c| text.is_char_boundary(c)) {
        let _ = Program::compile("m.L5X", &text[..cut], None);
    }
    for (k, _) in text.char_indices().filter(|(k, _)| k % 3 == 0) {
        for c in ["[", "]", ",", "(", ")", ";", ".", "'", "#", "<", "é"] {
            let mut m = text.clone();
            let end = k + m[k..].chars().next().map_or(0, char::len_utf8);
            m.replace_range(k..end, c);
            let _ = Program::compile("m.L5X", &m, None);
        }
    }
}

/// An export whose program `Main` has one FBD routine `Main` with
/// `sheets` (each the elements and wires of one `<Sheet>`), and an RLL
/// routine `Sub` that writes `sub`.
fn fbd_export(sheets: &[&str]) -> String {
    let sheets: String = sheets
        .iter()
        .enumerate()
        .map(|(k, s)| format!("<Sheet Number=\"{}\">\n{s}</Sheet>\n", k + 1))
        .collect();
    format!(
        "<?xml version=\"1.0\" encoding=\"UTF-8\" standalone=\"yes\"?>\n\
         <RSLogix5000Content SchemaRevision=\"1.0\" SoftwareRevision=\"33.01\" TargetName=\"T\" TargetType=\"Controller\">\n\
         <Controller Use=\"Target\" Name=\"T\">\n<Programs>\n\
         <Program Name=\"Main\" MainRoutineName=\"Main\">\n<Routines>\n\
         <Routine Name=\"Main\" Type=\"FBD\">\n<FBDContent SheetSize=\"Letter - 8.5 x 11 in\" SheetOrientation=\"Landscape\">\n{sheets}</FBDContent>\n</Routine>\n\
         <Routine Name=\"Sub\" Type=\"RLL\">\n<RLLContent>\n<Rung Number=\"0\" Type=\"N\">\n<Text>\n<![CDATA[XIC(a)OTE(sub);]]>\n</Text>\n</Rung>\n</RLLContent>\n</Routine>\n\
         </Routines>\n</Program>\n</Programs>\n</Controller>\n</RSLogix5000Content>\n"
    )
}

fn fbd(sheets: &[&str]) -> Program {
    Program::compile("f.L5X", &fbd_export(sheets), None).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn fbd_boolean_blocks_functions_connectors_and_calls() {
    let p = fbd(&[
        "<IRef ID=\"0\" Operand=\"a\"/>\n<IRef ID=\"1\" Operand=\"b\"/>\n<IRef ID=\"2\" Operand=\"c\"/>\n\
         <IRef ID=\"3\" Operand=\"1\"/>\n\
         <Block Type=\"BAND\" ID=\"4\" Operand=\"BAND_01\" VisiblePins=\"In1 In2 In3 Out\"/>\n\
         <Block Type=\"BOR\" ID=\"5\" Operand=\"BOR_01\" VisiblePins=\"In1 In2 Out\"/>\n\
         <Function Type=\"BXOR__F\" ID=\"6\"/>\n<Function Type=\"BNOT__F\" ID=\"7\"/>\n\
         <ORef ID=\"8\" Operand=\"both\"/>\n<ORef ID=\"9\" Operand=\"either\"/>\n<ORef ID=\"10\" Operand=\"odd\"/>\n\
         <OCon ID=\"11\" Name=\"NotA\"/>\n<JSR ID=\"12\" Routine=\"Sub\"/>\n\
         <Wire FromID=\"0\" ToID=\"4\" ToParam=\"In1\"/>\n<Wire FromID=\"1\" ToID=\"4\" ToParam=\"In2\"/>\n\
         <Wire FromID=\"3\" ToID=\"4\" ToParam=\"In3\"/>\n\
         <Wire FromID=\"0\" ToID=\"5\" ToParam=\"In1\"/>\n<Wire FromID=\"2\" ToID=\"5\" ToParam=\"In2\"/>\n\
         <Wire FromID=\"0\" ToID=\"6\" ToParam=\"In1\"/>\n<Wire FromID=\"1\" ToID=\"6\" ToParam=\"In2\"/>\n\
         <Wire FromID=\"0\" ToID=\"7\" ToParam=\"In\"/>\n<Wire FromID=\"7\" FromParam=\"Out\" ToID=\"11\"/>\n\
         <Wire FromID=\"4\" FromParam=\"Out\" ToID=\"8\"/>\n<Wire FromID=\"5\" FromParam=\"Out\" ToID=\"9\"/>\n\
         <Wire FromID=\"6\" FromParam=\"Out\" ToID=\"10\"/>\n",
        "<ICon ID=\"0\" Name=\"NotA\"/>\n<IRef ID=\"1\" Operand=\"both\"/>\n\
         <Block Type=\"BAND\" ID=\"2\" Operand=\"BAND_02\"/>\n<ORef ID=\"3\" Operand=\"later\"/>\n\
         <Wire FromID=\"0\" ToID=\"2\" ToParam=\"In1\"/>\n<Wire FromID=\"1\" ToID=\"2\" ToParam=\"In2\"/>\n\
         <Wire FromID=\"2\" FromParam=\"Out\" ToID=\"3\"/>\n",
    ]);
    assert_eq!(warnings(&p), Vec::<String>::new());
    let names: Vec<&str> = p.coils().iter().map(|c| c.signal.name()).collect();
    assert_eq!(names, ["both", "either", "odd", "later", "sub"]);
    // The IRef of 1 is TRUE; BAND's hidden In4..In8 leave it as it is.
    assert_eq!(sf(&p, "both"), "a * b");
    assert_eq!(sf(&p, "either"), "a + c");
    assert_eq!(sf(&p, "odd"), "(a * -b) + (-a * b)");
    // NOT a across the sheets through the connector; the IRef of a coil
    // the routine writes is that coil.
    assert_eq!(sf(&p, "later"), "-a * both");
    assert_eq!(sf(&p, "sub"), "a");
}

#[test]
fn fbd_what_is_not_logic_is_a_warning_at_its_element() {
    let p = fbd(&[
        // An unknown block, an unwired shown input, a loop, a feedback
        // wire, a wired EnableIn, a connector with no OCon, a number.
        "<IRef ID=\"0\" Operand=\"a\"/>\n\
         <Block Type=\"TONR\" ID=\"1\" Operand=\"TONR_01\" VisiblePins=\"TimerEnable PRE Reset ACC DN\"/>\n\
         <ORef ID=\"2\" Operand=\"timed\"/>\n\
         <Block Type=\"BAND\" ID=\"3\" Operand=\"BAND_01\"/>\n<ORef ID=\"4\" Operand=\"half\"/>\n\
         <Block Type=\"BOR\" ID=\"5\" Operand=\"BOR_01\"/>\n<Block Type=\"BAND\" ID=\"6\" Operand=\"BAND_02\"/>\n\
         <ORef ID=\"7\" Operand=\"looped\"/>\n\
         <Block Type=\"BOR\" ID=\"8\" Operand=\"BOR_02\"/>\n<ORef ID=\"9\" Operand=\"fed\"/>\n\
         <Block Type=\"BNOT\" ID=\"10\" Operand=\"BNOT_01\" VisiblePins=\"EnableIn In Out\"/>\n<ORef ID=\"11\" Operand=\"enabled\"/>\n\
         <ICon ID=\"12\" Name=\"Nowhere\"/>\n<ORef ID=\"13\" Operand=\"lost\"/>\n\
         <IRef ID=\"14\" Operand=\"100\"/>\n<ORef ID=\"15\" Operand=\"hundred\"/>\n<ORef ID=\"16\" Operand=\"empty\"/>\n\
         <Wire FromID=\"0\" ToID=\"1\" ToParam=\"TimerEnable\"/>\n<Wire FromID=\"1\" FromParam=\"DN\" ToID=\"2\"/>\n\
         <Wire FromID=\"0\" ToID=\"3\" ToParam=\"In1\"/>\n<Wire FromID=\"3\" FromParam=\"Out\" ToID=\"4\"/>\n\
         <Wire FromID=\"0\" ToID=\"5\" ToParam=\"In1\"/>\n<Wire FromID=\"6\" FromParam=\"Out\" ToID=\"5\" ToParam=\"In2\"/>\n\
         <Wire FromID=\"5\" FromParam=\"Out\" ToID=\"6\" ToParam=\"In1\"/>\n<Wire FromID=\"0\" ToID=\"6\" ToParam=\"In2\"/>\n\
         <Wire FromID=\"6\" FromParam=\"Out\" ToID=\"7\"/>\n\
         <Wire FromID=\"0\" ToID=\"8\" ToParam=\"In1\"/>\n<FeedbackWire FromID=\"8\" FromParam=\"Out\" ToID=\"8\" ToParam=\"In2\"/>\n\
         <Wire FromID=\"8\" FromParam=\"Out\" ToID=\"9\"/>\n\
         <Wire FromID=\"0\" ToID=\"10\" ToParam=\"EnableIn\"/>\n<Wire FromID=\"0\" ToID=\"10\" ToParam=\"In\"/>\n\
         <Wire FromID=\"10\" FromParam=\"Out\" ToID=\"11\"/>\n\
         <Wire FromID=\"12\" ToID=\"13\"/>\n<Wire FromID=\"14\" ToID=\"15\"/>\n",
    ]);
    for coil in [
        "timed", "half", "looped", "fed", "enabled", "lost", "hundred", "empty",
    ] {
        assert!(sf(&p, coil).starts_with("! "), "{coil}: {}", sf(&p, coil));
    }
    let not = "a call, timer, counter, edge or function, not boolean logic: the coils it feeds are not derivable";
    let sheet = "routine Main, sheet 1";
    let feeds = "what it feeds is not derivable";
    assert_eq!(
        warnings(&p),
        [
            format!("11:1: {sheet}: TONR block 'TONR_01' is not read: {feeds}"),
            format!("11:1: 'TONR(TONR_01)': {not}"),
            format!("13:1: {sheet}: input In2 of BAND block 'BAND_01' is not wired: {feeds}"),
            format!("13:1: 'BAND(BAND_01).In2 (not wired)': {not}"),
            format!("16:1: {sheet}: BAND block 'BAND_02' is in a loop of wires (its output comes back to its input): {feeds}"),
            format!("16:1: 'BAND(BAND_02) (in a loop)': {not}"),
            format!("37:1: {sheet}: a feedback wire into input In2 of BOR block 'BOR_02' carries the value of the previous scan: {feeds}"),
            format!("37:1: 'BOR(BOR_02).In2 (feedback wire)': {not}"),
            format!("20:1: {sheet}: EnableIn of BNOT block 'BNOT_01' is wired: while it is off the block holds its output, so {feeds}"),
            format!("20:1: 'BNOT(BNOT_01).EnableIn (wired)': {not}"),
            format!("22:1: {sheet}: ICon 'Nowhere' has no OCon of that name in this routine: {feeds}"),
            format!("22:1: 'ICon(Nowhere)': {not}"),
            format!("24:1: {sheet}: IRef '100' is a number, not a boolean: {feeds}"),
            format!("24:1: 'IRef(100)': {not}"),
            format!("26:1: {sheet}: ORef 'empty' is not wired: {feeds}"),
            format!("26:1: 'ORef(empty) (not wired)': {not}"),
            "47:1: program 'Main': routine 'Sub' is not called from the main routine by a JSR: not read".to_string(),
        ]
    );
}

#[test]
fn fbd_malformed_wires_and_names_are_errors_at_the_element() {
    let text = fbd_export(&[
        "<IRef ID=\"0\" Operand=\"1abc\"/>\n<ORef ID=\"1\" Operand=\"x\"/>\n<ORef ID=\"2\" Operand=\"y\"/>\n\
         <Wire FromID=\"0\" ToID=\"1\"/>\n<Wire FromID=\"7\" ToID=\"2\"/>\n<Wire ToID=\"2\"/>\n",
    ]);
    let e = Program::compile("f.L5X", &text, None).unwrap_err();
    assert_eq!(
        e.to_string(),
        "f.L5X:10:1: routine Main, sheet 1: '1abc' is not a tag name\n\
         f.L5X:14:1: routine Main, sheet 1: the wire from 7 to 2 names element 7, which is not on this sheet\n\
         f.L5X:15:1: routine Main, sheet 1: a wire without a FromID and a ToID"
    );
}

#[test]
fn mutated_fbd_exports_never_panic() {
    let text = include_str!("../../../../tests/data/paper000/fig6.fbd.L5X");
    let routine = text.find("<Routine ").unwrap_or(0);
    for cut in (routine..text.len())
        .filter(|&c| text.is_char_boundary(c))
        .step_by(7)
    {
        let _ = Program::compile("m.L5X", &text[..cut], None);
    }
    for (k, _) in text
        .char_indices()
        .filter(|(k, _)| *k >= routine && k % 5 == 0)
    {
        for c in ["0", "1", "\"", "<", "ID", "_", "é"] {
            let mut m = text.to_string();
            let end = k + m[k..].chars().next().map_or(0, char::len_utf8);
            m.replace_range(k..end, c);
            let _ = Program::compile("m.L5X", &m, None);
        }
    }
}

/// An Add-On Instruction definition: `(name, usage, required)`
/// parameters after the system's `EnableIn` and `EnableOut`, local tags,
/// and the rungs of its `Logic` routine.
fn definition(
    name: &str,
    parameters: &[(&str, &str, bool)],
    locals: &[&str],
    rungs: &[&str],
) -> String {
    let parameters: String = [("EnableIn", "Input", false), ("EnableOut", "Output", false)]
        .iter()
        .chain(parameters)
        .map(|(p, usage, required)| {
            format!("<Parameter Name=\"{p}\" TagType=\"Base\" DataType=\"BOOL\" Usage=\"{usage}\" Required=\"{required}\" Visible=\"true\"/>\n")
        })
        .collect();
    let locals: String = locals
        .iter()
        .map(|l| format!("<LocalTag Name=\"{l}\" DataType=\"BOOL\"/>\n"))
        .collect();
    let rungs: String = rungs
        .iter()
        .enumerate()
        .map(|(k, r)| {
            format!("<Rung Number=\"{k}\" Type=\"N\">\n<Text>\n<![CDATA[{r}]]>\n</Text>\n</Rung>\n")
        })
        .collect();
    format!(
        "<AddOnInstructionDefinition Name=\"{name}\" Revision=\"1.0\">\n<Parameters>\n{parameters}</Parameters>\n\
         <LocalTags>\n{locals}</LocalTags>\n<Routines>\n<Routine Name=\"Logic\" Type=\"RLL\">\n<RLLContent>\n{rungs}</RLLContent>\n</Routine>\n</Routines>\n\
         </AddOnInstructionDefinition>\n"
    )
}

/// [`export`] of program `Main` with `rungs`, and the Add-On Instruction
/// `definitions`.
fn with_definitions(definitions: &[String], rungs: &[&str]) -> Program {
    let text = export("", "", &[("Main", "RLL", rungs)]).replacen(
        "<Tags>\n",
        &format!(
            "<AddOnInstructionDefinitions>\n{}</AddOnInstructionDefinitions>\n<Tags>\n",
            definitions.concat()
        ),
        1,
    );
    Program::compile("a.L5X", &text, None).unwrap_or_else(|e| panic!("{e}"))
}

fn default_sf(p: &Program, coil: &str) -> String {
    match SwitchingFunction::expand(
        p,
        &Signal::new(coil),
        &Observability::default_for(p.dialect()),
    ) {
        Ok(sf) => sf.notation(),
        Err(e) => format!("! {e}"),
    }
}

#[test]
fn an_add_on_instruction_is_its_logic_over_the_caller_s_tags() {
    // An interlock: both inputs make the output; the required output is
    // copied to the caller's tag.
    let permissive = definition(
        "Permissive",
        &[
            ("In1", "Input", true),
            ("In2", "Input", true),
            ("Out", "Output", true),
        ],
        &[],
        &["XIC(In1)XIC(In2)OTE(Out);"],
    );
    // A seal-in on the caller's tag (InOut), stopped by an input given no
    // operand (the instance's member), through a local tag.
    let hold = definition(
        "Hold",
        &[
            ("Cmd", "Input", true),
            ("State", "InOut", true),
            ("Stop", "Input", false),
        ],
        &["Sealed"],
        &[
            "[XIC(Cmd),XIC(State)]XIO(Stop)OTE(Sealed);",
            "XIC(Sealed)OTE(State);",
        ],
    );
    let p = with_definitions(
        &[permissive, hold],
        &[
            "Permissive(Perm1,Guard_Closed,Air_OK,Perm_OK);",
            "XIO(Perm1.Out)OTE(Fault);",
            "XIO(Perm_OK)OTE(Fault2);",
            "Hold(H1,Start,Motor)XIC(Motor)OTE(Running);",
            "Permissive(Perm2,1,Air_OK,Air_Only);",
            "XIC(Enable)Permissive(Perm3,a,b,c);",
            "Permissive(Perm4,a)OTE(short);",
        ],
    );
    // The instance's output is the logic inside, over the caller's tags.
    assert_eq!(sf(&p, "Perm1.Out"), "Guard_Closed * Air_OK");
    assert_eq!(sf(&p, "Perm_OK"), "Perm1.Out");
    assert_eq!(default_sf(&p, "Fault"), "-(Guard_Closed * Air_OK)");
    assert_eq!(default_sf(&p, "Fault2"), "-(Guard_Closed * Air_OK)");
    // An InOut is the caller's tag; an input given no operand is the
    // instance's member; a local tag is a member too.
    assert_eq!(sf(&p, "H1.Sealed"), "(Start + Motor) * -H1.Stop");
    assert_eq!(default_sf(&p, "Motor"), "(Start + Motor) * -H1.Stop");
    // The rung goes on after the call with its condition.
    assert_eq!(sf(&p, "Running"), "Motor");
    // A number given to an input.
    assert_eq!(sf(&p, "Perm2.Out"), "Air_OK");
    // A call on a rung that may be false: its logic may not run.
    assert!(
        sf(&p, "Perm3.Out").contains(
            "runs the logic of Add-On Instruction 'Permissive' only when the rung is true"
        ),
        "{}",
        sf(&p, "Perm3.Out")
    );
    assert!(sf(&p, "c").starts_with("! "), "{}", sf(&p, "c"));
    assert!(sf(&p, "short").starts_with("! "), "{}", sf(&p, "short"));
    assert_eq!(
        warnings(&p)
            .into_iter()
            .filter(|w| !w.contains("': a call"))
            .collect::<Vec<_>>(),
        ["97:10: routine Main, rung 6: 'Permissive(Perm4,a)' gives 2 operands, Add-On Instruction 'Permissive' takes 4 (its instance, then In1, In2, Out): what follows it on the rung is not derivable"]
    );
    // A fault coil driven through the instruction blames the logic's
    // inputs, by the caller's names.
    let fault = SwitchingFunction::expand(
        &p,
        &Signal::new("Fault"),
        &Observability::default_for(p.dialect()),
    )
    .unwrap();
    let mut before = crate::values::Values::new();
    before.set(Signal::new("Guard_Closed"), true);
    before.set(Signal::new("Air_OK"), true);
    let mut now = before.clone();
    now.set(Signal::new("Guard_Closed"), false);
    let b = |s: &Signal| before.get(s);
    let e = crate::explain::explain(
        &fault,
        |s| now.get(s),
        Some(&b),
        crate::explain::Polarity::On,
        p.documentation(),
    )
    .unwrap();
    let culprits: Vec<String> = e.culprits.iter().map(ToString::to_string).collect();
    assert_eq!(culprits, ["Guard_Closed = 0 (expected 1)"]);
}

#[test]
fn programs_are_read_in_the_order_their_tasks_run_them() {
    // File order: Filling, then Draining, then Spare. The task runs
    // Draining first, then Filling: Lamp ends with Filling's value, and
    // in Filling the main routine's JSR runs Late after Early although
    // the file lists Late first.
    let rung = |r: &str| {
        format!("<Rung Number=\"0\" Type=\"N\">\n<Text>\n<![CDATA[{r}]]>\n</Text>\n</Rung>\n")
    };
    let routine = |name: &str, rungs: &[&str]| {
        let rungs: String = rungs.iter().map(|r| rung(r)).collect();
        format!("<Routine Name=\"{name}\" Type=\"RLL\">\n<RLLContent>\n{rungs}</RLLContent>\n</Routine>\n")
    };
    let program = |name: &str, routines: &[String]| {
        format!(
            "<Program Name=\"{name}\" MainRoutineName=\"Main\">\n<Routines>\n{}</Routines>\n</Program>\n",
            routines.concat()
        )
    };
    let text = format!(
        "<?xml version=\"1.0\" encoding=\"UTF-8\" standalone=\"yes\"?>\n\
         <RSLogix5000Content SchemaRevision=\"1.0\" SoftwareRevision=\"33.01\" TargetName=\"T\" TargetType=\"Controller\">\n\
         <Controller Use=\"Target\" Name=\"T\">\n<Programs>\n{}{}{}{}</Programs>\n<Tasks>\n\
         <Task Name=\"MainTask\" Type=\"CONTINUOUS\" Priority=\"10\" Watchdog=\"500\" InhibitTask=\"false\">\n\
         <ScheduledPrograms>\n<ScheduledProgram Name=\"Draining\"/>\n<ScheduledProgram Name=\"Filling\"/>\n</ScheduledPrograms>\n</Task>\n\
         <Task Name=\"Test\" Type=\"PERIODIC\" Rate=\"10\" Priority=\"10\" Watchdog=\"500\" InhibitTask=\"true\">\n\
         <ScheduledPrograms>\n<ScheduledProgram Name=\"Trial\"/>\n</ScheduledPrograms>\n</Task>\n\
         </Tasks>\n</Controller>\n</RSLogix5000Content>\n",
        program(
            "Filling",
            &[
                routine("Late", &["XIC(late)OTE(Valve);"]),
                routine("Main", &["XIC(fill)OTE(Lamp);", "JSR(Early,0);", "JSR(Late,0);"]),
                routine("Early", &["XIC(early)OTE(Valve);"]),
            ]
        ),
        program("Draining", &[routine("Main", &["XIC(drain)OTE(Lamp);"])]),
        program("Spare", &[routine("Main", &["XIC(spare)OTE(Lamp);"])]),
        program("Trial", &[routine("Main", &["XIC(trial)OTE(Lamp);"])]),
    );
    let p = Program::compile("t.L5X", &text, None).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(sf(&p, "Lamp"), "fill");
    assert_eq!(sf(&p, "Valve"), "late");
    assert_eq!(
        warnings(&p),
        [
            "93:1: task 'Test' is inhibited (InhibitTask=\"true\"): its programs Trial are not read",
            "59:1: program 'Spare' is scheduled in no task, so the controller never runs it: not read",
        ]
    );
}
