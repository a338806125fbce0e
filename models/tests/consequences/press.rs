//! A press whose logic nobody here wrote the papers for
//! (`tests/data/press/`), written three times: in FANUC PMC instruction
//! list (`press.il`), as a PLCopen XML ladder (`press-ld.xml`, OpenPLC
//! Editor's shape) and as a Studio 5000 export with RLL rungs
//! (`press.L5X`). Each program names the press's signals in its own
//! language; [`NAMES`] maps the instruction list's addresses to the
//! others', and the tests speak in the addresses. Each test loops over the
//! three programs and asserts the same marks for every one: the shapes the
//! papers do not have (an interlock ANDed with a request, a permissive
//! chain through two forced outputs, an operator's action on a faulted
//! machine, two faults reading one shared contact, a cause that clears
//! before its effect) are found whatever the language they are drawn in.

use cellwatch_models::consequence::{forced_outputs, Link};

use super::*;

const IL: &str = include_str!("../../../tests/data/press/press.il");
const LD: &str = include_str!("../../../tests/data/press/press-ld.xml");
const L5X: &str = include_str!("../../../tests/data/press/press.L5X");

/// Each signal of the press as the three programs name it: the
/// instruction list's address, the PLCopen variable, the Logix tag.
const NAMES: [[&str; 3]; 16] = [
    ["X1.00", "PumpRunning", "Pump_Running"],
    ["X1.01", "PressureReached", "Hydraulic_Pressure_OK"],
    ["X1.02", "ClampClosed", "Clamp_Closed"],
    ["X1.03", "ClampRequest", "Clamp_Request"],
    ["X1.04", "CycleStart", "Cycle_Start_PB"],
    ["X1.05", "CoolantFlowing", "Coolant_Flow"],
    ["X1.06", "CoolantRequest", "Coolant_Request"],
    ["X1.07", "RamRequest", "Ram_Request"],
    ["Y2.00", "ClampValve", "Clamp_Valve"],
    ["Y2.01", "HydraulicsReady", "Hydraulics_Ready"],
    ["Y2.02", "RamEnable", "Ram_Enable"],
    ["G10.00", "HydraulicFault", "Hydraulic_Fault"],
    ["G10.01", "ClampFault", "Clamp_Fault"],
    ["G10.02", "CycleStartFault", "Cycle_Start_Fault"],
    ["G10.03", "CoolantFault", "Coolant_Fault"],
    ["G10.04", "RamFault", "Ram_Fault"],
];

/// The press's five faults: each alarm's id and its fault coil.
const FAULTS: [(&str, &str); 5] = [
    ("hydraulic", "G10.00"),
    ("clamp", "G10.01"),
    ("cycle-start", "G10.02"),
    ("coolant", "G10.03"),
    ("ram", "G10.04"),
];

/// One of the three programs of the press.
struct Press {
    file: &'static str,
    source: &'static str,
    /// Its column of [`NAMES`].
    column: usize,
}

const PRESSES: [Press; 3] = [
    Press {
        file: "press.il",
        source: IL,
        column: 0,
    },
    Press {
        file: "press-ld.xml",
        source: LD,
        column: 1,
    },
    Press {
        file: "press.L5X",
        source: L5X,
        column: 2,
    },
];

impl Press {
    /// What this program calls the instruction list's `address`.
    fn signal(&self, address: &str) -> Signal {
        let row = NAMES.iter().find(|n| n[0] == address).unwrap();
        Signal::new(row[self.column])
    }

    fn program(&self) -> Program {
        kit::compile(self.file, self.source)
    }

    /// Every signal of the press observable (the PLC's tags, as the
    /// server publishes them).
    fn observable(&self, p: &Program) -> Observability {
        let names: Vec<&str> = NAMES.iter().map(|n| n[self.column]).collect();
        Observability::parse(p.dialect(), &names.join(",")).unwrap()
    }

