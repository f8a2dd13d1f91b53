"""Behaviour cloning with PyTorch on the batched environment, exported to ONNX in the format the
Rust agent runs (issue 25's example).

1. `formation.Batch` plays B runs driven by the expert and records each robot's own input (the
   occupancy image and `(delta_phi, d*)`) with the expert's wheel speeds, scaled to `v_train`.
2. A small CNN learns them (PyTorch, CPU).
3. DAgger: the next B runs are driven by the CNN (each robot at each tick with probability
   1 - 0.5^k, at iteration k) and labelled by the expert, so the network learns to recover from
   its own mistakes; the samples are aggregated and training continues.
4. It is exported to ONNX with the `formation.*` metadata, so `formation eval --model` and
   `formation.env.parallel_env(model=...)` take it.
5. The exported model drives one run through ONNX Runtime in Python; its metrics are printed.

    .venv/bin/python examples/python/behaviour_cloning.py --out /tmp/bc.onnx [--worlds 32 --iterations 4 --epochs 6]
"""

import argparse
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import torch
from torch import nn

import formation
from formation.env import parallel_env

REPO = Path(__file__).resolve().parents[2]
SPEC = formation.ModelSpec(size_px=50, resolution_m=0.1, beyond="border", v_train=0.7)


def rollouts(scenario: formation.Scenario, worlds: int, first_run: int, seed: int, every: int,
             policy: "Policy | None" = None, beta: float = 1.0, rng: "np.random.Generator | None" = None):
    """One DAgger iteration's data: B runs driven by the expert (``policy=None``) or, robot by
    robot and tick by tick, by the policy with probability ``1 - beta``; every ``every``-th tick
    each robot's own input is kept with the expert's wheel speeds, scaled to ``v_train``."""
    batch = formation.Batch(scenario, [seed] * worlds, list(range(first_run, first_run + worlds)))
    images, aux, labels = [], [], []
    while not batch.over:
        image = batch.occupancy(SPEC.size_px, SPEC.resolution_m, SPEC.beyond, SPEC.d_star_ref_m)
        inputs = batch.aux()
        expert = batch.expert_actions()
        if batch.tick % every == 0:
            v_star = batch.goals()[:, 2][:, None, None]
            images.append(image.astype(np.uint8))
            aux.append(inputs)
            labels.append((expert * SPEC.v_train / v_star).astype(np.float32))
        actions = expert
        if policy is not None and beta < 1.0:
            with torch.no_grad():
                raw = policy(torch.from_numpy(image.reshape(-1, 1, SPEC.size_px, SPEC.size_px)),
                             torch.from_numpy(inputs.reshape(-1, 2))).numpy()
            learned = batch.policy_actions(raw.reshape(expert.shape).astype(np.float32), SPEC.v_train)
            actions = np.where(rng.random(expert.shape[:2] + (1,)) < beta, expert, learned)
        batch.step(actions)
    flat = lambda xs: np.concatenate([x.reshape(-1, *x.shape[2:]) for x in xs])
    return flat(images), flat(aux), flat(labels)


class Policy(nn.Module):
    def __init__(self) -> None:
        super().__init__()
        self.conv = nn.Sequential(
            nn.Conv2d(1, 16, 5, stride=2), nn.ReLU(), nn.Conv2d(16, 32, 5, stride=2), nn.ReLU(), nn.Flatten()
        )
        self.head = nn.Sequential(nn.Linear(32 * 10 * 10 + 2, 128), nn.ReLU(), nn.Linear(128, 2))

    def forward(self, occupancy: torch.Tensor, aux: torch.Tensor) -> torch.Tensor:
        return self.head(torch.cat([self.conv(occupancy), aux], dim=1))


