//! Single-sample inference latency percentiles (ignored by default: a measurement, not a check).
//!
//! `cargo test -p formation-onnx --release --test latency -- --ignored --nocapture`

mod common;

use std::time::Instant;

use formation_onnx::OnnxPolicy;

const CALLS: usize = 10_000;
const WARMUP: usize = 500;

#[test]
#[ignore = "measurement; run with --ignored --nocapture"]
fn single_sample_latency_percentiles() {
    let fx = common::fixtures("latency");
    let started = Instant::now();
    let mut policy = OnnxPolicy::load(&fx.model("policy.onnx")).expect("loads");
    let load_ms = started.elapsed().as_secs_f64() * 1e3;
    let cases = fx.cases();
    for i in 0..WARMUP {
        let (image, aux, _) = &cases[i % cases.len()];
        policy.infer(image, *aux).expect("infer");
    }
    let mut micros: Vec<f64> = Vec::with_capacity(CALLS);
    for i in 0..CALLS {
        let (image, aux, _) = &cases[i % cases.len()];
        let t = Instant::now();
        let out = policy.infer(image, *aux).expect("infer");
        micros.push(t.elapsed().as_secs_f64() * 1e6);
        std::hint::black_box(out);
    }
    micros.sort_by(f64::total_cmp);
    let pct = |p: f64| micros[((p / 100.0) * (CALLS - 1) as f64).round() as usize];
    println!(
        "first load (runtime + session) {load_ms:.1} ms; {CALLS} single-sample calls: p50 {:.1} us, p90 {:.1} us, \
         p99 {:.1} us, max {:.1} us",
        pct(50.0),
        pct(90.0),
        pct(99.0),
        pct(100.0)
    );
    assert!(pct(50.0) > 0.0);
}