    /// The press's five faults, each a switching check over its coil with
    /// the outputs the program derives from it; every signal a tag.
    fn engine(&self) -> CellEngine {
        let p = self.program();
        let observable = self.observable(&p);
        let signals: BTreeSet<Signal> = NAMES.iter().map(|n| Signal::new(n[self.column])).collect();
        let checks = FAULTS
            .into_iter()
            .map(|(id, coil)| {
                let coil = self.signal(coil);
                let sf = SwitchingFunction::expand(&p, &coil, &observable).unwrap();
                assert!(
                    sf.leaves().iter().all(|l| signals.contains(l)),
                    "{}: {id} reads {:?}",
                    self.file,
                    sf.leaves()
                );
                SwitchingCheck {
                    forces: forced_outputs(&p, &coil, &observable, |s| signals.contains(s)),
                    ..kit::switching_check(id, sf, Severity::High)
                }
            })
            .collect();
        let sets: Vec<Box<dyn CheckSet>> = vec![Box::new(SwitchingChecks::new(checks))];
        kit::related(kit::cell("press", kit::tags(signals), sets), false)
    }

    /// The engine with the press running normally: pump on with pressure,
    /// clamp requested and closed, coolant requested and flowing, the ram
    /// requested and enabled, cycle start released, no fault coil on.
    fn running(&self) -> Running<'_> {
        let mut r = Running {
            press: self,
            e: self.engine(),
        };
        r.e.on_connection(true, 1);
        for (a, v) in [
            ("X1.00", true),
            ("X1.01", true),
            ("X1.02", true),
            ("X1.03", true),
            ("X1.04", false),
            ("X1.05", true),
            ("X1.06", true),
            ("X1.07", true),
            ("Y2.00", true),
            ("Y2.01", true),
            ("Y2.02", true),
            ("G10.00", false),
            ("G10.01", false),
            ("G10.02", false),
            ("G10.03", false),
            ("G10.04", false),
        ] {
            r.set(a, v, 1);
        }
        assert!(
            r.e.alarms().all(|a| !a.active),
            "{}: running raises nothing",
            self.file
        );
        r
    }
}

/// A press's engine, its signals set by the instruction list's addresses.
struct Running<'p> {
    press: &'p Press,
    e: CellEngine,
}

impl Running<'_> {
    fn set(&mut self, address: &str, v: bool, at: u64) -> EngineStep {
        set(&mut self.e, self.press.signal(address).name(), v, at)
    }

    /// What the consequence raised in `step` follows through.
    fn through(&self, step: &EngineStep) -> Vec<(Signal, bool)> {
        let raised = raised(step);
        assert_eq!(raised.len(), 1, "{}: {:?}", self.press.file, marks(step));
        raised[0].consequence.as_ref().unwrap().through.clone()
    }
}

fn mark(id: &str, cause: &str, first_out: &str) -> Mark {
    (id.into(), Some((cause.into(), first_out.into(), false)))
}

fn first_out(id: &str) -> Mark {
    (id.into(), None)
}

#[test]
fn the_three_programs_give_each_coil_the_same_function() {
    // Every coil of the ladders computes what the instruction list's
    // does, on every value of what it reads.
    let il = PRESSES[0].program();
    let il_observable = PRESSES[0].observable(&il);
    let coils: Vec<&str> = il.coils().iter().map(|c| c.signal.name()).collect();
    assert_eq!(
        coils,
        ["G10.00", "Y2.00", "G10.01", "G10.02", "G10.03", "Y2.01", "Y2.02", "G10.04"]
    );
    for press in &PRESSES[1..] {
        let p = press.program();
        assert!(
            p.warnings().is_empty(),
            "{}: {:?}",
            press.file,
            p.warnings()
        );
        let theirs: Vec<Signal> = p.coils().iter().map(|c| c.signal.clone()).collect();
        let ours: Vec<Signal> = coils.iter().map(|c| press.signal(c)).collect();
        assert_eq!(theirs, ours, "{}", press.file);
        for coil in &coils {
            let want = SwitchingFunction::expand(&il, &Signal::new(coil), &il_observable).unwrap();
            let got =
                SwitchingFunction::expand(&p, &press.signal(coil), &press.observable(&p)).unwrap();
            let leaves = want.leaves();
            for bits in 0..1u32 << leaves.len() {
                let on =
                    |s: &Signal| (bits >> leaves.iter().position(|l| l == s).unwrap()) & 1 == 1;
                let renamed = |s: &Signal| {
                    let row = NAMES.iter().find(|n| n[press.column] == s.name()).unwrap();
                    on(&Signal::new(row[0]))
                };
                assert_eq!(
                    got.evaluate(renamed).0,
                    want.evaluate(on).0,
                    "{}: {coil} on {bits:b} of {leaves:?}",
                    press.file
                );
            }
        }
    }
}

