//! `formation-report`: the HTML report of a formation-control evaluation.
//!
//! [`build_report`] searches a directory for the outputs of `formation eval --out` (a
//! `summary.json` per evaluation, optionally `runs/run-NNNN.json` run logs), training loss curves
//! (`*loss*.csv`) and latency profiles (`profile.json`), and writes one self-contained HTML file
//! with
//!
//! * Table I: success at 5 % and 10 % and the Fig. 9 medians, the paper's numbers beside ours
//!   (the paper has three robots: only a three-robot evaluation is compared with them, its team
//!   size taken from its run logs or its summary), with the input each policy was given as its model declares it (the occupancy window, its
//!   cells and whether they scale with d*, far hits, the LIDAR; also in each run's facts);
//! * Fig. 9: box plots of convergence time, relative formation error and orientation error over
//!   the runs that succeed at 10 %;
//! * for each run log (the paper's cases, Figs. 6-8): formation and orientation error over time,
//!   wheel commands, and the trajectories with the formation drawn every 3 s; for a team whose
//!   edges follow a neighbour graph, the median and worst edge error instead of one line per
//!   pair, and the graph of each snapshot (every 10 s); and a player of the run (the robots, their
//!   headings, the neighbour graph and its edge errors over time; [`player`]);
//! * the scaling over team sizes (`scaling*.json` from `formation eval --robots ...`): the table
//!   and success and convergence against the team size;
//! * reality ladders (`ladder*.json` from `formation eval --ladder PROFILE --json`): the table
//!   and success and convergence per rung, each controller and team size a line ([`ladder`]),
//!   so the reader sees which effect costs what;
//! * the training loss curve and the latency profile, when present.
//!
//! Every figure is also written as a standalone SVG file in `<out stem>-figures/` next to the
//! HTML file.
//!
//! Modules: [`input`] (finding and reading inputs), [`series`] and [`ladder`] (the plotted
//! numbers, pure),
//! [`figures`] (SVG drawing), [`player`] (the players' frames, pure), [`html`] (the page),
//! [`loss`] and [`profile`] (optional inputs).

pub mod error;
pub mod figures;
#[cfg(test)]
mod fixtures;
pub mod html;
pub mod input;
pub mod ladder;
pub mod loss;
pub mod player;
pub mod profile;
pub mod series;

use std::fs;
use std::path::{Path, PathBuf};

pub use error::ReportError;
use formation_proto::files::WriteError;

use figures::{BoxGroup, BoxPanel, Figure};
use html::{CaptionedFigure, PlacedFigure, ReportPage, RunSection, TableEntry, paper};
use input::{EvalData, Inputs, RunData, Trajectory};

/// What [`build_report`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct ReportSummary {
    /// The HTML file.
    pub html: PathBuf,
    /// The directory of the standalone SVG files.
    pub figures_dir: PathBuf,
    /// Every SVG file written, in page order.
    pub figures: Vec<PathBuf>,
    /// Evaluations found (`summary.json` files).
    pub evaluations: usize,
    /// Run logs drawn.
    pub runs_drawn: usize,
    /// Training loss curves drawn.
    pub loss_curves: usize,
    /// Latency profiles drawn.
    pub latency_profiles: usize,
    /// What the inputs lack (an eval output whose run logs are missing), for the command line to
    /// print; the page says it too.
    pub warnings: Vec<String>,
}

/// Builds the report from everything under `dir` and writes it to `out` (an HTML file), with the
/// figures as SVG files in `<out stem>-figures/` beside it (stale `.svg` files there are removed).
///
/// Errors: `dir` missing or not a directory; no `summary.json` under it; an input that cannot be
/// read or parsed (the error names the file); an output that cannot be written.
pub fn build_report(dir: &Path, out: &Path) -> Result<ReportSummary, ReportError> {
    check_output(out)?;
    let inputs = input::load_inputs(dir)?;
    let figures_dir = figures_dir_for(out);
    let href_dir = figures_dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let (page, figures) = assemble(&inputs, &href_dir)?;
    let html = html::render_page(&page);

    if let Some(parent) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
        formation_proto::files::create_private_dir_all(parent)
            .map_err(|e| WriteError::creating_dir(parent, e))?;
    }
    formation_proto::files::create_private_dir_all(&figures_dir)
        .map_err(|e| WriteError::creating_dir(&figures_dir, e))?;
    remove_stale_svgs(&figures_dir)?;
    let mut written = Vec::with_capacity(figures.len());
    for figure in &figures {
        let path = figures_dir.join(format!("{}.svg", figure.id));
        write_atomic(&path, figure.svg.as_bytes())?;
        written.push(path);
    }
    write_atomic(out, html.as_bytes())?;
    Ok(ReportSummary {
        html: out.to_path_buf(),
        figures_dir,
        figures: written,
        evaluations: inputs.evals.len(),
        runs_drawn: inputs.evals.iter().map(|e| e.runs.len()).sum(),
        loss_curves: inputs.loss_curves.len(),
        latency_profiles: inputs.profiles.len(),
        warnings: input_warnings(&inputs),
    })
}

