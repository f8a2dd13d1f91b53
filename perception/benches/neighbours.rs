//! Cost of detecting one robot's neighbours in its raw 900-beam scan (σ = 3 cm), inside a
//! hexagonal formation of 16 robots at d* = 1.5 m: the per-tick work of an agent whose model
//! takes detected neighbours.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use formation_perception::neighbours::NeighbourDetector;
use formation_proto::{LidarNoise, Pose};
use formation_world::{World, WorldConfig};

/// Robot 0 at the centre of a 16-robot hexagonal patch of spacing 1.5 m.
fn formation_scan() -> (Vec<f32>, WorldConfig) {
    let spacing = 1.5;
    let mut sites = Vec::new();
    for row in -3_i32..=3 {
        for col in -3_i32..=3 {
            let x = (f64::from(col) + 0.5 * f64::from(row)) * spacing;
            let y = f64::from(row) * spacing * 3f64.sqrt() / 2.0;
            sites.push(Pose::new(x, y, 0.1 * f64::from(col)));
        }
    }
    sites.sort_by(|a, b| a.x.hypot(a.y).total_cmp(&b.x.hypot(b.y)));
    sites.truncate(16);
    let config = WorldConfig {
        lidar_noise: LidarNoise { noise_std: 0.03 },
        ..WorldConfig::default()
    };
    let mut world = World::new(config, sites, 7);
    let mut scan = vec![0.0; config.lidar.beams];
    world.scan_into(0, &mut scan);
    (scan, config)
}

fn bench_detect(c: &mut Criterion) {
    let (scan, config) = formation_scan();
    let mut detector = NeighbourDetector::default();
    let mut found = Vec::new();
    detector.detect(&scan, &config.lidar, &mut found);
    assert!(
        found.len() >= 6,
        "the benchmark scan must show the ring of neighbours"
    );
    c.bench_function("neighbours_detect_900_beams_16_robot_formation", |b| {
        b.iter(|| detector.detect(black_box(&scan), &config.lidar, black_box(&mut found)))
    });
}

criterion_group!(benches, bench_detect);
criterion_main!(benches);
