//! The in-process loop of one run: sense, decide, step, record.
//!
//! [`run_episode`] drives a [`World`] built from a [`RunSpec`] with any [`Controller`]
//! (the expert, the learned policy run per robot, a test double) and records a [`Trajectory`] that the
//! [`metrics`](crate::metrics) score. Every robot's scan is taken at every tick whatever the controller,
//! so the world's noise generator is consumed in the same order by every controller and a run with the
//! expert and one with a policy see the same noise for the same states. The multi-process lockstep runtime
//! calls the same world methods in the same order, which is what makes it bit-identical to this loop.

use formation_proto::WheelCmd;
pub use formation_proto::control::{Controller, ControllerError, Observation};

use crate::scenario::RunSpec;
use crate::world::World;

/// The record of one run: defined with the run log in [`formation_schema`].
pub use formation_schema::Trajectory;

/// Runs `spec` to the end with `controller`.
///
/// Per tick `k` in `0..ticks`: goal = `spec.goal_at(t_k)`; every robot's scan; `controller.commands`;
/// `on_tick(observation, commands)` (used by DAgger and data collection to record samples); `World::step`;
/// record. Stops at the first controller error. [`run_episode_recorded`] also hands the trajectory
/// to a recorder as it grows.
pub fn run_episode(
    spec: &RunSpec,
    controller: &mut dyn Controller,
    on_tick: &mut dyn FnMut(&Observation<'_>, &[WheelCmd]),
) -> Result<Trajectory, ControllerError> {
    run_episode_recorded(spec, controller, on_tick, &mut |_| {
        Ok::<(), std::convert::Infallible>(())
    })
    .map_err(|e| match e {
        EpisodeError::Controller(e) => e,
        EpisodeError::Record(never) => match never {},
    })
}

/// Why [`run_episode_recorded`] stopped before the end.
#[derive(Debug, thiserror::Error)]
pub enum EpisodeError<E> {
    /// The controller could not produce commands.
    #[error(transparent)]
    Controller(#[from] ControllerError),
    /// The recorder failed (e.g. the run journal could not be written).
    #[error(transparent)]
    Record(E),
}

/// [`run_episode`], handing the trajectory recorded so far to `on_record` once after the initial
/// state is recorded and then after every step (so it sees `k + 1` samples, `k` command rows and
/// the collisions up to sample `k`). An error of `on_record` stops the episode at once.
pub fn run_episode_recorded<E>(
    spec: &RunSpec,
    controller: &mut dyn Controller,
    on_tick: &mut dyn FnMut(&Observation<'_>, &[WheelCmd]),
    on_record: &mut dyn FnMut(&Trajectory) -> Result<(), E>,
) -> Result<Trajectory, EpisodeError<E>> {
    let mut episode = Episode::new(spec.clone());
    on_record(episode.trajectory()).map_err(EpisodeError::Record)?;
    let mut commands = vec![WheelCmd::BRAKE; episode.world().n_robots()];
    while !episode.is_over() {
        commands.fill(WheelCmd::BRAKE);
        let observation = episode.observe();
        controller.commands(&observation, &mut commands)?;
        on_tick(&observation, &commands);
        episode
            .step(&commands)
            .map_err(|e| ControllerError::new(e.to_string()))?;
        on_record(episode.trajectory()).map_err(EpisodeError::Record)?;
    }
    Ok(episode.into_trajectory())
}

/// Why [`Episode::step`] refused to step.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum StepError {
    /// Every planned tick has been played.
    #[error(
        "the run is over: all {ticks} ticks of its duration have been played; reset to start \
         another run"
    )]
    Over {
        /// The run's planned ticks.
        ticks: u64,
    },
    /// Not one command per robot.
    #[error("{given} wheel commands for {robots} robots: give one command per robot")]
    Commands {
        /// Commands given.
        given: usize,
        /// Robots in the world.
        robots: usize,
    },
}

/// One run played tick by tick, for drivers that are not a [`Controller`] (the Python bindings'
/// environments); [`run_episode`] is this loop over a controller, so both give the same bits.
///
/// Per tick: [`Episode::observe`] (optional), then [`Episode::step`]. The scans of a tick are
/// taken exactly once, by the first of the two that is called in it, so the world's noise is
/// drawn in the same order whether or not the driver looks.
#[derive(Debug, Clone)]
pub struct Episode {
    spec: RunSpec,
    world: World,
    ticks: u64,
    trajectory: Trajectory,
    scans: Vec<Vec<f32>>,
    /// Whether `scans` hold this tick's scans.
    sensed: bool,
}

