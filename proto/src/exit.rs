//! The exit codes of formation's three binaries (`formation`, `formation-world`,
//! `formation-agent`), defined once: the guide's exit codes chapter (docs/src/exit-codes.md) lists
//! the same values.
//!
//! A termination signal gives the shell's convention, 128 + the signal's number: SIGINT (Ctrl-C)
//! 130, SIGTERM 143, so a supervisor (systemd, a CI runner, a shell script) tells a user's
//! Ctrl-C from a stop it asked for.

/// The signal that ended a process cleanly.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TerminationSignal {
    /// SIGINT (Ctrl-C).
    Interrupt,
    /// SIGTERM.
    Terminate,
}

impl TerminationSignal {
    /// The signal's POSIX number (2, 15).
    pub const fn number(self) -> i32 {
        match self {
            TerminationSignal::Interrupt => 2,
            TerminationSignal::Terminate => 15,
        }
    }

    /// The signal of POSIX number `number`, if it is SIGINT or SIGTERM.
    pub const fn from_number(number: i32) -> Option<TerminationSignal> {
        match number {
            2 => Some(TerminationSignal::Interrupt),
            15 => Some(TerminationSignal::Terminate),
            _ => None,
        }
    }

    /// `SIGINT` or `SIGTERM`.
    pub const fn name(self) -> &'static str {
        match self {
            TerminationSignal::Interrupt => "SIGINT",
            TerminationSignal::Terminate => "SIGTERM",
        }
    }
}

impl std::fmt::Display for TerminationSignal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// How a binary of formation ends. Every exit code any of them returns is one of these.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ProcessExit {
    /// 0: the work was done (`formation`: the command succeeded, runs completed even if a link was
    /// degraded; `formation-world`: every run was played; `formation-agent`: the world asked it
    /// to shut down, or it left because its world or launcher went away, saying so).
    Success,
    /// 1: the work was done and found a difference (`formation replay`: a replayed command
    /// differs from the recorded one), as `diff` and `cmp` say so; the report says where.
    Diverged,
    /// 2: an error, reported on stderr (bad flags or files, a failed launch, a run that ended
    /// with a robot that lost its agent for good, an agent refused by the world).
    Failure,
    /// 130: stopped by SIGINT (Ctrl-C); for `formation-world` also when its launcher closed its
    /// input (`--exit-on-stdin-close`) before its runs were done.
    Interrupted,
    /// 143: stopped by SIGTERM.
    Terminated,
}

impl ProcessExit {
    /// The exit code.
    pub const fn code(self) -> u8 {
        match self {
            ProcessExit::Success => 0,
            ProcessExit::Diverged => 1,
            ProcessExit::Failure => 2,
            ProcessExit::Interrupted => 130,
            ProcessExit::Terminated => 143,
        }
    }

    /// The exit of a process that `signal` stopped.
    pub const fn stopped_by(signal: TerminationSignal) -> ProcessExit {
        match signal {
            TerminationSignal::Interrupt => ProcessExit::Interrupted,
            TerminationSignal::Terminate => ProcessExit::Terminated,
        }
    }
}

impl From<ProcessExit> for std::process::ExitCode {
    fn from(exit: ProcessExit) -> std::process::ExitCode {
        std::process::ExitCode::from(exit.code())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_signal_gives_128_plus_its_number() {
        for signal in [TerminationSignal::Interrupt, TerminationSignal::Terminate] {
            assert_eq!(
                i32::from(ProcessExit::stopped_by(signal).code()),
                128 + signal.number()
            );
            assert_eq!(
                TerminationSignal::from_number(signal.number()),
                Some(signal)
            );
        }
        assert_eq!(
            ProcessExit::stopped_by(TerminationSignal::Interrupt).code(),
            130
        );
        assert_eq!(
            ProcessExit::stopped_by(TerminationSignal::Terminate).code(),
            143
        );
        assert_eq!(TerminationSignal::from_number(1), None);
        assert_eq!(ProcessExit::Success.code(), 0);
        assert_eq!(ProcessExit::Diverged.code(), 1);
        assert_eq!(ProcessExit::Failure.code(), 2);
    }
}
