//! `Batch`: `B` runs of one scenario played tick by tick together, in parallel on rayon's pool,
//! with numpy arrays in and out.
//!
//! World `b` of a batch made with `seeds[b]` and `runs[b]` is run `runs[b]` of `formation eval
//! --seed seeds[b]`: its spec is `Scenario::run_spec`, its loop `formation_world::Episode`, the
//! same functions the CLI's loop calls. Every output is one array for the whole batch, filled in
//! place world by world in parallel and handed to numpy without a copy; actions are read from one
//! `(B, N, 2)` array.

use formation_expert::{ExpertController, ExpertGains};
use formation_perception::beams::BeamDirections;
use formation_perception::neighbour_input::NeighbourInputBuilder;
use formation_perception::ranges::pool;
use formation_perception::stopping;
use formation_perception::{occupancy, policy_input};
use formation_proto::control::Controller;
use formation_proto::{
    AuxLayout, BeyondWindow, NeighbourInput, OccupancySpec, RangeInput, WheelCmd,
};
use formation_world::metrics::{MetricsConfig, run_metrics};
use formation_world::neighbours::NeighbourTracker;
use formation_world::{Episode, Scenario, StepError};
use numpy::{
    IntoPyArray, PyArray2, PyArray3, PyArrayDyn, PyArrayMethods, PyReadonlyArrayDyn,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use rayon::prelude::*;

use crate::EpisodeOver;
use crate::scenario::PyScenario;

/// One world of a batch: its run, its expert (when asked for) and its neighbour tracker.
struct Slot {
    episode: Episode,
    /// The expert, consulted once per tick (before each step) so that its neighbour state
    /// follows the run as in `formation eval --controller expert`.
    expert: Option<ExpertController>,
    /// The expert's commands for `expert_tick`.
    expert_commands: Vec<WheelCmd>,
    expert_tick: Option<u64>,
    /// The formation's edges under the scenario's rule, updated sample after sample.
    tracker: NeighbourTracker,
    positions: Vec<(f64, f64)>,
    /// Fills the `neighbours` input from each robot's own scan, as the agent's does (the
    /// detector's default settings, the agent's).
    neighbour_builder: NeighbourInputBuilder,
}

/// Why a world of the batch could not step.
#[derive(Debug, thiserror::Error)]
enum SlotError {
    #[error("world {world}: {source}")]
    Step { world: usize, source: StepError },
    #[error("world {world}: the expert cannot act: {message}")]
    Expert { world: usize, message: String },
}

impl From<SlotError> for PyErr {
    fn from(error: SlotError) -> PyErr {
        match &error {
            SlotError::Step {
                source: StepError::Over { .. },
                ..
            } => EpisodeOver::new_err(error.to_string()),
            SlotError::Step { .. } => PyValueError::new_err(error.to_string()),
            SlotError::Expert { .. } => PyRuntimeError::new_err(error.to_string()),
        }
    }
}

impl Slot {
    fn new(scenario: &Scenario, seed: u64, run: usize, expert: bool) -> Slot {
        let episode = Episode::new(scenario.run_spec(seed, run));
        let robots = scenario.n_robots();
        let expert = expert.then(|| {
            ExpertController::for_world(ExpertGains::default(), scenario.world_config())
                .with_neighbours(*scenario.neighbours())
        });
        let mut slot = Slot {
            episode,
            expert,
            expert_commands: vec![WheelCmd::BRAKE; robots],
            expert_tick: None,
            tracker: NeighbourTracker::new(*scenario.neighbours(), robots),
            positions: Vec::with_capacity(robots),
            neighbour_builder: NeighbourInputBuilder::default(),
        };
        slot.track();
        slot
    }

    fn track(&mut self) {
        self.positions.clear();
        self.positions
            .extend(self.episode.world().poses().iter().map(|p| (p.x, p.y)));
        self.tracker.update(&self.positions);
    }

    /// The expert's commands for this tick, computed once per tick.
    fn expert_commands(&mut self, world: usize) -> Result<&[WheelCmd], SlotError> {
        let Some(expert) = &mut self.expert else {
            return Ok(&self.expert_commands);
        };
        let tick = self.episode.world().tick();
        if self.expert_tick != Some(tick) && !self.episode.is_over() {
            self.expert_commands.fill(WheelCmd::BRAKE);
            let observation = self.episode.observe();
            expert
                .commands(&observation, &mut self.expert_commands)
                .map_err(|e| SlotError::Expert {
                    world,
                    message: e.to_string(),
                })?;
            self.expert_tick = Some(tick);
        }
        Ok(&self.expert_commands)
    }

    fn step(
        &mut self,
        world: usize,
        commands: &[WheelCmd],
    ) -> Result<Vec<(usize, usize)>, SlotError> {
        if self.episode.is_over() {
            return Err(SlotError::Step {
                world,
                source: StepError::Over {
                    ticks: self.episode.ticks(),
                },
            });
        }
        self.expert_commands(world)?;
        let collisions = self
            .episode
            .step(commands)
            .map_err(|source| SlotError::Step { world, source })?;
        self.track();
        Ok(collisions)
    }
}

/// `B` runs of one scenario, stepped together in parallel.
///
/// `Batch(scenario, seeds, runs, expert=True)`: world `b` plays run `runs[b]` of seed `seeds[b]`
/// (run `R` of `formation eval --seed S`). With `expert`, each world's expert is consulted
/// once per tick, before its step, whether or not `expert_actions()` is called.
#[pyclass(name = "Batch", module = "formation._native")]
pub struct Batch {
    scenario: Scenario,
    /// The direction of each beam of the scenario's LIDAR, for the agent's stopping governor in
    /// `policy_actions`.
    beams: BeamDirections,
    expert: bool,
    slots: Vec<Slot>,
}

impl Batch {
    fn robots(&self) -> usize {
        self.scenario.n_robots()
    }

    fn slot(&self, world: usize) -> PyResult<&Slot> {
        self.slots.get(world).ok_or_else(|| {
            PyValueError::new_err(format!(
                "world {world} is not in this batch of {} worlds",
                self.slots.len()
            ))
        })
    }

    /// The commands of a `(B, N, 2)` array of wheel speeds, refusing another shape and
    /// non-finite speeds.
    fn commands_of(&self, actions: &PyReadonlyArrayDyn<'_, f64>) -> PyResult<Vec<WheelCmd>> {
        let expected = [self.slots.len(), self.robots(), 2];
        if actions.shape() != expected {
            return Err(PyValueError::new_err(format!(
                "actions have shape {:?}; give (worlds, robots, 2) = {expected:?}: each robot's \
                 (left, right) wheel speeds in m/s",
                actions.shape()
            )));
        }
        let values = actions.as_slice().map_err(|_| {
            PyValueError::new_err(
                "actions must be a C-contiguous float64 array (np.ascontiguousarray)",
            )
        })?;
        if let Some(at) = values.iter().position(|v| !v.is_finite()) {
            let (world, robot) = (at / 2 / expected[1], at / 2 % expected[1]);
            return Err(PyValueError::new_err(format!(
                "action of robot {robot} in world {world} is {}: wheel speeds must be finite \
                 numbers (m/s)",
                values[at]
            )));
        }
        Ok(values
            .chunks_exact(2)
            .map(|w| WheelCmd {
                left: w[0],
                right: w[1],
            })
            .collect())
    }

    /// A `(B, N) + per_robot` array filled robot by robot from each robot's own scan and its
    /// world's d*, with `robot(its world's neighbour input builder, scan, d*, its values)`; a
    /// world whose d* cannot scale the input (`what`) is an error.
    fn array_from_scans<'py>(
        &mut self,
        py: Python<'py>,
        per_robot: &[usize],
        what: &str,
        robot: impl Fn(&mut NeighbourInputBuilder, &[f32], f64, &mut [f32]) + Sync,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let width: usize = per_robot.iter().product();
        self.per_robot_array(py, per_robot, |b, slot, chunk| {
            let observation = slot.episode.observe();
            let d_star = observation.goal.d_star;
            if !(d_star.is_finite() && d_star > 0.0) {
                return Err(format!("world {b}: d* {d_star} cannot scale the {what}"));
            }
            for (scan, cell) in observation.scans.iter().zip(chunk.chunks_exact_mut(width)) {
                robot(&mut slot.neighbour_builder, scan, d_star, cell);
            }
            Ok(())
        })
    }

    /// A `(B, N) + per_robot` array filled world by world in parallel, with the GIL released:
    /// `fill(b, slot, chunk)` writes world `b`'s values, robot after robot, into `chunk`.
    fn per_robot_array<'py, T: numpy::Element + Default + Clone + Send>(
        &mut self,
        py: Python<'py>,
        per_robot: &[usize],
        fill: impl Fn(usize, &mut Slot, &mut [T]) -> Result<(), String> + Sync,
    ) -> PyResult<Bound<'py, PyArrayDyn<T>>> {
        let (worlds, n) = (self.slots.len(), self.robots());
        let width: usize = per_robot.iter().product();
        let mut out = vec![T::default(); worlds * n * width];
        py.detach(|| self.fill(&mut out, n * width, &fill))?;
        let shape: Vec<usize> = [worlds, n].iter().chain(per_robot).copied().collect();
        out.into_pyarray(py).reshape(shape)
    }

    /// Fills `out` (`per_world` values per world) world by world in parallel.
    fn fill<T: Send>(
        &mut self,
        out: &mut [T],
        per_world: usize,
        fill: impl Fn(usize, &mut Slot, &mut [T]) -> Result<(), String> + Sync,
    ) -> PyResult<()> {
        self.slots
            .par_iter_mut()
            .zip(out.par_chunks_mut(per_world.max(1)))
            .enumerate()
            .try_for_each(|(b, (slot, chunk))| fill(b, slot, chunk))
            .map_err(PyValueError::new_err)
    }
}

