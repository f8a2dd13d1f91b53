//! `formation demo`: the README's main job. Runs the paper's three cases and the Table I
//! evaluation with the shipped model, every robot in its own OS process over iceoryx2 (or
//! in-process with `--in-process`), then writes the HTML report and prints its path. With
//! `--record FILE.mcap` case 1 is recorded; with `--foxglove HOST:PORT` the three cases are
//! served live to Foxglove ([`formation_world_node::live_view`]), one world after another on that address.

use std::path::Path;

use anyhow::Context;

use crate::args::{ControllerKind, DemoArgs, EvalArgs};
use crate::{eval, paths};

/// The paper's cases and where their scenarios live, relative to the repository root.
const CASES: [&str; 3] = ["case1", "case2", "case3"];

/// The case `--record` records.
const RECORDED_CASE: &str = "case1";

/// `formation demo`.
pub fn demo_command(args: &DemoArgs) -> anyhow::Result<()> {
    let root = paths::repo_root();
    let model = paths::resolve_model(args.model.as_deref())?;
    if let Some(file) = &args.record {
        formation_record::RecordTarget::File(file.clone()).check()?;
    }
    let foxglove =
        formation_world_node::live_view::requested(args.foxglove.as_deref(), "formation", true)?;
    formation_proto::files::create_private_dir_all(&args.out)
        .map_err(|e| paths::WriteError::creating_dir(&args.out, e))?;
    let mode = if args.in_process {
        "in-process"
    } else {
        "one process per robot"
    };
    println!("formation demo: model {} ({mode})", model.display());
    for case in CASES {
        let record = args.record.as_deref().filter(|_| case == RECORDED_CASE);
        let (out, _) = run_eval(
            args,
            &root.join(format!("scenarios/{case}.toml")),
            &model,
            (1, case),
            (record, foxglove),
        )?;
        let s = &out.summary;
        println!(
            "{case}: {} at 5 %, convergence {}",
            if s.success_rate_5 > 0.5 {
                "converged"
            } else {
                "did NOT converge"
            },
            s.median_convergence_s
                .map(|c| format!("{c:.1} s"))
                .unwrap_or_else(|| "-".into())
        );
    }
    let (table, _) = run_eval(
        args,
        &root.join("scenarios/table1.toml"),
        &model,
        (args.runs, "table1"),
        (None, None),
    )?;
    print!("{}", crate::table::table_text(&table));
    copy_training_curve(&model, &args.out)?;
    let html = args.out.join("report.html");
    formation_report::build_report(&args.out, &html)
        .with_context(|| format!("writing the report {}", html.display()))?;
    println!("report: {}", html.display());
    Ok(())
}

fn run_eval(
    args: &DemoArgs,
    scenario: &Path,
    model: &Path,
    (runs, name): (usize, &str),
    (record, foxglove): (Option<&Path>, Option<std::net::SocketAddr>),
) -> anyhow::Result<(eval::EvalOutput, Vec<eval::RunResult>)> {
    let dir = args.out.join(name);
    let eval_args = EvalArgs {
        scenario: scenario.to_path_buf(),
        controller: ControllerKind::Policy,
        model: Some(model.to_path_buf()),
        runs: Some(runs),
        seed: None,
        json: None,
        out: Some(dir.clone()),
        save_trajectories: None,
        processes: !args.in_process,
        transport: Default::default(),
        listen: None,
        threads: None,
        robots: None,
        record: None,
        record_runs: None,
        record_file: record.map(Path::to_path_buf),
        foxglove,
        first_run: None,
        shard: None,
        ladder: None,
        gains: None,
    };
    let (out, results) =
        eval::evaluate(&eval_args).with_context(|| format!("evaluating {name}"))?;
    eval::write_eval_dir(&dir, &out, &results)?;
    Ok((out, results))
}

/// Copies the model's training loss curve (written beside it by the trainer) into the report
/// directory, when there is one.
fn copy_training_curve(model: &Path, out: &Path) -> anyhow::Result<()> {
    let Some(dir) = model.parent() else {
        return Ok(());
    };
    let stem = model
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Ok(());
    };
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.starts_with(&stem) && name.ends_with(".csv") && name.contains("loss") {
            std::fs::copy(entry.path(), out.join(&name))
                .with_context(|| format!("copying {}", entry.path().display()))?;
        }
    }
    Ok(())
}
