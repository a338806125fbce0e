//! Fuzzes the Studio 5000 (L5X) reader and compiler: any input must give a
//! program or an error, never a panic, and every coil of a program must
//! expand and print without panicking. Inputs that are not XML are wrapped
//! as one rung's text, so the rung reader is reached too.

#![no_main]

use cellwatch_models::program::Program;
use cellwatch_models::signal::Observability;
use cellwatch_models::source;
use cellwatch_models::switching::SwitchingFunction;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = source::text("fuzz.L5X", data, None) else { return };
    let wrapped;
    let input: &str = if text.contains("RSLogix5000Content") {
        &text
    } else {
        wrapped = format!(
            "<RSLogix5000Content><Controller><Programs><Program Name=\"P\" MainRoutineName=\"M\"><Routines>\
             <Routine Name=\"M\" Type=\"RLL\"><RLLContent><Rung Number=\"0\"><Text><![CDATA[{}]]></Text></Rung>\
             </RLLContent></Routine></Routines></Program></Programs></Controller></RSLogix5000Content>",
            text.replace("]]>", "")
        );
        &wrapped
    };
    let Ok(program) = Program::compile("fuzz.L5X", input, None) else { return };
    let observable = Observability::default_for(program.dialect());
    for coil in program.coils().iter().take(64) {
        if let Ok(sf) = SwitchingFunction::expand(&program, &coil.signal, &observable) {
            let _ = sf.notation();
        }
    }
});
