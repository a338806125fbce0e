//! `cellwatch simulate cnc`: the simulated CNC as a standalone OPC UA server.

use std::io::Write;

use tokio::io::{AsyncBufReadExt, BufReader};

use crate::cli::{Failure, SimulateArgs};
use crate::sim::cnc::{Scenario, SimOptions, SimulatedCnc};
use crate::sources::pki;

/// Runs the simulator until interrupted. Commands on standard input:
/// `set ADDRESS 0|1`, `bad ADDRESS`, `quit`.
pub(crate) async fn cnc(args: &SimulateArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let sim = SimulatedCnc::start(&SimOptions {
        listen: args.listen,
        pki_dir: args.pki_dir.clone(),
        insecure: args.insecure,
    })
    .await
    .map_err(Failure::Runtime)?;
    for cert in &args.trust {
        pki::trust(cert, &args.pki_dir).map_err(Failure::Input)?;
    }
    let io = |e: std::io::Error| Failure::Runtime(e.to_string());
    writeln!(
        out,
        "simulated CNC on {} (tags in namespace {} as ns={};s=<address>)",
        sim.endpoint(),
        crate::sim::cnc::NAMESPACE,
        sim.namespace()
    )
    .map_err(io)?;
    writeln!(
        out,
        "server certificate: {} (trust it in the agent's pki/trusted/)",
        pki::own_cert(&args.pki_dir).display()
    )
    .map_err(io)?;
    writeln!(out, "commands: set ADDRESS 0|1, bad ADDRESS, quit").map_err(io)?;
    out.flush().map_err(io)?;
    let player = if args.scenario == "demo" {
        let s = sim.clone();
        Some(tokio::spawn(async move {
            Scenario::demo()
                .play(&s, |step| tracing::info!("{}", step.note))
                .await
        }))
    } else {
        None
    };
    let mut lines = BufReader::new(tokio::io::stdin()).lines();
    loop {
        tokio::select! {
            _ = tokio::signal::ctrl_c() => break,
            line = lines.next_line() => {
                let Ok(Some(line)) = line else {
                    // No (more) input: keep serving until interrupted.
                    tokio::signal::ctrl_c().await.ok();
                    break;
                };
                let words: Vec<&str> = line.split_whitespace().collect();
                let result = match words.as_slice() {
                    ["set", addr, v] => sim.set(addr, matches!(*v, "1" | "true" | "on")),
                    ["bad", addr] => sim.set_bad(addr),
                    ["quit"] => break,
                    [] => Ok(()),
                    _ => Err(format!("unknown command '{line}': set ADDRESS 0|1, bad ADDRESS, quit")),
                };
                match result {
                    Ok(()) => writeln!(out, "ok").map_err(io)?,
                    Err(e) => writeln!(out, "error: {e}").map_err(io)?,
                }
                out.flush().map_err(io)?;
            }
        }
    }
    if let Some(p) = player {
        p.abort();
    }
    sim.stop();
    Ok(())
}
