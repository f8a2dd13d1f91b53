//! A reality ladder (`formation eval --ladder PROFILE --json`, format `formation-ladder`) as
//! the lines its figure draws, without drawing: one line per controller (and model) and team
//! size, one point per rung, so the reader sees which effect costs what. Pure; the figure is
//! [`crate::figures::ladder_figure`].

use formation_schema::{LadderTable, ScalingRow};

/// One controller at one team size across the rungs.
#[derive(Debug, Clone, PartialEq)]
pub struct LadderLine {
    /// `expert`, or `policy <model id>`.
    pub driver: String,
    /// The controller alone (`expert`, `policy`), for a narrow legend.
    pub controller: String,
    /// Team size.
    pub robots: usize,
    /// Success at 10 % \[%\] on each rung (`None`: no row there, e.g. a policy that cannot
    /// drive the rung's LIDAR).
    pub success_10: Vec<Option<f64>>,
    /// Success at 5 % \[%\] on each rung.
    pub success_5: Vec<Option<f64>>,
    /// Median convergence time \[s\] on each rung (`None`: no row, or no run converged).
    pub convergence_s: Vec<Option<f64>>,
}

/// Everything the ladder figure draws.
#[derive(Debug, Clone, PartialEq)]
pub struct LadderSeries {
    /// The rungs' names, in order (`ideal`, `geometry and speed`, ...).
    pub rungs: Vec<String>,
    /// One line per controller and team size, in the order the table first lists them.
    pub lines: Vec<LadderLine>,
}

/// `expert`, or `policy <model id>`.
fn driver(row: &ScalingRow) -> String {
    match &row.model {
        Some(id) => format!("{} {id}", row.controller),
        None => row.controller.clone(),
    }
}

/// The lines of `table`'s figure.
pub fn ladder_series(table: &LadderTable) -> LadderSeries {
    let rungs: Vec<String> = table.rungs.iter().map(|r| r.rung.clone()).collect();
    let mut lines: Vec<LadderLine> = Vec::new();
    for (index, rung) in table.rungs.iter().enumerate() {
        for row in &rung.rows {
            let who = driver(row);
            let at = match lines
                .iter()
                .position(|l| l.driver == who && l.robots == row.robots)
            {
                Some(at) => at,
                None => {
                    lines.push(LadderLine {
                        driver: who,
                        controller: row.controller.clone(),
                        robots: row.robots,
                        success_10: vec![None; rungs.len()],
                        success_5: vec![None; rungs.len()],
                        convergence_s: vec![None; rungs.len()],
                    });
                    lines.len() - 1
                }
            };
            let line = &mut lines[at];
            line.success_10[index] = Some(100.0 * row.success_rate_10);
            line.success_5[index] = Some(100.0 * row.success_rate_5);
            line.convergence_s[index] = row.convergence_s.map(|q| q.median);
        }
    }
    LadderSeries { rungs, lines }
}

/// The runs of `values` without a gap: each a list of `(rung index, value)`, so a line is not
/// drawn across a rung that has no value.
pub fn unbroken_runs(values: &[Option<f64>]) -> Vec<Vec<(f64, f64)>> {
    let mut runs: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut current: Vec<(f64, f64)> = Vec::new();
    for (index, value) in values.iter().enumerate() {
        match value {
            Some(v) if v.is_finite() => current.push((index as f64, *v)),
            _ => {
                if !current.is_empty() {
                    runs.push(std::mem::take(&mut current));
                }
            }
        }
    }
    if !current.is_empty() {
        runs.push(current);
    }
    runs
}

/// A rung's name as an axis label: ` and ` shortened to ` & ` so eight names fit side by side.
pub fn rung_label(name: &str) -> String {
    name.replace(" and ", " & ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::scaling_row as row;
    use formation_schema::LadderRung;

    fn table() -> LadderTable {
        let rung = |name: &str, rows: Vec<ScalingRow>, refused: Option<&str>| LadderRung {
            rung: name.into(),
            added: Vec::new(),
            rows,
            policy_refused: refused.map(Into::into),
        };
        LadderTable {
            profile: "turtlebot3-burger".into(),
            scenario: "table1".into(),
            seed: 7,
            duration_s: 60.0,
            rungs: vec![
                rung(
                    "ideal",
                    vec![
                        row("expert", None, 3, 1.0),
                        row("policy", Some("policy-a"), 3, 0.9),
                        row("expert", None, 8, 0.95),
                    ],
                    None,
                ),
                rung(
                    "lidar geometry",
                    vec![row("expert", None, 3, 0.8), row("expert", None, 8, 0.5)],
                    Some("the model was trained on 900 beams"),
                ),
                rung(
                    "geometry and speed",
                    vec![
                        row("expert", None, 3, 0.7),
                        row("policy", Some("policy-a"), 3, 0.6),
                    ],
                    None,
                ),
            ],
        }
    }

    #[test]
    fn one_line_per_controller_and_team_size_with_a_gap_where_a_rung_has_no_row() {
        let series = ladder_series(&table());
        assert_eq!(
            series.rungs,
            ["ideal", "lidar geometry", "geometry and speed"]
        );
        let keys: Vec<(&str, usize)> = series
            .lines
            .iter()
            .map(|l| (l.driver.as_str(), l.robots))
            .collect();
        assert_eq!(keys, [("expert", 3), ("policy policy-a", 3), ("expert", 8)]);
        let policy = &series.lines[1];
        assert_eq!(policy.controller, "policy");
        assert_eq!(policy.success_10, [Some(90.0), None, Some(60.0)]);
        assert_eq!(policy.convergence_s, [Some(5.0), None, Some(5.0)]);
        let expert8 = &series.lines[2];
        assert_eq!(expert8.success_10, [Some(95.0), Some(50.0), None]);
        assert!((expert8.success_5[0].unwrap() - 85.0).abs() < 1e-9);
        assert_eq!(
            unbroken_runs(&policy.success_10),
            [vec![(0.0, 90.0)], vec![(2.0, 60.0)]]
        );
        assert_eq!(
            unbroken_runs(&expert8.success_10),
            [vec![(0.0, 95.0), (1.0, 50.0)]]
        );
        assert_eq!(rung_label("geometry and speed"), "geometry & speed");
    }

    #[test]
    fn a_ladder_file_of_another_format_or_version_is_refused_by_name() {
        let dir =
            std::env::temp_dir().join(format!("formation-report-ladder-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("ladder.json");
        let bytes = formation_schema::to_json_pretty(&table()).unwrap();
        let mut value: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
        // As written, it reads back.
        std::fs::write(&path, value.to_string()).unwrap();
        assert_eq!(formation_schema::read_ladder(&path).unwrap(), table());

        value["schema_version"] = serde_json::json!(2);
        std::fs::write(&path, value.to_string()).unwrap();
        let version = crate::input::load_inputs(&dir).unwrap_err().to_string();
        value["schema_version"] = serde_json::json!(1);
        value["format"] = serde_json::json!("formation-scaling");
        std::fs::write(&path, value.to_string()).unwrap();
        let format = crate::input::load_inputs(&dir).unwrap_err().to_string();
        std::fs::remove_dir_all(&dir).unwrap();
        let shown = path.display();
        assert!(
            version.starts_with(&format!(
                "{shown} is a formation reality ladder of schema version 2; this build reads"
            )),
            "{version}"
        );
        assert_eq!(
            format,
            format!(
                "{shown} is not a formation reality ladder: its format is `formation-scaling`, \
                 expected `formation-ladder`"
            )
        );
    }
}
