"""A random rollout of the PettingZoo environment, printing env-steps/s (issue 25's example).

    .venv/bin/python examples/python/random_rollout.py [--robots 16] [--seed 7]
"""

import argparse
import time
from pathlib import Path

from formation.env import parallel_env

REPO = Path(__file__).resolve().parents[2]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default=str(REPO / "scenarios" / "table1.toml"))
    parser.add_argument("--robots", type=int, default=16)
    parser.add_argument("--seed", type=int, default=7)
    args = parser.parse_args()
    env = parallel_env(scenario=args.scenario, robots=args.robots)
    env.reset(seed=args.seed)
    for agent in env.possible_agents:
        env.action_space(agent).seed(args.seed)
    steps, started = 0, time.perf_counter()
    infos = {}
    while env.agents:
        actions = {agent: env.action_space(agent).sample() for agent in env.agents}
        _, _, _, _, infos = env.step(actions)
        steps += 1
    elapsed = time.perf_counter() - started
    print(f"{steps} steps of {args.robots} robots in {elapsed:.2f} s: {steps / elapsed:.0f} env-steps/s")
    metrics = next((info["metrics"] for info in infos.values() if "metrics" in info), None)
    print(f"metrics of the run: {metrics}")


if __name__ == "__main__":
    main()
