//! IEC 61131-3 instruction lists as real programs write them: declared
//! types, function-block instances, functions as operators, arrays,
//! nested arithmetic, comparisons — each once misread, each pinned here.

#![allow(clippy::unwrap_used)] // test helpers fail loudly by design

use cellwatch_models::program::Program;
use cellwatch_models::signal::{Observability, Signal};
use cellwatch_models::switching::SwitchingFunction;

mod kit;

fn compile(src: &str) -> Program {
    kit::compile("p.il", src)
}

fn coils(p: &Program) -> Vec<&str> {
    p.coils().iter().map(|c| c.signal.name()).collect()
}

fn sf(p: &Program, coil: &str) -> String {
    SwitchingFunction::expand(
        p,
        &Signal::new(coil),
        &Observability::everything(p.dialect()),
    )
    .unwrap_or_else(|e| panic!("{e}"))
    .notation()
}

fn warned_lines(p: &Program) -> Vec<usize> {
    p.warnings().iter().map(|w| w.at.line).collect()
}

#[test]
fn an_sr_instance_takes_set_and_reset_as_its_inputs_not_as_a_latch() {
    let p = compile(
        "PROGRAM alarm\nVAR\n  ALRM_FF : SR;\n  Fault, Ack, Lamp : BOOL;\nEND_VAR\n\
         LD Fault\nS1 ALRM_FF\nLD Ack\nR ALRM_FF\nLD ALRM_FF.Q1\nST Lamp\nEND_PROGRAM\n",
    );
    // Before, `R ALRM_FF` made ALRM_FF a boolean latch coil.
    assert_eq!(coils(&p), ["Lamp"]);
    assert_eq!(sf(&p, "Lamp"), "ALRM_FF.Q1");
    assert_eq!(warned_lines(&p), [7, 9]);
    assert!(
        p.warnings()[1]
            .message
            .starts_with("'R ALRM_FF': an input of a function block instance"),
        "{:?}",
        p.warnings()
    );
}

#[test]
fn a_time_moved_to_a_timer_preset_is_not_a_coil() {
    let p = compile(
        "VAR\n  T_CMD_MAX : TIME := T#5s;\n  CMD_TMR : TON;\n  Cmd, Timeout : BOOL;\nEND_VAR\n\
         LD T_CMD_MAX\nST CMD_TMR.PT\nLD Cmd\nST CMD_TMR.IN\nCAL CMD_TMR\nLD CMD_TMR.Q\nST Timeout\n",
    );
    // Before: a boolean coil `CMD_TMR.PT = T_CMD_MAX`.
    assert_eq!(coils(&p), ["Timeout"]);
    assert_eq!(sf(&p, "Timeout"), "CMD_TMR.Q");
    assert_eq!(warned_lines(&p), [7, 9, 10]);
}

#[test]
fn nested_arithmetic_parentheses_are_read() {
    // Before: "'MUL( C' with no result to combine: no load before it".
    let p = compile(
        "VAR\n  A, B, C, X : INT;\n  Start, Run : BOOL;\nEND_VAR\n\
         LD A\nADD( B\n  MUL( C\n    SUB 1\n  )\n)\nST X\nLD Start\nST Run\n",
    );
    assert_eq!(coils(&p), ["Run"]);
    assert_eq!(sf(&p, "Run"), "Start");
    assert!(warned_lines(&p).contains(&6));
}

#[test]
fn functions_are_operators() {
    let p = compile(
        "FUNCTION SCALE : INT\nVAR_INPUT x : INT; END_VAR\nLD x\nEND_FUNCTION\n\
         PROGRAM p\nVAR\n  Raw, Value, Top : INT;\n  Ok : BOOL;\nEND_VAR\n\
         LD Raw\nBCD_TO_INT\nMAX 5\nSCALE\nLIMIT( 0\n)\nST Value\nLD Top\nGE 5\nST Ok\nEND_PROGRAM\n",
    );
    assert_eq!(coils(&p), ["Ok"]);
    assert_eq!(warned_lines(&p), [11, 12, 13, 14, 16]);
    // A function the file does not declare is still an unknown instruction.
    let e = Program::compile("p.il", "LD a\nFROBNICATE 3\nST b\n", None).unwrap_err();
    assert_eq!(e.to_string(), "p.il:2:1: unknown instruction 'FROBNICATE'");
}

#[test]
fn an_array_element_is_not_a_boolean() {
    let p = compile(
        "VAR\n  STK : ARRAY[0..7] OF INT;\n  PTR : INT;\n  Out : BOOL;\nEND_VAR\n\
         LD STK[PTR]\nST Out\nLD 3\nST STK[PTR]\n",
    );
    let out = p.coil(&Signal::new("Out")).unwrap();
    let why = out.definition.as_ref().unwrap_err();
    assert_eq!(why.reason, "'STK[PTR]' is not a boolean");
    assert_eq!(coils(&p), ["Out"]);
    assert_eq!(warned_lines(&p), [9]);
}

#[test]
fn a_comparison_stored_to_a_boolean_is_a_comparison_contact() {
    let p = compile(
        "VAR\n  TEMP : INT;\n  LIMIT_HI : INT;\n  Fan, Hot : BOOL;\nEND_VAR\n\
         LD TEMP\nGT 80\nST Hot\nLD TEMP\nGE LIMIT_HI\nAND Fan\nST Fan\n",
    );
    assert_eq!(sf(&p, "Hot"), "TEMP > 80");
    assert!(
        sf(&p, "Fan").starts_with("TEMP >= LIMIT_HI * Fan"),
        "{}",
        sf(&p, "Fan")
    );
    assert!(p.warnings().is_empty(), "{:?}", p.warnings());
}

#[test]
fn calls_without_cal_formal_calls_over_lines_glued_labels_and_strings() {
    let p = compile(
        "VAR\n  T1 : TON;\n  Go, Done, Msg_ok : BOOL;\n  Msg : STRING;\nEND_VAR\n\
         T1(IN := Go, PT := T#2s)\n\
         CAL T1(\n  IN := Go,\n  PT := T#2s\n)\n\
         next:LD T1.Q\nST Done\n\
         LD 'motor on'\nST Msg\nLD Go\nST Msg_ok\n",
    );
    assert_eq!(coils(&p), ["Done", "Msg_ok"]);
    assert_eq!(sf(&p, "Done"), "T1.Q");
    assert_eq!(warned_lines(&p), [6, 7, 14]);
}
