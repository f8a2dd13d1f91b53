//! An evaluation spread over workers: shares of its runs ([`EvalShard`]) and their merge into
//! the summary a single `formation eval` writes.
//!
//! Every run is a pure function of (scenario, base seed, run index, driver), so the shares of a
//! sweep hold the same per-run metrics as one evaluation, and [`merge_shards`] builds its
//! summary with the same [`eval_output`], byte for byte. The merge refuses shares of different
//! evaluations, a run held twice (a retried worker whose first attempt also finished) and a run
//! held by none, naming the runs.

use formation_schema::{EvalOutput, EvalShard, RunMetrics};
use formation_trainer_bridge::difference::FirstDifference;

use crate::rollout::eval_output;

/// Shares that do not make up one evaluation.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MergeError {
    /// Nothing to merge.
    #[error("no shards to merge: give the files `formation eval --shard` wrote")]
    Empty,
    /// Two shares of different evaluations.
    #[error(
        "shard {index} is of another evaluation than shard 0: its {field} is {found}, shard 0's \
         is {expected}; merge only the shards of one sweep cell"
    )]
    Mismatch {
        /// The share that differs, in the order given.
        index: usize,
        /// What differs (`controller`, `models`, `scenario`, `seed`, `team_size`).
        field: &'static str,
        /// Shard 0's value.
        expected: String,
        /// This share's value.
        found: String,
    },
    /// A run held by two shares.
    #[error(
        "run {run} is in two shards (runs {first:?} and {second:?}): a retried worker's shard was \
         kept twice; keep one shard per range of runs"
    )]
    Overlap {
        /// The first run held twice.
        run: usize,
        /// One share's runs.
        first: std::ops::Range<usize>,
        /// The other's.
        second: std::ops::Range<usize>,
    },
    /// Runs no share holds.
    #[error(
        "runs {missing:?} are in no shard (the evaluation has {runs} runs): evaluate them with \
         `formation eval --first-run {} --runs {} --shard FILE` and merge again",
        missing.start,
        missing.len()
    )]
    Gap {
        /// The first runs missing.
        missing: std::ops::Range<usize>,
        /// The runs the evaluation has.
        runs: usize,
    },
}

/// The runs a share holds.
fn runs_of(shard: &EvalShard) -> std::ops::Range<usize> {
    shard.first_run..shard.first_run + shard.per_run.len()
}

/// Merges the shares of one evaluation of `runs` runs (`None`: as many as the shares hold, from
/// run 0) into its summary: the [`EvalOutput`] that `formation eval` writes for all of them.
pub fn merge_shards(shards: &[EvalShard], runs: Option<usize>) -> Result<EvalOutput, MergeError> {
    let first = shards.first().ok_or(MergeError::Empty)?;
    for (index, shard) in shards.iter().enumerate().skip(1) {
        check_same_evaluation(first, shard, index)?;
    }
    let mut ordered: Vec<&EvalShard> = shards.iter().collect();
    ordered.sort_by_key(|s| (s.first_run, s.per_run.len()));
    let runs = runs.unwrap_or_else(|| ordered.iter().map(|s| runs_of(s).end).max().unwrap_or(0));
    let mut per_run: Vec<RunMetrics> = Vec::with_capacity(runs);
    let mut previous: Option<std::ops::Range<usize>> = None;
    for shard in ordered {
        let range = runs_of(shard);
        if range.is_empty() {
            continue;
        }
        if let Some(before) = &previous
            && range.start < before.end
        {
            return Err(MergeError::Overlap {
                run: range.start,
                first: before.clone(),
                second: range,
            });
        }
        if range.start > per_run.len() {
            return Err(MergeError::Gap {
                missing: per_run.len()..range.start.min(runs),
                runs,
            });
        }
        per_run.extend(shard.per_run.iter().cloned());
        previous = Some(range);
    }
    if per_run.len() < runs {
        return Err(MergeError::Gap {
            missing: per_run.len()..runs,
            runs,
        });
    }
    per_run.truncate(runs);
    let mut out = eval_output(
        &first.controller,
        first.models.clone(),
        &first.scenario,
        Some(first.seed),
        per_run,
    );
    out.team_size = first.team_size.clone();
    out.goal_speed = first.goal_speed.clone();
    out.model_inputs = first.model_inputs.clone();
    Ok(out)
}

