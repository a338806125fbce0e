//! The `cellwatch` binary: parses the command line and runs a command.
//! Exit status: 0 success, 1 runtime failure, 2 bad input.

use std::process::ExitCode;

/// jemalloc, configured in `.cargo/config.toml` to give freed pages back to
/// the system at once: what reading a large configuration or a burst of
/// changes took is returned, where glibc's allocator keeps most of it.
#[global_allocator]
static ALLOCATOR: tikv_jemallocator::Jemalloc = tikv_jemallocator::Jemalloc;

fn main() -> ExitCode {
    // Unlocked handles: each write locks briefly, so log lines from other
    // threads are never blocked behind the command's output.
    let code = cellwatch::cli::run(
        std::env::args_os(),
        &mut std::io::stdout(),
        &mut std::io::stderr(),
    );
    ExitCode::from(code)
}
