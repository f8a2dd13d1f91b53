//! Synthetic eval output written with the writers' own types (`formation_schema`'s `RunLog`,
//! `EvalOutput` and `LatencyProfile`, the summary computed by `formation_world`'s `summarize`),
//! in the on-disk layout `formation eval --out` writes, plus a loss curve.

#![allow(dead_code)] // each test binary uses a different part

use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::fs;
use std::path::Path;

use formation_proto::{Pose, WheelCmd};
use formation_schema::{
    EvalOutput, LatencyProfile, RunLog, RunMetrics, SchemaFile, StageStats, Trajectory,
};
use formation_world::metrics::summarize;
use serde_json::Value;

/// How the desired heading moves, like the paper's three cases.
#[derive(Clone, Copy)]
pub enum Heading {
    Constant(f64),
    Ramp(f64),
    Sine(f64),
}

impl Heading {
    fn at(self, t: f64) -> f64 {
        match self {
            Heading::Constant(phi) => phi,
            Heading::Ramp(omega) => omega * t,
            Heading::Sine(omega) => (omega * t).sin(),
        }
    }
}

/// A 3-robot run converging to an equilateral triangle of side `d_star` while moving at 0.7 m/s
/// along the heading schedule; `seconds` long at 20 Hz.
pub fn trajectory(heading: Heading, d_star: f64, seconds: f64, seed: u64) -> Trajectory {
    let dt = 0.05;
    let v_star = 0.7;
    let ticks = (seconds / dt).round() as usize;
    let wobble = |k: u64| ((seed * 7919 + k * 104_729) % 1000) as f64 / 1000.0 - 0.5;
    let initial: Vec<(f64, f64)> = (0..3)
        .map(|i| (3.0 * wobble(2 * i), 3.0 * wobble(2 * i + 1)))
        .collect();
    let heading_offsets: Vec<f64> = (0..3).map(|i| 2.0 * wobble(10 + i)).collect();
    let target = |phi: f64, i: usize| {
        let r = d_star / 3f64.sqrt();
        let a = phi + 2.0 * PI * i as f64 / 3.0;
        (r * a.cos(), r * a.sin())
    };
    let mut centre = (0.0, 0.0);
    let mut times = Vec::new();
    let mut phi_star = Vec::new();
    let mut poses = Vec::new();
    let mut commands = Vec::new();
    for k in 0..=ticks {
        let t = k as f64 * dt;
        let phi = heading.at(t);
        let decay = (-t / 3.0).exp();
        let row: Vec<Pose> = (0..3)
            .map(|i| {
                let (tx, ty) = target(phi, i);
                let x = centre.0 + tx + (initial[i].0 - tx) * decay;
                let y = centre.1 + ty + (initial[i].1 - ty) * decay;
                let theta = phi + heading_offsets[i] * decay;
                let theta = (theta + PI).rem_euclid(2.0 * PI) - PI;
                Pose { x, y, theta }
            })
            .collect();
        times.push(t);
        phi_star.push(phi);
        poses.push(row);
        if k < ticks {
            let turn: Vec<WheelCmd> = (0..3)
                .map(|i| {
                    let omega = -heading_offsets[i] * decay / 3.0;
                    let delta = 0.5 * 0.331 * omega;
                    WheelCmd {
                        left: (v_star - delta).clamp(-0.9, 0.9),
                        right: (v_star + delta).clamp(-0.9, 0.9),
                    }
                })
                .collect();
            commands.push(turn);
        }
        centre.0 += v_star * phi.cos() * dt;
        centre.1 += v_star * phi.sin() * dt;
    }
    Trajectory {
        dt,
        d_star,
        v_star,
        edges: vec![(0, 1), (0, 2), (1, 2)],
        neighbours: formation_proto::NeighbourRule::AllPairs,
        times,
        phi_star,
        poses,
        commands,
        collisions: Vec::new(),
    }
}