/// The file name a fix suggests for the report.
const REPORT_EXAMPLE: &str = "report.html";

/// Refuses, before anything is read or written, an `out` that cannot take the page: a folder,
/// a path under a file, or a file the report reads (a summary, a run log, ...), which the page
/// would destroy.
pub fn check_output(out: &Path) -> Result<(), ReportError> {
    formation_proto::files::check_output_file_as(out, REPORT_EXAMPLE)?;
    if let Some(what) = input::input_kind(out) {
        return Err(ReportError::OutIsInput {
            out: out.to_path_buf(),
            what,
            example: out.with_file_name(REPORT_EXAMPLE),
        });
    }
    Ok(())
}

/// `report.html` → `report-figures/` in the same directory.
pub fn figures_dir_for(out: &Path) -> PathBuf {
    let stem = out
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "report".into());
    out.with_file_name(format!("{stem}-figures"))
}

/// Lays out the page and draws its figures (no I/O).
pub fn assemble(inputs: &Inputs, href_dir: &str) -> Result<(ReportPage, Vec<Figure>), ReportError> {
    let mut numbering = FigureNumbering {
        next: 1,
        href_dir: href_dir.to_owned(),
        figures: Vec::new(),
    };
    let mut page = ReportPage {
        source_dir: inputs.root.display().to_string(),
        ..ReportPage::default()
    };
    add_table_and_statistics(&mut page, inputs, &mut numbering)?;
    add_runs(&mut page, inputs, &mut numbering)?;
    let scaling_figures = numbering.captioned_per_input(
        &inputs.scalings,
        "scaling",
        "Success and convergence against team size",
        |id, scaling| figures::scaling_figure(id, &scaling.content),
        |scaling| scaling_caption(&scaling.content),
    )?;
    page.scaling = table_sections(&inputs.root, &inputs.scalings, scaling_figures);
    let ladder_figures = numbering.captioned_per_input(
        &inputs.ladders,
        "ladder",
        "Success and convergence per rung of a reality ladder",
        |id, ladder| figures::ladder_figure(id, &ladder.content),
        |ladder| ladder_caption(&ladder.content),
    )?;
    page.ladders = table_sections(&inputs.root, &inputs.ladders, ladder_figures);
    page.training = numbering.captioned_per_input(
        &inputs.loss_curves,
        "training-loss",
        "Training and validation loss per epoch",
        figures::loss_figure,
        |curve| loss_caption(&inputs.root, curve),
    )?;
    page.response = numbering.captioned_per_input(
        &inputs.responses,
        "response",
        "Slope of each controller's response against the expert's label",
        |id, response| figures::response_figure(id, &response.content),
        |response| response_caption(&inputs.root, response),
    )?;
    page.latency = numbering.captioned_per_input(
        &inputs.profiles,
        "latency",
        "Latency per runtime stage",
        |id, profile| figures::latency_figure(id, &profile.stages, profile.inference_paper_ms),
        |profile| latency_caption(&inputs.root, profile),
    )?;
    page.inputs = input_list(inputs);
    Ok((page, numbering.figures))
}

