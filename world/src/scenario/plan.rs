//! The last phase: the fully resolved [`RunSpec`] of one run, a pure function of the scenario,
//! the base seed and the run index, with the seeds mixed for it.

use super::*;

/// Everything one run needs, resolved: no randomness is left except the world's sensor noise, which
/// is fixed by `noise_seed`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunSpec {
    /// Index of the run within its scenario.
    pub index: usize,
    /// The run's own seed, mixed from the base seed and the index.
    pub seed: u64,
    /// Team size.
    pub n_robots: usize,
    /// Desired pairwise distance \[m\].
    pub d_star: f64,
    /// Desired speed \[m/s\]: the scenario's fixed v*, or this run's draw from `goal.v_star_range`.
    pub v_star: f64,
    /// Desired heading over time.
    pub heading: HeadingSchedule,
    /// Simulated duration \[s\].
    pub duration_s: f64,
    /// Robot, sensor and time-step settings of the world.
    pub world: WorldConfig,
    /// Initial pose of each robot.
    pub initial: Vec<Pose>,
    /// Seed of the world's sensor-noise generator.
    pub noise_seed: u64,
    /// Which pairs are formation edges: the expert holds them at d* and the metrics score them,
    /// recomputed every tick from the robots' positions.
    pub neighbours: NeighbourRule,
}

impl RunSpec {
    /// Number of control ticks: `round(duration_s / dt)`.
    pub fn ticks(&self) -> u64 {
        (self.duration_s / self.world.dt).round() as u64
    }

    /// The goal every robot is given at time `t` \[s\].
    pub fn goal_at(&self, t: f64) -> Goal {
        Goal {
            phi_star: self.heading.phi_star(t),
            d_star: self.d_star,
            v_star: self.v_star,
        }
    }

    /// A fresh world in this run's initial state.
    pub fn make_world(&self) -> World {
        World::new(self.world, self.initial.clone(), self.noise_seed)
    }
}

impl Scenario {
    /// The resolved spec of run `run_index`, a pure function of `(self, base_seed, run_index)`.
    pub fn run_spec(&self, base_seed: u64, run_index: usize) -> RunSpec {
        let seed = run_seed(base_seed, run_index);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let d_star = match &self.d_star {
            DStarPlan::Fixed(d) => *d,
            DStarPlan::Choices(choices) => choices[rng.random_range(0..choices.len())],
            DStarPlan::Range { min, max } => rng.random_range(*min..=*max),
        };
        let heading = match self.heading {
            HeadingPlan::Fixed(schedule) => schedule,
            HeadingPlan::RandomConstant => HeadingSchedule::Constant {
                phi: rng.random_range(0.0..TAU),
            },
        };
        let range = sensing_range(&self.neighbours, &self.world);
        let positions = place_robots(&mut rng, self.n_robots, &self.init, range);
        // All positions are drawn before any heading.
        let initial = positions
            .into_iter()
            .map(|(x, y)| Pose {
                x,
                y,
                theta: wrap_angle(rng.random_range(0.0..TAU)),
            })
            .collect();
        RunSpec {
            index: run_index,
            seed,
            n_robots: self.n_robots,
            d_star,
            v_star: self.v_star.draw(seed),
            heading,
            duration_s: self.duration_s,
            world: self.world,
            initial,
            noise_seed: splitmix64(seed ^ NOISE_DOMAIN),
            neighbours: self.neighbours,
        }
    }
}

/// Domain-separation constants so the run seed and the noise seed are independent streams.
pub(super) const RUN_DOMAIN: u64 = 0x5EED_0F0F_2A2A_0001;
pub(super) const NOISE_DOMAIN: u64 = 0xA5A5_5A5A_C3C3_3C3C;
/// The domain of v*'s own generator (`goal.v_star_range`).
pub(super) const V_STAR_DOMAIN: u64 = 0x7E57_AB1E_0B57_A12D;

/// The seed of run `run_index` of a scenario with `base_seed`.
pub(super) fn run_seed(base_seed: u64, run_index: usize) -> u64 {
    splitmix64(splitmix64(base_seed ^ RUN_DOMAIN) ^ splitmix64(run_index as u64))
}