/// The occupancy rendering a model declares (its `formation.occupancy.*` metadata).
fn occupancy_spec(
    size_px: usize,
    resolution_m: f64,
    beyond: &str,
    d_star_ref_m: Option<f64>,
) -> PyResult<OccupancySpec> {
    if size_px == 0 || size_px > 1024 {
        return Err(PyValueError::new_err(format!(
            "size_px {size_px} is not in 1..=1024 (the model's formation.occupancy.size_px)"
        )));
    }
    let positive = |v: f64| v.is_finite() && v > 0.0;
    if !positive(resolution_m) || d_star_ref_m.is_some_and(|d| !positive(d)) {
        return Err(PyValueError::new_err(format!(
            "resolution_m {resolution_m} and d_star_ref_m {d_star_ref_m:?} must be finite and > 0"
        )));
    }
    let beyond = BeyondWindow::parse(beyond).ok_or_else(|| {
        PyValueError::new_err(format!("beyond {beyond:?} is not \"drop\" or \"border\""))
    })?;
    Ok(OccupancySpec {
        size_px,
        resolution_m,
        beyond,
        d_star_ref_m,
    })
}

#[pymethods]
impl Batch {
    #[new]
    #[pyo3(signature = (scenario, seeds, runs, expert=true))]
    fn new(
        py: Python<'_>,
        scenario: &PyScenario,
        seeds: Vec<u64>,
        runs: Vec<usize>,
        expert: bool,
    ) -> PyResult<Batch> {
        let mut batch = Batch {
            scenario: scenario.scenario.clone(),
            beams: BeamDirections::new(scenario.scenario.world_config().lidar.beams),
            expert,
            slots: Vec::new(),
        };
        batch.reset(py, seeds, runs)?;
        Ok(batch)
    }