/// Table I's rows, and Fig. 9's box plots over the multi-run evaluations (over every evaluation
/// when none has more than one run).
fn add_table_and_statistics(
    page: &mut ReportPage,
    inputs: &Inputs,
    numbering: &mut FigureNumbering,
) -> Result<(), ReportError> {
    let mut table_evals: Vec<&EvalData> = inputs.evals.iter().collect();
    // Multi-run evaluations (Table I proper) first, then the single-run cases.
    table_evals.sort_by_key(|e| (e.table.runs <= 1, e.name.clone()));
    page.table = table_evals
        .iter()
        .map(|e| TableEntry {
            name: e.name.clone(),
            detail: eval_detail(e),
            row: e.table.clone(),
            robots: e.team_size(),
            incomplete: incomplete_note(e),
            partial: partial_note(e),
            medians: medians_note(e),
            model_inputs: e.model_inputs.iter().map(model_input_note).collect(),
        })
        .collect();

    let multi_run: Vec<&EvalData> = table_evals
        .iter()
        .copied()
        .filter(|e| e.table.runs > 1)
        .collect();
    let fig9_evals = if multi_run.is_empty() {
        table_evals.clone()
    } else {
        multi_run
    };
    if !table_evals.is_empty() {
        let panels = fig9_panels(&fig9_evals);
        let figure = figures::box_figure("fig9-statistics", &panels)?;
        page.fig9 = Some(numbering.captioned(
            figure,
            "Box plots of convergence time, formation error and orientation error",
            &format!(
                "Box plot of convergence time, relative formation error and orientation error over the last 20 s, over the runs that succeed at 10 % (cf. paper Fig. 9). The thick line is the median, the box spans the 25th to 75th percentiles, the whiskers extend to the minimum and maximum, dots are single runs{}.",
                if compares_with_paper(&fig9_evals) {
                    "; the dashed line is the paper's median (of three robots: it compares with the three-robot evaluations only)"
                } else {
                    ""
                }
            ),
        ));
        page.fig9_note = format!(
            "Evaluations: {}.{}",
            fig9_evals
                .iter()
                .map(|e| format!("{} ({} runs)", e.name, e.table.runs))
                .collect::<Vec<_>>()
                .join(", "),
            if fig9_evals.len() < table_evals.len() {
                " Single-run evaluations (the cases below) are left out of the statistics."
            } else {
                ""
            }
        );
    }
    Ok(())
}

/// One section per drawn run of every evaluation (Figs. 6-8), and notes on the runs not drawn.
fn add_runs(
    page: &mut ReportPage,
    inputs: &Inputs,
    numbering: &mut FigureNumbering,
) -> Result<(), ReportError> {
    for eval in &inputs.evals {
        for run in &eval.runs {
            page.runs.push(run_section(eval, run, numbering)?);
        }
        if eval.runs_not_drawn > 0 {
            page.run_notes.push(format!(
                "{}: {} more run logs are not drawn (the report draws the first {}).",
                eval.name,
                eval.runs_not_drawn,
                input::MAX_RUNS_PLOTTED_PER_EVAL
            ));
        }
    }
    if page.runs.is_empty() {
        page.run_notes.push(
            "No run logs were found (runs/run-NNNN.json next to a summary.json): run `formation eval --save-trajectories N --out DIR/...` to draw Figs. 6-8."
                .to_owned(),
        );
    }
    Ok(())
}

/// The caption of a scaling table's figure, after `Figure N: `.
fn scaling_caption(table: &formation_schema::ScalingTable) -> String {
    format!(
        "(a) success at 10 % (thick) and 5 % (thin) and (b) median convergence time at 10 % against the team size ({}, seed {}, {} s per run).",
        table.scenario, table.seed, table.duration_s
    )
}

/// The caption of a reality ladder's figure, after `Figure N: `.
fn ladder_caption(table: &formation_schema::LadderTable) -> String {
    format!(
        "the {} profile's reality ladder on {}: (a) success at 10 % (thick) and 5 % (thin) and (b) median convergence time at 10 % per rung, each rung adding its effect to those left of it ({} s per run, seed {}).",
        table.profile, table.scenario, table.duration_s, table.seed
    )
}

/// One section per table read from a file (a scaling table, a reality ladder), with its figure.
fn table_sections<T: Clone>(
    root: &Path,
    tables: &[input::SourcedFile<T>],
    figures: Vec<CaptionedFigure>,
) -> Vec<html::TableSection<T>> {
    tables
        .iter()
        .zip(figures)
        .map(|(table, figure)| html::TableSection {
            source: relative(root, &table.source),
            table: table.content.clone(),
            figure,
        })
        .collect()
}

/// The caption of a training loss curve's figure (cf. Fig. 5), after `Figure N: `.
fn loss_caption(root: &Path, curve: &loss::LossCurve) -> String {
    format!(
        "Training and validation loss over epochs, log scale (cf. paper Fig. 5), from {}.",
        relative(root, &curve.source)
    )
}

