//! The report's figures as standalone SVG documents, drawn with plotters from the series in
//! [`crate::series`]: the paper's Figs. 6-8 panels (errors, wheel commands, trajectories), Fig. 9
//! box plots, the Fig. 5-style loss curve and the latency profile.
//!
//! Every figure has its legend in a strip to the right of the plot, so it never hides data, and
//! units on both axes. Colours come from one palette per robot, so robot 2 has the same colour in
//! every panel. A team larger than the palette gets one legend row per colour, naming the robots
//! that share it, and no legend runs past its panel.

use std::error::Error;
use std::ops::Range;

use plotters::chart::MeshStyle;
use plotters::coord::Shift;
use plotters::coord::ranged1d::ValueFormatter;
use plotters::coord::types::RangedCoordf64;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::error::ReportError;
use crate::input::{Quantiles, Trajectory};
use crate::loss::LossCurve;
use crate::profile::StageLatency;
use crate::series::{
    Series, Wheel, equal_aspect, formation_error_percent, heading_triangle, jitter,
    orientation_error, padded_range, paths, robot_label, snapshot_indices, wheel_commands,
};

/// The font family of all figure text (a generic family: nothing is loaded).
const FONT: &str = "sans-serif";
/// Figure text colour.
const INK: RGBColor = RGBColor(0x33, 0x33, 0x33);
/// Reference lines (tolerances, paper values) and formation snapshots.
const REFERENCE: RGBColor = RGBColor(0x88, 0x88, 0x88);
/// The paper's values.
const PAPER: RGBColor = RGBColor(0xC0, 0x39, 0x2B);
/// Box fill of Fig. 9.
const BOX: RGBColor = RGBColor(0x4C, 0x72, 0xB0);
/// Robot colours (Tableau 10), robot `i` gets `ROBOT_COLORS[i % 10]`.
pub const ROBOT_COLORS: [RGBColor; 10] = palette([
    0x1F77B4, 0xFF7F0E, 0x2CA02C, 0xD62728, 0x9467BD, 0x8C564B, 0xE377C2, 0x7F7F7F, 0xBCBD22,
    0x17BECF,
]);
/// Edge colours of the formation error panel (distinct from the robot colours).
pub const EDGE_COLORS: [RGBColor; 6] =
    palette([0x6A3D9A, 0x008B8B, 0xB15928, 0x33A02C, 0xE31A1C, 0x1F78B4]);

/// Colours from their `0xRRGGBB` codes.
const fn palette<const N: usize>(codes: [u32; N]) -> [RGBColor; N] {
    let mut colors = [RGBColor(0, 0, 0); N];
    let mut i = 0;
    while i < N {
        let [_, red, green, blue] = codes[i].to_be_bytes();
        colors[i] = RGBColor(red, green, blue);
        i += 1;
    }
    colors
}

/// Width \[px\] of the legend strip right of every plot.
const LEGEND_WIDTH: u32 = 140;
/// Seconds between the formation snapshots of the trajectory panel (the paper's 3 s).
pub const SNAPSHOT_EVERY_S: f64 = 3.0;
/// Seconds between snapshots of a team larger than the paper's three (their graph would
/// otherwise cover the paths).
pub const TEAM_SNAPSHOT_EVERY_S: f64 = 10.0;

/// Seconds between the snapshots of `traj`'s trajectory figure.
pub fn snapshot_every_s(traj: &Trajectory) -> f64 {
    if traj.n_robots() > 3 {
        TEAM_SNAPSHOT_EVERY_S
    } else {
        SNAPSHOT_EVERY_S
    }
}

/// One figure: a file stem and an SVG document.
#[derive(Debug, Clone, PartialEq)]
pub struct Figure {
    /// File stem, unique within a report (`case1-run0-errors`).
    pub id: String,
    /// The SVG document.
    pub svg: String,
}

/// The colour of robot `i`.
pub fn robot_color(i: usize) -> RGBColor {
    ROBOT_COLORS[i % ROBOT_COLORS.len()]
}

/// The colour of the `k`-th formation edge.
pub fn edge_color(k: usize) -> RGBColor {
    EDGE_COLORS[k % EDGE_COLORS.len()]
}

type Area<'a> = DrawingArea<SVGBackend<'a>, Shift>;
type DrawResult = Result<(), Box<dyn Error>>;

/// Draws a figure of `size` pixels on a white background.
fn render(
    id: &str,
    size: (u32, u32),
    draw: impl FnOnce(&Area<'_>) -> DrawResult,
) -> Result<Figure, ReportError> {
    let plot_error = |e: &dyn std::fmt::Display| ReportError::Plot {
        figure: id.to_owned(),
        message: e.to_string(),
    };
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        root.fill(&WHITE).map_err(|e| plot_error(&e))?;
        draw(&root).map_err(|e| plot_error(&e))?;
        root.present().map_err(|e| plot_error(&e))?;
    }
    Ok(Figure {
        id: id.to_owned(),
        svg,
    })
}

fn text_style(size: f64) -> TextStyle<'static> {
    TextStyle::from((FONT, size).into_font()).color(&INK)
}

/// The house style of every chart's mesh: tick labels of one size, axis titles at 17 px, grey
/// axes and faint grid lines.
trait HouseStyle {
    /// Applies the house style with tick labels of `label_size` px.
    fn house_style(&mut self, label_size: f64) -> &mut Self;
}

impl<X: Ranged, Y: Ranged, DB: DrawingBackend> HouseStyle for MeshStyle<'_, '_, X, Y, DB> {
    fn house_style(&mut self, label_size: f64) -> &mut Self {
        self.label_style(text_style(label_size))
            .axis_desc_style(text_style(17.0))
            .axis_style(RGBColor(0x66, 0x66, 0x66))
            .bold_line_style(RGBColor(0xE4, 0xE4, 0xE4))
            .light_line_style(RGBColor(0xF4, 0xF4, 0xF4))
    }
}

/// How a legend entry is marked.
#[derive(Debug, Clone, Copy)]
enum Mark {
    Line(RGBColor),
    Thin(RGBColor),
    Dashed(RGBColor),
    Triangle(RGBColor),
    Dot(RGBColor),
    Box,
    /// Text only (a heading over the entries below it).
    Heading,
}

/// Pixels between two legend rows, and the label font size \[px\], when every row fits.
const LEGEND_PITCH: i32 = 20;
const LEGEND_FONT: f64 = 15.0;
/// The tightest legend: rows this far apart, their labels at three quarters of it.
const LEGEND_MIN_PITCH: i32 = 12;

/// The legend entries of a team's robots, marked by `mark`: one per robot while every robot has
/// its own colour, else one per colour under a heading, listing the robots that share it
/// (`1, 11, 21`, or `1, 11, …, 61` for a long list), so the legend of 16, 32 or 64 robots has
/// eleven rows.
fn robot_entries(n: usize, mark: impl Fn(RGBColor) -> Mark) -> Vec<(Mark, String)> {
    if n <= ROBOT_COLORS.len() {
        return (0..n)
            .map(|i| (mark(robot_color(i)), robot_label(i)))
            .collect();
    }
    let mut entries = vec![(Mark::Heading, "robots by colour".to_owned())];
    for c in 0..ROBOT_COLORS.len() {
        let members: Vec<String> = (c..n)
            .step_by(ROBOT_COLORS.len())
            .map(|i| (i + 1).to_string())
            .collect();
        let label = if members.len() <= 4 {
            members.join(", ")
        } else {
            format!(
                "{}, {}, …, {}",
                members[0],
                members[1],
                members[members.len() - 1]
            )
        };
        entries.push((mark(robot_color(c)), label));
    }
    entries
}

