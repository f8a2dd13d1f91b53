//! Single-sample inference latency percentiles of the shipped models, side by side in one run
//! (ignored by default: a measurement, not a check).
//!
//! ```text
//! cargo test -p formation-onnx --release --test latency -- --ignored --nocapture
//! ```
//!
//! It measures `onnx/models/policy.onnx` (the default, its whole graph), `onnx/models/paper/
//! policy.onnx` (the paper's network) and the random-weight fixture of the paper's network, then
//! any further models named in `FORMATION_LATENCY_MODELS` (paths separated by `:`), each on the
//! same sparse images (and, for a model that takes the scan's ranges, the same ranges), through
//! `OnnxPolicy` with one intra-op thread, as an agent runs it.

mod common;

use std::path::{Path, PathBuf};
use std::time::Instant;

use formation_onnx::OnnxPolicy;
use formation_proto::PolicyInput;

const CALLS: usize = 10_000;
const WARMUP: usize = 500;
/// Distinct inputs cycled through (sparse images like a scan's, varied heading errors and d*).
const INPUTS: usize = 64;

/// Sparse 0/1 images of `size` x `size` cells and `(delta_phi, d*)` pairs, from a fixed LCG.
fn inputs(size: usize) -> Vec<(Vec<f32>, [f32; 2])> {
    let mut state: u64 = 0x9e37_79b9_7f4a_7c15;
    let mut next = move || {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (state >> 33) as f32 / (1u64 << 31) as f32
    };
    (0..INPUTS)
        .map(|_| {
            let image = (0..size * size)
                .map(|_| if next() < 0.02 { 1.0 } else { 0.0 })
                .collect();
            let aux = [next() * 6.0 - 3.0, 0.8 + next() * 1.7];
            (image, aux)
        })
        .collect()
}

/// Loads `path` and prints its load time and single-sample percentiles.
fn measure(label: &str, path: &Path) {
    let started = Instant::now();
    let mut policy = OnnxPolicy::load(path).expect("the model loads");
    let load_ms = started.elapsed().as_secs_f64() * 1e3;
    let cases = inputs(policy.metadata().occupancy.size_px);
    // A model that takes the scan's ranges gets them too: d* (1.5 m, in units of d*) where no
    // beam returns, a neighbour in a few sectors.
    let ranges: Vec<f32> = policy.metadata().ranges.map_or_else(Vec::new, |r| {
        (0..r.sectors)
            .map(|s| if s % 17 < 3 { 1.0 } else { r.clip })
            .collect()
    });
    // A model that takes detected neighbours gets six, held at d* around the robot, in its
    // first slots (per slot `x / d*, y / d*, held, present`, and no hidden pair's step where
    // the model declares `hidden=1`); the other slots are empty.
    let neighbours: Vec<f32> = policy.metadata().neighbours.map_or_else(Vec::new, |n| {
        (0..n.slots)
            .flat_map(|slot| {
                let angle = slot as f32 * std::f32::consts::TAU / 6.0;
                let mut values = vec![0.0; n.features()];
                if slot < 6 {
                    values[..4].copy_from_slice(&[angle.cos(), angle.sin(), 1.0, 1.0]);
                }
                values
            })
            .collect()
    });
    // One call on an image and its scalars, with the ranges and neighbours where the model
    // takes them.
    let mut infer = |image: &[f32], aux: &[f32]| {
        policy
            .infer(&PolicyInput {
                image,
                aux,
                ranges: &ranges,
                neighbours: &neighbours,
            })
            .expect("infer")
    };
    for i in 0..WARMUP {
        let (image, aux) = &cases[i % cases.len()];
        infer(image, aux);
    }
    let mut micros: Vec<f64> = Vec::with_capacity(CALLS);
    for i in 0..CALLS {
        let (image, aux) = &cases[i % cases.len()];
        let t = Instant::now();
        let out = infer(image, aux);
        micros.push(t.elapsed().as_secs_f64() * 1e6);
        std::hint::black_box(out);
    }
    micros.sort_by(f64::total_cmp);
    let pct = |p: f64| micros[((p / 100.0) * (CALLS - 1) as f64).round() as usize];
    println!(
        "{label:<40} load {load_ms:6.1} ms; {CALLS} single-sample calls: p50 {:6.1} us, p90 {:6.1} us, \
         p99 {:6.1} us, max {:7.1} us",
        pct(50.0),
        pct(90.0),
        pct(99.0),
        pct(100.0)
    );
    assert!(pct(50.0) > 0.0);
}

#[test]
#[ignore = "measurement; run with --ignored --nocapture"]
fn single_sample_latency_percentiles() {
    let models = Path::new(env!("CARGO_MANIFEST_DIR")).join("models");
    measure(
        "onnx/models/policy.onnx (default)",
        &models.join("policy.onnx"),
    );
    measure(
        "onnx/models/paper/policy.onnx",
        &models.join("paper").join("policy.onnx"),
    );
    let fx = common::fixtures("latency");
    measure("paper network, random weights", &fx.model("policy.onnx"));
    for path in std::env::var("FORMATION_LATENCY_MODELS")
        .unwrap_or_default()
        .split(':')
        .filter(|p| !p.is_empty())
    {
        measure(path, &PathBuf::from(path));
    }
}
