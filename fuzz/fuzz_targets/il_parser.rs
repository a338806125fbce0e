//! Fuzzes the instruction-list parser and compiler: any input must give a
//! program or an error, never a panic, and every coil of a program must
//! expand, print and evaluate without panicking.

#![no_main]

use cellwatch_models::programs::Dialect;
use cellwatch_models::program::Program;
use cellwatch_models::signal::Observability;
use cellwatch_models::source;
use cellwatch_models::switching::SwitchingFunction;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = source::text("fuzz.il", data, None) else { return };
    for dialect in [None, Some(Dialect::Pmc), Some(Dialect::Iec), Some(Dialect::Stl)] {
        let Ok(program) = Program::compile("fuzz.il", &text, dialect) else { continue };
        let observable = Observability::default_for(program.dialect());
        for coil in program.coils().iter().take(64) {
            if let Ok(sf) = SwitchingFunction::expand(&program, &coil.signal, &observable) {
                let _ = sf.notation();
                let _ = sf.readable();
                let _ = sf.evaluate(|s| s.name().len() % 2 == 0);
                for i in 1..=sf.steps.len() {
                    let _ = sf.step_notation(i);
                }
            }
        }
    }
});