/// Metrics of one synthetic run, varying with `k`.
pub fn run_metrics(k: u64, success_10: bool) -> RunMetrics {
    let u = ((k * 2_654_435_761) % 1000) as f64 / 1000.0;
    RunMetrics {
        success_5: success_10 && u > 0.15,
        success_10,
        convergence_s_5: success_10.then_some(9.0 + 6.0 * u),
        convergence_s_10: success_10.then_some(7.0 + 6.0 * u),
        rel_formation_error: 0.01 + 0.04 * u,
        max_edge_window_error: 0.02 + 0.05 * u,
        orientation_error_rad: 0.02 + 0.03 * u,
        collisions: 0,
        team: None,
        incomplete: None,
    }
}

/// The summary.json of `per_run`, as `formation eval` writes it.
pub fn summary(scenario: &str, per_run: &[RunMetrics]) -> EvalOutput {
    EvalOutput::of_runs(
        "policy",
        vec!["policy-abc123".into()],
        scenario,
        Some(42),
        summarize(per_run),
        per_run.to_vec(),
    )
}

/// The run log of a complete in-process run.
pub fn run_log(index: usize, metrics: RunMetrics, trajectory: Trajectory) -> RunLog {
    RunLog {
        index,
        metrics,
        planned_ticks: Some(trajectory.commands.len() as u64),
        trajectory,
        clock: "in-process".into(),
        models: vec!["policy-abc123".into(); 3],
        complete: true,
        stop_reason: None,
    }
}

/// Writes a file of one of the schema's formats, as its writer does.
pub fn write_file<F: SchemaFile>(path: &Path, value: &F) {
    fs::create_dir_all(path.parent().expect("parent")).expect("mkdir");
    fs::write(path, formation_schema::to_json_pretty(value).expect("json")).expect("write");
}

/// Writes a JSON value (a file read back and changed by a test).
pub fn write_json(path: &Path, value: &Value) {
    fs::create_dir_all(path.parent().expect("parent")).expect("mkdir");
    fs::write(path, serde_json::to_vec_pretty(value).expect("json")).expect("write");
}

fn stage(p50_us: f64, p90_us: f64, p99_us: f64, max_us: f64) -> StageStats {
    StageStats {
        count: 1000,
        p50_us,
        p90_us,
        p99_us,
        max_us,
        histogram: Vec::new(),
    }
}

/// The demo layout: `table1/` (20 runs, 19 successful), `case1..3/` with one run log each, a loss
/// curve and a latency profile. Returns the number of runs in `table1`.
pub fn write_demo_dir(root: &Path, case_seconds: f64) -> usize {
    let per_run: Vec<RunMetrics> = (0..20).map(|k| run_metrics(k, k != 7)).collect();
    write_file(
        &root.join("table1/summary.json"),
        &summary("table1", &per_run),
    );
    let cases = [
        ("case1", Heading::Constant(3.76), 2.0),
        ("case2", Heading::Ramp(0.1), 1.0),
        ("case3", Heading::Sine(0.2), 1.5),
    ];
    for (seed, (name, heading, d_star)) in cases.into_iter().enumerate() {
        let metrics = run_metrics(seed as u64, true);
        write_file(
            &root.join(name).join("summary.json"),
            &summary(name, std::slice::from_ref(&metrics)),
        );
        let log = run_log(
            0,
            metrics,
            trajectory(heading, d_star, case_seconds, seed as u64),
        );
        write_file(&root.join(name).join("runs/run-0000.json"), &log);
    }
    let mut csv = String::from("epoch,train_loss,val_loss,seconds\n");
    for epoch in 1..=40 {
        let e = f64::from(epoch);
        csv.push_str(&format!(
            "{epoch},{},{},{}\n",
            0.2 * (-e / 8.0).exp() + 0.009,
            0.22 * (-e / 9.0).exp() + 0.011,
            1.5 * e
        ));
    }
    fs::write(root.join("policy-loss.csv"), csv).expect("write csv");
    let stages = BTreeMap::from([
        ("scan".to_owned(), stage(45.0, 60.0, 95.0, 310.0)),
        ("occupancy".to_owned(), stage(30.0, 41.0, 70.0, 150.0)),
        ("inference".to_owned(), stage(820.0, 990.0, 1500.0, 4100.0)),
        (
            "round trip".to_owned(),
            stage(1100.0, 1400.0, 2100.0, 6000.0),
        ),
    ]);
    write_file(
        &root.join("profile/profile.json"),
        &LatencyProfile {
            runs: 1,
            clock: "lockstep".into(),
            used_commands: 1000,
            braked: BTreeMap::new(),
            braked_per_robot: Vec::new(),
            stages: stages.clone(),
            per_agent: vec![stages],
            inference_paper_ms: 2.1,
        },
    );
    per_run.len()
}

