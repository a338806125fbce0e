//! Fuzzes the chart readers (the TOML form and PLCopen XML): any input must
//! give charts or located errors, never a panic, and charts must run.

#![no_main]

use cellwatch_models::sfc::{self, run::Runner};
use cellwatch_models::source;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = source::text("fuzz.sfc", data, None) else { return };
    for parse in [sfc::text::parse, sfc::plcopen::parse] {
        if let Ok(charts) = parse("fuzz.sfc", &text, &|s| s.name().len() % 3 != 0) {
            let mut runner = Runner::new(&charts);
            for i in 0..4 {
                runner.scan(&charts, &|s| (s.name().len() + i) % 2 == 0, i == 2, &|_, _| true);
            }
        }
    }
});