/// Refuses `shard` when it is not of the same evaluation as `first`.
fn check_same_evaluation(
    first: &EvalShard,
    shard: &EvalShard,
    index: usize,
) -> Result<(), MergeError> {
    let difference = FirstDifference::of(first, shard)
        .display("controller", |s| &s.controller)
        .debug("models", |s| &s.models)
        .display("scenario", |s| &s.scenario)
        .display("seed", |s| s.seed)
        .debug("team_size", |s| &s.team_size)
        .debug("goal_speed", |s| &s.goal_speed)
        .debug("model_inputs", |s| &s.model_inputs)
        .found();
    match difference {
        Some((field, expected, found)) => Err(MergeError::Mismatch {
            index,
            field,
            expected,
            found,
        }),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rollout::{Driver, evaluate_run_range, evaluate_runs};
    use formation_expert::ExpertGains;
    use formation_world::Scenario;
    use formation_world::metrics::MetricsConfig;

    fn scenario() -> Scenario {
        Scenario::from_toml_str(
            "name = \"t\"\nrobots = 3\nduration_s = 8.0\nseed = 3\nruns = 7\n\
             [goal]\nv_star = 0.7\nd_star = 1.5\n[heading]\nschedule = \"random\"\n\
             [lidar]\nbeams = 90\n",
            "shards.toml",
        )
        .expect("scenario")
    }

    fn shard(scenario: &Scenario, range: std::ops::Range<usize>) -> EvalShard {
        let driver = Driver::Expert(ExpertGains::default());
        let results = evaluate_run_range(
            scenario,
            11,
            range.clone(),
            &driver,
            &MetricsConfig::default(),
            &|_| false,
            &|_| {},
        )
        .expect("runs");
        EvalShard {
            controller: "expert".into(),
            models: Vec::new(),
            scenario: scenario.name().into(),
            seed: 11,
            team_size: Vec::new(),
            goal_speed: Vec::new(),
            model_inputs: Vec::new(),
            first_run: range.start,
            per_run: results.into_iter().map(|r| r.metrics).collect(),
        }
    }

    #[test]
    fn shards_in_any_order_merge_into_the_whole_evaluations_summary_byte_for_byte() {
        let scenario = scenario();
        let whole = evaluate_runs(
            &scenario,
            11,
            7,
            &Driver::Expert(ExpertGains::default()),
            &MetricsConfig::default(),
            &|_| false,
            &|_| {},
        )
        .expect("runs");
        let expected = eval_output(
            "expert",
            Vec::new(),
            scenario.name(),
            Some(11),
            whole.into_iter().map(|r| r.metrics).collect(),
        );
        let shards = [
            shard(&scenario, 4..7),
            shard(&scenario, 0..2),
            shard(&scenario, 2..4),
        ];
        let merged = merge_shards(&shards, Some(7)).expect("merge");
        let json = |o: &EvalOutput| formation_schema::to_json_pretty(o).expect("json");
        assert_eq!(json(&merged), json(&expected));
        // Through the file format and back, too.
        let reread: Vec<EvalShard> = shards
            .iter()
            .map(|s| {
                let bytes = formation_schema::to_json(s).expect("json");
                formation_schema::from_json(&bytes, std::path::Path::new("s.json")).expect("read")
            })
            .collect();
        assert_eq!(
            json(&merge_shards(&reread, None).expect("merge")),
            json(&expected)
        );
    }

    #[test]
    fn a_run_held_twice_or_by_none_and_shards_of_two_evaluations_are_refused() {
        let scenario = scenario();
        let (a, b, c) = (
            shard(&scenario, 0..3),
            shard(&scenario, 2..5),
            shard(&scenario, 5..7),
        );
        assert!(matches!(
            merge_shards(&[a.clone(), b, c.clone()], Some(7)),
            Err(MergeError::Overlap { run: 2, .. })
        ));
        assert_eq!(
            merge_shards(&[a.clone(), c.clone()], Some(7)),
            Err(MergeError::Gap {
                missing: 3..5,
                runs: 7
            })
        );
        assert_eq!(
            merge_shards(std::slice::from_ref(&a), Some(7)),
            Err(MergeError::Gap {
                missing: 3..7,
                runs: 7
            })
        );
        let mut other_seed = c;
        other_seed.seed = 12;
        let refused = merge_shards(&[a, other_seed], None).expect_err("two seeds");
        assert!(
            matches!(
                &refused,
                MergeError::Mismatch {
                    index: 1,
                    field: "seed",
                    ..
                }
            ),
            "{refused}"
        );
        assert!(refused.to_string().contains("another evaluation"));
        assert_eq!(merge_shards(&[], None), Err(MergeError::Empty));
    }

    #[test]
    fn the_models_declared_inputs_carry_into_the_summary_and_must_agree() {
        let scenario = scenario();
        let input = formation_schema::ModelInput {
            model: "m-1".into(),
            occupancy: formation_proto::OccupancySpec::PAPER,
            lidar_beams: 90,
            lidar_max_range_m: 10.0,
            lidar_noise_std_m: None,
            trained_d_star_m: None,
        };
        let with_input = |range| EvalShard {
            model_inputs: vec![input.clone()],
            ..shard(&scenario, range)
        };
        let merged = merge_shards(&[with_input(0..4), with_input(4..7)], Some(7)).expect("merge");
        assert_eq!(merged.model_inputs, vec![input.clone()]);
        let mut scaled = with_input(4..7);
        scaled.model_inputs[0].occupancy.d_star_ref_m = Some(1.5);
        let refused = merge_shards(&[with_input(0..4), scaled], Some(7)).expect_err("two inputs");
        assert!(
            matches!(
                &refused,
                MergeError::Mismatch {
                    index: 1,
                    field: "model_inputs",
                    ..
                }
            ),
            "{refused}"
        );
    }
}