/// The caption of a response curve's figure, after `Figure N: `: each controller's slope
/// against the label's size.
fn response_caption(root: &Path, response: &input::ResponseData) -> String {
    let curve = &response.content;
    format!(
        "The response gauge (formation gauge): per bin of the expert's label size, the slope Σ p·l / Σ |l|² of each controller's formation velocity p against the expert's label l on the controller's own states (1: it moves as far as the expert asks; hollow marks: fewer than {} samples, not judged), {}, seed {}, {} s runs, every {} ticks, from {}.",
        formation_schema::MIN_JUDGED_SAMPLES,
        curve.scenario,
        curve.seed,
        formation_schema::trim_number(curve.duration_s),
        curve.stride,
        relative(root, &response.source)
    )
}

/// The caption of a latency profile's figure, after `Figure N: `.
fn latency_caption(root: &Path, profile: &profile::LatencyProfile) -> String {
    format!(
        "Latency per stage of the multi-process runtime, log scale: the box spans the median to the 90th percentile, the whisker reaches the 99th, the dot is the maximum{}, from {}.",
        profile_counts(profile),
        relative(root, &profile.source)
    )
}

/// Every input file, relative to the root: evaluations with their run logs, loss curves,
/// profiles, scaling tables.
fn input_list(inputs: &Inputs) -> Vec<String> {
    inputs
        .evals
        .iter()
        .flat_map(|e| std::iter::once(&e.source).chain(e.runs.iter().map(|r| &r.source)))
        .chain(inputs.loss_curves.iter().map(|c| &c.source))
        .chain(inputs.profiles.iter().map(|p| &p.source))
        .chain(inputs.scalings.iter().map(|s| &s.source))
        .chain(inputs.responses.iter().map(|r| &r.source))
        .chain(inputs.ladders.iter().map(|l| &l.source))
        .map(|path| relative(&inputs.root, path))
        .collect()
}

/// `; 3 runs, 1200 commands used, braked: late 3` from what a profile records.
fn profile_counts(profile: &profile::LatencyProfile) -> String {
    let mut parts = Vec::new();
    if let Some(runs) = profile.runs {
        parts.push(format!("{runs} runs"));
    }
    if let Some(used) = profile.used_commands {
        parts.push(format!("{used} commands used"));
    }
    if !profile.braked.is_empty() {
        let braked: Vec<String> = profile
            .braked
            .iter()
            .map(|(why, n)| format!("{why} {n}"))
            .collect();
        parts.push(format!("braked by the watchdog: {}", braked.join(", ")));
    }
    if parts.is_empty() {
        String::new()
    } else {
        format!("; {}", parts.join(", "))
    }
}

/// Hands out figure numbers and collects the figures in page order.
struct FigureNumbering {
    next: usize,
    href_dir: String,
    figures: Vec<Figure>,
}

impl FigureNumbering {
    fn take(&mut self) -> usize {
        self.next += 1;
        self.next - 1
    }

    /// Numbers and places `figure`, its caption `Figure N: ` followed by `text`.
    fn captioned(&mut self, figure: Figure, alt: &str, text: &str) -> CaptionedFigure {
        let number = self.take();
        CaptionedFigure {
            placed: self.place(figure, alt),
            caption: format!("Figure {number}: {text}"),
        }
    }

    /// One captioned figure per input, in order: input k's figure drawn by `draw` with the id
    /// `{id_prefix}-{k + 1}`, its caption's text (after `Figure N: `) by `text`.
    fn captioned_per_input<T>(
        &mut self,
        inputs: &[T],
        id_prefix: &str,
        alt: &str,
        draw: impl Fn(&str, &T) -> Result<Figure, ReportError>,
        text: impl Fn(&T) -> String,
    ) -> Result<Vec<CaptionedFigure>, ReportError> {
        let mut captioned = Vec::with_capacity(inputs.len());
        for (k, input) in inputs.iter().enumerate() {
            let figure = draw(&format!("{id_prefix}-{}", k + 1), input)?;
            captioned.push(self.captioned(figure, alt, &text(input)));
        }
        Ok(captioned)
    }

