//! Cost of the simulated world per control tick: every robot's 900-beam LIDAR scan followed by one
//! step.
//!
//! * `world_tick_scan_all_and_step_*`: the paper's 3 robots, and a dense 64-robot team on a grid.
//! * `world_tick_growth/N`: the growth series, N = 3 .. 4096 robots at the paper's density (see
//!   [`paper_density_layout`]), the numbers in `world/BENCH.md`.
//! * `reference_scan_all_growth/N`: the same layouts scanned by the all-bodies reference caster
//!   [`cast_scan`], robot by robot, for comparison (no step).
//! * `cast_scan_900_beams_*`: one robot's noiseless ray cast alone.
//! * `world_tick_growth_cpu/N` and `reference_scan_all_growth_cpu/N`: the growth series again, timed
//!   by the benchmarking thread's on-CPU time ([`ThreadCpuTime`]) rather than wall time, so that
//!   other jobs on a shared, loaded machine do not inflate the figures.

use std::f64::consts::TAU;
use std::hint::black_box;

use criterion::measurement::{Measurement, ValueFormatter};
use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use formation_proto::{LidarSpec, Pose, WheelCmd};
use formation_world::lidar::cast_scan;
use formation_world::{RobotParams, World, WorldConfig};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Team sizes of the growth series.
const GROWTH_SIZES: [usize; 6] = [3, 16, 64, 256, 1000, 4096];

/// The paper's three robots, a couple of metres apart.
fn three_robots() -> Vec<Pose> {
    vec![
        Pose::new(0.0, 0.0, 0.3),
        Pose::new(1.5, 0.4, 1.0),
        Pose::new(-0.6, 1.3, -2.0),
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

/// `n` robots at the paper's density: the paper puts 3 robots uniformly in a disc of radius 3 m, so
/// `n` robots go uniformly in a disc of radius `3 sqrt(n / 3)` m (the same 0.106 robots per m^2,
/// about 33 other robots within a 10 m LIDAR range in the bulk of a large team), reject-sampled to a
/// minimum pairwise spacing of 0.6 m, headings uniform in [0, 2 pi). Seeded: the same layout every run.
fn paper_density_layout(n: usize) -> Vec<Pose> {
    const MIN_SPACING: f64 = 0.6;
    let radius = 3.0 * (n as f64 / 3.0).sqrt();
    let mut rng = ChaCha8Rng::seed_from_u64(n as u64);
    let mut poses: Vec<Pose> = Vec::with_capacity(n);
    while poses.len() < n {
        let r = radius * rng.random::<f64>().sqrt();
        let (s, c) = (TAU * rng.random::<f64>()).sin_cos();
        let (x, y) = (r * c, r * s);
        let far_enough = poses
            .iter()
            .all(|p| (p.x - x).powi(2) + (p.y - y).powi(2) >= MIN_SPACING * MIN_SPACING);
        if far_enough {
            poses.push(Pose {
                x,
                y,
                theta: TAU * rng.random::<f64>(),
            });
        }
    }
    poses
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

/// One tick of `world`: every robot's scan, then one step.
fn tick(world: &mut World, scans: &mut [Vec<f32>], cmds: &[WheelCmd]) {
    world.scan_all(black_box(scans));
    black_box(world.step(black_box(cmds)));
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
            b.iter(|| tick(&mut world, &mut scans, &cmds))
        });
    }
}

/// On-CPU time \[ns\] of the benchmarking thread: the first field of Linux's
/// `/proc/thread-self/schedstat`. Time the thread spends waiting for a core does not count, so the
/// figures stay what a tick costs on an idle core when the machine is shared.
struct ThreadCpuTime;

fn thread_cpu_nanos() -> u64 {
    let schedstat = std::fs::read_to_string("/proc/thread-self/schedstat")
        .expect("ThreadCpuTime needs Linux's /proc/thread-self/schedstat");
    schedstat
        .split_whitespace()
        .next()
        .and_then(|field| field.parse().ok())
        .expect("schedstat starts with the on-CPU time in ns")
}

impl Measurement for ThreadCpuTime {
    type Intermediate = u64;
    type Value = u64;

