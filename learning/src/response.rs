//! The response gauge over a scenario's runs (`formation gauge`): each driver plays its own runs
//! in parallel, the expert relabels the states, and the tallies add up per team size
//! ([`formation_expert::response`] holds the pure gauge).
//!
//! A run is a pure function of (scenario, base seed, run index, driver), as in [`crate::rollout`],
//! and tallies are merged in run order, so the curve does not depend on the thread count.

use formation_expert::ExpertGains;
use formation_expert::response::{ResponseGauge, ResponseTally};
use formation_schema::{ResponseCurve, ResponseRow};
use formation_world::metrics::{MetricsConfig, run_metrics};
use formation_world::{Scenario, run_episode};
use rayon::prelude::*;

use crate::LearningError;
use crate::rollout::Driver;
use crate::scaling::ScalingDriver;

/// What to gauge and how.
#[derive(Debug, Clone)]
pub struct GaugeSettings {
    /// Base seed of the runs.
    pub seed: u64,
    /// Runs per team size and driver.
    pub runs: usize,
    /// The run length \[s\], else the scenario's.
    pub duration_s: Option<f64>,
    /// Every how many ticks a state is gauged.
    pub stride: u64,
    /// The gains of the expert that labels (the scored expert's: [`ExpertGains::default`]).
    pub label_gains: ExpertGains,
}

/// One run's tally and whether it succeeded at 10 %.
struct GaugedRun {
    tally: ResponseTally,
    success_10: bool,
}

