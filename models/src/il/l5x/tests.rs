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
        "t.L5X:1:1: no routine with any rung in it in this L5X export"
    );
    let e =
        Program::compile("t.L5X", &export("", "", &[]), Some(crate::il::Dialect::Iec)).unwrap_err();
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