    fn start(&self) -> u64 {
        thread_cpu_nanos()
    }

    fn end(&self, start: u64) -> u64 {
        thread_cpu_nanos() - start
    }

    fn add(&self, a: &u64, b: &u64) -> u64 {
        a + b
    }

    fn zero(&self) -> u64 {
        0
    }

    fn to_f64(&self, value: &u64) -> f64 {
        *value as f64
    }

    fn formatter(&self) -> &dyn ValueFormatter {
        &CpuNanosFormatter
    }
}

/// Shows nanoseconds in the unit that suits their size, like criterion's wall-time figures.
struct CpuNanosFormatter;

impl CpuNanosFormatter {
    fn unit_for(typical_nanos: f64) -> (f64, &'static str) {
        match typical_nanos {
            t if t < 1e3 => (1.0, "ns (cpu)"),
            t if t < 1e6 => (1e-3, "µs (cpu)"),
            t if t < 1e9 => (1e-6, "ms (cpu)"),
            _ => (1e-9, "s (cpu)"),
        }
    }
}

impl ValueFormatter for CpuNanosFormatter {
    fn scale_values(&self, typical_value: f64, values: &mut [f64]) -> &'static str {
        let (factor, unit) = Self::unit_for(typical_value);
        values.iter_mut().for_each(|v| *v *= factor);
        unit
    }

    fn scale_throughputs(
        &self,
        _typical_value: f64,
        throughput: &Throughput,
        values: &mut [f64],
    ) -> &'static str {
        let per_iteration = match *throughput {
            Throughput::Elements(n)
            | Throughput::Bytes(n)
            | Throughput::BytesDecimal(n)
            | Throughput::Bits(n) => n,
        } as f64;
        values
            .iter_mut()
            .for_each(|v| *v = per_iteration * 1e9 / *v);
        "elem/s (cpu)"
    }

    fn scale_for_machines(&self, _values: &mut [f64]) -> &'static str {
        "ns"
    }
}

fn bench_tick_growth<M: Measurement>(c: &mut Criterion<M>, group_name: &str) {
    let mut group = c.benchmark_group(group_name);
    group.sample_size(10);
    for n in GROWTH_SIZES {
        let mut world = World::new(WorldConfig::default(), paper_density_layout(n), 1);
        let mut scans = vec![vec![0.0_f32; world.config().lidar.beams]; n];
        let cmds = turning_commands(n);
        group.bench_function(BenchmarkId::from_parameter(n), |b| {
            b.iter(|| tick(&mut world, &mut scans, &cmds))
        });
    }
    group.finish();
}

fn bench_reference_scan_growth<M: Measurement>(c: &mut Criterion<M>, group_name: &str) {
    let mut group = c.benchmark_group(group_name);
    group.sample_size(10);
    let lidar = LidarSpec::default();
    let params = RobotParams::default();
    for n in GROWTH_SIZES {
        let poses = paper_density_layout(n);
        let mut scans = vec![vec![0.0_f32; lidar.beams]; n];
        group.bench_function(BenchmarkId::from_parameter(n), |b| {
            b.iter(|| {
                for (own, scan) in scans.iter_mut().enumerate() {
                    cast_scan(black_box(&poses), own, &params, &lidar, scan);
                }
            })
        });
    }
    group.finish();
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

fn bench_growth_wall_time(c: &mut Criterion) {
    bench_tick_growth(c, "world_tick_growth");
    bench_reference_scan_growth(c, "reference_scan_all_growth");
}

fn bench_growth_cpu_time(c: &mut Criterion<ThreadCpuTime>) {
    bench_tick_growth(c, "world_tick_growth_cpu");
    bench_reference_scan_growth(c, "reference_scan_all_growth_cpu");
}

criterion_group!(benches, bench_tick, bench_growth_wall_time, bench_cast_scan);
criterion_group! {
    name = cpu_time_benches;
    config = Criterion::default().with_measurement(ThreadCpuTime);
    targets = bench_growth_cpu_time
}
criterion_main!(benches, cpu_time_benches);
