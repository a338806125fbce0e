//! The simulated CNC: paper 000's engraving machine as an OPC UA server.
//!
//! Its "PLC" runs the shipped ESE and CSD programs: inputs (limit
//! switches, push buttons, mode switches, NC signals) are variables in
//! namespace [`NAMESPACE`] named by address (`nsu=urn:cellwatch:sim:cnc:plc;s=X0.06`), and the fault coils
//! `G8.02` and `G9.00` are recomputed from the programs on every change.
//! Faults are injected on a schedule ([`Scenario`]) or on command
//! ([`SimulatedCnc::set`], [`SimulatedCnc::set_bad`]). The server uses real
//! OPC UA security: its own key pair in its PKI directory, client
//! certificates trusted only from `trusted/`.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use cellwatch_models::program::Program;
use cellwatch_models::signal::{Observability, Signal};
use cellwatch_models::switching::SwitchingFunction;
use cellwatch_models::values::Values;
use opcua::types::Variant;

/// The namespace the simulated tags live in (index 2 on this server, 3
/// with a decoy namespace).
pub const NAMESPACE: &str = "urn:cellwatch:sim:cnc:plc";

pub use super::server::SimOptions;
use super::server::SimServer;
use super::SimError;

const ESE: &str = include_str!("../../../config/cnc/ese.il");
const CSD: &str = include_str!("../../../config/cnc/csd.il");
const ESE_NORMAL: &str = include_str!("../../../config/cnc/ese-normal.values");
const CSD_NORMAL: &str = include_str!("../../../config/cnc/csd-normal.values");

/// The part-done signal: one pulse per part.
pub const PART_DONE: &str = "X12.03";
/// Spindle temperature, °C (`Double`).
pub const SPINDLE_TEMPERATURE: &str = "D100";
/// Mode word (`Int16`): 1 AUTO, 2 JOG, 0 neither.
pub const MODE_WORD: &str = "D104";
/// Parts counter (`UInt16`), one up per part done, wrapping after 65535.
pub const PART_COUNTER: &str = "D108";
/// AUTO mode selected.
const AUTO: &str = "X201.02";
/// JOG mode selected.
const JOG: &str = "X201.06";

/// The machine's PLC: input image and the fault coils computed from it.
struct Plc {
    inputs: BTreeMap<Signal, bool>,
    coils: Vec<(Signal, SwitchingFunction)>,
    parts: u16,
    temperature: f64,
}

impl Plc {
    fn new() -> Plc {
        let mut inputs = BTreeMap::new();
        for (name, text) in [
            ("ese-normal.values", ESE_NORMAL),
            ("csd-normal.values", CSD_NORMAL),
        ] {
            let v = Values::parse_file(name, text, cellwatch_models::signal::pmc_address)
                .expect("shipped values parse");
            for s in v_signals(text) {
                inputs.insert(s.clone(), v.get(&s).unwrap_or(false));
            }
        }
        // The part-done pulse at the end of each engraving cycle.
        inputs.insert(Signal::new(PART_DONE), false);
        let mut coils = Vec::new();
        for (name, text, coil) in [("ese.il", ESE, "G8.02"), ("csd.il", CSD, "G9.00")] {
            let p = Program::compile(name, text, None).expect("shipped programs compile");
            let coil = Signal::new(coil);
            let sf = SwitchingFunction::expand(&p, &coil, &Observability::default_for(p.dialect()))
                .expect("derivable");
            coils.push((coil, sf));
        }
        Plc {
            inputs,
            coils,
            parts: 0,
            temperature: 35.0,
        }
    }

    /// The data registers and their values.
    fn registers(&self) -> Vec<(String, Variant)> {
        let on = |a: &str| self.inputs.get(&Signal::new(a)).copied().unwrap_or(false);
        let mode: i16 = match (on(AUTO), on(JOG)) {
            (true, false) => 1,
            (false, true) => 2,
            _ => 0,
        };
        vec![
            (
                SPINDLE_TEMPERATURE.into(),
                Variant::Double(self.temperature),
            ),
            (MODE_WORD.into(), Variant::Int16(mode)),
            (PART_COUNTER.into(), Variant::UInt16(self.parts)),
        ]
    }