/// Draws legend entries top-down in `area` (the strip right of a plot), from `top`. Rows are
/// [`LEGEND_PITCH`] apart; when they would run past the bottom of `area` they move closer (down
/// to [`LEGEND_MIN_PITCH`], the labels shrinking with them), and what still does not fit is
/// summed up in a last row (`+ 5 more`): rows never overlap each other or the panel below.
fn draw_legend(area: &Area<'_>, top: i32, entries: &[(Mark, String)]) -> DrawResult {
    let height = i32::try_from(area.dim_in_pixel().1).unwrap_or(i32::MAX);
    // The room from the first row's centre to the last row's centre, half a row kept free below.
    let room = (height - top - LEGEND_PITCH / 2).max(0);
    let rows = i32::try_from(entries.len()).unwrap_or(i32::MAX).max(1);
    let pitch = if rows <= 1 {
        LEGEND_PITCH
    } else {
        (room / (rows - 1)).clamp(LEGEND_MIN_PITCH, LEGEND_PITCH)
    };
    let fits = usize::try_from(room / pitch + 1).unwrap_or(usize::MAX);
    let mut shown: Vec<(Mark, String)> = entries.to_vec();
    if shown.len() > fits {
        let kept = fits.saturating_sub(1);
        let more = shown.len() - kept;
        shown.truncate(kept);
        shown.push((Mark::Heading, format!("+ {more} more")));
    }
    let font = LEGEND_FONT.min(0.75 * f64::from(pitch));
    let label_style = text_style(font).pos(Pos::new(HPos::Left, VPos::Center));
    for (k, (mark, label)) in shown.iter().enumerate() {
        let y = top + pitch * i32::try_from(k).unwrap_or(i32::MAX);
        let (x0, x1) = (6, 28);
        match *mark {
            Mark::Line(color) => area.draw(&PathElement::new(
                vec![(x0, y), (x1, y)],
                color.stroke_width(2),
            ))?,
            Mark::Thin(color) => area.draw(&PathElement::new(
                vec![(x0, y), (x1, y)],
                color.stroke_width(1),
            ))?,
            Mark::Dashed(color) => area.draw(&DashedPathElement::new(
                vec![(x0, y), (x1, y)],
                5,
                3,
                color.stroke_width(1),
            ))?,
            Mark::Triangle(color) => area.draw(&Polygon::new(
                vec![(x0 + 16, y), (x0 + 5, y - 6), (x0 + 5, y + 6)],
                color.filled(),
            ))?,
            Mark::Dot(color) => area.draw(&Circle::new((x0 + 11, y), 4, color.filled()))?,
            Mark::Box => {
                area.draw(&Rectangle::new(
                    [(x0, y - 6), (x1, y + 6)],
                    BOX.mix(0.25).filled(),
                ))?;
                area.draw(&Rectangle::new(
                    [(x0, y - 6), (x1, y + 6)],
                    BOX.stroke_width(1),
                ))?;
            }
            Mark::Heading => {
                area.draw(&Text::new(label.clone(), (x0, y), label_style.clone()))?;
                continue;
            }
        }
        area.draw(&Text::new(label.clone(), (x1 + 6, y), label_style.clone()))?;
    }
    Ok(())
}

/// A line of a time-series panel.
struct Line<'a> {
    series: &'a Series,
    color: RGBColor,
}

/// One line per series, the `i`th coloured `color(i)`.
fn coloured_lines(series: &[Series], color: fn(usize) -> RGBColor) -> Vec<Line<'_>> {
    series
        .iter()
        .enumerate()
        .map(|(i, series)| Line {
            series,
            color: color(i),
        })
        .collect()
}

/// A horizontal dashed reference line with its legend label.
struct Reference {
    y: f64,
    label: String,
}

/// How a time-series panel's lines are named in its legend.
#[derive(Debug, Clone, Copy, PartialEq)]
enum LineLegend {
    /// One entry per line, its series' label.
    PerLine,
    /// The lines are the team's robots, in order: [`robot_entries`].
    Robots,
}

/// One time-series panel: lines over `time \[s\]` with a legend strip on the right.
#[allow(clippy::too_many_arguments)]
fn time_panel(
    area: &Area<'_>,
    line_legend: LineLegend,
    title: &str,
    y_desc: &str,
    x_range: Range<f64>,
    lines: &[Line<'_>],
    references: &[Reference],
    zero_based: bool,
) -> DrawResult {
    let width = area.dim_in_pixel().0;
    let (plot, legend) = area.split_horizontally(width.saturating_sub(LEGEND_WIDTH));
    let y_values = lines
        .iter()
        .flat_map(|l| l.series.points.iter().map(|p| p.1))
        .chain(references.iter().map(|r| r.y));
    let y_range = padded_range(y_values, 0.05, zero_based);
    let mut chart = ChartBuilder::on(&plot)
        .caption(title, text_style(19.0))
        .margin(8)
        .x_label_area_size(46)
        .y_label_area_size(66)
        .build_cartesian_2d(x_range.clone(), y_range)?;
    configure_mesh(&mut chart, "time [s]", y_desc)?;
    for reference in references {
        chart.draw_series(DashedLineSeries::new(
            vec![(x_range.start, reference.y), (x_range.end, reference.y)],
            6,
            4,
            REFERENCE.stroke_width(1),
        ))?;
    }
    for line in lines {
        chart.draw_series(LineSeries::new(
            line.series.points.iter().copied(),
            line.color.stroke_width(2),
        ))?;
    }
    let line_entries = match line_legend {
        LineLegend::PerLine => lines
            .iter()
            .map(|l| (Mark::Line(l.color), l.series.label.clone()))
            .collect(),
        LineLegend::Robots => robot_entries(lines.len(), Mark::Line),
    };
    let entries: Vec<(Mark, String)> = line_entries
        .into_iter()
        .chain(
            references
                .iter()
                .map(|r| (Mark::Dashed(REFERENCE), r.label.clone())),
        )
        .collect();
    draw_legend(&legend, 44, &entries)
}

fn configure_mesh<X, Y>(
    chart: &mut ChartContext<'_, SVGBackend<'_>, Cartesian2d<X, Y>>,
    x_desc: &str,
    y_desc: &str,
) -> DrawResult
where
    X: Ranged<ValueType = f64> + ValueFormatter<f64>,
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    configure_mesh_labelled(chart, x_desc, y_desc, &|v| tick_label(*v))
}

/// [`configure_mesh`] with the x axis's labels made by `x_label`.
fn configure_mesh_labelled<X, Y>(
    chart: &mut ChartContext<'_, SVGBackend<'_>, Cartesian2d<X, Y>>,
    x_desc: &str,
    y_desc: &str,
    x_label: &dyn Fn(&f64) -> String,
) -> DrawResult
where
    X: Ranged<ValueType = f64> + ValueFormatter<f64>,
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .house_style(16.0)
        .x_label_formatter(x_label)
        .y_label_formatter(&|v| tick_label(*v))
        .x_labels(8)
        .y_labels(6)
        .draw()?;
    Ok(())
}