impl Episode {
    /// Run `spec` at tick 0, its initial state recorded.
    pub fn new(spec: RunSpec) -> Episode {
        let world = spec.make_world();
        let ticks = spec.ticks();
        let samples = usize::try_from(ticks).map_or(usize::MAX, |t| t.saturating_add(1));
        let capacity = samples.min(1 << 20);
        let trajectory = Trajectory {
            dt: spec.world.dt,
            d_star: spec.d_star,
            v_star: spec.v_star,
            edges: crate::neighbours::first_sample_edges(spec.neighbours, &spec.initial),
            neighbours: spec.neighbours,
            times: Vec::with_capacity(capacity),
            phi_star: Vec::with_capacity(capacity),
            poses: Vec::with_capacity(capacity),
            commands: Vec::with_capacity(capacity),
            collisions: Vec::new(),
        };
        let scans = vec![vec![0.0_f32; spec.world.lidar.beams]; world.n_robots()];
        let mut episode = Episode {
            spec,
            world,
            ticks,
            trajectory,
            scans,
            sensed: false,
        };
        episode.record_state();
        episode
    }

    fn record_state(&mut self) {
        let time = self.world.time();
        self.trajectory.times.push(time);
        self.trajectory
            .phi_star
            .push(self.spec.heading.phi_star(time));
        self.trajectory.poses.push(self.world.poses().to_vec());
    }

    /// The run being played.
    pub fn spec(&self) -> &RunSpec {
        &self.spec
    }

    /// The world in its current state.
    pub fn world(&self) -> &World {
        &self.world
    }

    /// The run's planned ticks ([`RunSpec::ticks`]).
    pub fn ticks(&self) -> u64 {
        self.ticks
    }

    /// Whether every planned tick has been played.
    pub fn is_over(&self) -> bool {
        self.world.tick() >= self.ticks
    }

    /// The trajectory recorded so far.
    pub fn trajectory(&self) -> &Trajectory {
        &self.trajectory
    }

    /// The trajectory recorded.
    pub fn into_trajectory(self) -> Trajectory {
        self.trajectory
    }

