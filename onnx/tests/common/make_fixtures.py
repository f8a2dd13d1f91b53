"""Writes the ONNX fixtures of formation-onnx's tests and bench into a directory.

Usage: python make_fixtures.py OUT_DIR CASES

Builds the paper's policy network (exact layers) with seeded random weights, exports it with the
TorchScript exporter (dynamo=False) with a dynamic batch and the contract's names, adds the
formation.* metadata with the `onnx` package, and writes torch's own outputs for random inputs:

- policy.onnx        the contract, S = 50
- wrong_name.onnx    input `image` instead of `occupancy`
- small_image.onnx   a 40 x 40 input while the metadata says size_px 50
- no_metadata.onnx   no metadata_props at all
- nan_output.onnx    valid contract, but a NaN bias makes every output NaN
- cases.f32          CASES records of little-endian f32: occupancy (2500), aux (2), torch wheels (2)
- ranges.onnx        the contract with a range input: `ranges` [B, 100], formation.ranges declared
- ranges_undeclared.onnx  a `ranges` input the metadata does not declare
- ranges_missing.onnx     formation.ranges declared, but no `ranges` input
- ranges_cases.f32   CASES records: occupancy (2500), aux (2), ranges (100), torch wheels (2)
- neighbours.onnx    the contract with a neighbour input: `neighbours` [B, 8, 4],
                     formation.neighbours declared
- neighbours_undeclared.onnx  a `neighbours` input the metadata does not declare
- neighbours_missing.onnx     formation.neighbours declared, but no `neighbours` input
- neighbours_cases.f32  CASES records: occupancy (2500), aux (2), neighbours (32), torch wheels (2)
"""

import sys
import warnings

import numpy as np
import onnx
import torch
from torch import nn

SIZE = 50
METADATA = {
    "formation.format": "formation-policy/1",
    "formation.occupancy.size_px": "50",
    "formation.occupancy.resolution_m": "0.1",
    "formation.occupancy.beyond": "drop",
    "formation.lidar.beams": "900",
    "formation.lidar.max_range": "10",
    "formation.lidar.noise_std": "0",
    "formation.v_train": "0.7",
    "formation.dataset_id": "parity-fixture",
    "formation.train.epochs": "0",
    "formation.train.final_train_loss": "nan",
    "formation.train.final_val_loss": "nan",
    "formation.train.samples": "0",
    "formation.dagger.iteration": "0",
    "formation.created_by": "formation-onnx tests",
}


class PolicyNet(nn.Module):
    def __init__(self, size):
        super().__init__()
        side = (size + 2 - 8) // 4 + 1
        side = (side - 4) // 2 + 1
        side = side - 3 + 1
        self.features = nn.Sequential(
            nn.Conv2d(1, 32, 8, stride=4, padding=1), nn.ReLU(),
            nn.Conv2d(32, 16, 4, stride=2), nn.ReLU(),
            nn.Conv2d(16, 16, 3, stride=1), nn.ReLU(),
            nn.Flatten(),
        )
        self.head = nn.Sequential(nn.Linear(16 * side * side + 2, 32), nn.ReLU(), nn.Linear(32, 2))

    def forward(self, occupancy, aux):
        return self.head(torch.cat([self.features(occupancy), aux], dim=1))


SECTORS = 100
RANGES_METADATA = {**METADATA, "formation.ranges": f"sectors={SECTORS},clip=3"}


class RangesNet(PolicyNet):
    """The paper's network with a range branch whose features join the head."""

    def __init__(self, size):
        super().__init__(size)
        self.ranges = nn.Sequential(nn.Linear(SECTORS, 8), nn.ReLU())
        self.head = nn.Sequential(nn.Linear(16 * 3 * 3 + 2 + 8, 32), nn.ReLU(), nn.Linear(32, 2))

    def forward(self, occupancy, aux, ranges):
        return self.head(torch.cat([self.features(occupancy), aux, self.ranges(ranges)], dim=1))


SLOTS = 8
NEIGHBOURS_METADATA = {**METADATA, "formation.neighbours": f"slots={SLOTS},threshold=1.3,nearest=2"}


class NeighboursNet(PolicyNet):
    """The paper's network with a neighbour branch (all slots flattened) whose features join the
    head."""

    def __init__(self, size):
        super().__init__(size)
        self.neighbours = nn.Sequential(nn.Flatten(), nn.Linear(SLOTS * 4, 8), nn.Tanh())
        self.head = nn.Sequential(nn.Linear(16 * 3 * 3 + 2 + 8, 32), nn.ReLU(), nn.Linear(32, 2))

    def forward(self, occupancy, aux, neighbours):
        return self.head(torch.cat([self.features(occupancy), aux, self.neighbours(neighbours)], dim=1))


