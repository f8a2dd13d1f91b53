//! How well the neighbour detector (`formation_perception::neighbours`) finds a team's robots in
//! real simulated scans: teams of `teams-generalist` (16 robots, d* drawn over 0.8-2.5 m, LIDAR
//! noise σ = 3 cm), in two kinds of state:
//!
//! * `start`: the scenario's own starting poses (a disc of radius 3 sqrt(N/3) m);
//! * `formation`: a hexagonal lattice patch of spacing d* (the formation the team holds), each
//!   robot moved by up to 5 % of d* and turned at random, the whole patch at a random angle.
//!
//! Every robot of every team is an observer. For each, its 8 nearest robots are the truth; one is
//! found when a detection lies within one body radius of its centre. A robot is "visible" when
//! its noiseless scan has at least 3 beams on its body. Spurious detections are those within one
//! body radius of no robot. Time is the detector's alone, per scan, on this build.
//!
//! ```sh
//! cargo run -p formation-perception --release --example detect_neighbours -- [RUNS] [NOISE_STD]
//! ```

use std::f64::consts::TAU;
use std::path::Path;
use std::time::{Duration, Instant};

use formation_perception::neighbours::{DetectedNeighbour, NeighbourDetector};
use formation_proto::{LidarNoise, Pose};
use formation_world::lidar::cast_scan;
use formation_world::{Scenario, World};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const ROBOTS: usize = 16;
const NEAREST: usize = 8;
/// Fits of fewer beams (slivers of partly hidden robots) make the error's tail.
const WIDE: usize = 10;

#[derive(Default)]
struct Tally {
    errors: Vec<f64>,
    /// The errors of detections fitted to at least [`WIDE`] beams.
    wide_errors: Vec<f64>,
    truths: usize,
    missed: usize,
    visible: usize,
    visible_missed: usize,
    detections: usize,
    spurious: usize,
    scans: usize,
    time: Duration,
}

impl Tally {
    fn report(&mut self, name: &str) {
        self.errors.sort_by(f64::total_cmp);
        self.wide_errors.sort_by(f64::total_cmp);
        let quantile = |errors: &[f64], q: f64| {
            errors[((errors.len() - 1) as f64 * q).round() as usize] * 1000.0
        };
        let at = |q: f64| quantile(&self.errors, q);
        let wide = |q: f64| quantile(&self.wide_errors, q);
        let share = |part: usize, whole: usize| 100.0 * part as f64 / whole.max(1) as f64;
        println!(
            "{name:9} scans {:6}  centre error mm: median {:5.1}  p90 {:5.1}  p99 {:5.1}  max {:6.1}  \
             missed of 8 nearest {:5.2} % (of the visible {:5.2} %, {:4.1} % hidden)  \
             spurious {:4.2} % of detections  {:5.1} µs a scan",
            self.scans,
            at(0.5),
            at(0.9),
            at(0.99),
            at(1.0),
            share(self.missed, self.truths),
            share(self.visible_missed, self.visible),
            share(self.truths - self.visible, self.truths),
            share(self.spurious, self.detections),
            self.time.as_secs_f64() * 1e6 / self.scans as f64,
        );
        println!(
            "{:9} fits of >= {WIDE} beams ({:4.1} % of the found): median {:5.1}  p90 {:5.1}  p99 {:5.1}  max {:6.1}",
            "",
            100.0 * self.wide_errors.len() as f64 / self.errors.len() as f64,
            wide(0.5),
            wide(0.9),
            wide(0.99),
            wide(1.0),
        );
    }
}

/// Robot `j`'s centre in robot `own`'s body frame.
fn body_frame(poses: &[Pose], own: usize, j: usize) -> (f64, f64) {
    let (o, p) = (poses[own], poses[j]);
    let (sin, cos) = o.theta.sin_cos();
    let (dx, dy) = (p.x - o.x, p.y - o.y);
    (cos * dx + sin * dy, -sin * dx + cos * dy)
}