#[test]
fn on_a_press_the_relation_runs_through_the_forced_outputs_and_the_clamp_coil_only() {
    for press in &PRESSES {
        let e = press.engine();
        let edges: Vec<(String, String, Link)> = e
            .relation()
            .edges()
            .map(|x| (x.cause, x.effect, x.link))
            .collect();
        let reads = |address: &str| Link::Reads(vec![press.signal(address)]);
        // The coolant fault reads the pump contactor the hydraulic fault
        // reads too: no edge, they stay independent. The ram fault reads
        // the ram enable, two outputs down from the hydraulic fault.
        assert_eq!(
            edges,
            [
                ("hydraulic".into(), "clamp".into(), reads("Y2.00")),
                ("clamp".into(), "cycle-start".into(), reads("G10.01")),
                ("hydraulic".into(), "ram".into(), reads("Y2.02")),
            ],
            "{}",
            press.file
        );
        let held: Vec<Signal> = ["G10.00", "Y2.00", "Y2.01", "Y2.02"]
            .map(|a| press.signal(a))
            .into();
        assert_eq!(e.relation().effects_of("hydraulic"), held, "{}", press.file);
    }
}

#[test]
fn a_hydraulic_fault_drops_the_clamp_and_an_operator_pressing_start_follows_from_it() {
    for press in &PRESSES {
        let mut r = press.running();
        let file = press.file;
        // The pressure is lost while the pump runs: the first-out.
        let s = r.set("X1.01", false, 2);
        assert_eq!(marks(&s), [first_out("hydraulic")], "{file}");
        // The PLC drops the clamp valve: the clamp fault, whose term holds
        // the clamp request too (a standing request, not the hydraulics'),
        // would not hold with the hydraulic fault's coil normal (the valve
        // re-derived on): its consequence.
        r.set("G10.00", true, 3);
        let s = r.set("Y2.00", false, 4);
        assert_eq!(
            marks(&s),
            [mark("clamp", "hydraulic", "hydraulic")],
            "{file}"
        );
        // Through the valve: 0 now, 1 without the hydraulic fault.
        assert_eq!(r.through(&s), [(press.signal("Y2.00"), false)], "{file}");
        let clamp = &raised(&s)[0];
        assert!(
            clamp
                .culprits
                .iter()
                .any(|c| c.address == press.signal("Y2.00")),
            "{file}: {:?}",
            clamp.culprits
        );
        r.set("G10.01", true, 5);
        // An operator presses cycle start on the faulted press: the cycle
        // start fault follows from the clamp's, whose first-out it keeps.
        let s = r.set("X1.04", true, 6);
        assert_eq!(
            marks(&s),
            [mark("cycle-start", "clamp", "hydraulic")],
            "{file}"
        );
        assert_eq!(r.through(&s), [(press.signal("G10.01"), true)], "{file}");
        // The coolant stops flowing meanwhile: a first-out of its own,
        // though it reads the pump contactor the hydraulic fault reads.
        let s = r.set("X1.05", false, 7);
        assert_eq!(marks(&s), [first_out("coolant")], "{file}");
    }
}

