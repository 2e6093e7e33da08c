//! The `pygmalion` command line (see `pygmalion --help` and the README).

use std::process::ExitCode;

fn main() -> ExitCode {
    // Rust ignores SIGPIPE, so printing into a closed pipe (`pygmalion info X | head -1`) would
    // panic in `println!`. Restore the default: the command ends quietly, like other tools.
    #[cfg(unix)]
    // SAFETY: setting a signal's disposition to the default before any other thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    match pygmalion::cli::run(std::env::args_os()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("pygmalion: error: {e}");
            ExitCode::FAILURE
        }
    }
}
