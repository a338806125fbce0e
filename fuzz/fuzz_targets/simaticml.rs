//! Fuzzes the TIA Portal SimaticML reader: any document must give a
//! program or located errors, never a panic, and every coil of a program
//! must expand and print; read as a tag table, any document must give
//! comments or an error.

#![no_main]

use cellwatch_models::comments::CommentDb;
use cellwatch_models::program::Program;
use cellwatch_models::signal::Observability;
use cellwatch_models::switching::SwitchingFunction;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(body) = std::str::from_utf8(data) else { return };
    // Start every input as a SimaticML document, so the fuzzer spends its
    // time in the reader rather than in telling formats apart.
    let text = format!("<?xml version=\"1.0\"?>\n<Document>{body}");
    if let Ok(program) = Program::compile("fuzz.xml", &text, None) {
        let observable = Observability::default_for(program.dialect());
        for coil in program.coils().iter().take(64) {
            if let Ok(sf) = SwitchingFunction::expand(&program, &coil.signal, &observable) {
                let _ = sf.notation();
                let _ = sf.evaluate(|s| s.name().len() % 2 == 0);
            }
        }
        let _ = CommentDb::parse("fuzz.xml", &text, |a| program.resolve(a));
    }
});