/// The chart of one panel of the scaling and ladder figures: `caption` above, `x` against `y`.
fn panel_chart<'a, 'b>(
    area: &'a Area<'b>,
    caption: &str,
    x: Range<f64>,
    y: Range<f64>,
) -> Result<PanelChart<'a, 'b>, Box<dyn Error>> {
    Ok(ChartBuilder::on(area)
        .caption(caption, text_style(19.0))
        .margin(8)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(x, y)?)
}

/// The [`panel_chart`] of the median convergence times `medians` \[s\]: from 0 to 10 % above
/// the largest (at least 1 s).
fn convergence_chart<'a, 'b>(
    area: &'a Area<'b>,
    caption: &str,
    x: Range<f64>,
    medians: impl Iterator<Item = f64>,
) -> Result<PanelChart<'a, 'b>, Box<dyn Error>> {
    let convergence_max = medians.fold(1.0_f64, f64::max);
    panel_chart(area, caption, x, 0.0..1.1 * convergence_max)
}

/// A chart of [`panel_chart`].
type PanelChart<'a, 'b> =
    ChartContext<'a, SVGBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// A line of `points` `color`ed 2 px wide with a dot at every point.
fn draw_dotted_line(
    chart: &mut PanelChart<'_, '_>,
    points: &[(f64, f64)],
    color: RGBColor,
) -> DrawResult {
    chart.draw_series(LineSeries::new(
        points.iter().copied(),
        color.stroke_width(2),
    ))?;
    chart.draw_series(points.iter().map(|&p| Circle::new(p, 3, color.filled())))?;
    Ok(())
}

/// The team-size axis of the scaling figure: whole team sizes, at least one robot either side of
/// the sizes shown (one size alone would otherwise get a sliver such as 15.6–16.4 robots).
pub fn team_size_range(sizes: impl IntoIterator<Item = usize>) -> Range<f64> {
    let (lo, hi) = sizes
        .into_iter()
        .fold((usize::MAX, 0), |(lo, hi), n| (lo.min(n), hi.max(n)));
    if lo > hi {
        return 0.0..1.0;
    }
    let pad = ((hi - lo) as f64 * 0.06).max(1.0);
    (lo as f64 - pad).max(0.0)..hi as f64 + pad
}

/// A team-size tick label: whole numbers only (a fractional tick is left unlabelled).
pub fn team_size_label(value: f64) -> String {
    let whole = value.round();
    if (value - whole).abs() < 1e-9 && whole >= 0.0 {
        format!("{whole:.0}")
    } else {
        String::new()
    }
}

/// The time axis of a run: its first to last sample.
fn time_range(traj: &Trajectory) -> Range<f64> {
    padded_range(traj.times.iter().copied(), 0.0, false)
}

/// Figs. 6a-8a: formation error `e_ij(t)` [%] (top) and orientation error \[rad\] (bottom).
pub fn errors_figure(id: &str, traj: &Trajectory) -> Result<Figure, ReportError> {
    let formation = formation_error_percent(traj);
    let orientation = orientation_error(traj);
    render(id, (640, 600), |root| {
        let (top, bottom) = root.split_vertically(300);
        let edge_lines = coloured_lines(&formation, edge_color);
        time_panel(
            &top,
            LineLegend::PerLine,
            "(a) formation error eᵢⱼ = |dᵢⱼ − d*| / d*",
            "formation error [%]",
            time_range(traj),
            &edge_lines,
            &[
                Reference {
                    y: 10.0,
                    label: "10 % tolerance".into(),
                },
                Reference {
                    y: 5.0,
                    label: "5 % tolerance".into(),
                },
            ],
            true,
        )?;
        let robot_lines = coloured_lines(&orientation, robot_color);
        time_panel(
            &bottom,
            LineLegend::Robots,
            "orientation error θᵢ − φ* (wrapped)",
            "orientation error [rad]",
            time_range(traj),
            &robot_lines,
            &[Reference {
                y: 0.0,
                label: "zero".into(),
            }],
            false,
        )
    })
}

/// Figs. 6b-8b: left (top) and right (bottom) wheel commands of every robot \[m/s\], with v*.
pub fn wheels_figure(id: &str, traj: &Trajectory) -> Result<Figure, ReportError> {
    let left = wheel_commands(traj, Wheel::Left);
    let right = wheel_commands(traj, Wheel::Right);
    let references: Vec<Reference> = if traj.v_star.is_finite() {
        vec![Reference {
            y: traj.v_star,
            label: format!("v* = {} m/s", trim_number(traj.v_star)),
        }]
    } else {
        Vec::new()
    };
    render(id, (640, 600), |root| {
        let (top, bottom) = root.split_vertically(300);
        for (area, series, title) in [
            (&top, &left, "(b) left wheel command"),
            (&bottom, &right, "right wheel command"),
        ] {
            let lines = coloured_lines(series, robot_color);
            time_panel(
                area,
                LineLegend::Robots,
                title,
                "wheel speed [m/s]",
                time_range(traj),
                &lines,
                &references,
                false,
            )?;
        }
        Ok(())
    })
}

/// Figs. 6c-8c: every robot's path, and every [`SNAPSHOT_EVERY_S`] ([`TEAM_SNAPSHOT_EVERY_S`]
/// for a team larger than three) the robots as triangles
/// pointing along their heading with the formation (dashed lines along the edges of that moment,
/// the neighbour graph for a team) between them.
/// Both axes have the same scale. Collisions are marked with a red ring.
pub fn trajectory_figure(id: &str, traj: &Trajectory) -> Result<Figure, ReportError> {
    let robot_paths = paths(traj);
    let every_s = snapshot_every_s(traj);
    let snapshots = snapshot_indices(&traj.times, every_s);
    let edges = crate::series::edges_per_sample(traj);
    let (width, height) = (640_u32, 600_u32);
    let (margin, x_label_area, y_label_area) = (8_u32, 46_u32, 66_u32);
    render(id, (width, height), |root| {
        let (plot, legend) = root.split_horizontally(width - LEGEND_WIDTH);
        let title = format!("(c) trajectories and formation every {every_s} s");
        let plot = plot.titled(title.as_str(), text_style(19.0))?;
        let (plot_w, plot_h) = plot.dim_in_pixel();
        let inner_w = f64::from(plot_w.saturating_sub(2 * margin + y_label_area).max(1));
        let inner_h = f64::from(plot_h.saturating_sub(2 * margin + x_label_area).max(1));
        let xs = robot_paths
            .iter()
            .flat_map(|s| s.points.iter().map(|p| p.0));
        let ys = robot_paths
            .iter()
            .flat_map(|s| s.points.iter().map(|p| p.1));
        let (x_range, y_range) = equal_aspect(
            padded_range(xs, 0.06, false),
            padded_range(ys, 0.06, false),
            inner_w,
            inner_h,
        );
        let marker = 0.03 * (x_range.end - x_range.start).max(y_range.end - y_range.start);
        let mut chart = ChartBuilder::on(&plot)
            .margin(margin)
            .x_label_area_size(x_label_area)
            .y_label_area_size(y_label_area)
            .build_cartesian_2d(x_range, y_range)?;
        configure_mesh(&mut chart, "x [m]", "y [m]")?;
        for (i, path) in robot_paths.iter().enumerate() {
            chart.draw_series(LineSeries::new(
                path.points.iter().copied(),
                robot_color(i).mix(0.8).stroke_width(2),
            ))?;
        }
        for &k in &snapshots {
            let poses = &traj.poses[k];
            for &(i, j) in edges.get(k).map_or(&[][..], Vec::as_slice) {
                let (a, b) = (poses[i], poses[j]);
                if [a.x, a.y, b.x, b.y].iter().all(|v| v.is_finite()) {
                    chart.draw_series(std::iter::once(DashedPathElement::new(
                        vec![(a.x, a.y), (b.x, b.y)],
                        4,
                        3,
                        REFERENCE.stroke_width(1),
                    )))?;
                }
            }
            for (i, pose) in poses.iter().enumerate() {
                if [pose.x, pose.y, pose.theta].iter().all(|v| v.is_finite()) {
                    let triangle = heading_triangle(pose.x, pose.y, pose.theta, marker);
                    chart.draw_series(std::iter::once(Polygon::new(
                        triangle.to_vec(),
                        robot_color(i).filled(),
                    )))?;
                }
            }
        }
        let collision_points: Vec<(f64, f64)> = traj
            .collisions
            .iter()
            .filter_map(|&(k, i, j)| {
                let poses = traj.poses.get(usize::try_from(k).ok()?)?;
                let (a, b) = (poses.get(i)?, poses.get(j)?);
                Some((0.5 * (a.x + b.x), 0.5 * (a.y + b.y)))
            })
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .collect();
        chart.draw_series(
            collision_points
                .iter()
                .map(|&p| Circle::new(p, 7, PAPER.stroke_width(2))),
        )?;

        let mut entries = robot_entries(traj.n_robots(), Mark::Triangle);
        entries.push((Mark::Dashed(REFERENCE), "formation".into()));
        if !collision_points.is_empty() {
            entries.push((Mark::Dot(PAPER), "collision".into()));
        }
        draw_legend(&legend, 44, &entries)
    })
}