/// Gauges every driver on every team size in `sizes` (drivers inner), each on its own runs.
/// `progress(row, runs_done)` is called as runs finish.
pub fn gauge_response(
    base: &Scenario,
    sizes: &[usize],
    drivers: &[ScalingDriver],
    settings: &GaugeSettings,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<ResponseCurve, LearningError> {
    settings
        .label_gains
        .validate()
        .map_err(|e| LearningError::Setting {
            setting: "label gains",
            problem: e.to_string(),
        })?;
    let cfg = MetricsConfig {
        team_figures: true,
        ..MetricsConfig::default()
    };
    let mut rows = Vec::with_capacity(sizes.len() * drivers.len());
    let mut duration_s = base.duration_s();
    for &robots in sizes {
        let scenario = base.with_robots(robots)?;
        for driver in drivers {
            let (run_driver, model) = match driver {
                ScalingDriver::Expert(gains) => (Driver::Expert(*gains), None),
                ScalingDriver::ExpertOwnScan(gains) => (Driver::ExpertOwnScan(*gains), None),
                ScalingDriver::Policy { model, id, .. } => {
                    (Driver::policy_for(&scenario, model)?, Some(id.clone()))
                }
            };
            let row = rows.len();
            // Build one controller first, so that a model that cannot load is a typed error.
            run_driver.controller(&scenario)?;
            let done = std::sync::atomic::AtomicUsize::new(0);
            let runs: Vec<GaugedRun> = (0..settings.runs)
                .into_par_iter()
                .map_init(
                    || run_driver.controller(&scenario),
                    |controller, i| {
                        let controller =
                            controller.as_mut().map_err(|e| LearningError::Setting {
                                setting: "driver",
                                problem: format!("could not be built on a worker thread: {e}"),
                            })?;
                        let mut spec = scenario.run_spec(settings.seed, i);
                        if let Some(d) = settings.duration_s {
                            spec.duration_s = d;
                        }
                        let mut gauge = ResponseGauge::new(
                            settings.label_gains,
                            spec.world.robot,
                            spec.neighbours,
                            settings.stride,
                        );
                        let mut label_error = None;
                        let traj = run_episode(&spec, controller.as_mut(), &mut |obs, cmds| {
                            if label_error.is_none() {
                                label_error = gauge.record(obs, cmds).err();
                            }
                        })
                        .map_err(|source| LearningError::Run { run: i, source })?;
                        if let Some(source) = label_error {
                            return Err(LearningError::Run { run: i, source });
                        }
                        let metrics = run_metrics(&traj, spec.ticks(), &cfg);
                        progress(
                            row,
                            done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1,
                        );
                        Ok(GaugedRun {
                            tally: *gauge.tally(),
                            success_10: metrics.success_10,
                        })
                    },
                )
                .collect::<Result<_, _>>()?;
            if let Some(d) = settings.duration_s {
                duration_s = d;
            }
            let mut tally = ResponseTally::default();
            for run in &runs {
                tally.merge(&run.tally);
            }
            let successes = runs.iter().filter(|r| r.success_10).count();
            rows.push(ResponseRow {
                controller: run_driver.name().to_owned(),
                model,
                robots,
                runs: runs.len(),
                success_rate_10: successes as f64 / runs.len().max(1) as f64,
                samples: tally.samples,
                bins: tally.to_bins(),
            });
        }
    }
    Ok(ResponseCurve {
        scenario: base.name().to_owned(),
        seed: settings.seed,
        duration_s,
        stride: settings.stride.max(1),
        expert_gains: serde_json::to_value(settings.label_gains).unwrap_or_default(),
        rows,
    })
}

/// The curve as a terminal table: one line per row and bin.
pub fn response_text(curve: &ResponseCurve) -> String {
    let mut out = format!(
        "response gauge: {} (seed {}, {} s runs, every {} ticks), slope = Σ p·l / Σ |l|²\n",
        curve.scenario,
        curve.seed,
        formation_schema::trim_number(curve.duration_s),
        curve.stride
    );
    out.push_str(
        "controller  N    runs  success@10%  label m/s   samples   slope   RMS error m/s\n",
    );
    for row in &curve.rows {
        for bin in &row.bins {
            let figure = |v: Option<f64>| v.map_or_else(|| "-".to_owned(), |v| format!("{v:.3}"));
            out.push_str(&format!(
                "{:<10}  {:<3}  {:>4}  {:>10.1}%  {:>4}–{:<4}  {:>8}  {:>6}{}  {:>7}\n",
                row.controller,
                row.robots,
                row.runs,
                100.0 * row.success_rate_10,
                formation_schema::trim_number(bin.label_min),
                formation_schema::trim_number(bin.label_max),
                bin.samples,
                figure(bin.slope),
                if bin.judged { " " } else { "*" },
                figure(bin.rms_error),
            ));
        }
    }
    out.push_str(&format!(
        "* fewer than {} samples: reported, not judged\n",
        formation_schema::MIN_JUDGED_SAMPLES
    ));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scenario() -> Scenario {
        let text = "name = \"t\"\nrobots = 5\nduration_s = 10.0\nseed = 3\nruns = 4\n\
                    [goal]\nv_star = 0.7\nd_star = 1.5\n[heading]\nschedule = \"random\"\n\
                    [lidar]\nbeams = 90\n";
        Scenario::from_toml_str(text, "t").unwrap()
    }

    fn settings(runs: usize) -> GaugeSettings {
        GaugeSettings {
            seed: 3,
            runs,
            duration_s: None,
            stride: 5,
            label_gains: ExpertGains::default(),
        }
    }

    #[test]
    fn the_scored_expert_gauged_gives_slope_one_and_no_error_whatever_the_threads() {
        let scenario = scenario();
        let drivers = [ScalingDriver::Expert(ExpertGains::default())];
        let curve = |threads| {
            crate::rollout::with_threads(Some(threads), || {
                gauge_response(&scenario, &[5, 8], &drivers, &settings(3), &|_, _| {})
            })
            .unwrap()
            .unwrap()
        };
        let one = curve(1);
        assert_eq!(one, curve(2));
        assert_eq!(one.rows.len(), 2);
        for row in &one.rows {
            assert_eq!(row.runs, 3);
            assert!(row.samples > 0);
            for bin in row.bins.iter().filter(|b| b.samples > 0) {
                assert!((bin.slope.unwrap() - 1.0).abs() < 1e-9, "{bin:?}");
                assert!(bin.rms_error.unwrap() < 1e-9, "{bin:?}");
            }
        }
        assert!(response_text(&one).contains("0.05–0.1"));
    }

    #[test]
    fn a_teacher_with_other_gains_is_seen_as_a_different_response() {
        // The expert with half the team gain, gauged against the scored expert: it moves about
        // half as far, so its slope is well below 1 where labels are small.
        let scenario = scenario();
        let slow = ExpertGains {
            k_formation_graph: 0.5,
            ..ExpertGains::default()
        };
        let curve = gauge_response(
            &scenario,
            &[8],
            &[ScalingDriver::Expert(slow)],
            &settings(2),
            &|_, _| {},
        )
        .unwrap();
        let small = &curve.rows[0].bins[0];
        assert!(small.samples > 0);
        let slope = small.slope.unwrap();
        assert!((0.3..0.7).contains(&slope), "slope {slope}");
    }

    #[test]
    fn the_law_on_each_robot_s_own_scan_responds_almost_as_the_expert() {
        // The teacher that sees only its own scan (its detected neighbours), gauged against the
        // expert that sees every pose, on noiseless scans: the same law through the detector, so
        // its slope is near 1 in every bin (not exactly: a hidden neighbour is missed).
        let text = "name = \"t\"\nrobots = 8\nduration_s = 20.0\nseed = 3\nruns = 4\n\
                    [goal]\nv_star = 0.7\nd_star = 1.5\n[heading]\nschedule = \"random\"\n";
        let scenario = Scenario::from_toml_str(text, "t").unwrap();
        let curve = gauge_response(
            &scenario,
            &[8],
            &[ScalingDriver::ExpertOwnScan(ExpertGains::default())],
            &settings(4),
            &|_, _| {},
        )
        .unwrap();
        let row = &curve.rows[0];
        assert_eq!(row.controller, "expert-own-scan");
        let filled: Vec<_> = row.bins.iter().filter(|b| b.samples >= 50).collect();
        assert!(filled.len() >= 3, "{row:?}");
        for bin in filled {
            let slope = bin.slope.unwrap();
            assert!((0.95..1.05).contains(&slope), "{bin:?}");
        }
    }

    #[test]
    fn bad_label_gains_are_refused_before_any_run() {
        let mut s = settings(1);
        s.label_gains.point_offset = f64::NAN;
        let err = gauge_response(&scenario(), &[5], &[], &s, &|_, _| {}).unwrap_err();
        assert!(err.to_string().contains("point_offset"), "{err}");
    }
}
