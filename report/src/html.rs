//! The report page: one self-contained HTML document (inline CSS, inline SVG, two small inline
//! scripts, a Content-Security-Policy that forbids loading anything) laid out like the paper's
//! results section: Table I, Fig. 9, the case runs (Figs. 6-8), training and latency.
//!
//! The first inline script only inspects the page: on load it checks that every figure's SVG has
//! a non-empty box and drawn elements and records the count in `data-figures-ok` on `<body>` (and
//! in the console), and counts the tables wider than their box (`data-tables-clipped`), which the
//! browser test reads back. The second (`player.js`) plays each run's recorded frames on a
//! `<canvas>` ([`crate::player`]).

use std::fmt::Write as _;

use crate::figures::Figure;
use crate::input::Summary;

/// The paper's Table I and Fig. 9 medians, shown beside ours.
pub mod paper {
    /// Success rate at the 5 % tolerance.
    pub const SUCCESS_RATE_5: f64 = 0.90;
    /// Success rate at the 10 % tolerance.
    pub const SUCCESS_RATE_10: f64 = 0.96;
    /// Median convergence time \[s\] ("about 10 s").
    pub const MEDIAN_CONVERGENCE_S: f64 = 10.0;
    /// Median relative formation error (fraction).
    pub const MEDIAN_REL_FORMATION_ERROR: f64 = 0.025;
    /// Median orientation error \[rad\].
    pub const MEDIAN_ORIENTATION_ERROR_RAD: f64 = 0.031;
    /// Runs in Table I.
    pub const RUNS: usize = 100;
    /// The team size of every figure above: the paper evaluates three robots only.
    pub const ROBOTS: usize = 3;
}

/// A figure placed on the page: its SVG inline and the file it is also written to.
#[derive(Debug, Clone)]
pub struct PlacedFigure {
    /// The figure.
    pub figure: Figure,
    /// Link to the standalone SVG file, relative to the HTML file.
    pub href: String,
    /// A short description for screen readers.
    pub alt: String,
}

/// A figure with a numbered caption.
#[derive(Debug, Clone)]
pub struct CaptionedFigure {
    /// The figure.
    pub placed: PlacedFigure,
    /// The caption, starting with `Figure N:` (plain text, escaped when written).
    pub caption: String,
}

/// A table read from a file (a scaling table, a reality ladder): the table and its figure.
#[derive(Debug, Clone)]
pub struct TableSection<T> {
    /// Where it came from, relative to the input directory.
    pub source: String,
    /// The table as written.
    pub table: T,
    /// Success and convergence against the team size, or per rung.
    pub figure: CaptionedFigure,
}

/// One scaling table: its rows and its figure.
pub type ScalingSection = TableSection<formation_schema::ScalingTable>;

/// One reality ladder: its rungs and its figure.
pub type LadderSection = TableSection<formation_schema::LadderTable>;

/// One case run: three panels and a fact sheet.
#[derive(Debug, Clone)]
pub struct RunSection {
    /// Heading (`case1 · run 0`).
    pub heading: String,
    /// Anchor id.
    pub anchor: String,
    /// Label / value pairs shown beside the trajectories.
    pub facts: Vec<(String, String)>,
    /// Panels (a) errors, (b) wheel commands, (c) trajectories.
    pub panels: Vec<PlacedFigure>,
    /// The caption of the three panels together.
    pub caption: String,
    /// True when the run stopped before its last tick.
    pub incomplete: bool,
    /// What the player shows and how it samples the run (plain text).
    pub player_note: String,
    /// The player's frames ([`crate::player::player_json`]); empty for no player.
    pub player_json: String,
}

/// One Table I row of ours.
#[derive(Debug, Clone)]
pub struct TableEntry {
    /// Evaluation name (its directory).
    pub name: String,
    /// Controller and scenario, for the second column.
    pub detail: String,
    /// The numbers.
    pub row: Summary,
    /// The team size, when the run logs or the summary say: only a team of
    /// [`paper::ROBOTS`] is compared with the paper.
    pub robots: Option<usize>,
    /// `N of M runs incomplete (stopped early: reason)` when some runs stopped early.
    pub incomplete: Option<String>,
    /// The output is partial: what is missing.
    pub partial: Option<String>,
    /// Which runs a median covers, when its rule leaves some successful runs out.
    pub medians: Option<String>,
    /// What each model was given (`input of model m-1: 50 × 50 cells ...`), policy only.
    pub model_inputs: Vec<String>,
}

