//! Cost of the simulated world per control tick: every robot's 900-beam LIDAR scan followed by one
//! step, for the paper's 3 robots and for a 64-robot team on a grid; and one robot's noiseless ray
//! cast alone.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use formation_proto::{LidarSpec, Pose, WheelCmd};
use formation_world::lidar::cast_scan;
use formation_world::{RobotParams, World, WorldConfig};

/// The paper's three robots, a couple of metres apart.
fn three_robots() -> Vec<Pose> {
    vec![
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
    ]
}

/// 64 robots on an 8 x 8 grid with 1.5 m spacing (10.5 m across: most of the team is within each
/// robot's 10 m range), headings varied so beams do not line up with the grid.
fn grid_of_64_robots() -> Vec<Pose> {
    (0..64)
        .map(|i| Pose {
            x: (i % 8) as f64 * 1.5,
            y: (i / 8) as f64 * 1.5,
            theta: i as f64 * 0.37,
        })
        .collect()
}

/// Commands that keep the team roughly in place over many iterations: a slow turn on the spot.
fn turning_commands(n: usize) -> Vec<WheelCmd> {
    vec![
        WheelCmd {
            left: -0.1,
            right: 0.1
        };
        n
    ]
}

fn bench_tick(c: &mut Criterion) {
    for (label, poses) in [
        ("3_robots", three_robots()),
        ("64_robots_grid", grid_of_64_robots()),
    ] {
        let n = poses.len();
        let mut world = World::new(WorldConfig::default(), poses, 1);
        let mut scans = vec![vec![0.0_f32; world.config().lidar.beams]; n];
        let cmds = turning_commands(n);
        c.bench_function(&format!("world_tick_scan_all_and_step_{label}"), |b| {
            b.iter(|| {
                world.scan_all(black_box(&mut scans));
                black_box(world.step(black_box(&cmds)))
            })
        });
    }
}

fn bench_cast_scan(c: &mut Criterion) {
    let lidar = LidarSpec::default();
    let params = RobotParams::default();
    let mut scan = vec![0.0_f32; lidar.beams];
    for (label, poses, own) in [
        ("3_robots", three_robots(), 0),
        // A robot in the middle of the grid, with the most neighbours in range.
        ("64_robots_grid_centre", grid_of_64_robots(), 27),
    ] {
        c.bench_function(&format!("cast_scan_900_beams_{label}"), |b| {
            b.iter(|| {
                cast_scan(
                    black_box(&poses),
                    own,
                    &params,
                    &lidar,
                    black_box(&mut scan),
                )
            })
        });
    }
}

criterion_group!(benches, bench_tick, bench_cast_scan);
criterion_main!(benches);
