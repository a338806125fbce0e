//! Fuzzes the `@`-frame decoder (paper 002): any bytes, fed in any split,
//! give frames or errors with end codes 14/15, never a panic, with the
//! buffer bounded; every frame decoded encodes back to bytes that decode to
//! the same frame.

#![no_main]

use cellwatch_models::at_bus::{Decoded, Decoder, END_DATA, END_FORMAT};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    for requests in [false, true] {
        let mut d = if requests {
            Decoder::requests()
        } else {
            Decoder::answers()
        };
        let mut out = Vec::new();
        // The first byte decides where the input is split.
        let split = data.first().map_or(0, |&b| b as usize).min(data.len());
        d.push(&data[..split], &mut out);
        d.push(&data[split..], &mut out);
        for o in out {
            match o {
                Decoded::Frame(f) | Decoded::Duplicate(f) => {
                    let mut again = if requests {
                        Decoder::requests()
                    } else {
                        Decoder::answers()
                    };
                    let mut back = Vec::new();
                    again.push(&f.encode(), &mut back);
                    assert_eq!(back, [Decoded::Frame(f)]);
                }
                Decoded::Error { end, .. } => assert!(end == END_FORMAT || end == END_DATA),
            }
        }
    }
});
