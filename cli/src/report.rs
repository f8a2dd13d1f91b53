//! `formation report`: builds the self-contained HTML report (Table I, Figs. 6-9, training and
//! latency when present) from eval and run output directories, with `formation-report`.
//!
//! It first recovers what abnormally ended launches left: run journals whose world and launcher
//! were both killed become incomplete run logs, and a run directory without a `summary.json` gets
//! one, so those runs appear in the report marked incomplete (said on stderr).

/// `formation report`.
pub fn report_command(args: &crate::args::ReportArgs) -> anyhow::Result<()> {
    // Before the recovery below writes anything: an --out the page cannot take is refused.
    formation_report::check_output(&args.out)?;
    if args.dir.is_dir() {
        crate::launch::recover_run_dirs(&args.dir);
    }
    let summary = formation_report::build_report(&args.dir, &args.out)?;
    for warning in &summary.warnings {
        eprintln!("formation: warning: {warning}");
    }
    println!(
        "wrote {} ({} evaluations, {} runs drawn, {} figures in {})",
        summary.html.display(),
        summary.evaluations,
        summary.runs_drawn,
        summary.figures.len(),
        summary.figures_dir.display()
    );
    Ok(())
}
