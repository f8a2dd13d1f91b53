//! The formation command-line tool: collect, train, dagger, eval, run, profile, swap, report.
