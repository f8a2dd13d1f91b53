//! Criterion bench: one single-sample forward pass of the paper's network through `OnnxPolicy`
//! (one intra-op thread), on a model with random weights written by the test fixtures.

#[path = "../tests/common/mod.rs"]
mod common;

use criterion::{Criterion, criterion_group, criterion_main};
use formation_onnx::OnnxPolicy;
use formation_proto::PolicyInput;

fn single_sample(c: &mut Criterion) {
    let fx = common::fixtures("bench");
    let mut policy = OnnxPolicy::load(&fx.model("policy.onnx")).expect("fixture loads");
    let cases = fx.cases();
    let mut next = 0;
    c.bench_function("onnx_policy_infer_single_sample", |b| {
        b.iter(|| {
            let (image, aux, _) = &cases[next % cases.len()];
            next += 1;
            policy
                .infer(&PolicyInput::image_and_aux(
                    std::hint::black_box(image),
                    aux,
                ))
                .expect("infer")
        })
    });
}

criterion_group!(benches, single_sample);
criterion_main!(benches);
