//! `formation`: the command-line entry point. It only maps errors to messages and exit codes;
//! everything else lives in the `formation` library.

use std::process::ExitCode;

fn main() -> ExitCode {
    match formation::main_with_args() {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!(
                "error: {}",
                formation_proto::errors::chain_text(err.as_ref())
            );
            ExitCode::from(2)
        }
    }
}