#[test]
fn a_hydraulic_fault_disables_the_ram_through_the_ready_relay_and_the_ram_fault_follows() {
    for press in &PRESSES {
        let mut r = press.running();
        let file = press.file;
        r.set("X1.01", false, 2);
        r.set("G10.00", true, 3);
        // The ready relay drops: no check reads it.
        assert!(raised(&r.set("Y2.01", false, 4)).is_empty(), "{file}");
        // The ram enable drops with it: the ram fault, requested and not
        // enabled, would not hold with the relay and then the enable
        // re-derived from the hydraulic fault's coil normal.
        let s = r.set("Y2.02", false, 5);
        assert_eq!(marks(&s), [mark("ram", "hydraulic", "hydraulic")], "{file}");
        // Through the enable it reads, not the relay it does not.
        assert_eq!(r.through(&s), [(press.signal("Y2.02"), false)], "{file}");
    }
}

#[test]
fn a_ready_relay_dropped_by_the_pump_stopping_makes_the_ram_fault_a_first_out() {
    for press in &PRESSES {
        let mut r = press.running();
        let file = press.file;
        // The pump stops: no hydraulic fault (it needs the pump running),
        // nor a coolant one (the same contact); the relay and the enable
        // drop, and the ram fault has no active cause.
        assert!(raised(&r.set("X1.00", false, 2)).is_empty(), "{file}");
        r.set("Y2.01", false, 3);
        let s = r.set("Y2.02", false, 4);
        assert_eq!(marks(&s), [first_out("ram")], "{file}");
    }
}

#[test]
fn a_contact_of_the_effects_own_gone_bad_keeps_it_a_first_out() {
    for press in &PRESSES {
        let mut r = press.running();
        let file = press.file;
        // The clamp has opened by itself (its sensor) before the
        // hydraulics fail: the clamp fault is raised by its own contact.
        let s = r.set("X1.02", false, 2);
        assert_eq!(marks(&s), [first_out("clamp")], "{file}");
        r.set("X1.02", true, 3);
        // Cleared; now the hydraulics fail and the sensor opens with the
        // valve: with the valve re-derived on, the clamp is still not
        // closed, so the clamp fault would hold anyway and is its own
        // first-out.
        r.set("X1.01", false, 4);
        r.set("G10.00", true, 5);
        r.set("X1.02", false, 6);
        let s = r.set("Y2.00", false, 7);
        assert!(raised(&s).is_empty(), "{file}: {:?}", marks(&s));
        let clamp = r.e.alarms().find(|a| a.id == "clamp").unwrap();
        assert!(
            clamp.active && clamp.consequence.is_none(),
            "{file}: {clamp:?}"
        );
    }
}

#[test]
fn an_effect_raised_after_its_cause_cleared_is_a_first_out() {
    for press in &PRESSES {
        let mut r = press.running();
        let file = press.file;
        r.set("X1.01", false, 2);
        r.set("G10.00", true, 3);
        let s = r.set("Y2.00", false, 4);
        assert_eq!(
            marks(&s),
            [mark("clamp", "hydraulic", "hydraulic")],
            "{file}"
        );
        r.set("G10.01", true, 5);
        // The pressure comes back; the PLC keeps the clamp fault latched.
        r.set("X1.01", true, 6);
        assert!(
            !r.e.alarms().any(|a| a.id == "hydraulic" && a.active),
            "{file}"
        );
        // Cycle start pressed now: it follows from the clamp, still in
        // fault, whose first-out stays the hydraulic fault that made it.
        let s = r.set("X1.04", true, 7);
        assert_eq!(
            marks(&s),
            [mark("cycle-start", "clamp", "hydraulic")],
            "{file}"
        );
        // Another press: the pressure comes back before the valve is seen
        // to drop (a slow valve feedback); the clamp fault raised then has
        // no active cause.
        let mut r = press.running();
        r.set("X1.01", false, 2);
        r.set("G10.00", true, 3);
        r.set("X1.01", true, 4);
        r.set("G10.00", false, 5);
        let s = r.set("Y2.00", false, 6);
        assert_eq!(marks(&s), [first_out("clamp")], "{file}");
    }
}
