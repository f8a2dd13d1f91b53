//! `formation eval --ladder PROFILE`: the reality ladder. The base scenario, then a robot
//! profile's effects added one at a time, cumulatively ([`RobotProfile::ladder`]), each rung
//! evaluated as the scaling table evaluates a team size: the expert always, the policy unless
//! `--controller expert`, over the same runs and seed. The table says which effect costs what.

use std::time::Instant;

use anyhow::Context;
use formation_expert::ExpertGains;
use formation_learning::rollout::with_threads;
use formation_learning::scaling::{ScalingDriver, evaluate_scaling};
use formation_schema::{LadderRung, LadderTable};
use formation_world::Scenario;
use formation_world::scenario::RobotProfile;

use crate::args::{ControllerKind, EvalArgs};
use crate::eval::{print_and_write_json, progress_bar};
use crate::paths;
use crate::team_models::policy_driver;

/// The profile named `name`, or an error listing the known ones.
pub fn profile_named(name: &str) -> anyhow::Result<RobotProfile> {
    Ok(RobotProfile::named_by_flag("--ladder", name)?)
}

/// `formation eval --ladder PROFILE` (dispatched before the other `eval` forms).
pub fn ladder_command(args: &EvalArgs) -> anyhow::Result<()> {
    crate::eval::refuse_gains_without_own_scan(args)?;
    let Some(profile_name) = args.ladder.as_deref() else {
        anyhow::bail!("--ladder PROFILE names the profile whose ladder to walk");
    };
    let profile = profile_named(profile_name)?;
    // A path that cannot be written, or one that is an input, is refused before the runs.
    if let Some(json) = &args.json {
        formation_proto::files::check_output_file(json)?;
        let mut inputs: Vec<(&'static str, &std::path::Path)> =
            vec![("--scenario", &args.scenario)];
        if let Some(model) = &args.model {
            inputs.push(("--model", model));
        }
        paths::refuse_overwriting_inputs(&[("--json", json, "ladder.json")], &[], &inputs)?;
    }
    if args.processes
        || args.out.is_some()
        || args.save_trajectories.is_some()
        || args.record.is_some()
    {
        anyhow::bail!(
            "--ladder evaluates every rung in-process and writes a table (print and --json); \
             --processes, --out, --save-trajectories and --record are for one evaluation: drop them"
        );
    }
    let base = Scenario::from_path(&args.scenario)?;
    let sizes = args.robots.clone().unwrap_or_else(|| vec![base.n_robots()]);
    let runs = args.runs.unwrap_or_else(|| base.runs());
    let seed = args.seed.unwrap_or_else(|| base.seed());
    let policy = match args.controller {
        ControllerKind::Policy => Some(policy_driver(args.model.as_deref(), &base, &sizes)?),
        ControllerKind::Expert | ControllerKind::ExpertOwnScan => None,
    };
    let own_scan = args.controller == ControllerKind::ExpertOwnScan;
    let ladder = profile.ladder();
    let drivers_per_rung = 1 + usize::from(policy.is_some()) + usize::from(own_scan);
    let per_rung = runs * sizes.len() * drivers_per_rung;
    let bar = progress_bar(per_rung * ladder.len(), "ladder");
    let started = Instant::now();
    let mut rungs = Vec::with_capacity(ladder.len());
    for (index, rung) in ladder.iter().enumerate() {
        let scenario = Scenario::from_path_overridden(&args.scenario, &rung.overrides)
            .with_context(|| {
                format!(
                    "the \"{}\" rung of the {} ladder (keys {}) does not fit scenario {}",
                    rung.name,
                    profile.name(),
                    rung.added.join(", "),
                    args.scenario.display()
                )
            })?;
        let mut drivers = vec![ScalingDriver::Expert(ExpertGains::default())];
        if own_scan {
            drivers.push(ScalingDriver::ExpertOwnScan(args.gains.unwrap_or_default()));
        }
        // A policy that cannot drive this rung (a LIDAR it was not trained on) gives no row,
        // and the rung says why; the expert's rows stand.
        let mut policy_refused = None;
        if let Some(driver @ ScalingDriver::Policy { model, .. }) = &policy {
            // Loading it for the rung's robot is the check the runs would make.
            let fits = formation_learning::Driver::policy_for(&scenario, model)
                .and_then(|d| d.controller(&scenario).map(drop));
            match fits {
                Ok(()) => drivers.push(driver.clone()),
                Err(refusal) => {
                    eprintln!("{}: no policy rows: {refusal}", rung.name);
                    policy_refused = Some(refusal.to_string());
                }
            }
        }
        let table = with_threads(args.threads, || {
            evaluate_scaling(&scenario, &sizes, seed, runs, &drivers, &|row, done| {
                bar.set_position((index * per_rung + row * runs + done) as u64)
            })
        })?
        .with_context(|| format!("evaluating the \"{}\" rung", rung.name))?;
        rungs.push(LadderRung {
            rung: rung.name.to_owned(),
            added: rung.added.iter().map(|k| (*k).to_owned()).collect(),
            rows: table.rows,
            policy_refused,
        });
    }
    bar.finish_and_clear();
    eprintln!(
        "evaluated {} runs in {:.1} s",
        per_rung * ladder.len(),
        started.elapsed().as_secs_f64()
    );
    let table = LadderTable {
        profile: profile.name().to_owned(),
        scenario: base.name().to_owned(),
        seed,
        duration_s: base.duration_s(),
        rungs,
    };
    print_and_write_json(&ladder_text(&table), &table, args.json.as_deref())
}

/// The ladder as Markdown: one line per rung, controller and team size.
pub fn ladder_text(table: &LadderTable) -> String {
    let pct = |x: f64| format!("{:.0} %", 100.0 * x);
    let mut text = format!(
        "Reality ladder of {} ({}, seed {}, {} s per run; each rung adds its effect to those \
         above it)\n\n\
         | rung | controller | N | runs | success @ 10 % | success @ 5 % | convergence, median | \
         collisions |\n|---|---|---:|---:|---:|---:|---:|---:|\n",
        table.profile, table.scenario, table.seed, table.duration_s
    );
    for rung in &table.rungs {
        for row in &rung.rows {
            let who = match &row.model {
                Some(id) => format!("{} `{id}`", row.controller),
                None => row.controller.clone(),
            };
            text.push_str(&format!(
                "| {} | {who} | {} | {} | {} | {} | {} | {} |\n",
                rung.rung,
                row.robots,
                row.runs,
                pct(row.success_rate_10),
                pct(row.success_rate_5),
                row.convergence_s
                    .map_or_else(|| "-".to_owned(), |q| format!("{:.1} s", q.median)),
                row.collisions,
            ));
        }
        if let Some(refusal) = &rung.policy_refused {
            text.push_str(&format!(
                "| {} | policy: no rows ({refusal}) | | | | | | |\n",
                rung.rung
            ));
        }
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unknown_profile_is_named_with_the_known_ones() {
        let message = profile_named("turtlebot4").unwrap_err().to_string();
        assert_eq!(
            message,
            "--ladder must name a robot profile, one of \"ideal\", \"pioneer-p3dx\", \
             \"turtlebot3-burger\" (got \"turtlebot4\")"
        );
        assert_eq!(
            profile_named("pioneer-p3dx").unwrap(),
            RobotProfile::Pioneer3dx
        );
    }

    #[test]
    fn the_text_has_a_line_per_rung_and_row() {
        let row = formation_learning::scaling::scaling_row("expert", None, 3, "all_pairs", &[]);
        let table = LadderTable {
            profile: "turtlebot3-burger".to_owned(),
            scenario: "s".to_owned(),
            seed: 1,
            duration_s: 2.0,
            rungs: vec![
                LadderRung {
                    rung: "ideal".to_owned(),
                    added: Vec::new(),
                    rows: vec![row.clone()],
                    policy_refused: None,
                },
                LadderRung {
                    rung: "motors".to_owned(),
                    added: vec!["robot.motor_tau".to_owned()],
                    rows: vec![row],
                    policy_refused: Some("900 beams, not 360".to_owned()),
                },
            ],
        };
        let text = ladder_text(&table);
        assert!(text.contains("| ideal | expert | 3 | 0 |"), "{text}");
        assert!(text.contains("| motors | expert | 3 | 0 |"), "{text}");
        assert!(
            text.contains("| motors | policy: no rows (900 beams, not 360) |"),
            "{text}"
        );
    }
}
