//! Synthetic eval output in the exact on-disk layout `formation eval --out` writes (`summary.json`
//! with the Table I keys flattened at the top level, `runs/run-NNNN.json` with `formation_world`'s
//! `Trajectory` serialisation), plus a loss curve and a latency profile.

#![allow(dead_code)] // each test binary uses a different part

use std::f64::consts::PI;
use std::fs;
use std::path::Path;

use formation_report::series::quartiles;
use serde_json::{Value, json};

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
pub fn trajectory(heading: Heading, d_star: f64, seconds: f64, seed: u64) -> Value {
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
        let row: Vec<Value> = (0..3)
            .map(|i| {
                let (tx, ty) = target(phi, i);
                let x = centre.0 + tx + (initial[i].0 - tx) * decay;
                let y = centre.1 + ty + (initial[i].1 - ty) * decay;
                let theta = phi + heading_offsets[i] * decay;
                let theta = (theta + PI).rem_euclid(2.0 * PI) - PI;
                json!({"x": x, "y": y, "theta": theta})
            })
            .collect();
        times.push(t);
        phi_star.push(phi);
        poses.push(Value::Array(row));
        if k < ticks {
            let turn: Vec<Value> = (0..3)
                .map(|i| {
                    let omega = -heading_offsets[i] * decay / 3.0;
                    let delta = 0.5 * 0.331 * omega;
                    json!({"left": (v_star - delta).clamp(-0.9, 0.9), "right": (v_star + delta).clamp(-0.9, 0.9)})
                })
                .collect();
            commands.push(Value::Array(turn));
        }
        centre.0 += v_star * phi.cos() * dt;
        centre.1 += v_star * phi.sin() * dt;
    }
    json!({
        "dt": dt, "d_star": d_star, "v_star": v_star,
        "edges": [[0, 1], [0, 2], [1, 2]],
        "times": times, "phi_star": phi_star, "poses": poses, "commands": commands,
        "collisions": []
    })
}

/// Metrics of one synthetic run, varying with `k`.
pub fn run_metrics(k: u64, success_10: bool) -> Value {
    let u = ((k * 2_654_435_761) % 1000) as f64 / 1000.0;
    json!({
        "success_5": success_10 && u > 0.15,
        "success_10": success_10,
        "convergence_s_5": if success_10 { json!(9.0 + 6.0 * u) } else { Value::Null },
        "convergence_s_10": if success_10 { json!(7.0 + 6.0 * u) } else { Value::Null },
        "rel_formation_error": 0.01 + 0.04 * u,
        "max_edge_window_error": 0.02 + 0.05 * u,
        "orientation_error_rad": 0.02 + 0.03 * u,
        "collisions": 0
    })
}

fn quantile_json(values: impl Iterator<Item = f64>) -> Value {
    match quartiles(values) {
        Some(q) => {
            json!({"min": q.min, "q1": q.q1, "median": q.median, "q3": q.q3, "max": q.max, "count": q.count})
        }
        None => Value::Null,
    }
}

/// A summary.json over `per_run` (computed as `formation_world::metrics::summarize` does).
pub fn summary(scenario: &str, per_run: &[Value]) -> Value {
    let runs = per_run.len();
    let frac = |key: &str| {
        per_run.iter().filter(|r| r[key] == json!(true)).count() as f64 / runs.max(1) as f64
    };
    let ok: Vec<&Value> = per_run
        .iter()
        .filter(|r| r["success_10"] == json!(true))
        .collect();
    let conv = quantile_json(ok.iter().filter_map(|r| r["convergence_s_10"].as_f64()));
    let form = quantile_json(ok.iter().filter_map(|r| r["rel_formation_error"].as_f64()));
    let orient = quantile_json(
        ok.iter()
            .filter_map(|r| r["orientation_error_rad"].as_f64()),
    );
    json!({
        "controller": "policy", "models": ["policy-abc123"], "scenario": scenario, "seed": 42,
        "runs": runs, "success_rate_5": frac("success_5"), "success_rate_10": frac("success_10"),
        "median_convergence_s": conv["median"], "median_rel_formation_error": form["median"],
        "median_orientation_error_rad": orient["median"], "collisions": 0,
        "convergence_s": conv, "rel_formation_error": form, "orientation_error_rad": orient,
        "per_run": per_run
    })
}

pub fn write_json(path: &Path, value: &Value) {
    fs::create_dir_all(path.parent().expect("parent")).expect("mkdir");
    fs::write(path, serde_json::to_vec_pretty(value).expect("json")).expect("write");
}

/// The demo layout: `table1/` (20 runs, 19 successful), `case1..3/` with one run log each, a loss
/// curve and a latency profile. Returns the number of runs in `table1`.
pub fn write_demo_dir(root: &Path, case_seconds: f64) -> usize {
    let per_run: Vec<Value> = (0..20).map(|k| run_metrics(k, k != 7)).collect();
    write_json(
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
        write_json(
            &root.join(name).join("summary.json"),
            &summary(name, std::slice::from_ref(&metrics)),
        );
        let log = json!({"index": 0, "metrics": metrics, "trajectory": trajectory(heading, d_star, case_seconds, seed as u64)});
        write_json(&root.join(name).join("runs/run-0000.json"), &log);
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
    write_json(
        &root.join("profile/profile.json"),
        &json!({"stages": [
            {"name": "scan", "p50_us": 45.0, "p90_us": 60.0, "p99_us": 95.0, "max_us": 310.0},
            {"name": "occupancy", "p50_us": 30.0, "p90_us": 41.0, "p99_us": 70.0, "max_us": 150.0},
            {"name": "inference", "p50_us": 820.0, "p90_us": 990.0, "p99_us": 1500.0, "max_us": 4100.0},
            {"name": "round trip", "p50_us": 1100.0, "p90_us": 1400.0, "p99_us": 2100.0, "max_us": 6000.0}
        ], "inference_paper_ms": 2.1}),
    );
    per_run.len()
}
