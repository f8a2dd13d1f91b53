//! Table I and the Fig. 9 medians of an evaluation as the terminal shows them, shared by
//! `formation eval`, `run`, `dagger` and `demo`.

use formation_schema::EvalOutput;

/// Formats Table I and the Fig. 9 medians as text, with the runs each median covers when the
/// rule leaves some out, a team size or v* its model was not trained on, and the incomplete runs, if
/// any.
pub fn table_text(out: &EvalOutput) -> String {
    let mut text = table_i_text(out);
    // A team size its model was not trained on, and a v* it was not trained at, are marked on
    // the table itself, as on the terminal before the runs and in the JSON (`team_size`,
    // `goal_speed`).
    let team_size = out.team_size.iter().filter_map(|t| t.describe());
    let goal_speed = out.goal_speed.iter().filter_map(|g| g.describe());
    for line in team_size.chain(goal_speed) {
        text.push_str(&format!("{line}\n"));
    }
    let incomplete = out.summary.runs_incomplete.max(out.incomplete_runs.len());
    if incomplete > 0 {
        text.push_str(&format!(
            "incomplete runs: {incomplete} of {}, counted as failures (stopped early{})\n",
            out.summary.runs,
            out.incomplete_runs
                .first()
                .and_then(|r| r.stop_reason.as_deref())
                .map(|reason| format!(": {reason}"))
                .unwrap_or_default()
        ));
    }
    text
}

/// `  (over 3 of the 7: 4 succeeded without converging)` after a median whose rule leaves out
/// some of the runs successful at 10 %; empty when it covers them all.
fn coverage_note(coverage: Option<&formation_schema::Coverage>, left_out_because: &str) -> String {
    match coverage {
        Some(c) if c.runs < c.of => format!(
            "   over {} of the {}: {} {left_out_because}",
            c.runs,
            c.of,
            c.of - c.runs
        ),
        _ => String::new(),
    }
}

fn table_i_text(out: &EvalOutput) -> String {
    let s = &out.summary;
    let pct = |x: f64| format!("{:.1} %", 100.0 * x);
    let opt = |x: Option<f64>, f: &dyn Fn(f64) -> String| x.map(f).unwrap_or_else(|| "-".into());
    let over = s.medians_over.as_ref();
    format!(
        "Table I ({} controller, {} runs of {}, seed {})\n\
         \x20 success at 5 %:   {:>8}   (paper: 90 %)\n\
         \x20 success at 10 %:  {:>8}   (paper: 96 %)\n\
         Fig. 9 medians over runs successful at 10 %{}\n\
         \x20 convergence time: {:>8}   (paper: ~10 s){}\n\
         \x20 formation error:  {:>8}   (paper: 2.5 %){}\n\
         \x20 orientation err.: {:>8}   (paper: 0.031 rad){}\n\
         runs with collisions: {}\n",
        out.controller,
        s.runs,
        out.scenario,
        out.seed
            .map_or_else(|| "unknown".to_owned(), |seed| seed.to_string()),
        pct(s.success_rate_5),
        pct(s.success_rate_10),
        over.map(|o| format!(" ({} runs)", o.rel_formation_error.of))
            .unwrap_or_default(),
        opt(s.median_convergence_s, &|x| format!("{x:.2} s")),
        coverage_note(
            over.map(|o| &o.convergence_s),
            "never stayed below 10 % to the end (not converged)"
        ),
        opt(s.median_rel_formation_error, &|x| format!(
            "{:.2} %",
            100.0 * x
        )),
        coverage_note(over.map(|o| &o.rel_formation_error), "without a value"),
        opt(s.median_orientation_error_rad, &|x| format!("{x:.3} rad")),
        coverage_note(over.map(|o| &o.orientation_error_rad), "without a value"),
        s.collisions,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_learning::eval_output;
    use formation_world::metrics::{RunMetrics, TicksPlayed};

    fn run(success_10: bool, convergence_s_10: Option<f64>) -> RunMetrics {
        RunMetrics {
            success_5: success_10,
            success_10,
            convergence_s_5: convergence_s_10,
            convergence_s_10,
            rel_formation_error: 0.01,
            max_edge_window_error: 0.02,
            orientation_error_rad: 0.01,
            collisions: 0,
            team: None,
            incomplete: None,
        }
    }

    #[test]
    fn the_table_says_which_runs_each_median_covers_and_how_many_were_incomplete() {
        let mut runs: Vec<RunMetrics> = (0..7).map(|k| run(true, (k < 3).then_some(4.0))).collect();
        let mut cut = run(false, Some(2.0));
        cut.incomplete = Some(TicksPlayed {
            ticks: 392,
            planned_ticks: 1200,
        });
        runs.push(cut);
        let out = eval_output("expert", Vec::new(), "accel", Some(7), runs);
        let text = table_text(&out);
        assert!(
            text.contains("Fig. 9 medians over runs successful at 10 % (7 runs)"),
            "{text}"
        );
        assert!(
            text.contains("over 3 of the 7: 4 never stayed below 10 % to the end (not converged)"),
            "{text}"
        );
        assert!(
            text.contains("incomplete runs: 1 of 8, counted as failures"),
            "{text}"
        );
        assert!(text.contains("success at 10 %:    87.5 %"), "{text}");

        // A complete evaluation whose successful runs all converged: no note.
        let out = eval_output(
            "expert",
            Vec::new(),
            "t",
            Some(7),
            vec![run(true, Some(3.0))],
        );
        let text = table_text(&out);
        assert!(
            !text.contains(" of the ") && !text.contains("incomplete"),
            "{text}"
        );
    }
}