    fn place(&mut self, figure: Figure, alt: &str) -> PlacedFigure {
        self.figures.push(figure.clone());
        let href = if self.href_dir.is_empty() {
            format!("{}.svg", figure.id)
        } else {
            format!("{}/{}.svg", self.href_dir, figure.id)
        };
        PlacedFigure {
            figure,
            href,
            alt: alt.to_owned(),
        }
    }
}

/// `N of M runs incomplete (stopped early: reason)`, when some runs of `eval` stopped early.
pub fn incomplete_note(eval: &EvalData) -> Option<String> {
    let count = eval.incomplete.len().max(eval.table.runs_incomplete);
    if count == 0 {
        return None;
    }
    let mut reasons: Vec<&str> = Vec::new();
    for reason in eval
        .incomplete
        .iter()
        .filter_map(|i| i.stop_reason.as_deref())
    {
        if !reasons.contains(&reason) {
            reasons.push(reason);
        }
    }
    let runs = eval.table.runs.max(count);
    Some(format!(
        "{count} of {runs} run{} incomplete (stopped early{})",
        if runs == 1 { "" } else { "s" },
        if reasons.is_empty() {
            String::new()
        } else {
            format!(": {}", reasons.join("; "))
        }
    ))
}

/// `partial output: ... missing runs/run-0002.json, ...` when the writer of an eval output could
/// not write all of it (a full disk) or its run logs have gone since.
pub fn partial_note(eval: &EvalData) -> Option<String> {
    if eval.output_complete && eval.missing_run_logs.is_empty() {
        return None;
    }
    let mut note = String::from("partial output");
    if !eval.output_complete {
        note.push_str(
            ": the eval that wrote it could not write all its files (its summary.json says `complete: false`)",
        );
    }
    if !eval.missing_run_logs.is_empty() {
        let names: Vec<String> = eval
            .missing_run_logs
            .iter()
            .map(|p| p.display().to_string())
            .collect();
        note.push_str(&format!(
            "{} {} of the {} run logs its summary lists {} missing: {}",
            if eval.output_complete { ":" } else { ";" },
            names.len(),
            eval.expected_run_logs.len(),
            if names.len() == 1 { "is" } else { "are" },
            names.join(", ")
        ));
    }
    note.push_str("; re-run the eval to draw them");
    Some(note)
}

/// `convergence median over 3 of the 7 runs successful at 10 % (4 did not converge)` when a
/// median's rule leaves successful runs out.
pub fn medians_note(eval: &EvalData) -> Option<String> {
    let over = eval.table.medians_over.as_ref()?;
    let mut parts = Vec::new();
    for (what, coverage, why) in [
        (
            "the convergence median",
            &over.convergence_s,
            "did not converge: their largest edge error never stayed below 10 % to the end",
        ),
        (
            "the formation error median",
            &over.rel_formation_error,
            "have no value",
        ),
        (
            "the orientation error median",
            &over.orientation_error_rad,
            "have no value",
        ),
    ] {
        if coverage.runs < coverage.of {
            parts.push(format!(
                "{what} is over {} of the {} runs successful at 10 % ({} {why})",
                coverage.runs,
                coverage.of,
                coverage.of - coverage.runs
            ));
        }
    }
    (!parts.is_empty()).then(|| parts.join("; "))
}

/// Warnings about what the report's inputs lack (partial outputs), for the command line.
pub fn input_warnings(inputs: &Inputs) -> Vec<String> {
    inputs
        .evals
        .iter()
        .filter_map(|e| partial_note(e).map(|note| format!("{}: {note}", e.source.display())))
        .collect()
}

/// What a model was given, as its metadata declares it: `input of model m-1: 50 × 50 cells of
/// 0.1 m (a fixed 5 m window), far hits dropped; 900-beam 10 m LIDAR`.
pub fn model_input_note(input: &formation_schema::ModelInput) -> String {
    format!("input of model {}: {}", input.model, input.describe())
}

/// The input each of an evaluation's models was given, for a run's facts: the description
/// alone for one model, each prefixed by its id for several; `None` without any (the expert,
/// or a summary written before models recorded it).
fn model_inputs_fact(eval: &EvalData) -> Option<String> {
    match eval.model_inputs.as_slice() {
        [] => None,
        [one] => Some(one.describe()),
        many => Some(
            many.iter()
                .map(|input| format!("{}: {}", input.model, input.describe()))
                .collect::<Vec<_>>()
                .join("; "),
        ),
    }
}

