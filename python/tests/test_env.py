"""The PettingZoo environment: PettingZoo's own API and seed tests at 3 and 16 robots, bit
identity with `formation eval` (expert and the shipped ONNX policy), and bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import MODEL, REPO, cli_run_poses, pose_rows, team_scenario
from pettingzoo.test import parallel_api_test, parallel_seed_test

import formation
from formation.env import parallel_env
from formation.model import ModelSpec

TABLE1 = str(REPO / "scenarios" / "table1.toml")


def short_env(robots: int, **kwargs):
    return parallel_env(scenario=TABLE1, robots=robots, overrides={"duration_s": 2.0}, **kwargs)


@pytest.mark.parametrize("robots", [3, 16])
def test_pettingzoos_parallel_api_test_passes(robots):
    parallel_api_test(short_env(robots), num_cycles=100)


@pytest.mark.parametrize("robots", [3, 16])
def test_pettingzoos_parallel_seed_test_passes(robots):
    parallel_seed_test(lambda: short_env(robots))


@pytest.mark.parametrize("robots", [3, 16])
def test_an_expert_episode_equals_formation_eval_bit_for_bit(tmp_path, robots):
    scenario = team_scenario(tmp_path, robots, 6.0)
    seed, run = 11, 1
    expected = pose_rows(cli_run_poses(scenario, tmp_path / "out", seed, run, "expert"))
    env = parallel_env(scenario=str(scenario))
    env.reset(seed=seed, run=run)
    while env.agents:
        _, _, _, _, infos = env.step(env.expert_actions())
    got = trajectory_rows(env)
    assert len(got) == len(expected) == 121
    assert got == expected
    assert "metrics" in infos["robot_0"]


def policy_session(model=MODEL):
    """An ONNX Runtime session on ``model`` set up as the agent's own."""
    import onnxruntime as ort

    options = ort.SessionOptions()
    # The agent's session: one intra-op and one inter-op thread, default graph optimisation.
    options.intra_op_num_threads = 1
    options.inter_op_num_threads = 1
    return ort.InferenceSession(str(model), options, providers=["CPUExecutionProvider"])


def trajectory_rows(env) -> list:
    """The environment's trajectory as rows of pose tuples, to compare with `pose_rows`."""
    return [[tuple(p) for p in row] for row in env.trajectory().tolist()]


def play_policy(env, session, observations, output: str, inputs=("occupancy", "aux")) -> list:
    """Steps ``env`` from ``observations`` to its end, each robot's action ``session``'s
    ``output`` on its own observation's ``inputs`` (one robot at a time, as each agent runs its
    own model); returns :func:`trajectory_rows`."""
    while env.agents:
        outputs = {}
        for agent, obs in observations.items():
            feed = {name: obs[name][None] for name in inputs}
            outputs[agent] = session.run([output], feed)[0][0]
        observations, _, _, _, _ = env.step(env.policy_actions(outputs))
    return trajectory_rows(env)


def declared_inputs(spec) -> tuple:
    """The inputs ``spec``'s model takes, by name, as the agent feeds them."""
    return ("occupancy", "aux") + (("ranges",) if spec.ranges else ()) + (("neighbours",) if spec.neighbours else ())


def tiny_model(tmp_path, name: str, seed: int, *flags: str):
    """Writes ``tests/fixtures/tiny_policy.py``'s formation_velocity model with ``seed`` and
    ``flags`` to ``tmp_path / name``; returns its path."""
    import subprocess
    import sys

    model = tmp_path / name
    subprocess.run(
        [sys.executable, str(REPO / "tests" / "fixtures" / "tiny_policy.py"), str(model), "--seed", str(seed),
         "--output", "formation_velocity", *flags],
        check=True,
    )
    return model


def team_policy_episode(tmp_path, model):
    """`formation eval`'s poses (as `pose_rows`) for ``model`` driving 5 robots at d* = 3 m in
    seed 2's run 0, and an environment on the same scenario and model to replay it."""
    scenario = team_scenario(tmp_path, 5, 3.0)
    expected = pose_rows(cli_run_poses(scenario, tmp_path / "out", 2, 0, "policy", model))
    return expected, parallel_env(scenario=str(scenario), model=model)


