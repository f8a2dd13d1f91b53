//! `formation report` (placeholder until the report lands).

/// `formation report`.
pub fn report_command(_args: &crate::args::ReportArgs) -> anyhow::Result<()> {
    anyhow::bail!("not yet available")
}
