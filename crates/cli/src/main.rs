//! `actrack-cli`: the command-line interface of actrack.

use std::process::ExitCode;

fn main() -> ExitCode {
    eprintln!("actrack-cli: no commands are implemented yet (see the project's open issues)");
    ExitCode::from(1)
}