    /// Every variable and its value: inputs, then coils.
    fn image(&self) -> Vec<(Signal, bool)> {
        let mut out: Vec<(Signal, bool)> =
            self.inputs.iter().map(|(s, v)| (s.clone(), *v)).collect();
        for (coil, sf) in &self.coils {
            out.push((
                coil.clone(),
                sf.evaluate(|s| self.inputs.get(s).copied().unwrap_or(false))
                    .0,
            ));
        }
        out
    }
}

fn v_signals(text: &str) -> Vec<Signal> {
    text.lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("address") && !l.trim().is_empty())
        .filter_map(|l| l.split(',').next())
        .filter_map(|a| cellwatch_models::signal::pmc_address(a).ok())
        .collect()
}

/// A running simulated CNC.
#[derive(Clone)]
pub struct SimulatedCnc {
    server: SimServer,
    plc: Arc<Mutex<Plc>>,
}

impl SimulatedCnc {
    /// Starts the server; it runs until [`SimulatedCnc::stop`].
    ///
    /// # Errors
    /// The port cannot be bound or the server cannot be built.
    pub async fn start(options: &SimOptions) -> Result<SimulatedCnc, SimError> {
        let plc = Plc::new();
        let image: Vec<(String, bool)> = plc
            .image()
            .into_iter()
            .map(|(s, v)| (s.to_string(), v))
            .collect();
        let server = SimServer::start(options, "cnc", "cellwatch simulated CNC", &image).await?;
        for ((name, value), description) in plc.registers().into_iter().zip([
            "Spindle temperature, degrees C",
            "Mode word: 1 AUTO, 2 JOG, 0 neither",
            "Parts counter, one up per part done",
        ]) {
            server.add_register(&name, value, description)?;
        }
        Ok(SimulatedCnc {
            server,
            plc: Arc::new(Mutex::new(plc)),
        })
    }

    /// The endpoint URL clients connect to.
    pub fn endpoint(&self) -> String {
        self.server.endpoint()
    }

    /// The address the server listens on.
    pub fn addr(&self) -> SocketAddr {
        self.server.addr()
    }

    /// Dials out to a client listening at `client` (OPC UA reverse
    /// connect).
    pub fn reverse_connect(&self, client: SocketAddr) {
        self.server.reverse_connect(client);
    }

    /// The namespace index of the tags.
    pub fn namespace(&self) -> u16 {
        self.server.namespace()
    }

    /// Sets an input (by address, `X0.06`) and recomputes the coils.
    ///
    /// # Errors
    /// The address is not an input of the machine.
    pub fn set(&self, address: &str, value: bool) -> Result<(), SimError> {
        let signal = cellwatch_models::signal::pmc_address(address)?;
        let (image, registers) = {
            let mut plc = self.plc.lock().map_err(|_| SimError::Poisoned)?;
            let before = match plc.inputs.get_mut(&signal) {
                Some(v) => std::mem::replace(v, value),
                None => return Err(SimError::NotInput { signal }),
            };
            if signal.name() == PART_DONE && value && !before {
                plc.parts = plc.parts.wrapping_add(1);
            }
            (plc.image(), plc.registers())
        };
        let values: Vec<(String, bool)> =
            image.into_iter().map(|(s, v)| (s.to_string(), v)).collect();
        self.server.set(&values)?;
        self.server.set_registers(&registers)
    }

    /// Sets the spindle temperature (°C).
    ///
    /// # Errors
    /// The server refuses the update.
    pub fn set_temperature(&self, celsius: f64) -> Result<(), SimError> {
        let registers = {
            let mut plc = self.plc.lock().map_err(|_| SimError::Poisoned)?;
            plc.temperature = celsius;
            plc.registers()
        };
        self.server.set_registers(&registers)
    }