    /// Starts world `b` anew on run `runs[b]` of seed `seeds[b]`; the batch keeps its size
    /// unless both lists give another.
    fn reset(&mut self, py: Python<'_>, seeds: Vec<u64>, runs: Vec<usize>) -> PyResult<()> {
        if seeds.len() != runs.len() || seeds.is_empty() {
            return Err(PyValueError::new_err(format!(
                "{} seeds and {} runs: give one seed and one run index per world, at least one",
                seeds.len(),
                runs.len()
            )));
        }
        let (scenario, expert) = (&self.scenario, self.expert);
        self.slots = py.detach(|| {
            seeds
                .par_iter()
                .zip(&runs)
                .map(|(&seed, &run)| Slot::new(scenario, seed, run, expert))
                .collect()
        });
        Ok(())
    }

    /// Worlds in the batch.
    #[getter]
    fn worlds(&self) -> usize {
        self.slots.len()
    }

    /// Robots per world.
    #[getter]
    fn robots_per_world(&self) -> usize {
        self.robots()
    }

    /// Ticks played so far (the same in every world).
    #[getter]
    fn tick(&self) -> u64 {
        self.slots.first().map_or(0, |s| s.episode.world().tick())
    }

    /// The ticks of a run: `round(duration_s / dt)`.
    #[getter]
    fn ticks(&self) -> u64 {
        self.slots.first().map_or(0, |s| s.episode.ticks())
    }

