//! The `cellwatch` binary: parses the command line and runs a command.
//! Exit status: 0 success, 1 runtime failure, 2 bad input.

use std::process::ExitCode;

fn main() -> ExitCode {
    let stdout = std::io::stdout();
    let stderr = std::io::stderr();
    let code = cellwatch::cli::run(std::env::args_os(), &mut stdout.lock(), &mut stderr.lock());
    ExitCode::from(code)
}