/// One box of a Fig. 9 panel.
#[derive(Debug, Clone, PartialEq)]
pub struct BoxGroup {
    /// Category label (the evaluation's name).
    pub label: String,
    /// Its order statistics, already in the panel's unit; `None` when no run succeeded.
    pub stats: Option<Quantiles>,
    /// Every successful run's value, drawn as dots over the box.
    pub dots: Vec<f64>,
}

/// One Fig. 9 panel: a quantity, its unit and the paper's median.
#[derive(Debug, Clone, PartialEq)]
pub struct BoxPanel {
    /// Panel title.
    pub title: String,
    /// Y axis description with the unit.
    pub y_desc: String,
    /// One box per evaluation.
    pub groups: Vec<BoxGroup>,
    /// The paper's median, in the panel's unit.
    pub paper_median: Option<f64>,
}

/// Fig. 9: side-by-side box plots (median, quartiles, whiskers to min/max) with every run's value
/// as a dot and the paper's median as a dashed line.
pub fn box_figure(id: &str, panels: &[BoxPanel]) -> Result<Figure, ReportError> {
    let panel_width = 300_u32;
    let width = panel_width * panels.len().max(1) as u32 + LEGEND_WIDTH + 20;
    render(id, (width, 440), |root| {
        let (plots, legend) = root.split_horizontally(width - LEGEND_WIDTH - 20);
        let areas = plots.split_evenly((1, panels.len().max(1)));
        for (panel, area) in panels.iter().zip(&areas) {
            box_panel(area, panel)?;
        }
        let mut entries = vec![
            (Mark::Box, "quartiles".into()),
            (Mark::Line(INK), "median".into()),
            (Mark::Dot(BOX), "one run".into()),
        ];
        if panels.iter().any(|p| p.paper_median.is_some()) {
            entries.push((Mark::Dashed(PAPER), "paper median".into()));
        }
        draw_legend(&legend, 44, &entries)
    })
}

fn box_panel(area: &Area<'_>, panel: &BoxPanel) -> DrawResult {
    let n = panel.groups.len().max(1);
    let values = panel
        .groups
        .iter()
        .flat_map(|g| {
            g.dots
                .iter()
                .copied()
                .chain(g.stats.iter().flat_map(|q| [q.min, q.max]))
        })
        .chain(panel.paper_median);
    let y_range = padded_range(values, 0.08, false);
    let x_range = -0.6..n as f64 - 0.4;
    let mut chart = ChartBuilder::on(area)
        .caption(&panel.title, text_style(19.0))
        .margin(8)
        .x_label_area_size(36)
        .y_label_area_size(66)
        .build_cartesian_2d(x_range.clone(), y_range.clone())?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(0)
        .x_label_formatter(&|_| String::new())
        .y_desc(panel.y_desc.as_str())
        .y_label_formatter(&|v| tick_label(*v))
        .house_style(16.0)
        .y_labels(6)
        .draw()?;
    let label_style = text_style(16.0).pos(Pos::new(HPos::Center, VPos::Top));
    for (g, group) in panel.groups.iter().enumerate() {
        let x = g as f64;
        let count = group.stats.map_or(0, |q| q.count);
        chart.draw_series(std::iter::once(
            EmptyElement::at((x, y_range.start))
                + Text::new(
                    format!("{} (n = {count})", group.label),
                    (0, 8),
                    label_style.clone(),
                ),
        ))?;
        let Some(q) = group.stats else {
            chart.draw_series(std::iter::once(Text::new(
                "no successful run",
                (x, 0.5 * (y_range.start + y_range.end)),
                text_style(13.0).pos(Pos::new(HPos::Center, VPos::Center)),
            )))?;
            continue;
        };
        let half = 0.22;
        chart.draw_series([
            Rectangle::new([(x - half, q.q1), (x + half, q.q3)], BOX.mix(0.22).filled()),
            Rectangle::new([(x - half, q.q1), (x + half, q.q3)], BOX.stroke_width(1)),
        ])?;
        chart.draw_series([
            PathElement::new(vec![(x, q.q3), (x, q.max)], INK.stroke_width(1)),
            PathElement::new(vec![(x, q.min), (x, q.q1)], INK.stroke_width(1)),
            PathElement::new(
                vec![(x - half / 2.0, q.max), (x + half / 2.0, q.max)],
                INK.stroke_width(1),
            ),
            PathElement::new(
                vec![(x - half / 2.0, q.min), (x + half / 2.0, q.min)],
                INK.stroke_width(1),
            ),
            PathElement::new(
                vec![(x - half, q.median), (x + half, q.median)],
                INK.stroke_width(3),
            ),
        ])?;
        chart.draw_series(
            group
                .dots
                .iter()
                .enumerate()
                .filter(|(_, v)| v.is_finite())
                .map(|(k, &v)| Circle::new((x + 0.3 * jitter(k), v), 2, BOX.mix(0.55).filled())),
        )?;
    }
    if let Some(paper) = panel.paper_median {
        chart.draw_series(DashedLineSeries::new(
            vec![(x_range.start, paper), (x_range.end, paper)],
            6,
            4,
            PAPER.stroke_width(2),
        ))?;
    }
    Ok(())
}