fn eval_detail(eval: &EvalData) -> String {
    let mut parts = vec![if eval.controller.is_empty() {
        "?".to_owned()
    } else {
        eval.controller.clone()
    }];
    if !eval.scenario.is_empty() {
        parts.push(eval.scenario.clone());
    }
    if let Some(seed) = eval.seed {
        parts.push(format!("seed {seed}"));
    }
    if let Some(robots) = eval.team_size() {
        parts.push(format!("{robots} robots"));
    }
    parts.join(" · ")
}

/// Whether any of `evals` is a team of the paper's size, the only one compared with the paper.
fn compares_with_paper(evals: &[&EvalData]) -> bool {
    evals.iter().any(|e| e.team_size() == Some(paper::ROBOTS))
}

/// The three Fig. 9 panels, one box per evaluation, in the panels' units (s, %, rad); the
/// paper's medians only when some evaluation is a team of the paper's size.
pub fn fig9_panels(evals: &[&EvalData]) -> Vec<BoxPanel> {
    let paper_median = |value: f64| compares_with_paper(evals).then_some(value);
    let successful = |e: &EvalData| -> Vec<input::RunMetrics> {
        e.per_run.iter().filter(|r| r.success_10).cloned().collect()
    };
    let scaled = |q: Option<input::Quantiles>, factor: f64| {
        q.map(|q| input::Quantiles {
            min: q.min * factor,
            q1: q.q1 * factor,
            median: q.median * factor,
            q3: q.q3 * factor,
            max: q.max * factor,
            count: q.count,
        })
    };
    let mut convergence = Vec::new();
    let mut formation = Vec::new();
    let mut orientation = Vec::new();
    for eval in evals {
        let runs = successful(eval);
        let conv_dots: Vec<f64> = runs.iter().filter_map(|r| r.convergence_s_10).collect();
        let form_dots: Vec<f64> = runs.iter().map(|r| 100.0 * r.rel_formation_error).collect();
        let orient_dots: Vec<f64> = runs.iter().map(|r| r.orientation_error_rad).collect();
        convergence.push(BoxGroup {
            label: eval.name.clone(),
            stats: eval.table.convergence_s,
            dots: conv_dots,
        });
        formation.push(BoxGroup {
            label: eval.name.clone(),
            stats: scaled(eval.table.rel_formation_error, 100.0),
            dots: form_dots,
        });
        orientation.push(BoxGroup {
            label: eval.name.clone(),
            stats: eval.table.orientation_error_rad,
            dots: orient_dots,
        });
    }
    vec![
        BoxPanel {
            title: "convergence time".into(),
            y_desc: "convergence time [s]".into(),
            groups: convergence,
            paper_median: paper_median(paper::MEDIAN_CONVERGENCE_S),
        },
        BoxPanel {
            title: "relative formation error".into(),
            y_desc: "formation error [%]".into(),
            groups: formation,
            paper_median: paper_median(100.0 * paper::MEDIAN_REL_FORMATION_ERROR),
        },
        BoxPanel {
            title: "orientation error".into(),
            y_desc: "orientation error [rad]".into(),
            groups: orientation,
            paper_median: paper_median(paper::MEDIAN_ORIENTATION_ERROR_RAD),
        },
    ]
}

/// The paper's figure for the case a scenario reproduces, by its name.
fn paper_figure(scenario: &str) -> Option<&'static str> {
    match scenario {
        "case1" => Some("Fig. 6"),
        "case2" => Some("Fig. 7"),
        "case3" => Some("Fig. 8"),
        _ => None,
    }
}

