//! The models a team drives: each robot's model file, checked against the scenario before
//! anything runs, what each model's trained team sizes and v* say about this team and its runs'
//! v*, and the input each
//! model declares (its occupancy window and LIDAR, for the summary). Shared by `formation eval`
//! and the launcher.

use std::path::{Path, PathBuf};

use anyhow::Context;
use formation_world::Scenario;
use formation_world::scenario::VStarPlan;

use crate::paths;

/// The model path for each robot: the scenario's per-robot overrides (each checked like
/// `--model`: a regular file within the size limit), else `default`; nothing is loaded yet.
pub fn resolved_models_per_robot(
    scenario: &Scenario,
    default: &Path,
) -> anyhow::Result<Vec<PathBuf>> {
    let models = assigned_models(scenario, default)?;
    for assigned in scenario.agent_models() {
        paths::resolve_model(Some(&assigned.model))?;
    }
    Ok(models)
}

/// The model path for each robot as the scenario assigns them, else `default`.
fn assigned_models(scenario: &Scenario, default: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let mut models = vec![default.to_path_buf(); scenario.n_robots()];
    for assigned in scenario.agent_models() {
        let slot = models.get_mut(assigned.robot).with_context(|| {
            format!(
                "the scenario assigns a model to robot {}, but it has only {} robots (0..{})",
                assigned.robot,
                scenario.n_robots(),
                scenario.n_robots()
            )
        })?;
        *slot = assigned.model.clone();
    }
    Ok(models)
}

/// Model ids of the given files, as the agents would report them, beside each model's metadata
/// (its declared input and its envelope), after checking each model against the contract and the scenario's LIDAR (beams, range,
/// window), and the scenario's d* against each model's trained d* range (its envelope), before
/// anything runs.
pub fn checked_models(
    models: &[PathBuf],
    scenario: &Scenario,
) -> anyhow::Result<Vec<(String, formation_onnx::ModelMetadata)>> {
    Ok(
        formation_robot_agent::decision::check_team_models_with_metadata(
            models,
            &scenario.world_config().lidar,
            &scenario_d_stars(scenario),
        )?,
    )
}

/// Each distinct model of a team (by id, in first-use order) that records its trained team
/// sizes, against the team's size `robots`.
pub fn team_sizes_of(
    models: &[(String, formation_onnx::ModelMetadata)],
    robots: usize,
) -> Vec<formation_schema::ModelTeamSize> {
    distinct(models)
        .filter_map(|(id, metadata)| {
            formation_schema::ModelTeamSize::new(id, &metadata.envelope().team_sizes, robots)
        })
        .collect()
}

/// Each distinct model of a team (by id, in first-use order) trained at another v* than the
/// runs' `v_star` (`formation.v_train`), against it; empty when every model was trained at it.
/// Where v* is drawn per run (`goal.v_star_range`), the end of the range farthest from the
/// model's v_train is the one reported.
pub fn goal_speeds_of(
    models: &[(String, formation_onnx::ModelMetadata)],
    v_star: VStarPlan,
) -> Vec<formation_schema::ModelGoalSpeed> {
    distinct(models)
        .filter_map(|(id, metadata)| {
            let v_star = v_star.farthest_from(metadata.v_train);
            formation_schema::ModelGoalSpeed::new(id, metadata.v_train, v_star, metadata.output)
        })
        .filter(formation_schema::ModelGoalSpeed::is_outside)
        .collect()
}

/// The input each distinct model of a team declares (by id, in first-use order).
pub fn model_inputs_of(
    models: &[(String, formation_onnx::ModelMetadata)],
) -> Vec<formation_schema::ModelInput> {
    distinct(models)
        .map(|(id, metadata)| model_input(id, metadata))
        .collect()
}

/// The input model `id` declares in its metadata: its occupancy window, its LIDAR, and the d*
/// range and noise of its training data.
pub fn model_input(
    id: &str,
    metadata: &formation_onnx::ModelMetadata,
) -> formation_schema::ModelInput {
    let envelope = metadata.envelope();
    formation_schema::ModelInput {
        model: id.to_owned(),
        occupancy: metadata.occupancy,
        lidar_beams: metadata.beams,
        lidar_max_range_m: metadata.max_range,
        lidar_noise_std_m: envelope.noise_std,
        trained_d_star_m: envelope.d_star.map(|(lo, hi)| [lo, hi]),
    }
}