@pytest.mark.parametrize("robots,given", [(3, True), (16, True), (16, False)])
def test_an_onnx_policy_episode_equals_formation_eval_bit_for_bit(tmp_path, robots, given):
    # Without model= the environment renders the shipped default's declared input (issue 39),
    # which is what `formation eval` gives its agents without --model: the same episode.
    scenario = team_scenario(tmp_path, robots, 3.0)
    seed, run = 5, 0
    expected = pose_rows(cli_run_poses(scenario, tmp_path / "out", seed, run, "policy"))
    env = parallel_env(scenario=str(scenario), **({"model": MODEL} if given else {}))
    session = policy_session()
    observations, _ = env.reset(seed=seed, run=run)
    got = play_policy(env, session, observations, env.spec.output, declared_inputs(env.spec))
    assert len(got) == len(expected) == 61
    assert got == expected


def test_a_formation_velocity_policy_episode_equals_formation_eval_bit_for_bit(tmp_path):
    # A model that declares formation.output = formation_velocity: the environment adds the
    # reference term as the Rust agent does (issue 34), so the episode is formation eval's.
    model = tiny_model(tmp_path, "fv.onnx", 3)
    assert ModelSpec.from_onnx(model).output == "formation_velocity"
    expected, env = team_policy_episode(tmp_path, model)
    session = policy_session(model)
    observations, _ = env.reset(seed=2, run=0)
    got = play_policy(env, session, observations, "formation_velocity")
    assert len(got) == len(expected) == 61
    assert got == expected


def test_under_a_wheel_limit_the_agents_stopping_governor_keeps_the_robots_apart(tmp_path):
    # Run 13 of teams-generalist-accel at 3 robots, seed 7: two robots start 0.95 m apart at
    # d* = 1.23 m and one backs into the other while it turns; the shipped policy touched it at
    # 1.7 s before the agent's stopping governor (issue 34). The environment turns the policy's
    # outputs into wheels as the agent does, governor included: the same episode, no contact.
    scenario = team_scenario(tmp_path, 3, 3.0, base="teams-generalist-accel.toml")
    seed, run = 7, 13
    expected = pose_rows(cli_run_poses(scenario, tmp_path / "out", seed, run, "policy"))
    env = parallel_env(scenario=str(scenario), model=MODEL)
    session = policy_session()
    observations, _ = env.reset(seed=seed, run=run)
    got = play_policy(env, session, observations, env.spec.output, declared_inputs(env.spec))
    assert len(got) == len(expected) == 61
    assert got == expected
    closest = min(
        math.dist(a[:2], b[:2]) for row in got for i, a in enumerate(row) for b in row[i + 1:]
    )
    assert 0.5 < closest < 0.7, f"the bodies (0.25 m each) came to {closest:.3f} m between centres"


def test_the_range_input_is_read_by_the_agents_own_parser():
    # formation.ranges as the agent reads it (RangeInput::parse): keys in either order, spaces
    # allowed, values checked; what the environment's ranges space is sized by.
    from formation._native import range_input

    assert range_input("sectors=100,clip=3") == (100, 3.0)
    assert range_input(" clip = 2.5 , sectors = 6 ") == (6, 2.5)
    for bad in ["sectors=100", "sectors=x,clip=3", "sectors=2,clip=3", "sectors=8,clip=0", ""]:
        with pytest.raises(ValueError, match="formation.ranges"):
            range_input(bad)


def test_a_ranges_policy_episode_equals_formation_eval_bit_for_bit(tmp_path):
    # A model that takes the scan's ranges beside its image (formation.ranges, issue 34 item 6):
    # the environment feeds what the Rust agent feeds, so the episode is formation eval's.
    model = tiny_model(tmp_path, "ranges.onnx", 5, "--ranges-sectors", "100")
    assert ModelSpec.from_onnx(model).ranges == "sectors=100,clip=3"
    expected, env = team_policy_episode(tmp_path, model)
    assert env.observation_space("robot_0")["ranges"].shape == (100,)
    session = policy_session(model)
    observations, _ = env.reset(seed=2, run=0)
    # The ranges are the documented pooling of the robot's own scan (checked here in numpy).
    scans = env.batch.scans()[0]
    d_star = env.batch.goals()[0][1]
    beams = scans.shape[1]
    sector = np.floor(np.arange(beams) * 100 / beams + 0.5).astype(int) % 100
    for i, agent in enumerate(env.possible_agents):
        scan = scans[i].astype(np.float64)
        hit = (scan >= 0) & (scan < env.scenario.max_range)
        want = np.full(100, 3.0)
        for s in range(100):
            mine = scan[(sector == s) & hit]
            if mine.size:
                want[s] = min(3.0, mine.mean() / d_star)
        assert np.allclose(observations[agent]["ranges"], want, rtol=1e-6), agent
    got = play_policy(env, session, observations, "formation_velocity", ("occupancy", "aux", "ranges"))
    assert len(got) == len(expected) == 61
    assert got == expected