/// A run's section (cf. Figs. 6-8): its three panels, its caption and its facts.
fn run_section(
    eval: &EvalData,
    run: &RunData,
    numbering: &mut FigureNumbering,
) -> Result<RunSection, ReportError> {
    let traj = &run.trajectory;
    let stem = format!("{}-run{}", sanitize(&eval.name), run.index);
    let number = numbering.take();
    let panels = run_panels(&stem, traj, numbering)?;
    let mut caption = run_caption(eval, run, number);
    let duration =
        traj.times.last().copied().unwrap_or(0.0) - traj.times.first().copied().unwrap_or(0.0);
    let mut facts = run_facts(eval, run, duration);
    if !run.complete {
        let planned = run
            .planned_ticks
            .map(|ticks| format!(" of {:.1} s", ticks as f64 * traj.dt))
            .unwrap_or_default();
        let reason = run
            .stop_reason
            .as_deref()
            .map(|r| format!(": {r}"))
            .unwrap_or_default();
        facts.insert(
            0,
            (
                "complete".to_owned(),
                format!("no, stopped early after {duration:.1} s{planned}{reason}"),
            ),
        );
        caption.push_str(&format!(
            " Incomplete run: it stopped early after {duration:.1} s{planned}{reason}; its metrics are over the ticks it played."
        ));
    }
    let player = player::player_data(traj);
    Ok(RunSection {
        heading: format!("{} · run {}", eval.name, run.index),
        anchor: format!("run-{stem}"),
        facts,
        panels,
        caption,
        incomplete: !run.complete,
        player_note: player_note(&player),
        // A run log without samples is refused when read; no frame, no player all the same.
        player_json: if player.frames.is_empty() {
            String::new()
        } else {
            player::player_json(&player)
        },
    })
}

/// What the player shows, and how often it samples the run.
fn player_note(player: &player::PlayerData) -> String {
    let every = if player.stride == 1 {
        "every recorded sample".to_owned()
    } else {
        format!(
            "every {} recorded sample ({} of {}; positions are interpolated between them)",
            ordinal(player.stride),
            player.frames.len(),
            player.samples
        )
    };
    format!(
        "Player: the {} robots (a triangle points along each heading, with the path of the last 10 s) and the formation's edges coloured by their error |dᵢⱼ − d*| / d*, from {every}. Space plays and pauses; the slider picks the time.",
        player.robots
    )
}

/// `2nd`, `3rd`, `4th`, ...
fn ordinal(n: usize) -> String {
    let suffix = match (n % 10, n % 100) {
        (_, 11..=13) => "th",
        (1, _) => "st",
        (2, _) => "nd",
        (3, _) => "rd",
        _ => "th",
    };
    format!("{n}{suffix}")
}

/// A run's panels: (a) the errors, (b) the wheel commands, (c) the trajectories.
fn run_panels(
    stem: &str,
    traj: &Trajectory,
    numbering: &mut FigureNumbering,
) -> Result<Vec<PlacedFigure>, ReportError> {
    Ok(vec![
        numbering.place(
            figures::errors_figure(&format!("{stem}-errors"), traj)?,
            "Formation and orientation error over time",
        ),
        numbering.place(
            figures::wheels_figure(&format!("{stem}-wheels"), traj)?,
            "Left and right wheel commands over time",
        ),
        numbering.place(
            figures::trajectory_figure(&format!("{stem}-trajectory"), traj)?,
            &format!(
                "Robot trajectories with the formation every {} s",
                figures::snapshot_every_s(traj)
            ),
        ),
    ])
}

/// The caption of a run's figure `number`, before any note on an incomplete run.
fn run_caption(eval: &EvalData, run: &RunData, number: usize) -> String {
    let traj = &run.trajectory;
    let team_note = if traj.neighbours == formation_proto::NeighbourRule::AllPairs {
        String::new()
    } else {
        format!(
            " The formation's edges follow the {} neighbour rule and change with the robots' \
             positions: (a) shows the median and the worst edge error over the edges of each \
             instant, (c) the neighbour graph of each snapshot.",
            traj.neighbours.name()
        )
    };
    let heading = heading_description(&traj.phi_star);
    let cf = paper_figure(&eval.scenario)
        .map(|f| format!(" (cf. paper {f})"))
        .unwrap_or_default();
    format!(
        "Figure {number}: {} run {}{cf} with {heading} and desired formation distance d* = {} m: (a) formation and orientation error; (b) robot control (left and right wheel); (c) robot trajectories, the triangles and dashed lines showing the robots and the formation every {} s.{team_note}",
        eval.name,
        run.index,
        figures::trim_number(traj.d_star),
        figures::snapshot_every_s(traj),
    )
}

