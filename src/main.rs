//! The `pygmalion` command line (see `pygmalion --help` and the README).

use std::process::ExitCode;

fn main() -> ExitCode {
    match pygmalion::cli::run(std::env::args_os()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("pygmalion: error: {e}");
            ExitCode::FAILURE
        }
    }
}