/// The first entry of each model id, in order.
fn distinct(
    models: &[(String, formation_onnx::ModelMetadata)],
) -> impl Iterator<Item = &(String, formation_onnx::ModelMetadata)> {
    let mut seen: Vec<&str> = Vec::new();
    models.iter().filter(move |(id, _)| {
        let new = !seen.contains(&id.as_str());
        if new {
            seen.push(id);
        }
        new
    })
}

/// Prints, on stderr, a line for each model that never saw a team of this size: a note when
/// the size is zero-shot, a warning when it is below every trained size.
pub fn print_team_size_notes(team_size: &[formation_schema::ModelTeamSize]) {
    for line in team_size.iter().filter_map(|t| t.describe()) {
        eprintln!("formation: {line}");
    }
}

/// Prints, on stderr, a line for each model trained at another v* than the runs': a note near
/// its trained v*, a warning further ([`formation_proto::GoalSpeedFit::describe`]).
pub fn print_goal_speed_notes(goal_speed: &[formation_schema::ModelGoalSpeed]) {
    for line in goal_speed.iter().filter_map(|g| g.describe()) {
        eprintln!("formation: {line}");
    }
}

/// The d* values that bound a scenario's runs: its fixed d*, each of its choices, or its
/// range's ends.
pub fn scenario_d_stars(scenario: &Scenario) -> Vec<f64> {
    scenario.d_star().bounds()
}

/// The model path of every robot: the scenario's per-robot models, else `default`. Each model is
/// loaded and checked against the contract and the scenario's LIDAR (beams, range, window) here,
/// before any process starts ([`formation_robot_agent::decision::check_team_models_for`]); a missing or
/// unusable file, a model trained for another sensor or for another d* range than the
/// scenario's, and a robot out of range are errors naming the robot, the file and the fix.
pub fn models_per_robot(scenario: &Scenario, default: &Path) -> anyhow::Result<Vec<PathBuf>> {
    Ok(checked_team_models(scenario, default)?.0)
}

/// What a launch's summary says about its models: each distinct model's trained team sizes
/// against the team's size, and the input each declares.
#[derive(Debug, Clone, Default)]
pub struct TeamModelNotes {
    /// The team-size records ([`team_sizes_of`]).
    pub team_size: Vec<formation_schema::ModelTeamSize>,
    /// The trained-v* records of the models trained at another v* ([`goal_speeds_of`]).
    pub goal_speed: Vec<formation_schema::ModelGoalSpeed>,
    /// The declared inputs ([`model_inputs_of`]).
    pub model_inputs: Vec<formation_schema::ModelInput>,
}

/// [`models_per_robot`], with each distinct model's trained team sizes against the scenario's
/// team size and its declared input (for the terminal and `summary.json`).
pub fn checked_team_models(
    scenario: &Scenario,
    default: &Path,
) -> anyhow::Result<(Vec<PathBuf>, TeamModelNotes)> {
    let models = assigned_models(scenario, default)?;
    let checked = checked_models(&models, scenario)?;
    let notes = TeamModelNotes {
        team_size: team_sizes_of(&checked, scenario.n_robots()),
        goal_speed: goal_speeds_of(&checked, scenario.v_star()),
        model_inputs: model_inputs_of(&checked),
    };
    Ok((models, notes))
}