/// Fig. 5-style training curve: train and validation loss per epoch on a log scale (values that
/// are not positive cannot be drawn on it and are left out).
pub fn loss_figure(id: &str, curve: &LossCurve) -> Result<Figure, ReportError> {
    let train = positive_points(&curve.epochs, &curve.train_loss);
    let val = positive_points(&curve.epochs, &curve.val_loss);
    render(id, (720, 400), |root| {
        let (plot, legend) = root.split_horizontally(720 - LEGEND_WIDTH);
        let x_range = padded_range(curve.epochs.iter().copied(), 0.0, false);
        let (lo, hi) = log_bounds(train.iter().chain(&val).map(|p| p.1));
        let mut chart = ChartBuilder::on(&plot)
            .caption("training loss", text_style(19.0))
            .margin(8)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(x_range, (lo..hi).log_scale())?;
        configure_mesh(&mut chart, "epoch", "loss (MSE) [(m/s)²]")?;
        chart.draw_series(LineSeries::new(
            train.iter().copied(),
            robot_color(0).stroke_width(2),
        ))?;
        chart.draw_series(LineSeries::new(
            val.iter().copied(),
            robot_color(1).stroke_width(2),
        ))?;
        let mut entries = vec![(Mark::Line(robot_color(0)), "training".to_owned())];
        if !val.is_empty() {
            entries.push((Mark::Line(robot_color(1)), "validation".to_owned()));
        }
        draw_legend(&legend, 44, &entries)
    })
}

/// The scaling figure: (a) success at 10 % (solid) and 5 % (thin) against the team size, and
/// (b) the median convergence time at 10 % against the team size, one colour per controller
/// (and model) of the table.
pub fn scaling_figure(
    id: &str,
    table: &formation_schema::ScalingTable,
) -> Result<Figure, ReportError> {
    let mut drivers: Vec<String> = Vec::new();
    for row in &table.rows {
        let who = scaling_driver(row);
        if !drivers.contains(&who) {
            drivers.push(who);
        }
    }
    let x_range = team_size_range(table.rows.iter().map(|r| r.robots));
    let (width, height) = (960_u32, 400_u32);
    render(id, (width, height), |root| {
        let (plots, legend) = root.split_horizontally(width - LEGEND_WIDTH);
        let (left, right) = plots.split_horizontally((width - LEGEND_WIDTH) / 2);
        let mut success = panel_chart(
            &left,
            "(a) success against team size",
            x_range.clone(),
            0.0..105.0,
        )?;
        configure_mesh_labelled(&mut success, "robots", "success [%]", &|v| {
            team_size_label(*v)
        })?;
        let medians = table
            .rows
            .iter()
            .filter_map(|r| r.convergence_s.map(|q| q.median));
        let mut convergence = convergence_chart(
            &right,
            "(b) median convergence (10 %)",
            x_range.clone(),
            medians,
        )?;
        configure_mesh_labelled(&mut convergence, "robots", "convergence [s]", &|v| {
            team_size_label(*v)
        })?;
        let mut entries = Vec::new();
        for (k, who) in drivers.iter().enumerate() {
            let rows: Vec<&formation_schema::ScalingRow> = table
                .rows
                .iter()
                .filter(|r| scaling_driver(r) == *who)
                .collect();
            let color = robot_color(k);
            let at = |f: &dyn Fn(&formation_schema::ScalingRow) -> Option<f64>| -> Vec<(f64, f64)> {
                rows.iter()
                    .filter_map(|r| f(r).map(|y| (r.robots as f64, y)))
                    .collect()
            };
            let s10 = at(&|r| Some(100.0 * r.success_rate_10));
            let s5 = at(&|r| Some(100.0 * r.success_rate_5));
            let conv = at(&|r| r.convergence_s.map(|q| q.median));
            draw_dotted_line(&mut success, &s10, color)?;
            success.draw_series(LineSeries::new(s5.iter().copied(), color.stroke_width(1)))?;
            draw_dotted_line(&mut convergence, &conv, color)?;
            // The legend is narrow: the controller, numbered when several models share it (the
            // table names each model).
            let controller = rows.first().map_or("", |r| r.controller.as_str());
            let same = drivers
                .iter()
                .filter(|d| d.split(' ').next() == Some(controller))
                .count();
            let label = if same > 1 {
                format!("{controller} {}", k + 1)
            } else {
                controller.to_owned()
            };
            entries.push((Mark::Line(color), format!("{label} @ 10 %")));
            entries.push((Mark::Thin(color), format!("{label} @ 5 %")));
        }
        draw_legend(&legend, 44, &entries)
    })
}

/// The reality ladder's figure: (a) success at 10 % (solid) and 5 % (thin) and (b) the median
/// convergence time at 10 %, against the rungs in the order their effects were added, one
/// colour per controller (and model) and team size ([`crate::ladder::ladder_series`]). A rung
/// without a row (a policy that cannot drive its LIDAR) leaves a gap in that line.
pub fn ladder_figure(
    id: &str,
    table: &formation_schema::LadderTable,
) -> Result<Figure, ReportError> {
    use crate::ladder::{ladder_series, rung_label, unbroken_runs};
    let series = ladder_series(table);
    let rungs = series.rungs.len().max(1);
    let x_range = -0.4..(rungs as f64 - 0.6);
    let names: Vec<String> = series.rungs.iter().map(|r| rung_label(r)).collect();
    let rung_name = |v: &f64| -> String {
        let whole = v.round();
        if (v - whole).abs() > 1e-9 || whole < 0.0 {
            return String::new();
        }
        names.get(whole as usize).cloned().unwrap_or_default()
    };
    let (width, height) = (1100_u32, 720_u32);
    render(id, (width, height), |root| {
        let (plots, legend) = root.split_horizontally(width - LEGEND_WIDTH);
        let (top, bottom) = plots.split_vertically(height / 2);
        let rung_mesh = |chart: &mut PanelChart<'_, '_>, y_desc: &str| -> DrawResult {
            chart
                .configure_mesh()
                .y_desc(y_desc)
                .house_style(14.0)
                .x_label_formatter(&rung_name)
                .y_label_formatter(&|v| tick_label(*v))
                .x_labels(rungs)
                .y_labels(6)
                .draw()?;
            Ok(())
        };
        let mut success = panel_chart(&top, "(a) success per rung", x_range.clone(), 0.0..105.0)?;
        rung_mesh(&mut success, "success [%]")?;
        let medians = series
            .lines
            .iter()
            .flat_map(|l| l.convergence_s.iter().flatten().copied())
            .filter(|v| v.is_finite());
        let mut convergence = convergence_chart(
            &bottom,
            "(b) median convergence (10 %) per rung",
            x_range.clone(),
            medians,
        )?;
        rung_mesh(&mut convergence, "convergence [s]")?;
        let mut entries = Vec::new();
        for (k, line) in series.lines.iter().enumerate() {
            let color = robot_color(k);
            for run in unbroken_runs(&line.success_10) {
                draw_dotted_line(&mut success, &run, color)?;
            }
            for run in unbroken_runs(&line.success_5) {
                success.draw_series(LineSeries::new(run.iter().copied(), color.stroke_width(1)))?;
            }
            for run in unbroken_runs(&line.convergence_s) {
                draw_dotted_line(&mut convergence, &run, color)?;
            }
            // The legend is narrow: the controller and the team size (the table names the
            // model).
            entries.push((
                Mark::Line(color),
                format!("{} N={}", line.controller, line.robots),
            ));
        }
        if !entries.is_empty() {
            entries.insert(0, (Mark::Heading, "thin: at 5 %".to_owned()));
            entries.insert(0, (Mark::Heading, "thick: at 10 %".to_owned()));
        }
        draw_legend(&legend, 44, &entries)
    })
}