def test_a_neighbours_policy_episode_equals_formation_eval_bit_for_bit(tmp_path):
    # A model that takes the neighbours its robot detects in its own scan (formation.neighbours,
    # issue 34): the environment feeds what the Rust agent feeds, so the episode is formation eval's.
    model = tiny_model(tmp_path, "neighbours.onnx", 5, "--neighbour-slots", "4")
    assert ModelSpec.from_onnx(model).neighbours == "slots=4,threshold=1.3,nearest=2"
    expected, env = team_policy_episode(tmp_path, model)
    space = env.observation_space("robot_0")
    assert space["neighbours"].shape == (4, 4)
    assert "ranges" not in space.spaces
    session = policy_session(model)
    observations, _ = env.reset(seed=2, run=0)
    # The slots are the robot's own detections (the detector alone, checked here) in units of
    # d*, held ones first, the empty slots zeros.
    scans = env.batch.scans()[0]
    d_star = env.batch.goals()[0][1]
    held_somewhere = False
    for i, agent in enumerate(env.possible_agents):
        slots = observations[agent]["neighbours"]
        assert slots.dtype == np.float32 and slots.shape == (4, 4)
        found = formation.detect_neighbours(scans[i], env.scenario.max_range)
        present = slots[:, 3] == 1.0
        assert present.sum() == min(len(found), 4), agent
        assert np.all(slots[~present] == 0.0), agent
        held = slots[present, 2]
        assert np.all(np.diff(held) <= 0), f"{agent}: held slots come first"
        held_somewhere |= bool(held.any())
        for x, y in slots[present, :2]:
            distances = np.hypot(found[:, 0] / d_star - x, found[:, 1] / d_star - y)
            assert distances.min() < 1e-5, agent
    assert held_somewhere
    got = play_policy(env, session, observations, "formation_velocity", ("occupancy", "aux", "neighbours"))
    assert len(got) == len(expected) == 61
    assert got == expected


def test_a_bad_neighbour_declaration_is_refused_naming_the_key():
    with pytest.raises(ValueError, match="formation.neighbours.*slots=K,threshold=T,nearest=M"):
        formation._native.neighbour_input("slots=4")
    assert formation._native.neighbour_input("slots=4,threshold=1.3,nearest=2") == (4, 1.3, 2, 4)
    assert formation._native.neighbour_input("slots=4,threshold=1.3,nearest=2,hidden=1") == (4, 1.3, 2, 6)


def test_the_shipped_pair_models_observations_hold_six_numbers_a_slot(tmp_path):
    # The shipped pair network declares hidden=1: each slot also carries the step aside of its
    # hidden pairs, and the observation space says so.
    model = MODEL
    assert ModelSpec.from_onnx(model).neighbours.endswith(",hidden=1")
    env = parallel_env(scenario=str(team_scenario(tmp_path, 5, 3.0)), model=model)
    space = env.observation_space("robot_0")["neighbours"]
    assert space.shape == (16, 6)
    observations, _ = env.reset(seed=2, run=0)
    for agent, obs in observations.items():
        assert obs["neighbours"].shape == (16, 6) and space.contains(obs["neighbours"]), agent


def test_a_spec_with_an_output_the_package_does_not_know_is_refused_by_name():
    with pytest.raises(ValueError, match="output 'torques' is not 'wheels' or 'formation_velocity'"):
        ModelSpec.from_metadata({"formation.format": "formation-policy/1", "formation.occupancy.size_px": "50",
                                 "formation.occupancy.resolution_m": "0.1", "formation.occupancy.beyond": "drop",
                                 "formation.v_train": "0.7", "formation.lidar.beams": "900",
                                 "formation.lidar.max_range": "10", "formation.output": "torques"})