    /// Sets the parts counter (as an operator resetting it does).
    ///
    /// # Errors
    /// The server refuses the update.
    pub fn set_part_counter(&self, parts: u16) -> Result<(), SimError> {
        let registers = {
            let mut plc = self.plc.lock().map_err(|_| SimError::Poisoned)?;
            plc.parts = parts;
            plc.registers()
        };
        self.server.set_registers(&registers)
    }

    /// Adds a data register of any type (see [`SimServer::add_register`]).
    ///
    /// # Errors
    /// A variable of that name exists.
    pub fn add_register(&self, name: &str, value: Variant) -> Result<(), SimError> {
        self.server.add_register(name, value, "")
    }

    /// The index of the decoy namespace ([`SimOptions::decoy`]), if any.
    pub fn decoy_namespace(&self) -> Option<u16> {
        self.server.decoy_namespace()
    }

    /// Writes data registers added with [`SimulatedCnc::add_register`].
    ///
    /// # Errors
    /// No such register.
    pub fn set_registers(&self, values: &[(String, Variant)]) -> Result<(), SimError> {
        self.server.set_registers(values)
    }

    /// Marks an input's value as bad (a broken sensor wire).
    ///
    /// # Errors
    /// The address is not an input of the machine.
    pub fn set_bad(&self, address: &str) -> Result<(), SimError> {
        let signal = cellwatch_models::signal::pmc_address(address)?;
        let value = {
            let plc = self.plc.lock().map_err(|_| SimError::Poisoned)?;
            *plc.inputs.get(&signal).ok_or_else(|| SimError::NotInput {
                signal: signal.clone(),
            })?
        };
        self.server.set_bad(signal.name(), value)
    }

    /// Sets a variable of the decoy namespace ([`SimOptions::decoy`]).
    ///
    /// # Errors
    /// There is no decoy namespace or no such variable in it.
    pub fn set_decoy(&self, address: &str, value: bool) -> Result<(), SimError> {
        self.server.set_decoy(&[(address.to_string(), value)])
    }

    /// Deletes a variable from the server (a changed PLC configuration).
    ///
    /// # Errors
    /// No such variable.
    pub fn delete(&self, address: &str) -> Result<(), SimError> {
        self.server.delete(address)
    }

    /// Tells a variable's monitored items it has no data, then nothing
    /// more (see [`SimServer::no_data`]).
    pub fn no_data(&self, address: &str) {
        self.server.no_data(address);
    }

    /// Deletes a variable and tells its monitored items nothing (see
    /// [`SimServer::delete_quietly`]).
    ///
    /// # Errors
    /// No such variable.
    pub fn delete_quietly(&self, address: &str) -> Result<(), SimError> {
        self.server.delete_quietly(address)
    }

    /// Adds a deleted input or register back, with the value the machine
    /// holds (see [`SimServer::restore`]).
    ///
    /// # Errors
    /// Not a variable of the machine, or not deleted.
    pub fn restore(&self, address: &str) -> Result<(), SimError> {
        let value = self.holds(address)?;
        self.server.restore(address, value)
    }

    /// Recreates an input or register with the value the machine holds,
    /// telling its monitored items nothing (see
    /// [`SimServer::recreate_quietly`]).
    ///
    /// # Errors
    /// Not a variable of the machine.
    pub fn recreate_quietly(&self, address: &str) -> Result<(), SimError> {
        let value = self.holds(address)?;
        self.server.recreate_quietly(address, value)
    }

    /// The value the machine holds at `address`, an input or a register.
    fn holds(&self, address: &str) -> Result<Variant, SimError> {
        let value = {
            let plc = self.plc.lock().map_err(|_| SimError::Poisoned)?;
            match plc
                .registers()
                .into_iter()
                .find(|(name, _)| name == address)
            {
                Some((_, v)) => v,
                None => {
                    let signal = cellwatch_models::signal::pmc_address(address)?;
                    Variant::Boolean(*plc.inputs.get(&signal).ok_or_else(|| {
                        SimError::NotVariable {
                            signal: signal.clone(),
                        }
                    })?)
                }
            }
        };
        Ok(value)
    }

