//! `formation gauge`: the response gauge. The policy (and, with `--expert`, an expert with other
//! gains, a teacher for instance; with `--own-scan`, the expert's law on each robot's own scan)
//! plays its own runs; the scored expert relabels every `--stride`-th
//! state; the slope and RMS error of the controller's formation velocity against the label are
//! printed per team size and bin of the label's size, and written with `--json`
//! ([`formation_schema::ResponseCurve`]). It costs minutes of simulation, no training.

use formation_expert::ExpertGains;
use formation_learning::response::{GaugeSettings, gauge_response, response_text};
use formation_learning::scaling::ScalingDriver;
use formation_world::Scenario;

use crate::args::GaugeArgs;
use crate::eval::{RowSweep, print_and_write_json};
use crate::paths;
use crate::team_models::policy_driver;

/// `formation gauge`.
pub fn gauge_command(args: &GaugeArgs) -> anyhow::Result<()> {
    // A path that cannot be written is refused before minutes of runs, not after.
    if let Some(json) = &args.json {
        formation_proto::files::check_output_file(json)?;
        let mut inputs = vec![("--scenario", args.scenario.as_path())];
        if let Some(model) = &args.model {
            inputs.push(("--model", model.as_path()));
        }
        paths::refuse_overwriting_inputs(&[("--json", json, "response.json")], &[], &inputs)?;
    }
    let base = Scenario::from_path(&args.scenario)?;
    let sizes = args.robots.clone().unwrap_or_else(|| vec![base.n_robots()]);
    let runs = args.runs.unwrap_or_else(|| base.runs());
    let seed = args.seed.unwrap_or_else(|| base.seed());
    let mut drivers = Vec::new();
    let gains = args.expert.unwrap_or_default();
    if args.expert.is_some() {
        drivers.push(ScalingDriver::Expert(gains));
    }
    if args.own_scan {
        drivers.push(ScalingDriver::ExpertOwnScan(gains));
    }
    if !args.no_policy {
        drivers.push(policy_driver(args.model.as_deref(), &base, &sizes)?);
    }
    let settings = GaugeSettings {
        seed,
        runs,
        duration_s: args.duration_s,
        stride: args.stride,
        label_gains: ExpertGains::default(),
    };
    let curve = RowSweep::new("gauge", "gauged", sizes.len() * drivers.len(), runs)
        .run(args.threads, |progress| {
            gauge_response(&base, &sizes, &drivers, &settings, progress)
        })?;
    print_and_write_json(&response_text(&curve), &curve, args.json.as_deref())
}
