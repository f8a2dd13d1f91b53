//! `formation report`: builds the self-contained HTML report (Table I, Figs. 6-9, training and
//! latency when present) from eval and run output directories, with `formation-report`.

/// `formation report`.
pub fn report_command(args: &crate::args::ReportArgs) -> anyhow::Result<()> {
    let summary = formation_report::build_report(&args.dir, &args.out)?;
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