    /// How many subscriptions the server holds (see
    /// [`SimServer::subscriptions`]).
    pub fn subscriptions(&self) -> usize {
        self.server.subscriptions()
    }

    /// Says `level` as the server's `ServiceLevel` (see
    /// [`SimServer::set_service_level`]).
    pub fn set_service_level(&self, level: u8) {
        self.server.set_service_level(level);
    }

    /// Stops the server; connected clients see the connection drop.
    pub fn stop(&self) {
        self.server.stop();
    }
}

/// A value a scenario step writes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Set {
    /// An input contact.
    Contact(bool),
    /// The spindle temperature, °C.
    Temperature(f64),
}

impl std::fmt::Display for Set {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Set::Contact(b) => write!(f, "{}", u8::from(*b)),
            Set::Temperature(t) => write!(f, "{t} °C"),
        }
    }
}

/// A fault to inject at a time.
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    /// Seconds from the start of the cycle.
    pub at: Duration,
    /// Input to change.
    pub address: &'static str,
    /// Its new value.
    pub value: Set,
    /// What it means on the shop floor.
    pub note: &'static str,
}

/// A repeating schedule of injected faults.
#[derive(Debug, Clone)]
pub struct Scenario {
    /// The steps of one cycle, in time order.
    pub steps: Vec<Step>,
    /// The cycle length.
    pub period: Duration,
}

impl Scenario {
    /// The demo's cycle: the Y over-travel switch opens (ESE), then an
    /// operator presses cycle start in JOG mode (CSD).
    pub fn demo() -> Scenario {
        let step = |s: u64, address, value, note| Step {
            at: Duration::from_secs(s),
            address,
            value: Set::Contact(value),
            note,
        };
        let heat = |s: u64, celsius, note| Step {
            at: Duration::from_secs(s),
            address: SPINDLE_TEMPERATURE,
            value: Set::Temperature(celsius),
            note,
        };
        Scenario {
            steps: vec![
                step(1, PART_DONE, true, "part done"),
                step(2, PART_DONE, false, "next part loaded"),
                step(
                    3,
                    "X0.06",
                    false,
                    "Y axis runs onto its over-travel limit switch",
                ),
                heat(4, 88.5, "spindle bearing runs hot"),
                step(8, "X0.06", true, "Y axis moved back off the limit switch"),
                heat(9, 41.0, "spindle cooled down"),
                step(12, "X201.02", false, "operator leaves AUTO mode"),
                step(12, "X201.06", true, "operator selects JOG mode"),
                step(
                    14,
                    "X200.01",
                    true,
                    "operator presses cycle start (in JOG mode)",
                ),
                step(15, "X200.01", false, "operator releases cycle start"),
                step(18, "X201.06", false, "operator leaves JOG mode"),
                step(18, "X201.02", true, "operator selects AUTO mode"),
                step(21, PART_DONE, true, "part done"),
                step(22, PART_DONE, false, "next part loaded"),
            ],
            period: Duration::from_secs(24),
        }
    }

    /// Plays the scenario on `sim` forever, calling `note` for each step.
    pub async fn play(&self, sim: &SimulatedCnc, note: impl Fn(&Step)) {
        let start = tokio::time::Instant::now();
        let mut cycle = 0u32;
        loop {
            for step in &self.steps {
                tokio::time::sleep_until(start + self.period * cycle + step.at).await;
                note(step);
                let done = match step.value {
                    Set::Contact(v) => sim.set(step.address, v),
                    Set::Temperature(t) => sim.set_temperature(t),
                };
                if let Err(e) = done {
                    tracing::error!(error = %e, "scenario step failed");
                }
            }
            cycle += 1;
            tokio::time::sleep_until(start + self.period * cycle).await;
        }
    }
}