/// `n` sites of a hexagonal lattice of `spacing`, nearest the origin first, jittered, turned.
fn formation(rng: &mut ChaCha8Rng, n: usize, spacing: f64) -> Vec<Pose> {
    let mut sites = Vec::new();
    for row in -4_i32..=4 {
        for col in -4_i32..=4 {
            let x = (f64::from(col) + 0.5 * f64::from(row)) * spacing;
            let y = f64::from(row) * spacing * 3f64.sqrt() / 2.0;
            sites.push((x, y));
        }
    }
    sites.sort_by(|a, b| a.0.hypot(a.1).total_cmp(&b.0.hypot(b.1)));
    let turn = TAU * rng.random::<f64>();
    let (sin, cos) = turn.sin_cos();
    sites
        .iter()
        .take(n)
        .map(|&(x, y)| {
            let jitter = 0.05 * spacing;
            let x = x + jitter * (2.0 * rng.random::<f64>() - 1.0);
            let y = y + jitter * (2.0 * rng.random::<f64>() - 1.0);
            Pose::new(
                cos * x - sin * y,
                sin * x + cos * y,
                TAU * rng.random::<f64>(),
            )
        })
        .collect()
}

fn measure(world: &mut World, tally: &mut Tally, detector: &mut NeighbourDetector) {
    let (config, poses) = (*world.config(), world.poses().to_vec());
    let lidar = config.lidar;
    let radius = config.robot.body_radius;
    let (mut scan, mut clean) = (vec![0.0; lidar.beams], vec![0.0; lidar.beams]);
    let mut found: Vec<DetectedNeighbour> = Vec::new();
    for own in 0..poses.len() {
        world.scan_into(own, &mut scan);
        cast_scan(&poses, own, &config.robot, &lidar, &mut clean);
        let started = Instant::now();
        detector.detect(&scan, &lidar, &mut found);
        tally.time += started.elapsed();
        tally.scans += 1;
        let mut others: Vec<(f64, f64)> = (0..poses.len())
            .filter(|&j| j != own)
            .map(|j| body_frame(&poses, own, j))
            .collect();
        others.sort_by(|a, b| a.0.hypot(a.1).total_cmp(&b.0.hypot(b.1)));
        for &(x, y) in others.iter().take(NEAREST) {
            let beams_on = clean
                .iter()
                .enumerate()
                .filter(|&(k, &r)| {
                    let bearing = TAU * k as f64 / lidar.beams as f64;
                    let r = f64::from(r);
                    r < lidar.max_range
                        && (r * bearing.cos() - x).hypot(r * bearing.sin() - y) < radius + 1e-3
                })
                .count();
            let visible = beams_on >= 3;
            let nearest = found
                .iter()
                .map(|f| ((f.x - x).hypot(f.y - y), f.beams))
                .min_by(|a, b| a.0.total_cmp(&b.0));
            let (error, beams) = nearest.unwrap_or((f64::INFINITY, 0));
            tally.truths += 1;
            tally.visible += usize::from(visible);
            if error < radius {
                tally.errors.push(error);
                if beams >= WIDE {
                    tally.wide_errors.push(error);
                }
            } else {
                tally.missed += 1;
                tally.visible_missed += usize::from(visible);
            }
        }
        tally.detections += found.len();
        tally.spurious += found
            .iter()
            .filter(|f| {
                others
                    .iter()
                    .all(|&(x, y)| (f.x - x).hypot(f.y - y) >= radius)
            })
            .count();
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let runs: usize = args.next().map(|a| a.parse()).transpose()?.unwrap_or(50);
    let noise_std: f64 = args.next().map(|a| a.parse()).transpose()?.unwrap_or(0.03);
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/teams-generalist.toml");
    let scenario = Scenario::from_path(&path)?.with_robots(ROBOTS)?;
    println!(
        "{} runs of {ROBOTS} robots ({}, seed {}), σ = {noise_std} m",
        runs,
        scenario.name(),
        scenario.seed()
    );
    let mut detector = NeighbourDetector::default();
    let (mut start, mut held) = (Tally::default(), Tally::default());
    for run in 0..runs {
        let mut spec = scenario.run_spec(scenario.seed(), run);
        spec.world.lidar_noise = LidarNoise { noise_std };
        measure(&mut spec.make_world(), &mut start, &mut detector);
        let mut rng = ChaCha8Rng::seed_from_u64(spec.seed);
        let poses = formation(&mut rng, ROBOTS, spec.d_star);
        let mut world = World::new(spec.world, poses, spec.noise_seed);
        measure(&mut world, &mut held, &mut detector);
    }
    start.report("start");
    held.report("formation");
    Ok(())
}