def test_reset_without_a_seed_plays_the_next_run_of_the_last_seed():
    env = short_env(3)
    env.reset(seed=4)
    assert env.seed_and_run == (4, 0)
    env.reset()
    assert env.seed_and_run == (4, 1)
    env.reset(seed=4, options={"run": 7})
    assert env.seed_and_run == (4, 7)
    first = env.trajectory()
    batch = formation.Batch(env.scenario, [4], [7])
    assert np.array_equal(batch.trajectory(0), first)


def test_without_a_model_the_observation_is_the_shipped_models_declared_input(tmp_path):
    scenario = team_scenario(tmp_path, 16, 1.0)
    default = parallel_env(scenario=str(scenario))
    given = parallel_env(scenario=str(scenario), model=MODEL)
    assert default.spec == given.spec == ModelSpec.from_onnx(MODEL)
    a, _ = default.reset(seed=3)
    b, _ = given.reset(seed=3)
    for agent in a:
        for name in declared_inputs(default.spec):
            assert np.array_equal(a[agent][name], b[agent][name]), (agent, name)


def test_bad_actions_raise_clear_exceptions():
    env = short_env(3)
    env.reset(seed=1)
    good = {a: np.zeros(2) for a in env.agents}
    with pytest.raises(ValueError, match=r"action of robot_1 is 'fast', not numbers"):
        env.step({**good, "robot_1": "fast"})
    with pytest.raises(ValueError, match=r"action of robot_1 has shape \(3,\)"):
        env.step({**good, "robot_1": np.zeros(3)})
    with pytest.raises(ValueError, match="action of robot_2 is .*nan.*must be finite"):
        env.step({**good, "robot_2": np.array([0.1, math.nan])})
    with pytest.raises(ValueError, match=r"no action for \['robot_0'\]"):
        env.step({a: v for a, v in good.items() if a != "robot_0"})
    with pytest.raises(ValueError, match="unknown agents"):
        env.step({**good, "robot_9": np.zeros(2)})
    while env.agents:
        env.step({a: np.zeros(2) for a in env.agents})
    with pytest.raises(formation.EpisodeOver, match="call reset"):
        env.step(good)


def test_an_unknown_or_bad_scenario_key_raises_the_clis_message():
    with pytest.raises(formation.ScenarioError, match="unknown field `speed`"):
        parallel_env(scenario=TABLE1, overrides={"goal.speed": 1.0})
    with pytest.raises(formation.ScenarioError, match="table1.toml"):
        parallel_env(scenario=TABLE1, overrides={"goal.v_star": -1.0})
    with pytest.raises(formation.ScenarioError, match="cannot read scenario file"):
        parallel_env(scenario=str(REPO / "scenarios" / "missing.toml"))
    with pytest.raises(formation.ScenarioError, match="robots"):
        parallel_env(scenario=TABLE1, robots=1)


def test_a_collision_terminates_the_robots_in_contact(tmp_path):
    env = short_env(3, collision_penalty=5.0)
    env.reset(seed=2)
    poses = env.batch.poses()[0]
    # Drive robot 0 straight at robot 1 until they touch.
    rewards, terms = {}, {}
    for _ in range(40):
        if not env.agents or any(terms.values()):
            break
        p = env.batch.poses()[0]
        bearing = math.atan2(p[1, 1] - p[0, 1], p[1, 0] - p[0, 0])
        turn = math.remainder(bearing - p[0, 2], 2 * math.pi)
        actions = {a: np.zeros(2) for a in env.agents}
        actions["robot_0"] = np.array([1.0 - turn, 1.0 + turn])
        _, rewards, terms, _, _ = env.step(actions)
    assert terms.get("robot_0") and terms.get("robot_1"), poses
    assert rewards["robot_0"] < -5.0
    assert "robot_0" not in env.agents and "robot_2" in env.agents


def test_the_single_robot_view_passes_gymnasiums_checker():
    from gymnasium.utils.env_checker import check_env

    from formation.env import SingleRobotEnv

    env = SingleRobotEnv(robot=1, scenario=TABLE1, overrides={"duration_s": 1.0})
    check_env(env, skip_render_check=True)
    obs, _ = env.reset(seed=3)
    assert obs["occupancy"].shape == (1, 50, 50)
    done, steps = False, 0
    while not done:
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        done, steps = terminated or truncated, steps + 1
    assert steps == 20 and "metrics" in info or terminated
