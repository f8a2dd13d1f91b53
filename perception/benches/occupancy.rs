//! Cost of rendering one robot's occupancy image from a raw 900-beam scan with two neighbours in view,
//! the per-tick perception work of every agent (and of demonstration collection, per robot).

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use formation_perception::occupancy::render;
use formation_proto::{BeyondWindow, LidarSpec, OccupancySpec, Pose};
use formation_world::RobotParams;
use formation_world::lidar::cast_scan;

/// Robot 0 at the origin with two neighbours inside the paper's 5 x 5 m window.
fn scan_with_two_neighbours(lidar: &LidarSpec) -> Vec<f32> {
    let poses = [
        Pose {
            x: 0.0,
            y: 0.0,
            theta: 0.3,
        },
        Pose {
            x: 1.5,
            y: 0.4,
            theta: 1.0,
        },
        Pose {
            x: -0.6,
            y: 1.3,
            theta: -2.0,
        },
    ];
    let mut scan = vec![0.0; lidar.beams];
    cast_scan(&poses, 0, &RobotParams::default(), lidar, &mut scan);
    scan
}

fn bench_render(c: &mut Criterion) {
    let lidar = LidarSpec::default();
    let scan = scan_with_two_neighbours(&lidar);
    let hits = scan
        .iter()
        .filter(|&&r| f64::from(r) < lidar.max_range)
        .count();
    assert!(hits > 0, "the benchmark scan must see the neighbours");
    for beyond in [BeyondWindow::Drop, BeyondWindow::Border] {
        let spec = OccupancySpec {
            beyond,
            ..OccupancySpec::PAPER
        };
        let mut image = vec![0_u8; spec.size_px * spec.size_px];
        c.bench_function(
            &format!(
                "occupancy_render_900_beams_2_neighbours_{}",
                beyond.as_str()
            ),
            |b| b.iter(|| render(black_box(&scan), &lidar, &spec, black_box(&mut image))),
        );
    }
}

criterion_group!(benches, bench_render);
criterion_main!(benches);