def export(model, path, size, input_names, metadata):
    shapes = {
        "occupancy": (2, 1, size, size),
        "image": (2, 1, size, size),
        "aux": (2, 2),
        "ranges": (2, SECTORS),
        "neighbours": (2, SLOTS, 4),
    }
    example = tuple(torch.zeros(*shapes[name]) for name in input_names)
    dynamic = {name: {0: "batch"} for name in [*input_names, "wheels"]}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(model.eval(), example, path, input_names=input_names, output_names=["wheels"],
                          dynamic_axes=dynamic, opset_version=17, dynamo=False)
    proto = onnx.load(path)
    del proto.metadata_props[:]
    for key, value in metadata.items():
        entry = proto.metadata_props.add()
        entry.key, entry.value = key, value
    onnx.checker.check_model(proto)
    onnx.save(proto, path)


def main():
    out, cases = sys.argv[1], int(sys.argv[2])
    torch.manual_seed(20261122)
    model = PolicyNet(SIZE).eval()
    export(model, f"{out}/policy.onnx", SIZE, ["occupancy", "aux"], METADATA)
    export(model, f"{out}/wrong_name.onnx", SIZE, ["image", "aux"], METADATA)
    export(model, f"{out}/no_metadata.onnx", SIZE, ["occupancy", "aux"], {})
    export(PolicyNet(40), f"{out}/small_image.onnx", 40, ["occupancy", "aux"], METADATA)
    broken = PolicyNet(SIZE)
    with torch.no_grad():
        broken.head[2].bias.fill_(float("nan"))
    export(broken, f"{out}/nan_output.onnx", SIZE, ["occupancy", "aux"], METADATA)

    rng = np.random.default_rng(7)
    occupancy = (rng.random((cases, 1, SIZE, SIZE)) < 0.08).astype(np.float32)
    aux = np.stack([rng.uniform(-np.pi, np.pi, cases), rng.uniform(0.5, 3.0, cases)], axis=1).astype(np.float32)
    with torch.no_grad():
        wheels = model(torch.from_numpy(occupancy), torch.from_numpy(aux)).numpy()
    records = np.concatenate([occupancy.reshape(cases, -1), aux, wheels], axis=1).astype("<f4")
    records.tofile(f"{out}/cases.f32")

    ranged = RangesNet(SIZE).eval()
    export(ranged, f"{out}/ranges.onnx", SIZE, ["occupancy", "aux", "ranges"], RANGES_METADATA)
    export(ranged, f"{out}/ranges_undeclared.onnx", SIZE, ["occupancy", "aux", "ranges"], METADATA)
    export(model, f"{out}/ranges_missing.onnx", SIZE, ["occupancy", "aux"], RANGES_METADATA)
    ranges = rng.uniform(0.1, 3.0, (cases, SECTORS)).astype(np.float32)
    with torch.no_grad():
        wheels = ranged(torch.from_numpy(occupancy), torch.from_numpy(aux), torch.from_numpy(ranges)).numpy()
    records = np.concatenate([occupancy.reshape(cases, -1), aux, ranges, wheels], axis=1).astype("<f4")
    records.tofile(f"{out}/ranges_cases.f32")

    neighboured = NeighboursNet(SIZE).eval()
    export(neighboured, f"{out}/neighbours.onnx", SIZE, ["occupancy", "aux", "neighbours"], NEIGHBOURS_METADATA)
    export(neighboured, f"{out}/neighbours_undeclared.onnx", SIZE, ["occupancy", "aux", "neighbours"], METADATA)
    export(model, f"{out}/neighbours_missing.onnx", SIZE, ["occupancy", "aux"], NEIGHBOURS_METADATA)
    neighbours = np.zeros((cases, SLOTS, 4), dtype=np.float32)
    for case in range(cases):
        present = rng.integers(1, SLOTS + 1)
        neighbours[case, :present, :2] = rng.uniform(-3.0, 3.0, (present, 2))
        neighbours[case, :present, 2] = rng.integers(0, 2, present)
        neighbours[case, :present, 3] = 1.0
    with torch.no_grad():
        wheels = neighboured(torch.from_numpy(occupancy), torch.from_numpy(aux), torch.from_numpy(neighbours)).numpy()
    records = np.concatenate([occupancy.reshape(cases, -1), aux, neighbours.reshape(cases, -1), wheels], axis=1)
    records.astype("<f4").tofile(f"{out}/neighbours_cases.f32")


if __name__ == "__main__":
    main()