/// `expert`, or `policy <model id>`.
fn scaling_driver(row: &formation_schema::ScalingRow) -> String {
    match &row.model {
        Some(id) => format!("{} {id}", row.controller),
        None => row.controller.clone(),
    }
}

/// Per-stage latency: a box from p50 to p90, a whisker to p99, a dot at the maximum, on a log
/// scale in microseconds; the paper's inference time as a dashed line.
pub fn latency_figure(
    id: &str,
    stages: &[StageLatency],
    paper_ms: Option<f64>,
) -> Result<Figure, ReportError> {
    let width = (200 + 110 * stages.len() as u32).max(560) + LEGEND_WIDTH;
    render(id, (width, 440), |root| {
        let (plot, legend) = root.split_horizontally(width - LEGEND_WIDTH);
        let values = stages
            .iter()
            .flat_map(|s| [Some(s.p50_us), s.p90_us, s.p99_us, s.max_us])
            .flatten()
            .chain(paper_ms.map(|ms| ms * 1000.0));
        let (lo, hi) = log_bounds(values.filter(|v| *v > 0.0));
        let n = stages.len().max(1);
        let mut chart = ChartBuilder::on(&plot)
            .caption("latency per stage", text_style(19.0))
            .margin(8)
            .x_label_area_size(34)
            .y_label_area_size(70)
            .build_cartesian_2d(-0.6..n as f64 - 0.4, (lo..hi).log_scale())?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(0)
            .x_label_formatter(&|_| String::new())
            .y_desc("latency [µs]")
            .y_label_formatter(&|v| tick_label(*v))
            .house_style(16.0)
            .draw()?;
        let label_style = text_style(16.0).pos(Pos::new(HPos::Center, VPos::Top));
        let floor = lo;
        for (s, stage) in stages.iter().enumerate() {
            let x = s as f64;
            let half = 0.25;
            let p50 = stage.p50_us.max(floor);
            let p90 = stage.p90_us.unwrap_or(p50).max(floor);
            chart.draw_series(std::iter::once(
                EmptyElement::at((x, lo))
                    + Text::new(stage.name.clone(), (0, 8), label_style.clone()),
            ))?;
            chart.draw_series([
                Rectangle::new([(x - half, p50), (x + half, p90)], BOX.mix(0.22).filled()),
                Rectangle::new([(x - half, p50), (x + half, p90)], BOX.stroke_width(1)),
            ])?;
            chart.draw_series(std::iter::once(PathElement::new(
                vec![(x - half, p50), (x + half, p50)],
                INK.stroke_width(3),
            )))?;
            if let Some(p99) = stage.p99_us {
                let p99 = p99.max(floor);
                chart.draw_series([
                    PathElement::new(vec![(x, p90), (x, p99)], INK.stroke_width(1)),
                    PathElement::new(
                        vec![(x - half / 2.0, p99), (x + half / 2.0, p99)],
                        INK.stroke_width(1),
                    ),
                ])?;
            }
            if let Some(max) = stage.max_us {
                chart.draw_series(std::iter::once(Circle::new(
                    (x, max.max(floor)),
                    4,
                    PAPER.filled(),
                )))?;
            }
        }
        if let Some(ms) = paper_ms {
            chart.draw_series(DashedLineSeries::new(
                vec![(-0.6, ms * 1000.0), (n as f64 - 0.4, ms * 1000.0)],
                6,
                4,
                PAPER.stroke_width(2),
            ))?;
        }
        let mut entries = vec![
            (Mark::Line(INK), "median (p50)".to_owned()),
            (Mark::Box, "p50 – p90".to_owned()),
            (Mark::Thin(INK), "p90 – p99".to_owned()),
            (Mark::Dot(PAPER), "maximum".to_owned()),
        ];
        if let Some(ms) = paper_ms {
            entries.push((Mark::Dashed(PAPER), format!("paper {} ms", trim_number(ms))));
        }
        draw_legend(&legend, 44, &entries)
    })
}

fn positive_points(xs: &[f64], ys: &[f64]) -> Vec<(f64, f64)> {
    xs.iter()
        .zip(ys)
        .map(|(&x, &y)| (x, y))
        .filter(|&(x, y)| x.is_finite() && y.is_finite() && y > 0.0)
        .collect()
}

/// Bounds of a log axis covering the positive values with a little room; `1..10` for none.
fn log_bounds(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite() && *v > 0.0)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if lo > hi {
        return (1.0, 10.0);
    }
    (lo / 1.5, hi * 1.5)
}

/// An axis tick label: up to six decimals without trailing zeros (`10`, `0.72`, `0.005`), no
/// decimals from 1000 on.
pub fn tick_label(value: f64) -> String {
    if value.abs() >= 1000.0 {
        return format!("{value:.0}");
    }
    formation_schema::trim_decimals(value, 6)
}

/// A number without trailing zeros (`0.7`, `2`, `2.15`).
pub use formation_schema::trim_number;