    /// This tick's observation: the goal, every pose (its heading as the robot's compass reads
    /// it, [`World::observed_poses`]) and every robot's scan (as its LIDAR hands it out, held
    /// between a slow LIDAR's scans; [`World::scan_age`] says how old), all taken now if this
    /// tick's were not taken yet.
    pub fn observe(&mut self) -> Observation<'_> {
        if !self.sensed {
            self.world.scan_all(&mut self.scans);
            self.world.read_compasses();
            self.sensed = true;
        }
        let time = self.world.time();
        Observation {
            tick: self.world.tick(),
            time,
            goal: self.spec.goal_at(time),
            poses: self.world.observed_poses(),
            wheel_speeds: self.world.wheel_speeds(),
            scans: &self.scans,
        }
    }

    /// Steps the world with `commands[i]` for robot `i` (after taking this tick's scans if
    /// [`Episode::observe`] did not) and records the new state; returns the pairs in contact
    /// after the step.
    pub fn step(&mut self, commands: &[WheelCmd]) -> Result<Vec<(usize, usize)>, StepError> {
        if self.is_over() {
            return Err(StepError::Over { ticks: self.ticks });
        }
        let robots = self.world.n_robots();
        if commands.len() != robots {
            return Err(StepError::Commands {
                given: commands.len(),
                robots,
            });
        }
        self.observe();
        let report = self.world.step(commands);
        self.sensed = false;
        self.trajectory.commands.push(report.applied);
        let sample = self.world.tick();
        self.trajectory
            .collisions
            .extend(report.collisions.iter().map(|&(i, j)| (sample, i, j)));
        self.record_state();
        Ok(report.collisions)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::integrate;
    use crate::scenario::Scenario;
    use crate::test_support::RampTeam;
    use formation_proto::control::controller_fn;

    fn short_spec(noise_std: f64) -> RunSpec {
        RampTeam {
            noise_std,
            ..RampTeam::default()
        }
        .run_spec("episode-test", 11, 0)
    }

    /// Drives every robot with the same wheel speeds.
    fn constant_wheels(cmd: WheelCmd) -> impl Controller {
        controller_fn(move |_, out| {
            out.fill(cmd);
            Ok(())
        })
    }

    #[test]
    fn episode_records_every_tick_and_matches_manual_integration() {
        let spec = short_spec(0.0);
        let cmd = WheelCmd::new(0.3, 0.5);
        let mut controller = constant_wheels(cmd);
        let mut seen_ticks = Vec::new();
        let traj = run_episode(&spec, &mut controller, &mut |obs, cmds| {
            assert_eq!(obs.goal, spec.goal_at(obs.time));
            assert_eq!(obs.scans.len(), 3);
            assert!(obs.scans.iter().all(|scan| scan.len() == 90));
            assert_eq!(cmds, [cmd; 3]);
            seen_ticks.push(obs.tick);
        })
        .unwrap();

        let ticks = spec.ticks();
        assert_eq!(ticks, 20);
        assert_eq!(seen_ticks, (0..ticks).collect::<Vec<_>>());
        assert_eq!(traj.times.len(), 21);
        assert_eq!(traj.phi_star.len(), 21);
        assert_eq!(traj.poses.len(), 21);
        assert_eq!(traj.commands, vec![vec![cmd; 3]; 20]);
        assert_eq!(traj.poses[0], spec.initial);
        assert_eq!(traj.edges, vec![(0, 1), (0, 2), (1, 2)]);
        assert_eq!(traj.neighbours, crate::neighbours::NeighbourRule::AllPairs);
        for (k, (&t, &phi)) in traj.times.iter().zip(&traj.phi_star).enumerate() {
            assert_eq!(t, k as f64 * spec.world.dt);
            assert_eq!(phi, spec.heading.phi_star(t));
        }

        for (robot, start) in spec.initial.iter().enumerate() {
            let manual = (0..ticks).fold(*start, |pose, _| {
                integrate(pose, cmd, &spec.world.robot, spec.world.dt)
            });
            let recorded = traj.poses[ticks as usize][robot];
            assert!(
                (manual.x - recorded.x).abs() < 1e-12
                    && (manual.y - recorded.y).abs() < 1e-12
                    && (manual.theta - recorded.theta).abs() < 1e-12,
                "robot {robot}: manual {manual:?} recorded {recorded:?}"
            );
        }
    }

    #[test]
    fn non_finite_commands_are_recorded_as_the_brake_the_world_applied() {
        let spec = short_spec(0.0);
        let mut controller = constant_wheels(WheelCmd::new(f64::NAN, 0.2));
        let traj = run_episode(&spec, &mut controller, &mut |_, _| {}).unwrap();
        assert!(
            traj.commands
                .iter()
                .flatten()
                .all(|c| *c == WheelCmd::BRAKE)
        );
        assert_eq!(traj.poses.last(), traj.poses.first());
    }

    #[test]
    fn a_controller_error_stops_the_episode() {
        let spec = short_spec(0.0);
        // Brakes every robot, and refuses tick 3.
        let mut controller = controller_fn(|obs, out| {
            if obs.tick == 3 {
                return Err(ControllerError::new(format!("refusing tick {}", obs.tick)));
            }
            out.fill(WheelCmd::BRAKE);
            Ok(())
        });
        let mut calls = 0;
        let error = run_episode(&spec, &mut controller, &mut |_, _| calls += 1).unwrap_err();
        assert_eq!(error.to_string(), "refusing tick 3");
        assert_eq!(calls, 3);
    }

    #[test]
    fn episodes_replay_bit_for_bit_with_sensor_noise() {
        let spec = short_spec(0.05);
        let mut scans_a = Vec::new();
        let mut scans_b = Vec::new();
        let cmd = WheelCmd::new(0.4, 0.1);
        let a = run_episode(&spec, &mut constant_wheels(cmd), &mut |obs, _| {
            scans_a.push(obs.scans.to_vec())
        })
        .unwrap();
        let b = run_episode(&spec, &mut constant_wheels(cmd), &mut |obs, _| {
            scans_b.push(obs.scans.to_vec())
        })
        .unwrap();
        assert_eq!(a, b);
        let bits = |scans: &Vec<Vec<Vec<f32>>>| -> Vec<u32> {
            scans
                .iter()
                .flatten()
                .flatten()
                .map(|r| r.to_bits())
                .collect()
        };
        assert_eq!(bits(&scans_a), bits(&scans_b));
    }

    #[test]
    fn the_recorder_sees_the_trajectory_grow_and_can_stop_the_episode() {
        let spec = short_spec(0.0);
        let cmd = WheelCmd::new(0.2, 0.3);
        let mut seen = Vec::new();
        let full = run_episode_recorded(
            &spec,
            &mut constant_wheels(cmd),
            &mut |_, _| {},
            &mut |traj| {
                seen.push((traj.poses.len(), traj.commands.len(), traj.times.len()));
                Ok::<(), String>(())
            },
        )
        .unwrap();
        let expected: Vec<_> = (0..=20).map(|k| (k + 1, k, k + 1)).collect();
        assert_eq!(seen, expected);
        assert_eq!(
            full,
            run_episode(&spec, &mut constant_wheels(cmd), &mut |_, _| {}).unwrap()
        );

        let error = run_episode_recorded(
            &spec,
            &mut constant_wheels(cmd),
            &mut |_, _| {},
            &mut |traj| {
                if traj.commands.len() == 5 {
                    Err("disk full".to_owned())
                } else {
                    Ok(())
                }
            },
        )
        .unwrap_err();
        assert!(matches!(error, EpisodeError::Record(ref m) if m == "disk full"));
    }

    #[test]
    fn an_episode_stepped_by_hand_equals_the_loop_and_refuses_bad_steps() {
        let spec = short_spec(0.05);
        let cmd = WheelCmd::new(0.4, 0.1);
        let looped = run_episode(&spec, &mut constant_wheels(cmd), &mut |_, _| {}).unwrap();
        let mut episode = Episode::new(spec.clone());
        assert_eq!(
            episode.step(&[cmd; 2]),
            Err(StepError::Commands {
                given: 2,
                robots: 3
            })
        );
        let mut k = 0;
        while !episode.is_over() {
            // Observing on some ticks only draws the same noise: the step takes the scans.
            if k % 3 == 0 {
                episode.observe();
                episode.observe();
            }
            episode.step(&[cmd; 3]).unwrap();
            k += 1;
        }
        assert_eq!(k, spec.ticks());
        let over = episode.step(&[cmd; 3]).unwrap_err();
        assert_eq!(over, StepError::Over { ticks: 20 });
        assert!(over.to_string().contains("reset"), "{over}");
        assert_eq!(episode.into_trajectory(), looped);
    }

    #[test]
    fn the_heading_a_controller_receives_carries_the_compass_bias() {
        let text = "name = \"compass\"\nrobots = 3\nduration_s = 1.0\nseed = 2\n[goal]\n\
                    v_star = 0.3\nd_star = 1.5\n[heading]\nschedule = \"random\"\n\
                    [compass]\nbias_deg = 4.0\n[lidar]\nscan_rate_hz = 5.0\n";
        let spec = Scenario::from_toml_str(text, "compass")
            .unwrap()
            .run_spec(2, 0);
        let cmd = WheelCmd::new(0.2, 0.3);
        let mut received = Vec::new();
        let traj = run_episode(&spec, &mut constant_wheels(cmd), &mut |obs, _| {
            received.push(obs.poses.to_vec())
        })
        .unwrap();
        for (tick, seen) in received.iter().enumerate() {
            for (robot, (seen, truth)) in seen.iter().zip(&traj.poses[tick]).enumerate() {
                let error = formation_proto::wrap_angle(seen.theta - truth.theta);
                assert!(
                    (error - 4f64.to_radians()).abs() < 1e-9,
                    "tick {tick}, robot {robot}: {error}"
                );
                assert_eq!((seen.x, seen.y), (truth.x, truth.y));
            }
        }
        // The trajectory keeps the true poses, and the episode exposes the held scans' ages.
        let mut episode = Episode::new(spec);
        episode.observe();
        let ages: Vec<f64> = (0..3).map(|r| episode.world().scan_age(r)).collect();
        assert!(ages.iter().all(|&a| (0.0..0.2).contains(&a)), "{ages:?}");
    }
}