/// A team of `n` robots under the Gabriel neighbour rule, `seconds` long at 20 Hz: from a loose
/// jittered grid they close to a triangular lattice of spacing `d* = 1 m` while the team drives
/// along a gentle curve at 0.4 m/s.
pub fn team_trajectory(n: usize, seconds: f64) -> Trajectory {
    let dt = 0.05;
    let ticks = (seconds / dt).round() as usize;
    let cols = (n as f64).sqrt().ceil() as usize;
    let wobble = |k: usize| ((k * 104_729 + 7919) % 1000) as f64 / 1000.0 - 0.5;
    let lattice: Vec<(f64, f64)> = (0..n)
        .map(|i| {
            let (row, col) = ((i / cols) as f64, (i % cols) as f64);
            (col + 0.5 * (row % 2.0), row * 3f64.sqrt() / 2.0)
        })
        .collect();
    let start: Vec<(f64, f64)> = lattice
        .iter()
        .enumerate()
        .map(|(i, &(x, y))| (1.7 * x + wobble(2 * i), 1.7 * y + wobble(2 * i + 1)))
        .collect();
    let (mut times, mut phi_star, mut poses, mut commands) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut centre = (0.0, 0.0);
    for k in 0..=ticks {
        let t = k as f64 * dt;
        let heading = 0.4 * (0.1 * t).sin();
        let decay = (-t / 8.0).exp();
        let row: Vec<Pose> = (0..n)
            .map(|i| Pose {
                x: centre.0 + lattice[i].0 + (start[i].0 - lattice[i].0) * decay,
                y: centre.1 + lattice[i].1 + (start[i].1 - lattice[i].1) * decay,
                theta: heading + 1.5 * wobble(3 * i) * decay,
            })
            .collect();
        times.push(t);
        phi_star.push(heading);
        poses.push(row);
        if k < ticks {
            commands.push(vec![
                WheelCmd {
                    left: 0.4,
                    right: 0.4
                };
                n
            ]);
        }
        centre.0 += 0.4 * heading.cos() * dt;
        centre.1 += 0.4 * heading.sin() * dt;
    }
    Trajectory {
        dt,
        d_star: 1.0,
        v_star: 0.4,
        edges: Vec::new(),
        neighbours: formation_proto::NeighbourRule::Gabriel(
            formation_proto::GabrielRule::with_range(10.0),
        ),
        times,
        phi_star,
        poses,
        commands,
        collisions: Vec::new(),
    }
}

/// One eval output (`team/`) holding one run log of `team_trajectory(n, seconds)`.
pub fn write_team_dir(root: &Path, n: usize, seconds: f64) {
    let metrics = run_metrics(0, true);
    write_file(
        &root.join("team/summary.json"),
        &summary("teams", std::slice::from_ref(&metrics)),
    );
    let log = run_log(0, metrics, team_trajectory(n, seconds));
    write_file(&root.join("team/runs/run-0000.json"), &log);
}