/// The response figure: each controller's slope (log-scaled label size on x) per team size, one
/// colour per row of the curve; a bin with too few samples to be judged is drawn hollow.
pub fn response_figure(
    id: &str,
    curve: &formation_schema::ResponseCurve,
) -> Result<Figure, ReportError> {
    let slope_max = curve
        .rows
        .iter()
        .flat_map(|r| r.bins.iter().filter_map(|b| b.slope))
        .fold(1.2_f64, f64::max)
        .min(5.0);
    let slope_min = curve
        .rows
        .iter()
        .flat_map(|r| r.bins.iter().filter_map(|b| b.slope))
        .fold(0.0_f64, f64::min)
        .max(-1.0);
    let (width, height) = (960_u32, 400_u32);
    render(id, (width, height), |root| {
        let (plot, legend) = root.split_horizontally(width - LEGEND_WIDTH);
        let mut chart = ChartBuilder::on(&plot)
            .caption("slope against the expert's label size", text_style(19.0))
            .margin(8)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d((0.04_f64..1.0_f64).log_scale(), slope_min..slope_max)?;
        configure_mesh_labelled(&mut chart, "label size [m/s]", "slope", &|v| {
            formation_schema::trim_number(*v)
        })?;
        chart.draw_series(LineSeries::new(
            [(0.04, 1.0), (1.0, 1.0)],
            BLACK.mix(0.3).stroke_width(1),
        ))?;
        let mut entries = Vec::new();
        for (k, row) in curve.rows.iter().enumerate() {
            let color = robot_color(k);
            let points: Vec<(f64, f64, bool)> = row
                .bins
                .iter()
                .filter_map(|b| {
                    b.slope.map(|s| {
                        (
                            (b.label_min * b.label_max).sqrt(),
                            s.clamp(slope_min, slope_max),
                            b.judged,
                        )
                    })
                })
                .collect();
            chart.draw_series(LineSeries::new(
                points.iter().map(|&(x, y, _)| (x, y)),
                color.stroke_width(2),
            ))?;
            chart.draw_series(points.iter().map(|&(x, y, judged)| {
                let style = if judged {
                    color.filled()
                } else {
                    color.stroke_width(1)
                };
                Circle::new((x, y), 4, style)
            }))?;
            entries.push((
                Mark::Line(color),
                format!("{} N = {}", row.controller, row.robots),
            ));
        }
        draw_legend(&legend, 44, &entries)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_proto::{Pose, WheelCmd};

    #[test]
    fn the_team_size_axis_holds_whole_sizes_around_one_size_or_many() {
        assert_eq!(team_size_range([16]), 15.0..17.0);
        assert_eq!(team_size_range([1]), 0.0..2.0);
        let many = team_size_range([3, 5, 8, 13, 16, 32, 64]);
        assert!(
            many.start <= 3.0 - 1.0 && many.end >= 64.0 + 1.0,
            "{many:?}"
        );
        assert_eq!(team_size_label(16.0), "16");
        assert_eq!(team_size_label(15.6), "");
        assert_eq!(team_size_label(16.4), "");
        let row = crate::fixtures::scaling_row("expert", None, 16, 1.0);
        let table = formation_schema::ScalingTable {
            scenario: "teams".into(),
            seed: 1,
            duration_s: 60.0,
            rows: vec![row],
        };
        let figure = scaling_figure("scaling", &table).unwrap();
        // Every text element's content (plotters writes it on the line after the tag).
        let texts: Vec<&str> = figure
            .svg
            .split("<text")
            .skip(1)
            .filter_map(|t| Some(t[t.find('>')? + 1..t.find("</text>")?].trim()))
            .collect();
        assert!(texts.contains(&"16"), "the size is labelled: {texts:?}");
        assert!(
            !texts
                .iter()
                .any(|t| t.starts_with("15.") || t.starts_with("16.")),
            "no fraction of a robot: {texts:?}"
        );
    }

    /// Three robots moving along +x, the formation shrinking towards `d*`.
    fn traj(samples: usize) -> Trajectory {
        let dt = 0.1;
        let times: Vec<f64> = (0..samples).map(|k| k as f64 * dt).collect();
        let poses = times
            .iter()
            .map(|&t| {
                let s = 1.0 + 0.5 * (-t).exp();
                vec![
                    Pose::new(t, 0.0, 0.1),
                    Pose::new(t + s, 0.0, 0.0),
                    Pose::new(t + 0.5 * s, 0.8 * s, -0.1),
                ]
            })
            .collect();
        Trajectory {
            dt,
            d_star: 1.0,
            v_star: 0.7,
            edges: vec![(0, 1), (0, 2), (1, 2)],
            neighbours: formation_proto::NeighbourRule::AllPairs,
            times: times.clone(),
            phi_star: vec![0.0; samples],
            poses,
            commands: vec![
                vec![
                    WheelCmd {
                        left: 0.6,
                        right: 0.8
                    };
                    3
                ];
                samples - 1
            ],
            collisions: vec![],
        }
    }

    /// The point count of every polyline stroked in `color`, in drawing order (a legend's sample
    /// line is a 2-point polyline drawn after the data).
    fn polyline_lengths(svg: &str, color: RGBColor) -> Vec<usize> {
        let stroke = format!("stroke=\"#{:02X}{:02X}{:02X}\"", color.0, color.1, color.2);
        svg.split("<polyline")
            .skip(1)
            .filter_map(|tag| {
                let tag = &tag[..tag.find("/>")?];
                if !tag.contains(&stroke) {
                    return None;
                }
                let start = tag.find("points=\"")? + 8;
                let end = start + tag[start..].find('"')?;
                Some(tag[start..end].split_whitespace().count())
            })
            .collect()
    }

    #[test]
    fn each_robot_and_edge_line_has_one_point_per_sample() {
        let t = traj(101);
        let errors = errors_figure("e", &t).expect("draws");
        for k in 0..3 {
            assert_eq!(
                polyline_lengths(&errors.svg, edge_color(k)),
                vec![101, 2],
                "edge {k}"
            );
        }
        let wheels = wheels_figure("w", &t).expect("draws");
        // Left and right panels: one line per robot each, one point per command.
        for i in 0..3 {
            assert_eq!(
                polyline_lengths(&wheels.svg, robot_color(i)),
                vec![100, 2, 100, 2],
                "robot {i}"
            );
        }
        assert!(wheels.svg.contains("v* = 0.7 m/s"));
        let paths = trajectory_figure("t", &t).expect("draws");
        for i in 0..3 {
            let lengths = polyline_lengths(&paths.svg, robot_color(i));
            assert_eq!(lengths.len(), 1, "one path per robot");
        }
    }

    #[test]
    fn trajectory_draws_a_triangle_per_robot_per_snapshot() {
        let t = traj(101); // 10 s: snapshots at 0, 3, 6, 9 s
        let svg = trajectory_figure("t", &t).expect("draws").svg;
        let fill = |c: RGBColor| format!("fill=\"#{:02X}{:02X}{:02X}\"", c.0, c.1, c.2);
        let polygons: Vec<&str> = svg.split("<polygon").skip(1).collect();
        for i in 0..3 {
            // 4 snapshots, plus the legend marker.
            assert_eq!(
                polygons
                    .iter()
                    .filter(|p| p.contains(&fill(robot_color(i))))
                    .count(),
                5
            );
        }
        assert!(svg.contains("robot 3") && svg.contains("formation"));
        assert!(!svg.contains("collision"));
        let mut hit = t.clone();
        hit.collisions.push((5, 0, 1));
        assert!(
            trajectory_figure("t", &hit)
                .expect("draws")
                .svg
                .contains("collision")
        );
    }

    #[test]
    fn changing_the_data_changes_the_figure() {
        let t = traj(60);
        let mut moved = t.clone();
        moved.poses[30][1].x += 2.0;
        assert_ne!(
            trajectory_figure("t", &t).expect("draws").svg,
            trajectory_figure("t", &moved).expect("draws").svg
        );
        assert_ne!(
            errors_figure("e", &t).expect("draws").svg,
            errors_figure("e", &moved).expect("draws").svg
        );
        let mut faster = t.clone();
        faster.commands[10][0].left = 0.9;
        assert_ne!(
            wheels_figure("w", &t).expect("draws").svg,
            wheels_figure("w", &faster).expect("draws").svg
        );
        assert_eq!(
            wheels_figure("w", &t).expect("draws").svg,
            wheels_figure("w", &t.clone()).expect("draws").svg
        );
    }

    #[test]
    fn trajectory_axes_have_equal_scale() {
        let t = traj(101);
        let svg = trajectory_figure("t", &t).expect("draws").svg;
        // The path of robot 1 runs along y = 0 from x = 0 to x = 10 m, robot 3 is 0.8 s above it at
        // t = 10 s (s ~ 1): compare pixel distances per metre on the two axes.
        let points = |c: RGBColor| -> Vec<(f64, f64)> {
            let stroke = format!("stroke=\"#{:02X}{:02X}{:02X}\"", c.0, c.1, c.2);
            let tag = svg
                .split("<polyline")
                .find(|t| t.contains(&stroke))
                .expect("path");
            let start = tag.find("points=\"").expect("points") + 8;
            let end = start + tag[start..].find('"').expect("end");
            tag[start..end]
                .split_whitespace()
                .map(|p| {
                    let (x, y) = p.split_once(',').expect("x,y");
                    (x.parse().expect("x"), y.parse().expect("y"))
                })
                .collect()
        };
        let r1 = points(robot_color(0));
        let r3 = points(robot_color(2));
        let px_per_m_x = (r1[100].0 - r1[0].0) / 10.0;
        let last = &t.poses[100];
        let px_per_m_y = (r1[100].1 - r3[100].1) / (last[2].y - last[0].y);
        assert!(
            (px_per_m_x / px_per_m_y - 1.0).abs() < 0.05,
            "x {px_per_m_x} px/m, y {px_per_m_y} px/m"
        );
    }

    #[test]
    fn box_figure_places_quartiles() {
        let q = Quantiles {
            min: 1.0,
            q1: 2.0,
            median: 3.0,
            q3: 4.0,
            max: 5.0,
            count: 4,
        };
        let panel = |stats| BoxPanel {
            title: "convergence time".into(),
            y_desc: "time [s]".into(),
            groups: vec![BoxGroup {
                label: "table1".into(),
                stats,
                dots: vec![1.0, 2.5, 3.5, 5.0],
            }],
            paper_median: Some(10.0),
        };
        let svg = box_figure("b", &[panel(Some(q))]).expect("draws").svg;
        assert!(svg.contains("table1 (n = 4)"));
        let blue_dots = svg.matches("<circle").count();
        assert_eq!(blue_dots, 4 + 1, "one dot per run and the legend's");
        let moved = box_figure("b", &[panel(Some(Quantiles { median: 3.5, ..q }))])
            .expect("draws")
            .svg;
        assert_ne!(svg, moved);
        let empty = box_figure("b", &[panel(None)]).expect("draws").svg;
        assert!(empty.contains("no successful run"));
    }

    #[test]
    fn loss_and_latency_figures() {
        let curve = LossCurve {
            source: "l.csv".into(),
            epochs: vec![1.0, 2.0, 3.0, 4.0],
            train_loss: vec![0.1, 0.05, 0.0, 0.04],
            val_loss: vec![0.2, 0.1, 0.08, 0.07],
        };
        let svg = loss_figure("l", &curve).expect("draws").svg;
        assert_eq!(
            polyline_lengths(&svg, robot_color(0)),
            vec![3, 2],
            "the zero loss is left out"
        );
        assert_eq!(polyline_lengths(&svg, robot_color(1)), vec![4, 2]);
        let stages = vec![
            StageLatency {
                name: "scan".into(),
                p50_us: 50.0,
                p90_us: Some(70.0),
                p99_us: Some(90.0),
                max_us: Some(200.0),
                count: None,
            },
            StageLatency {
                name: "inference".into(),
                p50_us: 900.0,
                p90_us: None,
                p99_us: None,
                max_us: None,
                count: Some(3),
            },
        ];
        let svg = latency_figure("p", &stages, Some(2.1)).expect("draws").svg;
        assert!(
            svg.contains(">\nscan\n") && svg.contains(">\ninference\n"),
            "stage labels"
        );
        assert!(svg.contains("paper 2.1 ms"));
    }

    #[test]
    fn numbers_are_trimmed() {
        assert_eq!(tick_label(10.0), "10");
        assert_eq!(tick_label(0.1 + 0.2), "0.3");
        assert_eq!(tick_label(-0.0000001), "0");
        assert_eq!(tick_label(12500.0), "12500");
        assert_eq!(trim_number(0.7), "0.7");
        assert_eq!(trim_number(2.0), "2");
        assert_eq!(trim_number(-0.0001), "0");
        assert_eq!(trim_number(3.756), "3.756");
    }

    /// `n` robots on parallel lines, `samples` samples.
    fn team_traj(n: usize, samples: usize) -> Trajectory {
        let dt = 0.1;
        let times: Vec<f64> = (0..samples).map(|k| k as f64 * dt).collect();
        let poses = times
            .iter()
            .map(|&t| {
                (0..n)
                    .map(|i| Pose {
                        x: t,
                        y: i as f64,
                        theta: 0.01 * i as f64,
                    })
                    .collect()
            })
            .collect();
        Trajectory {
            dt,
            d_star: 1.0,
            v_star: 0.7,
            edges: (1..n).map(|i| (i - 1, i)).collect(),
            neighbours: formation_proto::NeighbourRule::AllPairs,
            times: times.clone(),
            phi_star: vec![0.0; samples],
            poses,
            commands: vec![
                (0..n)
                    .map(|i| WheelCmd {
                        left: 0.5 + 0.01 * i as f64,
                        right: 0.6
                    })
                    .collect();
                samples - 1
            ],
            collisions: vec![],
        }
    }

    /// The legend texts of a figure `width` wide (those in the strip right of the plots): their
    /// label, `y` and font size.
    fn legend_texts(svg: &str, width: u32) -> Vec<(String, f64, f64)> {
        let attr = |tag: &str, name: &str| -> Option<f64> {
            let start = tag.find(&format!(" {name}=\""))? + name.len() + 3;
            tag[start..start + tag[start..].find('"')?].parse().ok()
        };
        svg.split("<text")
            .skip(1)
            .filter_map(|t| {
                let tag = &t[..t.find('>')?];
                let label = t[t.find('>')? + 1..t.find("</text>")?].trim().to_owned();
                let x = attr(tag, "x")?;
                (x >= f64::from(width - LEGEND_WIDTH))
                    .then(|| Some((label, attr(tag, "y")?, attr(tag, "font-size")?)))?
            })
            .collect()
    }

    #[test]
    fn legends_never_overlap_at_any_team_size() {
        for n in [3, 16, 32, 64] {
            let traj = team_traj(n, 40);
            for figure in [
                errors_figure("e", &traj).unwrap(),
                wheels_figure("w", &traj).unwrap(),
                trajectory_figure("t", &traj).unwrap(),
            ] {
                let texts = legend_texts(&figure.svg, 640);
                let labels: Vec<&str> = texts.iter().map(|t| t.0.as_str()).collect();
                assert!(texts.len() >= 3, "{n} robots, {}: {labels:?}", figure.id);
                for (a, (label_a, ya, size_a)) in texts.iter().enumerate() {
                    assert!(
                        *ya - size_a / 2.0 >= 0.0 && *ya + size_a / 2.0 <= 600.0,
                        "{n} robots, {}: {label_a} at y = {ya} is off the figure",
                        figure.id
                    );
                    for (label_b, yb, size_b) in &texts[a + 1..] {
                        assert!(
                            (ya - yb).abs() >= size_a.max(*size_b),
                            "{n} robots, {}: {label_a:?} at y = {ya} and {label_b:?} at y = {yb} overlap",
                            figure.id
                        );
                    }
                }
                // The wheel and orientation legends keep their reference lines.
                if figure.id == "w" {
                    assert_eq!(
                        labels.iter().filter(|l| l.starts_with("v* = 0.7")).count(),
                        2,
                        "{n} robots: {labels:?}"
                    );
                }
                if n > ROBOT_COLORS.len() {
                    // Robots share a row per colour (an explicit edge list may still be cut
                    // short, with a `+ N more` row).
                    assert!(
                        figure.id == "e" || !labels.iter().any(|l| l.contains("more")),
                        "{n} robots, {}: every colour is named: {labels:?}",
                        figure.id
                    );
                    assert!(labels.iter().any(|l| l.starts_with("1, 11")), "{labels:?}");
                }
            }
        }
        // The legend of the three-robot figures names each robot.
        let svg = wheels_figure("w", &team_traj(3, 40)).unwrap().svg;
        let labels: Vec<String> = legend_texts(&svg, 640).into_iter().map(|t| t.0).collect();
        assert!(labels.iter().any(|l| l == "robot 3"), "{labels:?}");
    }
}