/// A run's facts (label, value), before any note on an incomplete run; `duration` \[s\] is the
/// time it covers.
fn run_facts(eval: &EvalData, run: &RunData, duration: f64) -> Vec<(String, String)> {
    let traj = &run.trajectory;
    let yes_no = |b: bool| if b { "yes" } else { "no" }.to_owned();
    let mut facts = vec![
        (
            "scenario".to_owned(),
            if eval.scenario.is_empty() {
                "–".to_owned()
            } else {
                eval.scenario.clone()
            },
        ),
        ("controller".to_owned(), eval_detail(eval)),
        ("robots".to_owned(), traj.n_robots().to_string()),
        ("duration".to_owned(), format!("{duration:.1} s")),
        (
            "d*, v*".to_owned(),
            format!(
                "{} m, {} m/s",
                figures::trim_number(traj.d_star),
                figures::trim_number(traj.v_star)
            ),
        ),
        ("success at 5 %".to_owned(), yes_no(run.scores.success_5)),
        ("success at 10 %".to_owned(), yes_no(run.scores.success_10)),
        (
            "convergence (10 %)".to_owned(),
            html::or_dash(run.scores.convergence_s_10, |s| format!("{s:.2} s")),
        ),
        (
            "formation error, last 20 s".to_owned(),
            html::or_dash(Some(run.scores.rel_formation_error), |e| {
                format!("{:.2} %", 100.0 * e)
            }),
        ),
        (
            "orientation error, last 20 s".to_owned(),
            html::or_dash(Some(run.scores.orientation_error_rad), |r| {
                format!("{r:.3} rad")
            }),
        ),
        ("collisions".to_owned(), run.scores.collisions.to_string()),
    ];
    if let Some(input) = model_inputs_fact(eval) {
        // After the controller: what the policy was given.
        facts.insert(2, ("policy input".to_owned(), input));
    }
    facts
}

/// `constant desired orientation φ* = 3.76 rad` or `time-varying desired orientation φ*(t) from
/// a to b rad`.
pub fn heading_description(phi_star: &[f64]) -> String {
    let finite: Vec<f64> = phi_star.iter().copied().filter(|p| p.is_finite()).collect();
    let (lo, hi) = finite
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    if finite.is_empty() {
        "no recorded desired orientation".to_owned()
    } else if hi - lo < 1e-9 {
        format!(
            "constant desired orientation φ* = {} rad",
            figures::trim_number(lo)
        )
    } else {
        format!(
            "time-varying desired orientation φ*(t) between {} and {} rad",
            figures::trim_number(lo),
            figures::trim_number(hi)
        )
    }
}

/// A figure id from a directory name: path separators and anything unusual become `-`.
fn sanitize(name: &str) -> String {
    let cleaned: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' || c == '-' {
                c
            } else {
                '-'
            }
        })
        .collect();
    let trimmed = cleaned.trim_matches('-');
    if trimmed.is_empty() {
        "eval".to_owned()
    } else {
        trimmed.to_owned()
    }
}

fn relative(root: &Path, path: &Path) -> String {
    path.strip_prefix(root)
        .unwrap_or(path)
        .display()
        .to_string()
}

fn remove_stale_svgs(dir: &Path) -> Result<(), ReportError> {
    let read_error = |source| ReportError::Read {
        path: dir.to_path_buf(),
        source,
    };
    for entry in fs::read_dir(dir).map_err(read_error)? {
        let path = entry.map_err(read_error)?.path();
        if path.extension().is_some_and(|e| e == "svg") {
            fs::remove_file(&path).map_err(|source| ReportError::Write {
                path: path.clone(),
                source,
            })?;
        }
    }
    Ok(())
}

/// Writes `bytes` to `path` atomically ([`formation_proto::files::write_atomic`]).
fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), ReportError> {
    formation_proto::files::write_atomic(path, bytes).map_err(|e| WriteError::new(path, e).into())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn figure_dir_and_ids() {
        assert_eq!(
            figures_dir_for(Path::new("out/report.html")),
            Path::new("out/report-figures")
        );
        assert_eq!(figures_dir_for(Path::new("r.html")), Path::new("r-figures"));
        assert_eq!(sanitize("demo/case 1"), "demo-case-1");
        assert_eq!(sanitize("."), "eval");
    }

    #[test]
    fn heading_descriptions() {
        assert_eq!(
            heading_description(&[3.76, 3.76]),
            "constant desired orientation φ* = 3.76 rad"
        );
        assert_eq!(
            heading_description(&[0.0, 0.5, f64::NAN]),
            "time-varying desired orientation φ*(t) between 0 and 0.5 rad"
        );
        assert_eq!(heading_description(&[]), "no recorded desired orientation");
    }
}
