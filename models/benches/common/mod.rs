//! The generated benchmark cell shared by the benches: 10,000 signals and
//! 1,000 fault rungs shaped like ESE, contacts drawn at random from a fixed
//! seed so that every run measures the same cell.

#![allow(dead_code)] // each bench uses part of it

use cellwatch_models::program::Program;
use cellwatch_models::signal::{Observability, Signal};
use cellwatch_models::switching::SwitchingFunction;

pub(crate) const SIGNALS: usize = 10_000;
pub(crate) const CHECKS: usize = 1_000;

/// A small deterministic generator (xorshift64*), so every run measures the
/// same cell.
pub(crate) struct Rng(pub(crate) u64);

impl Rng {
    pub(crate) fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    pub(crate) fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

pub(crate) fn address(i: usize) -> String {
    format!("X{}.{:02X}", i / 16, i % 16)
}

/// One fault rung like ESE's: OR chains of normally-closed contacts, an AND
/// of an OR group through the stack, about 30 contacts in 4 to 6 blocks.
fn rung(rng: &mut Rng, coil: usize, out: &mut String) {
    let contact = |rng: &mut Rng| address(rng.below(SIGNALS));
    out.push_str(&format!("RD.NOT {}\n", contact(rng)));
    for _ in 0..5 {
        out.push_str(&format!("OR.NOT {}\n", contact(rng)));
    }
    out.push_str(&format!("AND.NOT {}\n", contact(rng)));
    out.push_str(&format!("RD.NOT.STK {}\n", contact(rng)));
    for _ in 0..3 {
        out.push_str(&format!("OR.NOT {}\n", contact(rng)));
    }
    out.push_str("AND.STK\n");
    for _ in 0..2 {
        out.push_str(&format!("AND {}\n", contact(rng)));
    }
    for _ in 0..8 {
        out.push_str(&format!("OR.NOT {}\n", contact(rng)));
    }
    out.push_str(&format!("WRT R{coil}\nRD R{coil}\n"));
    for _ in 0..8 {
        out.push_str(&format!("OR.NOT {}\n", contact(rng)));
    }
    out.push_str(&format!("WRT G{coil}.00\n"));
}

/// The cell's switching functions, one per fault coil `G<c>.00`, and the
/// generator (to draw the changes from).
pub(crate) fn generated_sfs() -> (Vec<SwitchingFunction>, Rng) {
    let mut rng = Rng(0x00C0_FFEE_1234_5678);
    let mut src = String::new();
    for c in 0..CHECKS {
        rung(&mut rng, c, &mut src);
    }
    let program = Program::compile("generated.il", &src, None).expect("generated program compiles");
    let observable = Observability::default_for(program.dialect());
    let sfs = (0..CHECKS)
        .map(|c| {
            SwitchingFunction::expand(&program, &Signal::new(&format!("G{c}.00")), &observable)
                .expect("derivable")
        })
        .collect();
    (sfs, rng)
}