/// The policy driver of the scaling table and the gauge: `model` (else `base`'s own model, else
/// the shipped default),
/// checked against `base`'s sensor and d* before anything runs, with a note on the terminal for
/// each team size of `sizes` and for a v* the model was not trained at.
pub fn policy_driver(
    model: Option<&std::path::Path>,
    base: &Scenario,
    sizes: &[usize],
) -> anyhow::Result<formation_learning::scaling::ScalingDriver> {
    let model = crate::paths::resolve_model_for(model, base)?;
    let checked = checked_models(std::slice::from_ref(&model), base)?;
    for &robots in sizes {
        print_team_size_notes(&team_sizes_of(&checked, robots));
    }
    print_goal_speed_notes(&goal_speeds_of(&checked, base.v_star()));
    let Some((id, metadata)) = checked.into_iter().next() else {
        anyhow::bail!("no model to run: give --model FILE");
    };
    Ok(formation_learning::scaling::ScalingDriver::Policy {
        model,
        input: Some(model_input(&id, &metadata)),
        trained_team_sizes: metadata.envelope().team_sizes,
        v_train: metadata.v_train,
        output: metadata.output,
        id,
    })
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use formation_onnx::ModelMetadata;
    use formation_proto::OccupancySpec;

    use super::*;

    fn metadata(occupancy: OccupancySpec, extra: &[(&str, &str)]) -> ModelMetadata {
        ModelMetadata {
            occupancy,
            beams: 900,
            max_range: 10.0,
            v_train: 0.7,
            dataset_id: "d".into(),
            output: formation_onnx::PolicyOutput::Wheels,
            aux: formation_proto::AuxLayout::PAPER,
            ranges: None,
            neighbours: None,
            extra: extra
                .iter()
                .map(|(k, v)| ((*k).to_owned(), (*v).to_owned()))
                .collect::<BTreeMap<_, _>>(),
        }
    }

    #[test]
    fn each_distinct_model_declares_its_input_once_in_first_use_order() {
        let scaled = OccupancySpec {
            d_star_ref_m: Some(1.5),
            ..OccupancySpec::PAPER
        };
        let envelope = [
            (formation_onnx::contract::keys::D_STAR_MIN, "0.8"),
            (formation_onnx::contract::keys::D_STAR_MAX, "2.5"),
            (formation_onnx::contract::keys::NOISE_STD, "0.03"),
            (formation_onnx::contract::keys::TEAM_SIZES, "3,5"),
        ];
        let team = [
            ("scaled".to_owned(), metadata(scaled, &envelope)),
            ("paper".to_owned(), metadata(OccupancySpec::PAPER, &[])),
            ("scaled".to_owned(), metadata(scaled, &envelope)),
        ];
        let inputs = model_inputs_of(&team);
        assert_eq!(
            inputs.iter().map(|i| i.model.as_str()).collect::<Vec<_>>(),
            ["scaled", "paper"]
        );
        assert_eq!(inputs[0].occupancy, scaled);
        assert_eq!(inputs[0].trained_d_star_m, Some([0.8, 2.5]));
        assert_eq!(inputs[0].lidar_noise_std_m, Some(0.03));
        assert_eq!(
            (inputs[0].lidar_beams, inputs[0].lidar_max_range_m),
            (900, 10.0)
        );
        assert_eq!(inputs[1].occupancy, OccupancySpec::PAPER);
        assert_eq!(inputs[1].trained_d_star_m, None);
        // The team sizes follow the same distinct models.
        let sizes = team_sizes_of(&team, 4);
        assert_eq!(sizes.len(), 1, "only the scaled model records team sizes");
        assert!(sizes[0].zero_shot);
        // So do the v* records, only for a v* off the trained one (0.7 here).
        assert!(goal_speeds_of(&team, VStarPlan::Fixed(0.7)).is_empty());
        let speeds = goal_speeds_of(&team, VStarPlan::Fixed(0.4));
        assert_eq!(
            speeds.iter().map(|g| g.model.as_str()).collect::<Vec<_>>(),
            ["scaled", "paper"]
        );
        assert_eq!(speeds[0].fit, formation_proto::GoalSpeedFit::Slower);
        // A v* drawn per run is reported at the end of its range farthest from v_train.
        let drawn = goal_speeds_of(
            &team,
            VStarPlan::Range {
                min: 0.5,
                max: 0.75,
            },
        );
        assert_eq!(drawn[0].v_star, 0.5);
        let faster = goal_speeds_of(&team, VStarPlan::Range { min: 0.6, max: 1.2 });
        assert_eq!(
            (faster[0].v_star, faster[0].fit),
            (1.2, formation_proto::GoalSpeedFit::Faster)
        );
        assert!(goal_speeds_of(&team, VStarPlan::Range { min: 0.7, max: 0.7 }).is_empty());
    }
}