/// Everything on the page.
#[derive(Debug, Clone, Default)]
pub struct ReportPage {
    /// The input directory, as shown.
    pub source_dir: String,
    /// Table I rows.
    pub table: Vec<TableEntry>,
    /// Fig. 9.
    pub fig9: Option<CaptionedFigure>,
    /// Remarks under Fig. 9 (which evaluations it covers).
    pub fig9_note: String,
    /// Case runs.
    pub runs: Vec<RunSection>,
    /// Remarks under the case runs (run logs not drawn, evaluations without run logs).
    pub run_notes: Vec<String>,
    /// Training loss curves.
    pub training: Vec<CaptionedFigure>,
    /// Response curves (`formation gauge`).
    pub response: Vec<CaptionedFigure>,
    /// Latency profiles.
    pub latency: Vec<CaptionedFigure>,
    /// Scaling tables over team sizes.
    pub scaling: Vec<ScalingSection>,
    /// Reality ladders.
    pub ladders: Vec<LadderSection>,
    /// Input files, relative to the input directory.
    pub inputs: Vec<String>,
}

/// Escapes text for HTML element content and attribute values.
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// A fraction as a percentage with one decimal (`0.9` → `90.0 %`).
pub fn percent(fraction: f64) -> String {
    format!("{:.1} %", 100.0 * fraction)
}

/// An optional value, or an en dash.
pub fn or_dash(value: Option<f64>, format: impl Fn(f64) -> String) -> String {
    value
        .filter(|v| v.is_finite())
        .map(format)
        .unwrap_or_else(|| "–".to_owned())
}