    /// Whether every tick has been played.
    #[getter]
    fn over(&self) -> bool {
        self.slots.iter().all(|s| s.episode.is_over())
    }

    /// Every robot's pose `(x, y, theta)`: `(B, N, 3)` float64.
    fn poses<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        self.per_robot_array(py, &[3], |_, slot, chunk| {
            for (pose, cell) in slot
                .episode
                .world()
                .poses()
                .iter()
                .zip(chunk.chunks_exact_mut(3))
            {
                cell.copy_from_slice(&[pose.x, pose.y, pose.theta]);
            }
            Ok(())
        })
    }

    /// The wheel speeds each robot ran in the last step: `(B, N, 2)` float64.
    fn wheel_speeds<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        self.per_robot_array(py, &[2], |_, slot, chunk| {
            for (w, cell) in slot
                .episode
                .world()
                .wheel_speeds()
                .iter()
                .zip(chunk.chunks_exact_mut(2))
            {
                cell.copy_from_slice(&[w.left, w.right]);
            }
            Ok(())
        })
    }

    /// Each world's goal now, `(phi*, d*, v*)`: `(B, 3)` float64.
    fn goals<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let rows: Vec<Vec<f64>> = self
            .slots
            .iter()
            .map(|s| {
                let goal = s.episode.spec().goal_at(s.episode.world().time());
                vec![goal.phi_star, goal.d_star, goal.v_star]
            })
            .collect();
        Ok(PyArray2::from_vec2(py, &rows)?)
    }

    /// Every robot's LIDAR scan of this tick: `(B, N, beams)` float32 (taken once per tick).
    fn scans<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let beams = self.scenario.world_config().lidar.beams;
        self.per_robot_array(py, &[beams], |_, slot, chunk| {
            let observation = slot.episode.observe();
            for (scan, cell) in observation.scans.iter().zip(chunk.chunks_exact_mut(beams)) {
                cell.copy_from_slice(scan);
            }
            Ok(())
        })
    }

    /// Every robot's occupancy image of this tick's scan, rendered by `formation_perception`
    /// with the model's declared settings at the goal's d*: `(B, N, 1, S, S)` float32 of 0/1,
    /// the `occupancy` input of a policy.
    #[pyo3(signature = (size_px, resolution_m, beyond="drop", d_star_ref_m=None))]
    fn occupancy<'py>(
        &mut self,
        py: Python<'py>,
        size_px: usize,
        resolution_m: f64,
        beyond: &str,
        d_star_ref_m: Option<f64>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let spec = occupancy_spec(size_px, resolution_m, beyond, d_star_ref_m)?;
        let cells = size_px * size_px;
        let lidar = self.scenario.world_config().lidar;
        self.per_robot_array(py, &[1, size_px, size_px], |b, slot, chunk| {
            let observation = slot.episode.observe();
            let d_star = observation.goal.d_star;
            if spec.scales_with_d_star() && !(d_star.is_finite() && d_star > 0.0) {
                return Err(format!("world {b}: d* {d_star} cannot size the window"));
            }
            let mut image = vec![0_u8; cells];
            for (scan, cell) in observation.scans.iter().zip(chunk.chunks_exact_mut(cells)) {
                occupancy::render_at(scan, &lidar, &spec, d_star, &mut image);
                occupancy::to_f32(&image, cell);
            }
            Ok(())
        })
    }

    /// Every robot's scalars beside the image, the policy's `aux` input, as the model declares
    /// them (`layout`, its `formation.aux`; the paper's `delta_phi,d_star` by default), made by
    /// the agent's own `formation_proto::PolicyIo`: `(B, N, A)` float32.
    #[pyo3(signature = (layout = "delta_phi,d_star"))]
    fn aux<'py>(&mut self, py: Python<'py>, layout: &str) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let layout = AuxLayout::parse(layout).map_err(|e| {
            PyValueError::new_err(format!(
                "aux layout {layout:?} (the model's formation.aux): {e}"
            ))
        })?;
        let width = layout.len();
        self.per_robot_array(py, &[width], |b, slot, chunk| {
            let world = slot.episode.world();
            let goal = slot.episode.spec().goal_at(world.time());
            policy_input::check_goal(&goal).map_err(|e| format!("world {b}: {e}"))?;
            for (pose, cell) in world.poses().iter().zip(chunk.chunks_exact_mut(width)) {
                cell.copy_from_slice(&layout.values(pose.theta, &goal));
            }
            Ok(())
        })
    }

    /// Every robot's scan ranges pooled into sectors, the `ranges` input of a model that
    /// declares one (`ranges`, its `formation.ranges`, e.g. `"sectors=100,clip=3"`), made by the
    /// agent's own `formation_perception::ranges::pool`: `(B, N, K)` float32.
    fn ranges<'py>(
        &mut self,
        py: Python<'py>,
        ranges: &str,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let spec = RangeInput::parse(ranges).map_err(|e| {
            PyValueError::new_err(format!(
                "range input {ranges:?} (the model's formation.ranges): {e}"
            ))
        })?;
        let lidar = self.scenario.world_config().lidar;
        spec.check_beams(lidar.beams).map_err(|e| {
            PyValueError::new_err(format!(
                "range input {ranges:?} for this scenario's LIDAR: {e}"
            ))
        })?;
        self.array_from_scans(py, &[spec.sectors], "ranges", |_, scan, d_star, cell| {
            pool(scan, &lidar, &spec, d_star, cell)
        })
    }

    /// Every robot's detected neighbours, the `neighbours` input of a model that declares one
    /// (`neighbours`, its `formation.neighbours`, e.g. `"slots=8,threshold=1.3,nearest=2"`),
    /// filled from the robot's own scan by the agent's own
    /// `formation_perception::neighbour_input::NeighbourInputBuilder` (its detector's default
    /// settings, as the agent's): `(B, N, K, 4)` float32, per slot `(x / d*, y / d*, held,
    /// present)`.
    fn neighbours<'py>(
        &mut self,
        py: Python<'py>,
        neighbours: &str,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let spec = NeighbourInput::parse(neighbours).map_err(|e| {
            PyValueError::new_err(format!(
                "neighbour input {neighbours:?} (the model's formation.neighbours): {e}"
            ))
        })?;
        let lidar = self.scenario.world_config().lidar;
        self.array_from_scans(
            py,
            &[spec.slots, spec.features()],
            "neighbours",
            |builder, scan, d_star, cell| builder.fill(scan, &lidar, &spec, d_star, cell),
        )
    }

    /// A policy's outputs `(B, N, 2)` (float32) as wheel speeds for each world's goal, as the
    /// agent turns them into wheels: `(B, N, 2)` float64. `output` is what the model declares
    /// (`wheels`, at its training speed `v_train`, or `formation_velocity`, which is shaped for
    /// the world's wheel acceleration limit and to which each robot's reference term is added),
    /// then, under that limit, slowed by the agent's stopping governor on each robot's own scan
    /// (`formation_perception::stopping`). Each robot's heading is its compass's, as its agent
    /// is handed it.
    #[pyo3(signature = (outputs, v_train, output = "wheels"))]
    fn policy_actions<'py>(
        &mut self,
        py: Python<'py>,
        outputs: PyReadonlyArrayDyn<'py, f32>,
        v_train: f64,
        output: &str,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let output = formation_proto::PolicyOutput::parse(output).ok_or_else(|| {
            PyValueError::new_err(format!(
                "output {output:?} is not `wheels` or `formation_velocity` (the model's formation.output)"
            ))
        })?;
        let n = self.robots();
        let expected = [self.slots.len(), n, 2];
        if outputs.shape() != expected {
            return Err(PyValueError::new_err(format!(
                "policy outputs have shape {:?}, expected {expected:?}",
                outputs.shape()
            )));
        }
        if !(v_train.is_finite() && v_train > 0.0) {
            return Err(PyValueError::new_err(format!(
                "v_train {v_train} must be > 0 (the model's formation.v_train)"
            )));
        }
        let raw = outputs
            .as_slice()
            .map_err(|_| PyValueError::new_err("policy outputs must be C-contiguous float32"))?;
        let mut out = Vec::with_capacity(raw.len());
        for (b, slot) in self.slots.iter_mut().enumerate() {
            let wheels = slot.episode.spec().world.robot.wheel_limits();
            let observation = slot.episode.observe();
            let goal = observation.goal;
            policy_input::check_goal(&goal)
                .map_err(|e| PyValueError::new_err(format!("world {b}: {e}")))?;
            // The heading as each robot's compass reads it, as its agent is handed it.
            for ((w, pose), scan) in raw[b * n * 2..(b + 1) * n * 2]
                .chunks_exact(2)
                .zip(observation.poses.iter())
                .zip(observation.scans.iter())
            {
                let cmd = policy_input::command_of_output(
                    output,
                    v_train,
                    [w[0], w[1]],
                    pose.theta,
                    &goal,
                    wheels,
                );
                // The agent's stopping governor, on the robot's own scan.
                let cmd = stopping::keep_stopping_distance(
                    cmd,
                    scan,
                    &self.beams,
                    formation_proto::DEFAULT_BODY_RADIUS_M,
                    formation_proto::DEFAULT_WHEEL_SEPARATION_M,
                    goal.d_star,
                    wheels.max_accel,
                );
                out.extend([cmd.left, cmd.right]);
            }
        }
        out.into_pyarray(py).reshape(vec![self.slots.len(), n, 2])
    }

    /// The expert's wheel speeds for this tick, as `formation eval --controller expert` drives:
    /// `(B, N, 2)` float64. Needs a batch made with `expert=True`.
    fn expert_actions<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        if !self.expert {
            return Err(PyRuntimeError::new_err(
                "this batch was made with expert=False; make it with expert=True for expert actions",
            ));
        }
        self.per_robot_array(py, &[2], |b, slot, chunk| {
            let commands = slot.expert_commands(b).map_err(|e| e.to_string())?;
            for (cmd, cell) in commands.iter().zip(chunk.chunks_exact_mut(2)) {
                cell.copy_from_slice(&[cmd.left, cmd.right]);
            }
            Ok(())
        })
    }

    /// Steps every world with `actions[b, i] = (left, right)` wheel speeds \[m/s\] (saturated to
    /// the robot's limits by the world); returns `(B, N)` bool: whether each robot is in contact
    /// after the step. Raises `ValueError` for another shape or a non-finite speed and
    /// `EpisodeOver` after the last tick.
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        actions: PyReadonlyArrayDyn<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray2<bool>>> {
        let commands = self.commands_of(&actions)?;
        let n = self.robots();
        let mut collided = vec![false; self.slots.len() * n];
        let stepped: Result<(), SlotError> = py.detach(|| {
            self.slots
                .par_iter_mut()
                .zip(commands.par_chunks(n))
                .zip(collided.par_chunks_mut(n))
                .enumerate()
                .try_for_each(|(b, ((slot, commands), collided))| {
                    for (i, j) in slot.step(b, commands)? {
                        collided[i] = true;
                        collided[j] = true;
                    }
                    Ok(())
                })
        });
        stepped?;
        collided.into_pyarray(py).reshape([self.slots.len(), n])
    }

    /// World `world`'s formation edges `(i, j)` now, under the scenario's neighbour rule.
    fn edges(&self, world: usize) -> PyResult<Vec<(usize, usize)>> {
        Ok(self.slot(world)?.tracker.edges().to_vec())
    }

    /// World `world`'s poses at every sample so far: `(ticks played + 1, N, 3)` float64.
    fn trajectory<'py>(
        &self,
        py: Python<'py>,
        world: usize,
    ) -> PyResult<Bound<'py, PyArray3<f64>>> {
        let trajectory = self.slot(world)?.episode.trajectory();
        let samples = trajectory.poses.len();
        let out: Vec<f64> = trajectory
            .poses
            .iter()
            .flatten()
            .flat_map(|p| [p.x, p.y, p.theta])
            .collect();
        out.into_pyarray(py).reshape([samples, self.robots(), 3])
    }

    /// World `world`'s run metrics (Table I) as JSON, the `metrics` of its run log: scored as
    /// `formation eval` scores a run, over the ticks played (a run not played to the end is
    /// marked incomplete).
    fn metrics_json(&self, world: usize) -> PyResult<String> {
        let episode = &self.slot(world)?.episode;
        let metrics = run_metrics(
            episode.trajectory(),
            episode.ticks(),
            &MetricsConfig::default(),
        );
        serde_json::to_string(&metrics)
            .map_err(|e| PyRuntimeError::new_err(format!("cannot write the metrics: {e}")))
    }

    /// World `world`'s run spec as JSON: its seed, d*, heading schedule, initial poses, noise
    /// seed.
    fn spec_json(&self, world: usize) -> PyResult<String> {
        serde_json::to_string(self.slot(world)?.episode.spec())
            .map_err(|e| PyRuntimeError::new_err(format!("cannot write the run spec: {e}")))
    }
}
