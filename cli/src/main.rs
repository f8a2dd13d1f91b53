//! `formation`: the command-line entry point. It only maps errors to messages and exit codes
//! ([`formation_proto::exit::ProcessExit`], through [`formation_cli::exit_for_error`]); everything
//! else lives in the `formation` library.

use std::process::ExitCode;

use formation_proto::exit::ProcessExit;

fn main() -> ExitCode {
    // First, before any thread: ONNX Runtime then writes nothing outside the run's folders, here
    // and in the processes the command starts.
    formation_onnx::disable_telemetry_before_threads();
    let exit = match formation_cli::main_with_args() {
        Ok(()) => ProcessExit::Success,
        Err(err) => {
            eprintln!(
                "error: {}",
                formation_proto::errors::chain_text(err.as_ref())
            );
            formation_cli::exit_for_error(&err)
        }
    };
    exit.into()
}