const STYLE: &str = r#"
:root { --ink: #1d2327; --muted: #5f6b73; --rule: #dfe3e6; --accent: #2b5f9e; --paper: #c0392b; --bg: #f6f7f8; }
* { box-sizing: border-box; }
html { -webkit-text-size-adjust: 100%; }
body { margin: 0; background: var(--bg); color: var(--ink);
  font: 16px/1.55 system-ui, -apple-system, "Segoe UI", Roboto, "Helvetica Neue", Arial, sans-serif; }
header { background: #fff; border-bottom: 1px solid var(--rule); }
header .wrap { padding: 28px 32px 18px; }
.wrap { max-width: 1240px; margin: 0 auto; padding: 0 32px; }
h1 { font-size: 1.75rem; margin: 0 0 4px; letter-spacing: -0.01em; }
h2 { font-size: 1.3rem; margin: 40px 0 12px; padding-bottom: 6px; border-bottom: 1px solid var(--rule); }
h3 { font-size: 1.08rem; margin: 0 0 12px; }
.subtitle { margin: 0; color: var(--muted); }
nav { margin-top: 14px; font-size: 0.92rem; }
nav a { color: var(--accent); text-decoration: none; margin-right: 18px; }
nav a:hover { text-decoration: underline; }
code { font-family: ui-monospace, SFMono-Regular, Menlo, Consolas, monospace; font-size: 0.88em;
  background: #eef1f3; padding: 1px 5px; border-radius: 3px; }
.card { background: #fff; border: 1px solid var(--rule); border-radius: 6px; padding: 20px 22px; margin: 0 0 20px; }
table.results { border-collapse: collapse; width: 100%; font-size: 0.94rem; font-variant-numeric: tabular-nums; }
table.results th, table.results td { padding: 7px 10px; border-bottom: 1px solid var(--rule); text-align: right; white-space: nowrap; }
table.results th:first-child, table.results td:first-child { text-align: left; }
table.results thead th { font-weight: 600; color: var(--muted); font-size: 0.84rem; text-transform: uppercase; letter-spacing: 0.03em; border-bottom: 2px solid var(--ink); vertical-align: bottom; white-space: normal; }
table.results tr.paper td { color: var(--paper); font-style: italic; background: #fdf6f5; }
table.results .detail { color: var(--muted); font-size: 0.82rem; font-style: normal; }
table.results .detail code { word-break: break-all; white-space: normal; }
.table-scroll { overflow-x: auto; }
figure { margin: 0; }
figure.plot { background: #fff; }
figure.plot svg { display: block; width: 100%; height: auto; }
.card > figure.plot svg { width: auto; max-width: 100%; margin: 0 auto; }
figcaption, .caption { font-size: 0.9rem; color: var(--muted); margin-top: 8px; }
figcaption b, .caption b { color: var(--ink); }
.svg-link { font-size: 0.8rem; color: var(--accent); text-decoration: none; }
figure.plot > .svg-link { display: block; text-align: right; margin-top: 2px; }
.panels { display: grid; grid-template-columns: 1fr 1fr; gap: 18px 22px; align-items: start; }
dl.facts { display: grid; grid-template-columns: max-content 1fr; gap: 6px 16px; margin: 0; font-size: 0.93rem; font-variant-numeric: tabular-nums; }
dl.facts dt { color: var(--muted); }
dl.facts dd { margin: 0; }
.note { font-size: 0.9rem; color: var(--muted); }
.ok { color: #1e7b34; font-weight: 600; }
.fail { color: var(--paper); font-weight: 600; }
.incomplete { color: var(--paper); font-weight: 600; font-size: 0.82rem; white-space: normal; }
.badge { display: inline-block; margin-left: 8px; padding: 0 6px; border: 1px solid var(--paper); border-radius: 3px; color: var(--paper); font-size: 0.75rem; font-weight: 600; vertical-align: middle; text-transform: uppercase; letter-spacing: 0.04em; }
footer { color: var(--muted); font-size: 0.85rem; padding: 24px 32px 40px; text-align: center; }
ul.inputs { columns: 2; font-size: 0.88rem; }
figure.player { margin: 18px 0 0; padding-top: 14px; border-top: 1px solid var(--rule); outline: none; }
figure.player canvas { display: block; width: 100%; height: 440px; border: 1px solid var(--rule); border-radius: 4px; background: #fff; }
.player-controls { display: flex; align-items: center; gap: 12px; margin-top: 8px; font-size: 0.9rem; }
.player-controls button { min-width: 5em; font: inherit; padding: 3px 10px; }
.player-controls input[type=range] { flex: 1; }
.player-clock { min-width: 21em; font-variant-numeric: tabular-nums; color: var(--muted); }
.player-scale { display: inline-block; width: 110px; height: 9px; vertical-align: middle; border-radius: 2px;
  background: linear-gradient(to right, hsl(130,75%,40%), hsl(65,75%,40%), hsl(0,75%,40%)); }
@media (max-width: 900px) { .panels { grid-template-columns: 1fr; } ul.inputs { columns: 1; } .wrap { padding: 0 14px; } }
@media print { body { background: #fff; } .card { border: none; padding: 0; } nav, .svg-link { display: none; } }
"#;

/// Runs in `<head>`: records page errors and blocked loads in `data-page-errors` on `<html>`, and
/// once the document is parsed checks every figure and records the result on `<body>` (and in the
/// console), for the browser test.
const CHECK_SCRIPT: &str = r#"
(function () {
  var problems = [];
  function record(problem) {
    problems.push(problem);
    document.documentElement.setAttribute('data-page-errors', problems.join(' | '));
  }
  window.addEventListener('error', function (event) {
    record('error: ' + (event.message || (event.target && event.target.outerHTML) || 'unknown'));
  }, true);
  document.addEventListener('securitypolicyviolation', function (event) {
    record('blocked: ' + event.blockedURI);
  });
  function check() {
    var figures = document.querySelectorAll('figure.plot');
    var ok = 0, bad = [];
    figures.forEach(function (figure) {
      var svg = figure.querySelector('svg');
      var box = svg ? svg.getBoundingClientRect() : null;
      var inner = svg ? svg.getBBox() : null;
      var drawn = svg ? svg.querySelectorAll('polyline, polygon, rect, circle, line').length : 0;
      if (box && box.width > 0 && box.height > 0 && inner.width > 0 && inner.height > 0 && drawn > 1) {
        ok += 1;
      } else {
        bad.push(figure.getAttribute('data-figure'));
      }
    });
    document.body.setAttribute('data-figures-total', String(figures.length));
    document.body.setAttribute('data-figures-ok', String(ok));
    document.body.setAttribute('data-figures-bad', bad.join(' '));
    var clipped = [];
    document.querySelectorAll('.table-scroll').forEach(function (box, k) {
      if (box.scrollWidth > box.clientWidth + 1) { clipped.push(k + ':' + box.scrollWidth + '>' + box.clientWidth); }
    });
    document.body.setAttribute('data-tables-clipped', clipped.length ? clipped.join(' ') : 'none');
    console.log('formation-report: ' + ok + '/' + figures.length + ' figures drawn');
  }
  document.addEventListener('DOMContentLoaded', check);
})();
"#;

/// Plays the runs' frames (see the module documentation of [`crate::player`]).
const PLAYER_SCRIPT: &str = include_str!("player.js");

/// Renders the page.
pub fn render_page(page: &ReportPage) -> String {
    let mut html = String::with_capacity(1 << 20);
    write_head(&mut html, page, &nav_sections(page));
    write_table(&mut html, page);
    if let Some(fig9) = &page.fig9 {
        write_fig9(&mut html, page, fig9);
    }
    if !page.runs.is_empty() || !page.run_notes.is_empty() {
        write_runs(&mut html, page);
    }
    write_table_sections(
        &mut html,
        "scaling",
        "Scaling over team sizes",
        &page.scaling,
        write_scaling,
    );
    write_table_sections(
        &mut html,
        "ladder",
        "Reality ladders",
        &page.ladders,
        write_ladder,
    );
    write_figure_sections(&mut html, page);
    write_inputs_and_footer(&mut html, page);
    html
}

/// The navigation's (anchor, title) of every section the page has.
fn nav_sections(page: &ReportPage) -> Vec<(&'static str, &'static str)> {
    let mut sections: Vec<(&str, &str)> = vec![("table-1", "Table I")];
    if page.fig9.is_some() {
        sections.push(("fig-9", "Statistics"));
    }
    if !page.runs.is_empty() {
        sections.push(("runs", "Case runs"));
    }
    if !page.scaling.is_empty() {
        sections.push(("scaling", "Scaling"));
    }
    if !page.ladders.is_empty() {
        sections.push(("ladder", "Reality ladders"));
    }
    if !page.training.is_empty() {
        sections.push(("training", "Training"));
    }
    if !page.response.is_empty() {
        sections.push(("response", "Response"));
    }
    if !page.latency.is_empty() {
        sections.push(("latency", "Latency"));
    }
    sections.push(("inputs", "Inputs"));
    sections
}

/// The document's head (policy, check script, style) and the page header with its navigation,
/// up to the opening of `<main>`.
fn write_head(html: &mut String, page: &ReportPage, sections: &[(&str, &str)]) {
    html.push_str("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n");
    html.push_str("<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n");
    html.push_str(
        "<meta http-equiv=\"Content-Security-Policy\" content=\"default-src 'none'; style-src 'unsafe-inline'; script-src 'unsafe-inline'; img-src data:\">\n",
    );
    html.push_str("<title>Formation control report</title>\n<script>");
    html.push_str(CHECK_SCRIPT);
    html.push_str("</script>\n<script>");
    html.push_str(PLAYER_SCRIPT);
    html.push_str("</script>\n<style>");
    html.push_str(STYLE);
    html.push_str("</style>\n</head>\n<body>\n<header><div class=\"wrap\">\n");
    html.push_str("<h1>Decentralised formation control: evaluation report</h1>\n");
    let _ = writeln!(
        html,
        "<p class=\"subtitle\">Table I and Figs. 6–9 of <i>Learning Decentralized Control Policies for Multi-Robot Formation</i>, reproduced from the run data in <code>{}</code>.</p>",
        escape(&page.source_dir)
    );
    html.push_str("<nav>");
    for (anchor, title) in sections {
        let _ = write!(html, "<a href=\"#{anchor}\">{title}</a>");
    }
    html.push_str("</nav>\n</div></header>\n<main class=\"wrap\">\n");
}

/// The statistics section: Fig. 9 and its note.
fn write_fig9(html: &mut String, page: &ReportPage, fig9: &CaptionedFigure) {
    html.push_str("<section id=\"fig-9\">\n<h2>Statistics over successful runs (cf. paper Fig. 9)</h2>\n<div class=\"card\">\n");
    write_captioned(html, fig9);
    if !page.fig9_note.is_empty() {
        let _ = writeln!(html, "<p class=\"note\">{}</p>", escape(&page.fig9_note));
    }
    html.push_str("</div>\n</section>\n");
}

/// The case runs section: every run, then the notes on runs.
fn write_runs(html: &mut String, page: &ReportPage) {
    html.push_str("<section id=\"runs\">\n<h2>Case runs (cf. paper Figs. 6–8)</h2>\n");
    for run in &page.runs {
        write_run(html, run);
    }
    for note in &page.run_notes {
        let _ = writeln!(html, "<p class=\"note\">{}</p>", escape(note));
    }
    html.push_str("</section>\n");
}

/// A section of tables read from files (`anchor`, `title`), each written by `write`; nothing
/// when there are none.
fn write_table_sections<T>(
    html: &mut String,
    anchor: &str,
    title: &str,
    sections: &[TableSection<T>],
    write: fn(&mut String, &TableSection<T>),
) {
    if sections.is_empty() {
        return;
    }
    let _ = writeln!(html, "<section id=\"{anchor}\">\n<h2>{title}</h2>");
    for section in sections {
        write(html, section);
    }
    html.push_str("</section>\n");
}

/// The training and latency sections, each only when it has figures.
fn write_figure_sections(html: &mut String, page: &ReportPage) {
    for (anchor, title, figures) in [
        ("training", "Training (cf. paper Fig. 5)", &page.training),
        ("response", "Response to formation errors", &page.response),
        (
            "latency",
            "Latency profile (paper: 2.1 ms per inference)",
            &page.latency,
        ),
    ] {
        if figures.is_empty() {
            continue;
        }
        let _ = writeln!(
            html,
            "<section id=\"{anchor}\">\n<h2>{}</h2>",
            escape(title)
        );
        for figure in figures {
            html.push_str("<div class=\"card\">\n");
            write_captioned(html, figure);
            html.push_str("</div>\n");
        }
        html.push_str("</section>\n");
    }
}

/// The inputs section, the footer and the end of the document.
fn write_inputs_and_footer(html: &mut String, page: &ReportPage) {
    html.push_str("<section id=\"inputs\">\n<h2>Inputs</h2>\n<ul class=\"inputs\">\n");
    for input in &page.inputs {
        let _ = writeln!(html, "<li><code>{}</code></li>", escape(input));
    }
    html.push_str("</ul>\n</section>\n</main>\n");
    html.push_str(
        "<footer>Written by <code>formation report</code>. Self-contained: every figure is inline SVG and the page loads nothing else.</footer>\n",
    );
    html.push_str("</body>\n</html>\n");
}

/// The paper's success rates under a row's name: only a team of [`paper::ROBOTS`] is compared
/// with the paper; another team size says so, and an unknown one says nothing.
fn paper_note(robots: Option<usize>) -> String {
    match robots {
        Some(paper::ROBOTS) => format!(
            "<div class=\"detail\">paper: {} at 5 %, {} at 10 %</div>",
            percent_whole(paper::SUCCESS_RATE_5),
            percent_whole(paper::SUCCESS_RATE_10)
        ),
        Some(_) => format!(
            "<div class=\"detail\">paper: {} robots only</div>",
            paper::ROBOTS
        ),
        None => String::new(),
    }
}

/// A fraction as a whole percentage (`90 %`), as the paper prints it.
fn percent_whole(fraction: f64) -> String {
    format!("{:.0} %", 100.0 * fraction)
}

/// Opens a results table in a card (it scrolls sideways on a narrow page) with these column
/// heads, up to the first row; the caller closes it.
fn open_results_table(html: &mut String, heads: &[&str]) {
    html.push_str("<div class=\"card\">\n<div class=\"table-scroll\">\n<table class=\"results\">\n<thead><tr>");
    for head in heads {
        let _ = write!(html, "<th>{head}</th>");
    }
    html.push_str("</tr></thead>\n<tbody>\n");
}

/// The driver of a row: the controller, and the model id on a second line (on one line the
/// scaling table was wider than the page at 1300 px and its last column was clipped).
fn driver_cell(controller: &str, model: Option<&str>) -> String {
    match model {
        Some(id) => format!(
            "{}<div class=\"detail\"><code>{}</code></div>",
            escape(controller),
            escape(id)
        ),
        None => escape(controller),
    }
}

/// A median convergence time with its IQR on a second line; `–` where none converged.
fn convergence_cell(quantiles: Option<&crate::input::Quantiles>) -> String {
    quantiles.map_or_else(
        || "–".to_owned(),
        |q| {
            format!(
                "{:.1} s<div class=\"detail\">IQR {:.1}–{:.1}</div>",
                q.median, q.q1, q.q3
            )
        },
    )
}

fn write_table(html: &mut String, page: &ReportPage) {
    html.push_str(
        "<section id=\"table-1\">\n<h2>Table I: success rate (paper: over 100 runs)</h2>\n",
    );
    open_results_table(
        html,
        &[
            "Evaluation",
            "Runs",
            "Success at 5 %",
            "Success at 10 %",
            "Median convergence time",
            "Median formation error",
            "Median orientation error",
            "Runs with collisions",
        ],
    );
    let _ = writeln!(
        html,
        "<tr class=\"paper\"><td>Paper (Table I, Fig. 9)<div class=\"detail\">{} robots · learned policy · V-REP</div></td><td>{}</td><td>{}</td><td>{}</td><td>≈ {:.0} s</td><td>{}</td><td>{:.3} rad</td><td>–</td></tr>",
        paper::ROBOTS,
        paper::RUNS,
        percent(paper::SUCCESS_RATE_5),
        percent(paper::SUCCESS_RATE_10),
        paper::MEDIAN_CONVERGENCE_S,
        percent(paper::MEDIAN_REL_FORMATION_ERROR),
        paper::MEDIAN_ORIENTATION_ERROR_RAD,
    );
    for entry in &page.table {
        let row = &entry.row;
        let paper_note = paper_note(entry.robots);
        let incomplete = entry
            .incomplete
            .as_deref()
            .map(|note| format!("<div class=\"incomplete\">{}</div>", escape(note)))
            .unwrap_or_default();
        let _ = writeln!(
            html,
            "<tr><td>{}<div class=\"detail\">{}</div>{paper_note}{incomplete}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            escape(&entry.name),
            escape(&entry.detail),
            row.runs,
            percent(row.success_rate_5),
            percent(row.success_rate_10),
            or_dash(row.median_convergence_s, |s| format!("{s:.2} s")),
            or_dash(row.median_rel_formation_error, |e| format!(
                "{:.2} %",
                100.0 * e
            )),
            or_dash(row.median_orientation_error_rad, |r| format!("{r:.3} rad")),
            row.collisions,
        );
    }
    html.push_str("</tbody>\n</table>\n</div>\n");
    for entry in &page.table {
        // (class, note, what follows the note), in this order.
        let notes = [
            ("note incomplete", entry.partial.as_deref(), ""),
            (
                "note incomplete",
                entry.incomplete.as_deref(),
                " An incomplete run has no final 20 s to judge: it counts as a run that did not succeed, and its other metrics are over the ticks it played.",
            ),
            ("note", entry.medians.as_deref(), ""),
        ]
        .into_iter()
        .filter_map(|(class, note, after)| Some((class, note?, after)))
        .chain(
            entry
                .model_inputs
                .iter()
                .map(|note| ("note model-input", note.as_str(), "")),
        );
        for (class, note, after) in notes {
            let _ = writeln!(
                html,
                "<p class=\"{class}\">{}: {}.{after}</p>",
                escape(&entry.name),
                escape(note)
            );
        }
    }
    html.push_str(
        "<p class=\"note\">A run succeeds at tolerance τ when, for every pair of robots, the mean of the relative formation error |dᵢⱼ − d*| / d* over the last 20 s is below τ. The error medians are over the runs that succeed at 10 %; the convergence time is when the largest pairwise error falls below 10 % for good, and its median is over the runs that succeed at 10 % and converged (a run can succeed on its 20 s mean without converging).</p>\n</div>\n</section>\n",
    );
}

fn write_placed(html: &mut String, placed: &PlacedFigure, caption: Option<&str>) {
    let svg = placed.figure.svg.replacen(
        "<svg ",
        &format!("<svg role=\"img\" aria-label=\"{}\" ", escape(&placed.alt)),
        1,
    );
    let _ = writeln!(
        html,
        "<figure class=\"plot\" data-figure=\"{}\">",
        escape(&placed.figure.id)
    );
    html.push_str(&svg);
    html.push('\n');
    if let Some(caption) = caption {
        let _ = writeln!(
            html,
            "<figcaption>{} <a class=\"svg-link\" href=\"{}\">[SVG]</a></figcaption>",
            bold_figure_number(caption),
            escape(&placed.href)
        );
    } else {
        let _ = writeln!(
            html,
            "<a class=\"svg-link\" href=\"{}\">[SVG]</a>",
            escape(&placed.href)
        );
    }
    html.push_str("</figure>\n");
}

/// A reality ladder: one table row per rung, controller and team size, the policy's refusal
/// where it has no rows, then the figure.
fn write_ladder(html: &mut String, section: &LadderSection) {
    let table = &section.table;
    let _ = writeln!(
        html,
        "<h3>The <code>{}</code> profile on <code>{}</code></h3>",
        escape(&table.profile),
        escape(&table.scenario)
    );
    open_results_table(
        html,
        &[
            "Rung (adds)",
            "Controller",
            "Robots",
            "Runs",
            "Success at 10 %",
            "Success at 5 %",
            "Median convergence (IQR)",
            "Runs with collisions",
        ],
    );
    for rung in &table.rungs {
        let added = if rung.added.is_empty() {
            String::new()
        } else {
            let keys: Vec<String> = rung
                .added
                .iter()
                .map(|k| format!("<code>{}</code>", escape(k)))
                .collect();
            format!("<div class=\"detail\">{}</div>", keys.join(", "))
        };
        let name = format!("{}{added}", escape(&rung.rung));
        for row in &rung.rows {
            let who = driver_cell(&row.controller, row.model.as_deref());
            let convergence = convergence_cell(row.convergence_s.as_ref());
            let _ = writeln!(
                html,
                "<tr><td>{name}</td><td>{who}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{convergence}</td><td>{}</td></tr>",
                row.robots,
                row.runs,
                percent(row.success_rate_10),
                percent(row.success_rate_5),
                row.collisions
            );
        }
        if let Some(why) = &rung.policy_refused {
            let _ = writeln!(
                html,
                "<tr><td>{name}</td><td colspan=\"7\">policy: no rows ({})</td></tr>",
                escape(why)
            );
        }
    }
    html.push_str("</tbody>\n</table>\n</div>\n");
    let _ = writeln!(
        html,
        "<p class=\"note\">From <code>{}</code> (seed {}, {} s per run). Each rung adds its effect to those above it; success is the strict check of the scaling table.</p>",
        escape(&section.source),
        table.seed,
        table.duration_s
    );
    write_captioned(html, &section.figure);
    html.push_str("</div>\n");
}

fn write_scaling(html: &mut String, section: &ScalingSection) {
    open_results_table(
        html,
        &[
            "Controller",
            "Robots",
            "Neighbour rule",
            "Runs",
            "Success at 5 %",
            "Success at 10 %",
            "Anchor-compatible",
            "Median convergence (IQR)",
            "Median formation error",
            "Runs with collisions",
        ],
    );
    for row in &section.table.rows {
        // The model id and the IQR go on a second line of their cells: on one line the table
        // was wider than the page at 1300 px and its last column was clipped.
        let who = driver_cell(&row.controller, row.model.as_deref());
        let convergence = convergence_cell(row.convergence_s.as_ref());
        let error = row
            .rel_formation_error
            .map_or_else(|| "–".to_owned(), |q| percent(q.median));
        let _ = writeln!(
            html,
            "<tr><td>{who}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            row.robots,
            escape(&row.neighbours),
            row.runs,
            percent(row.success_rate_5),
            percent(row.success_rate_10),
            percent(row.anchor_success_rate),
            convergence,
            error,
            row.collisions
        );
    }
    html.push_str("</tbody>\n</table>\n</div>\n");
    let _ = writeln!(
        html,
        "<p class=\"note\">From <code>{}</code>. Success is the strict check: every edge of the neighbour graph within the tolerance over the last 20 s, the graph connected and no collision (the paper's check for all pairs); anchor-compatible: mean edge error at most 10 % at the end and no two robots closer than 0.2 m.</p>",
        escape(&section.source)
    );
    let mut described: Vec<&str> = Vec::new();
    for input in section
        .table
        .rows
        .iter()
        .filter_map(|row| row.model_input.as_ref())
    {
        if !described.contains(&input.model.as_str()) {
            described.push(&input.model);
            let _ = writeln!(
                html,
                "<p class=\"note model-input\">{}.</p>",
                escape(&crate::model_input_note(input))
            );
        }
    }
    write_captioned(html, &section.figure);
    html.push_str("</div>\n");
}

fn write_captioned(html: &mut String, figure: &CaptionedFigure) {
    write_placed(html, &figure.placed, Some(&figure.caption));
}

/// Escapes a caption and sets its leading `Figure N:` in bold.
fn bold_figure_number(caption: &str) -> String {
    match caption.split_once(':') {
        Some((number, rest)) if number.starts_with("Figure ") => {
            format!("<b>{}:</b>{}", escape(number), escape(rest))
        }
        _ => escape(caption),
    }
}

fn write_run(html: &mut String, run: &RunSection) {
    let _ = writeln!(
        html,
        "<article class=\"card\" id=\"{}\">",
        escape(&run.anchor)
    );
    let badge = if run.incomplete {
        "<span class=\"badge\">incomplete</span>"
    } else {
        ""
    };
    let _ = writeln!(
        html,
        "<h3>{}{badge}</h3>\n<div class=\"panels\">",
        escape(&run.heading)
    );
    for panel in &run.panels {
        write_placed(html, panel, None);
    }
    html.push_str("<dl class=\"facts\">\n");
    for (label, value) in &run.facts {
        let class = match value.as_str() {
            "yes" => " class=\"ok\"",
            "no" => " class=\"fail\"",
            v if v.starts_with("no, ") => " class=\"fail\"",
            _ => "",
        };
        let _ = writeln!(
            html,
            "<dt>{}</dt><dd{class}>{}</dd>",
            escape(label),
            escape(value)
        );
    }
    html.push_str("</dl>\n</div>\n");
    write_player(html, run);
    let _ = writeln!(
        html,
        "<p class=\"caption\">{}</p>\n</article>",
        bold_figure_number(&run.caption)
    );
}

/// A run's player: the canvas, the controls, the edge error scale and the frames as JSON.
fn write_player(html: &mut String, run: &RunSection) {
    if run.player_json.is_empty() {
        return;
    }
    let _ = writeln!(
        html,
        "<figure class=\"player\" tabindex=\"0\" data-run=\"{}\" aria-label=\"Player of {}\">",
        escape(&run.anchor),
        escape(&run.heading)
    );
    html.push_str("<canvas></canvas>\n<div class=\"player-controls\"><button type=\"button\" class=\"player-play\">Play</button>");
    html.push_str("<input type=\"range\" class=\"player-time\" aria-label=\"time\">");
    html.push_str("<select class=\"player-speed\" aria-label=\"speed\"><option value=\"0.5\">0.5×</option><option value=\"1\" selected>1×</option><option value=\"2\">2×</option><option value=\"5\">5×</option></select>");
    html.push_str(
        "<label><input type=\"checkbox\" class=\"player-follow\"> follow the team</label>",
    );
    html.push_str("<output class=\"player-clock\"></output></div>\n");
    let _ = writeln!(
        html,
        "<figcaption>{} Edge error: <span class=\"player-scale\"></span> 0 % · 10 % · ≥ 20 %.</figcaption>",
        escape(&run.player_note)
    );
    // Numbers and fixed keys only: it cannot close the element early.
    let _ = writeln!(
        html,
        "<script type=\"application/json\" class=\"player-data\">{}</script>\n</figure>",
        run.player_json
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    fn placed(id: &str) -> PlacedFigure {
        PlacedFigure {
            figure: Figure {
                id: id.into(),
                svg: "<svg width=\"10\" height=\"10\"><rect/></svg>".into(),
            },
            href: format!("r-figures/{id}.svg"),
            alt: "a <figure>".into(),
        }
    }

    #[test]
    fn escaping() {
        assert_eq!(escape("a<b>&\"c'"), "a&lt;b&gt;&amp;&quot;c&#39;");
        assert_eq!(percent(0.955), "95.5 %");
        assert_eq!(or_dash(None, |v| v.to_string()), "–");
        assert_eq!(or_dash(Some(f64::NAN), |v| v.to_string()), "–");
    }

    #[test]
    fn page_has_table_rows_sections_and_no_external_resources() {
        let page = ReportPage {
            source_dir: "out/<demo>".into(),
            table: vec![TableEntry {
                name: "table1".into(),
                detail: "policy · table1".into(),
                row: Summary {
                    runs: 20,
                    success_rate_5: 0.85,
                    success_rate_10: 0.95,
                    median_convergence_s: Some(11.25),
                    median_rel_formation_error: Some(0.0312),
                    median_orientation_error_rad: None,
                    collisions: 2,
                    runs_incomplete: 1,
                    medians_over: None,
                    convergence_s: None,
                    rel_formation_error: None,
                    orientation_error_rad: None,
                    anchor_success_rate: None,
                    connected_rate: None,
                },
                robots: Some(3),
                incomplete: Some("1 of 20 runs incomplete (stopped early: <Ctrl-C>)".into()),
                partial: None,
                medians: None,
                model_inputs: Vec::new(),
            }],
            fig9: Some(CaptionedFigure {
                placed: placed("fig9"),
                caption: "Figure 1: boxes".into(),
            }),
            runs: vec![RunSection {
                heading: "case1 · run 0".into(),
                anchor: "run-case1-0".into(),
                facts: vec![("success at 5 %".into(), "yes".into())],
                panels: vec![placed("a"), placed("b"), placed("c")],
                caption: "Figure 2: case".into(),
                incomplete: true,
                player_note: "Player".into(),
                player_json: "{\"t\":[0]}".into(),
            }],
            ..ReportPage::default()
        };
        let html = render_page(&page);
        assert!(html.contains("<td>table1<div class=\"detail\">policy · table1</div>"));
        for cell in [
            "85.0 %",
            "95.0 %",
            "11.25 s",
            "3.12 %",
            "<td>–</td>",
            "90.0 %",
            "96.0 %",
        ] {
            assert!(html.contains(cell), "{cell}");
        }
        assert!(html.contains("out/&lt;demo&gt;"));
        assert!(html.contains(
            "<div class=\"incomplete\">1 of 20 runs incomplete (stopped early: &lt;Ctrl-C&gt;)</div>"
        ));
        assert!(html.contains("case1 · run 0<span class=\"badge\">incomplete</span>"));
        assert_eq!(html.matches("<figure class=\"plot\"").count(), 4);
        assert!(html.contains("aria-label=\"a &lt;figure&gt;\""));
        assert!(html.contains("<b>Figure 2:</b> case"));
        // The run's player: its canvas, its controls and its frames as JSON.
        assert!(html.contains("<figure class=\"player\" tabindex=\"0\" data-run=\"run-case1-0\""));
        assert!(html.contains(
            "<script type=\"application/json\" class=\"player-data\">{\"t\":[0]}</script>"
        ));
        assert!(html.contains("class=\"player-play\"") && html.contains("class=\"player-time\""));
        assert_eq!(html.matches("<canvas>").count(), 1);
        assert!(html.contains("href=\"#fig-9\"") && !html.contains("href=\"#training\""));
        assert!(!html.contains("http://") && !html.contains("https://") && !html.contains(" src="));
    }
}
