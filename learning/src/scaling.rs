//! The scaling table: the Table I figures of each driver on each team size, from one scenario.
//!
//! Every team size is the base scenario resized with [`Scenario::with_robots`] (its disc radius
//! and neighbour rule follow the size unless the file fixed them), evaluated over the same run
//! indices and base seed, with the team figures on (so 3-robot rows have the anchor-compatible
//! rate too).

use std::path::PathBuf;

use formation_expert::ExpertGains;
use formation_schema::{ModelGoalSpeed, ModelTeamSize, ScalingRow, ScalingTable};
use formation_world::Scenario;
use formation_world::metrics::{MetricsConfig, RunMetrics, quantiles, summarize};

use crate::LearningError;
use crate::rollout::{Driver, evaluate_runs};

/// A driver of the scaling table.
#[derive(Debug, Clone, PartialEq)]
pub enum ScalingDriver {
    /// The expert with these gains.
    Expert(ExpertGains),
    /// The expert's law with these gains on each robot's own scan ([`Driver::ExpertOwnScan`]).
    ExpertOwnScan(ExpertGains),
    /// The policy `model` (with its id) on every robot (scenario `[[agent]]` entries apply).
    Policy {
        /// The ONNX model.
        model: PathBuf,
        /// Its model id, for the table.
        id: String,
        /// The team sizes it was trained on (its envelope; empty when it records none), so
        /// that a row for another size is marked zero-shot.
        trained_team_sizes: Vec<usize>,
        /// The v* \[m/s\] it was trained at (`formation.v_train`), so that a row at another v*
        /// is marked.
        v_train: f64,
        /// What its output is (`formation.output`), for the note on a row at another v*.
        output: formation_proto::PolicyOutput,
        /// The input it declares (its occupancy window and LIDAR), for its rows.
        input: Option<formation_schema::ModelInput>,
    },
}