def train(model: Policy, images, aux, labels, epochs: int) -> Policy:
    """``epochs`` passes of Adam over the aggregated samples (images stored as 0/1 bytes)."""
    model.train()
    optimiser = torch.optim.Adam(model.parameters(), lr=1e-3)
    steps = epochs * ((len(labels) + 255) // 256)
    schedule = torch.optim.lr_scheduler.OneCycleLR(optimiser, max_lr=2e-3, total_steps=steps)
    data = [torch.from_numpy(a) for a in (images, aux, labels)]
    for epoch in range(epochs):
        order = torch.randperm(len(labels))
        total = 0.0
        for start in range(0, len(order), 256):
            idx = order[start : start + 256]
            loss = nn.functional.mse_loss(model(data[0][idx].float(), data[1][idx]), data[2][idx])
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            schedule.step()
            total += loss.item() * len(idx)
        print(f"epoch {epoch + 1}: loss {total / len(order):.5f}")
    model.eval()
    return model


def export(model: Policy, scenario: formation.Scenario, out: Path) -> None:
    model.eval()
    example = (torch.zeros(1, 1, SPEC.size_px, SPEC.size_px), torch.zeros(1, 2))
    torch.onnx.export(
        model, example, str(out), input_names=["occupancy", "aux"], output_names=["wheels"],
        dynamic_axes={"occupancy": {0: "batch"}, "aux": {0: "batch"}, "wheels": {0: "batch"}}, dynamo=False,
    )
    proto = onnx.load(str(out))
    meta = {
        "formation.format": "formation-policy/1",
        "formation.occupancy.size_px": str(SPEC.size_px),
        "formation.occupancy.resolution_m": str(SPEC.resolution_m),
        "formation.occupancy.beyond": SPEC.beyond,
        "formation.lidar.beams": str(scenario.beams),
        "formation.lidar.max_range": str(scenario.max_range),
        "formation.v_train": str(SPEC.v_train),
        "formation.dataset_id": "python-behaviour-cloning",
    }
    for key, value in meta.items():
        entry = proto.metadata_props.add()
        entry.key, entry.value = key, value
    onnx.save(proto, str(out))


def drive(out: Path, scenario_path: str, robots: int, seed: int) -> dict:
    options = ort.SessionOptions()
    options.intra_op_num_threads = options.inter_op_num_threads = 1
    session = ort.InferenceSession(str(out), options, providers=["CPUExecutionProvider"])
    env = parallel_env(scenario=scenario_path, robots=robots, model=out)
    observations, _ = env.reset(seed=seed)
    while env.agents:
        outputs = {
            a: session.run(["wheels"], {"occupancy": o["occupancy"][None], "aux": o["aux"][None]})[0][0]
            for a, o in observations.items()
        }
        observations, _, _, _, _ = env.step(env.policy_actions(outputs))
    return env.metrics()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default=str(REPO / "scenarios" / "table1.toml"))
    parser.add_argument("--robots", type=int, default=3)
    parser.add_argument("--worlds", type=int, default=32, help="runs per iteration")
    parser.add_argument("--iterations", type=int, default=4, help="1: behaviour cloning alone")
    parser.add_argument("--every", type=int, default=2, help="keep every k-th tick")
    parser.add_argument("--epochs", type=int, default=6, help="per iteration")
    parser.add_argument("--seed", type=int, default=1000, help="the demonstrations' seed")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    scenario = formation.Scenario(args.scenario, robots=args.robots)
    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    model, data = Policy(), None
    for iteration in range(args.iterations):
        beta = 0.5 ** iteration
        new = rollouts(scenario, args.worlds, iteration * args.worlds, args.seed, args.every,
                       policy=model if iteration > 0 else None, beta=beta, rng=rng)
        data = new if data is None else tuple(np.concatenate(pair) for pair in zip(data, new))
        print(f"iteration {iteration} (beta {beta:.2f}): {len(data[2])} samples")
        model = train(model, *data, args.epochs)
    export(model, scenario, args.out)
    print(f"wrote {args.out}; `formation eval --model {args.out}` takes it")
    print(f"one run driven by it (seed 7, run 0): {drive(args.out, args.scenario, args.robots, seed=7)}")


if __name__ == "__main__":
    main()
