"""The PettingZoo ``ParallelEnv`` of one formation run (and the reward it documents).

``parallel_env(scenario="scenarios/table1.toml", robots=16)`` plays run ``R`` of seed ``S``
(``reset(seed=S, options={"run": R})``, or ``reset(seed=S, run=R)``) exactly as ``formation eval
--seed S`` plays it: the world, the sensor, the expert and the metrics are the Rust crates'.
A ``reset()`` without a seed plays the next run of the last seed (run 0 of the scenario's seed
first), as ``formation eval`` goes through its runs.

Agents are ``robot_0 .. robot_{N-1}``.

* **Observation** of a robot: its own input as the model declares it (:class:`ModelSpec`), and
  nothing else: ``{"occupancy": (1, S, S) float32 of 0/1, "aux": (delta_phi, d*) float32}`` or,
  for a scan model, ``{"scan": (beams,) float32, "aux": ...}``; for a model that declares the
  scan's ranges beside its image (``formation.ranges``), also ``"ranges": (K,) float32``, the
  agent's own pooling of the scan into K sectors; for a model that declares the neighbours it
  detects (``formation.neighbours``), also ``"neighbours": (K, 4) float32`` (``(K, 6)`` with
  ``hidden=1``), the agent's own
  detections in K slots of ``(x / d*, y / d*, held, present)``.
* **Action**: its ``(left, right)`` wheel speeds in m/s, within ``±max_wheel_speed`` (the world
  saturates them as a real robot would). A NaN, another shape, a missing robot or a step after
  the end raises.
* **Reward** of robot ``i`` after a step, at the new sample (goal ``phi*, d*, v*``)::

      r_i = -(w_formation * e_f + w_heading * e_h + w_speed * e_v) - collision_penalty * [collided]

  with ``e_f`` the mean over ``i``'s formation edges (the scenario's neighbour rule) of
  ``| |p_i - p_j| - d* |`` in metres (0 without edges), ``e_h = |wrap(theta_i - phi*)|`` in
  radians and ``e_v = |(left + right) / 2 - v*|`` in m/s of the wheel speeds the robot ran.
  Weights default to 1, the penalty to 10.
* **Termination**: a robot whose body touches another's after a step is terminated (when
  ``terminate_on_collision``); it stays in the world, braked. **Truncation**: every robot at the
  scenario's duration.
* **Infos**: when the run ends, each robot's info holds ``"metrics"``, the run's Table I metrics
  (the run log's ``metrics``), also given by :meth:`FormationParallelEnv.metrics`.
* :meth:`FormationParallelEnv.expert_actions`: the expert's wheel speeds for this tick, for
  imitation; :meth:`FormationParallelEnv.policy_actions` turns a policy's raw outputs into wheel
  speeds as the agent does.

:class:`SingleRobotEnv` is a Gymnasium view of one robot, the expert driving the others.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Dict, Mapping, Optional

import numpy as np
import gymnasium
from gymnasium import spaces
from pettingzoo import ParallelEnv

from formation._native import Batch, EpisodeOver, Scenario, neighbour_input, range_input
from formation.model import ModelSpec


#: The shipped default policy, relative to the repository root.
SHIPPED_MODEL = Path("onnx") / "models" / "policy.onnx"


def shipped_model() -> Path:
    """The shipped default policy, whose declared input an environment renders when given
    neither ``model`` nor ``spec`` (as ``formation eval`` and ``run`` drive it when given no
    ``--model``). Raises, naming both, when this installation has no repository beside it."""
    for root in Path(__file__).resolve().parents:
        candidate = root / SHIPPED_MODEL
        if candidate.is_file():
            return candidate
    raise ValueError(
        f"no model to take the observation from: the shipped default ({SHIPPED_MODEL}) is not "
        "beside this installation of formation, and the environment will not guess an input; "
        "pass model='path/to/policy.onnx' (its declared input is rendered) or spec=ModelSpec(...)"
    )


def parallel_env(**kwargs: Any) -> "FormationParallelEnv":
    """A :class:`FormationParallelEnv` (keyword arguments as its constructor's)."""
    return FormationParallelEnv(**kwargs)


class FormationParallelEnv(ParallelEnv):
    """One formation run as a PettingZoo parallel environment (see the module documentation).

    ``scenario`` is a scenario path or a :class:`Scenario`; ``robots`` and ``overrides`` (dotted
    keys, ``{"goal.v_star": 0.5}``) change it as the CLI does; ``model`` (an ONNX path) or
    ``spec`` (a :class:`ModelSpec`) fixes the observation, and without either it is the shipped
    default model's declared input (:func:`shipped_model`); ``expert=False`` skips the expert.
    """

    metadata = {"name": "formation_v0", "render_modes": []}

    def __init__(
        self,
        scenario: Any = "scenarios/table1.toml",
        robots: Optional[int] = None,
        overrides: Optional[Mapping[str, Any]] = None,
        model: Optional[str | Path] = None,
        spec: Optional[ModelSpec] = None,
        expert: bool = True,
        terminate_on_collision: bool = True,
        w_formation: float = 1.0,
        w_heading: float = 1.0,
        w_speed: float = 1.0,
        collision_penalty: float = 10.0,
    ) -> None:
        if isinstance(scenario, Scenario):
            if robots is not None or overrides:
                raise ValueError("robots and overrides apply to a scenario path; load the Scenario with them")
            self.scenario = scenario
        else:
            self.scenario = Scenario(str(scenario), robots=robots, overrides=dict(overrides or {}))
        if spec is None:
            spec = ModelSpec.from_onnx(model if model is not None else shipped_model())
        self.spec = spec
        if spec.beams is not None and spec.beams != self.scenario.beams:
            raise ValueError(
                f"the model was trained with {spec.beams} LIDAR beams and the scenario has "
                f"{self.scenario.beams}: set the scenario's [lidar] beams (overrides={{'lidar.beams': "
                f"{spec.beams}}}) or use a model trained for it"
            )
        self.terminate_on_collision = terminate_on_collision
        self.weights = (float(w_formation), float(w_heading), float(w_speed))
        self.collision_penalty = float(collision_penalty)
        n = self.scenario.robots
        self.possible_agents = [f"robot_{i}" for i in range(n)]
        self.agents: list = []
        self._index = {a: i for i, a in enumerate(self.possible_agents)}
        self._seed = self.scenario.seed
        self._run = -1
        self._batch = Batch(self.scenario, [self._seed], [0], expert=expert)
        self._live = np.zeros(n, dtype=bool)
        self._observation_space = self._make_observation_space()
        wheel = self.scenario.max_wheel_speed
        self._action_space = spaces.Box(-wheel, wheel, shape=(2,), dtype=np.float64)
        self._observation_spaces = {a: self._observation_space for a in self.possible_agents}
        self._action_spaces = {a: self._action_space for a in self.possible_agents}

    def _make_observation_space(self) -> spaces.Dict:
        pi = np.float32(math.pi)
        # Each declared scalar's bounds (formation_proto::AuxInput): a heading error or a d*.
        bounds = {"delta_phi": (-pi, pi), "d_star": (0.0, np.inf)}
        names = [name.strip() for name in self.spec.aux.split(",")]
        unknown = [name for name in names if name not in bounds]
        if unknown:
            raise ValueError(
                f"the model declares the inputs {unknown} (formation.aux), which this build cannot feed; "
                f"it feeds {sorted(bounds)}"
            )
        aux = spaces.Box(
            low=np.array([bounds[name][0] for name in names], dtype=np.float32),
            high=np.array([bounds[name][1] for name in names], dtype=np.float32),
            dtype=np.float32,
        )
        if self.spec.input == "scan":
            own = spaces.Box(0.0, np.float32(self.scenario.max_range), (self.scenario.beams,), np.float32)
            return spaces.Dict({"scan": own, "aux": aux})
        size = self.spec.size_px
        image = spaces.Box(0.0, 1.0, (1, size, size), np.float32)
        observation = {"occupancy": image, "aux": aux}
        if self.spec.ranges is not None:
            sectors, clip = range_input(self.spec.ranges)
            observation["ranges"] = spaces.Box(0.0, np.float32(clip), (sectors,), np.float32)
        if self.spec.neighbours is not None:
            slots, _, _, features = neighbour_input(self.spec.neighbours)
            # Per slot: the centre in units of d* (unbounded), the held and present flags, and
            # with hidden=1 the step aside of the slot's hidden pairs (unbounded).
            low = [-np.inf, -np.inf, 0.0, 0.0] + [-np.inf] * (features - 4)
            high = [np.inf, np.inf, 1.0, 1.0] + [np.inf] * (features - 4)
            low = np.tile(np.array(low, dtype=np.float32), (slots, 1))
            high = np.tile(np.array(high, dtype=np.float32), (slots, 1))
            observation["neighbours"] = spaces.Box(low, high, dtype=np.float32)
        return spaces.Dict(observation)

    def observation_space(self, agent: str) -> spaces.Space:
        return self._observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Space:
        return self._action_spaces[agent]

    @property
    def batch(self) -> Batch:
        """The native batch of one world behind this environment."""
        return self._batch

    @property
    def seed_and_run(self) -> tuple:
        """``(S, R)``: this is run ``R`` of ``formation eval --seed S``."""
        return (self._seed, self._run)

    def reset(self, seed: Optional[int] = None, options: Optional[dict] = None, run: Optional[int] = None):
        if run is None and options:
            run = options.get("run")
        if seed is not None:
            if not (isinstance(seed, (int, np.integer)) and 0 <= seed < 2**64):
                raise ValueError(f"seed {seed!r} must be an integer in [0, 2**64)")
            self._seed = int(seed)
            self._run = 0 if run is None else int(run)
        else:
            self._run = self._run + 1 if run is None else int(run)
        if self._run < 0:
            raise ValueError(f"run {self._run} must be >= 0")
        self._batch.reset([self._seed], [self._run])
        self.agents = list(self.possible_agents)
        self._live[:] = True
        observations = self._observations(self.agents)
        return observations, {a: {} for a in self.agents}

    def _observations(self, agents: list) -> Dict[str, dict]:
        aux = self._batch.aux(self.spec.aux)[0]
        if self.spec.input == "scan":
            own = self._batch.scans()[0]
            key = "scan"
        else:
            s = self.spec
            own = self._batch.occupancy(s.size_px, s.resolution_m, s.beyond, s.d_star_ref_m)[0]
            key = "occupancy"
        observations = {a: {key: own[self._index[a]], "aux": aux[self._index[a]]} for a in agents}
        if self.spec.input != "scan" and self.spec.ranges is not None:
            ranges = self._batch.ranges(self.spec.ranges)[0]
            for agent, observation in observations.items():
                observation["ranges"] = ranges[self._index[agent]]
        if self.spec.input != "scan" and self.spec.neighbours is not None:
            neighbours = self._batch.neighbours(self.spec.neighbours)[0]
            for agent, observation in observations.items():
                observation["neighbours"] = neighbours[self._index[agent]]
        return observations

    def _wheel_array(self, actions: Mapping[str, Any]) -> np.ndarray:
        if not isinstance(actions, Mapping):
            raise TypeError(f"actions must be a dict of agent -> (left, right), got {type(actions).__name__}")
        unknown = [a for a in actions if a not in self._index]
        if unknown:
            raise ValueError(f"unknown agents {unknown}; agents are robot_0 .. robot_{len(self._index) - 1}")
        missing = [a for a in self.agents if a not in actions]
        if missing:
            raise ValueError(f"no action for {missing}: give every live agent its (left, right) wheel speeds")
        wheels = np.zeros((1, len(self.possible_agents), 2), dtype=np.float64)
        for agent in self.agents:
            try:
                action = np.asarray(actions[agent], dtype=np.float64)
            except (TypeError, ValueError) as e:
                raise ValueError(
                    f"action of {agent} is {actions[agent]!r}, not numbers: give (left, right) wheel "
                    f"speeds in m/s, e.g. np.array([0.2, 0.3])"
                ) from e
            if action.shape != (2,):
                raise ValueError(
                    f"action of {agent} has shape {action.shape}; give (left, right) wheel speeds, shape (2,)"
                )
            if not np.all(np.isfinite(action)):
                raise ValueError(f"action of {agent} is {action.tolist()}: wheel speeds must be finite (m/s)")
            wheels[0, self._index[agent]] = action
        return wheels

    def step(self, actions: Mapping[str, Any]):
        if not self.agents:
            raise EpisodeOver("the run is over: every agent is done; call reset() to start another run")
        wheels = self._wheel_array(actions)
        live_before = list(self.agents)
        collided = self._batch.step(wheels)[0]
        rewards = self._rewards(collided)
        over = self._batch.over
        terminations, truncations = {}, {}
        for agent in live_before:
            i = self._index[agent]
            hit = bool(collided[i]) and self.terminate_on_collision
            terminations[agent] = hit
            truncations[agent] = over and not hit
            if hit or over:
                self._live[i] = False
        observations = self._observations(live_before)
        self.agents = [a for a in self.possible_agents if self._live[self._index[a]]]
        infos: Dict[str, dict] = {a: {} for a in live_before}
        if not self.agents:
            metrics = self.metrics()
            for agent in live_before:
                infos[agent]["metrics"] = metrics
        return observations, {a: float(rewards[self._index[a]]) for a in live_before}, terminations, truncations, infos

    def _rewards(self, collided: np.ndarray) -> np.ndarray:
        poses = self._batch.poses()[0]
        phi_star, d_star, v_star = self._batch.goals()[0]
        wheels = self._batch.wheel_speeds()[0]
        n = len(self.possible_agents)
        err_sum, err_count = np.zeros(n), np.zeros(n)
        for i, j in self._batch.edges(0):
            e = abs(math.hypot(*(poses[i, :2] - poses[j, :2])) - d_star)
            err_sum[[i, j]] += e
            err_count[[i, j]] += 1
        e_f = np.divide(err_sum, err_count, out=np.zeros(n), where=err_count > 0)
        e_h = np.abs((poses[:, 2] - phi_star + np.pi) % (2 * np.pi) - np.pi)
        e_v = np.abs(wheels.mean(axis=1) - v_star)
        w_f, w_h, w_v = self.weights
        return -(w_f * e_f + w_h * e_h + w_v * e_v) - self.collision_penalty * collided.astype(np.float64)

    def expert_actions(self) -> Dict[str, np.ndarray]:
        """The expert's ``(left, right)`` for every live agent at this tick (``formation eval
        --controller expert`` drives with these)."""
        actions = self._batch.expert_actions()[0]
        return {a: actions[self._index[a]] for a in self.agents}

    def policy_actions(self, outputs: Mapping[str, Any]) -> Dict[str, np.ndarray]:
        """A policy's raw outputs per agent as wheel speeds for the goal, turned into wheels as
        the Rust agent does for the output the model declares (``spec.output``: ``wheels`` at
        ``v_train``, scaled to v*, or ``formation_velocity`` with the reference term added), and
        under a wheel acceleration limit slowed by the agent's stopping governor on the robot's
        own scan."""
        raw = np.zeros((1, len(self.possible_agents), 2), dtype=np.float32)
        for agent, out in outputs.items():
            raw[0, self._index[agent]] = np.asarray(out, dtype=np.float32).reshape(2)
        wheels = self._batch.policy_actions(raw, self.spec.v_train, self.spec.output)[0]
        return {a: wheels[self._index[a]] for a in outputs}

    def metrics(self) -> dict:
        """The run's Table I metrics so far (final when the run is over): the run log's
        ``metrics``, as ``formation eval`` scores it."""
        return json.loads(self._batch.metrics_json(0))

    def trajectory(self) -> np.ndarray:
        """Every robot's pose at every sample so far: ``(samples, N, 3)``."""
        return self._batch.trajectory(0)

    def render(self) -> None:
        return None

    def close(self) -> None:
        return None


class SingleRobotEnv(gymnasium.Env):
    """A Gymnasium view of one robot of a :class:`FormationParallelEnv`: the learner drives robot
    ``robot`` and the expert drives the others (the DAgger setting). Observation, action and
    reward are that robot's; it terminates when it collides and is truncated at the scenario's
    duration. Keyword arguments go to :class:`FormationParallelEnv`.
    """

    metadata = {"render_modes": []}

    def __init__(self, robot: int = 0, **kwargs: Any) -> None:
        kwargs["expert"] = True
        self.parallel = FormationParallelEnv(**kwargs)
        if not 0 <= robot < len(self.parallel.possible_agents):
            raise ValueError(f"robot {robot} is not in the team of {len(self.parallel.possible_agents)}")
        self.agent = self.parallel.possible_agents[robot]
        self.observation_space = self.parallel.observation_space(self.agent)
        self.action_space = self.parallel.action_space(self.agent)

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        super().reset(seed=seed)
        observations, infos = self.parallel.reset(seed=seed, options=options)
        return observations[self.agent], infos[self.agent]

    def step(self, action: Any):
        if self.agent not in self.parallel.agents:
            raise EpisodeOver("the run is over for this robot; call reset() to start another run")
        actions = self.parallel.expert_actions()
        actions[self.agent] = action
        observations, rewards, terms, truncs, infos = self.parallel.step(actions)
        return observations[self.agent], rewards[self.agent], terms[self.agent], truncs[self.agent], infos[self.agent]