/// Evaluates every driver on every team size in `sizes` (in that order, drivers inner) over
/// `runs` runs of base seed `seed`. `progress(row, runs_done)` is called as runs finish.
pub fn evaluate_scaling(
    base: &Scenario,
    sizes: &[usize],
    seed: u64,
    runs: usize,
    drivers: &[ScalingDriver],
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<ScalingTable, LearningError> {
    let cfg = MetricsConfig {
        team_figures: true,
        ..MetricsConfig::default()
    };
    let mut rows = Vec::with_capacity(sizes.len() * drivers.len());
    for &robots in sizes {
        let scenario = base.with_robots(robots)?;
        for driver in drivers {
            let (run_driver, model, team_size, goal_speed, model_input) = match driver {
                ScalingDriver::Expert(gains) => (Driver::Expert(*gains), None, None, None, None),
                ScalingDriver::ExpertOwnScan(gains) => {
                    (Driver::ExpertOwnScan(*gains), None, None, None, None)
                }
                ScalingDriver::Policy {
                    model,
                    id,
                    trained_team_sizes,
                    v_train,
                    output,
                    input,
                } => (
                    Driver::policy_for(&scenario, model)?,
                    Some(id.clone()),
                    ModelTeamSize::new(id, trained_team_sizes, robots),
                    ModelGoalSpeed::new(
                        id,
                        *v_train,
                        scenario.v_star().farthest_from(*v_train),
                        *output,
                    )
                    .filter(ModelGoalSpeed::is_outside),
                    input.clone(),
                ),
            };
            let row = rows.len();
            let results = evaluate_runs(
                &scenario,
                seed,
                runs,
                &run_driver,
                &cfg,
                &|_| false,
                &|done| progress(row, done),
            )?;
            let metrics: Vec<RunMetrics> = results.into_iter().map(|r| r.metrics).collect();
            rows.push(ScalingRow {
                team_size,
                goal_speed,
                model_input,
                ..scaling_row(
                    run_driver.name(),
                    model,
                    robots,
                    scenario.neighbours().name(),
                    &metrics,
                )
            });
        }
    }
    Ok(ScalingTable {
        scenario: base.name().to_owned(),
        seed,
        duration_s: base.duration_s(),
        rows,
    })
}

/// One row of the table from its runs' metrics.
pub fn scaling_row(
    controller: &str,
    model: Option<String>,
    robots: usize,
    neighbours: &str,
    runs: &[RunMetrics],
) -> ScalingRow {
    let summary = summarize(runs);
    let anchor = runs
        .iter()
        .filter(|r| r.team.as_ref().is_some_and(|t| t.anchor_success))
        .count();
    ScalingRow {
        controller: controller.to_owned(),
        model,
        robots,
        neighbours: neighbours.to_owned(),
        runs: runs.len(),
        success_rate_5: summary.success_rate_5,
        success_rate_10: summary.success_rate_10,
        anchor_success_rate: if runs.is_empty() {
            0.0
        } else {
            anchor as f64 / runs.len() as f64
        },
        convergence_s: summary.convergence_s,
        rel_formation_error: summary.rel_formation_error,
        max_edge_window_error: quantiles(runs.iter().map(|r| r.max_edge_window_error)),
        collisions: summary.collisions,
        team_size: None,
        goal_speed: None,
        model_input: None,
    }
}

/// The table as Markdown: one line per row.
pub fn scaling_text(table: &ScalingTable) -> String {
    let pct = |x: f64| format!("{:.0} %", 100.0 * x);
    let median_iqr = |q: &Option<formation_schema::Quantiles>, scale: f64, unit: &str, digits| {
        q.map_or_else(
            || "-".to_owned(),
            |q| {
                format!(
                    "{:.d$}{unit} ({:.d$}-{:.d$})",
                    scale * q.median,
                    scale * q.q1,
                    scale * q.q3,
                    d = digits
                )
            },
        )
    };
    let mut text = format!(
        "Scaling ({}, seed {}, {} s per run; success: every edge, connected, no collision)\n\n\
         | controller | N | rule | runs | success @ 5 % | success @ 10 % | anchor-compatible | \
         convergence, median (IQR) | formation error, median (IQR) | worst edge, median | collisions |\n\
         |---|---:|---|---:|---:|---:|---:|---|---|---:|---:|\n",
        table.scenario, table.seed, table.duration_s
    );
    for row in &table.rows {
        let zero_shot = if row.team_size.as_ref().is_some_and(|t| t.zero_shot) {
            " (zero-shot)"
        } else {
            ""
        };
        let speed = row
            .goal_speed
            .as_ref()
            .filter(|g| g.is_outside())
            .map(|g| format!(" (v* {:.2}x v_train)", g.factor))
            .unwrap_or_default();
        let who = match &row.model {
            Some(id) => format!("{} `{id}`{zero_shot}{speed}", row.controller),
            None => row.controller.clone(),
        };
        text.push_str(&format!(
            "| {who} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
            row.robots,
            row.neighbours,
            row.runs,
            pct(row.success_rate_5),
            pct(row.success_rate_10),
            pct(row.anchor_success_rate),
            median_iqr(&row.convergence_s, 1.0, " s", 1),
            median_iqr(&row.rel_formation_error, 100.0, " %", 2),
            row.max_edge_window_error
                .map_or_else(|| "-".to_owned(), |q| format!("{:.2} %", 100.0 * q.median)),
            row.collisions,
        ));
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_schema::TeamMetrics;

    fn run(success_10: bool, anchor: bool, error: f64, collisions: usize) -> RunMetrics {
        RunMetrics {
            success_5: false,
            success_10,
            convergence_s_5: None,
            convergence_s_10: Some(error * 100.0),
            rel_formation_error: error,
            max_edge_window_error: 2.0 * error,
            orientation_error_rad: 0.0,
            collisions,
            team: Some(TeamMetrics {
                connected: true,
                edges_scored: 3,
                median_edge_window_error: error,
                final_mean_edge_error: error,
                final_min_distance: 1.0,
                anchor_success: anchor,
            }),
            incomplete: None,
        }
    }

    #[test]
    fn a_row_counts_rates_quartiles_and_collisions() {
        let runs = [
            run(true, true, 0.01, 0),
            run(true, true, 0.03, 0),
            run(false, true, 0.2, 1),
            run(false, false, 0.4, 0),
        ];
        let row = scaling_row("expert", None, 8, "gabriel", &runs);
        assert_eq!((row.runs, row.robots, row.collisions), (4, 8, 1));
        assert_eq!(
            (
                row.success_rate_5,
                row.success_rate_10,
                row.anchor_success_rate
            ),
            (0.0, 0.5, 0.75)
        );
        assert!((row.rel_formation_error.unwrap().median - 0.02).abs() < 1e-12);
        assert_eq!(row.max_edge_window_error.unwrap().max, 0.8);
        assert_eq!(row.convergence_s.unwrap().count, 2);
        let text = scaling_text(&ScalingTable {
            scenario: "s".into(),
            seed: 1,
            duration_s: 60.0,
            rows: vec![row],
        });
        assert!(
            text.contains("| expert | 8 | gabriel | 4 | 0 % | 50 % | 75 % | 2.0 s (1.5-2.5) |"),
            "{text}"
        );
        let empty = scaling_row("policy", Some("m".into()), 3, "all_pairs", &[]);
        assert_eq!(empty.anchor_success_rate, 0.0);
    }

    #[test]
    fn a_policy_row_for_a_size_the_model_never_saw_is_marked_zero_shot() {
        let runs = [run(true, true, 0.01, 0)];
        let row = |robots| ScalingRow {
            team_size: ModelTeamSize::new("m", &[3, 5, 8], robots),
            ..scaling_row("policy", Some("m".into()), robots, "gabriel", &runs)
        };
        let text = scaling_text(&ScalingTable {
            scenario: "s".into(),
            seed: 1,
            duration_s: 60.0,
            rows: vec![row(5), row(24)],
        });
        assert!(text.contains("| policy `m` | 5 |"), "{text}");
        assert!(text.contains("| policy `m` (zero-shot) | 24 |"), "{text}");
    }

    #[test]
    fn a_policy_row_at_a_v_star_the_model_was_not_trained_at_is_marked() {
        let runs = [run(true, true, 0.01, 0)];
        let row = |v_star| ScalingRow {
            goal_speed: ModelGoalSpeed::new(
                "m",
                0.7,
                v_star,
                formation_proto::PolicyOutput::Wheels,
            )
            .filter(ModelGoalSpeed::is_outside),
            ..scaling_row("policy", Some("m".into()), 3, "all_pairs", &runs)
        };
        let (trained, slower) = (row(0.7), row(0.4));
        assert_eq!(trained.goal_speed, None);
        let text = scaling_text(&ScalingTable {
            scenario: "s".into(),
            seed: 1,
            duration_s: 60.0,
            rows: vec![trained, slower],
        });
        assert!(text.contains("| policy `m` | 3 |"), "{text}");
        assert!(
            text.contains("| policy `m` (v* 0.57x v_train) | 3 |"),
            "{text}"
        );
    }

    #[test]
    fn the_expert_table_is_deterministic_and_names_each_size_rule() {
        let text = "name = \"s\"\nrobots = 3\nduration_s = 20.0\nseed = 3\n\
                    [goal]\nv_star = 0.7\nd_star = 1.5\n[heading]\nschedule = \"random\"\n[lidar]\nbeams = 90\n";
        let base = Scenario::from_toml_str(text, "s").unwrap();
        let drivers = [ScalingDriver::Expert(ExpertGains::default())];
        let table = evaluate_scaling(&base, &[3, 5], 3, 3, &drivers, &|_, _| {}).unwrap();
        assert_eq!(table.rows.len(), 2);
        assert_eq!(
            (table.rows[0].robots, table.rows[0].neighbours.as_str()),
            (3, "all_pairs")
        );
        assert_eq!(
            (table.rows[1].robots, table.rows[1].neighbours.as_str()),
            (5, "gabriel")
        );
        assert_eq!(
            table,
            evaluate_scaling(&base, &[3, 5], 3, 3, &drivers, &|_, _| {}).unwrap()
        );
        assert!(matches!(
            evaluate_scaling(&base, &[1], 3, 3, &drivers, &|_, _| {}),
            Err(LearningError::Scenario(_))
        ));
    }
}
