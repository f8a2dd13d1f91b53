"""Command line: ``python -m formation_trainer train ...`` and ``python -m formation_trainer export ...``.

Exit status: 0 on success, 2 for a usage or data problem (message on stderr), 3 when a Python
dependency (PyTorch, ONNX, ...) is missing, so the Rust bridge can say how to install it.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

MISSING_DEPENDENCY_EXIT = 3
USAGE_EXIT = 2
#: ``model.ARCHITECTURE_NAMES``, spelled out so that ``--help`` works without PyTorch.
ARCHITECTURE_NAMES = ["paper", "wide", "wide-head", "pair", "pair-potential"]


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m formation_trainer", description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True)

    train = commands.add_parser("train", help="train the policy CNN and export it to ONNX")
    train.add_argument("--data", type=Path, action="append", required=True, help="dataset directory (repeatable)")
    train.add_argument("--out", type=Path, required=True, help="ONNX model to write (.pt, .loss.csv, .loss.png beside it)")
    train.add_argument("--epochs", type=int, default=10)
    train.add_argument("--batch-size", type=int, default=32)
    train.add_argument("--lr", type=float, default=1e-4)
    train.add_argument("--device", choices=["auto", "cpu", "cuda"], default="auto")
    train.add_argument("--val-fraction", type=float, default=0.1, help="share of runs held out for validation")
    train.add_argument("--seed", type=int, default=0)
    train.add_argument("--init-from", type=Path, help="warm start from this .pt checkpoint, or from a policy .onnx written by this trainer")
    train.add_argument("--parity-out", type=Path, help="write a few inputs with torch outputs as JSON")
    train.add_argument(
        "--d-star-range",
        type=_d_star_range,
        help="MIN,MAX: the d* range the model is declared for (its envelope; must hold the data's)",
    )

    train.add_argument(
        "--architecture",
        choices=ARCHITECTURE_NAMES,
        help="the network: paper (the paper's CNN), wide or wide-head (CNNs for teams), or pair (sums one learned "
        "term per neighbour the robot detects in its own scan; needs a dataset collected with --neighbours K and "
        "--output formation_velocity), or pair-potential (the same with each term scaled by the law's pair profile "
        "(r^4 - 1) / r^3). Default: pair for a dataset that declares neighbours, else paper; "
        "a warm start keeps its own",
    )
    train.add_argument(
        "--mirror",
        action="store_true",
        help="also train on every sample reflected about the robot's heading axis (an exact symmetry of the task), "
        "and export the network averaged over the reflection",
    )
    train.add_argument(
        "--mirror-augment-only",
        action="store_true",
        help="train on reflected samples as --mirror does, but export the network itself (one evaluation per decision)",
    )

    train.add_argument(
        "--samples-per-epoch",
        type=int,
        help="train each epoch on this many training samples drawn at random (default: all of them)",
    )

    train.add_argument(
        "--relative-loss",
        action="store_true",
        help="weight each sample's squared error by (d_ref/d*)^2, so small d* is fitted as tightly, relative to d*, as large",
    )

    train.add_argument(
        "--output",
        choices=("wheels", "formation_velocity"),
        default="wheels",
        help="what the model outputs: wheels (the paper's wheel speeds at v_train) or formation_velocity "
        "(the expert's correction in the robot's frame, to which the agent adds v* (cos dphi, sin dphi))",
    )
    train.add_argument(
        "--response-weight",
        type=float,
        metavar="EPS",
        help="weight each sample's squared error by 1/(|f| + EPS), f the expert's formation velocity [m/s] "
        "(mean weight 1), so small corrections count (for example 0.05)",
    )

    exp = commands.add_parser("export", help="export a .pt checkpoint to ONNX (with the parity check)")
    exp.add_argument("--checkpoint", type=Path, required=True)
    exp.add_argument("--out", type=Path, required=True, help="ONNX model to write")
    exp.add_argument("--data", type=Path, action="append", help="dataset(s) whose samples feed the parity check")
    exp.add_argument("--parity-out", type=Path, help="write a few inputs with torch outputs as JSON")
    exp.add_argument("--seed", type=int, default=0)
    return parser


# The `train` options that pass to TrainConfig's field of the same name as they are.
_TRAIN_OPTIONS = (
    "data",
    "out",
    "epochs",
    "batch_size",
    "lr",
    "device",
    "val_fraction",
    "seed",
    "init_from",
    "parity_out",
    "d_star_range",
    "architecture",
    "samples_per_epoch",
    "relative_loss",
    "output",
    "response_weight",
)


def _train(args) -> None:
    from . import train

    config = train.TrainConfig(
        **{name: getattr(args, name) for name in _TRAIN_OPTIONS},
        mirror=args.mirror or args.mirror_augment_only,
        mirror_average=not args.mirror_augment_only,
    )
    report = train.run(config, log=lambda line: print(line, flush=True))
    print(train.report_line(report), flush=True)


def _export(args) -> None:
    import numpy as np

    from . import dataset, export, train

    checkpoint = train.load_checkpoint(args.checkpoint)
    model = train.model_from_checkpoint(checkpoint)
    size = model.size_px
    declared = export.declared_ranges(checkpoint["metadata"])
    declared_neighbours = export.declared_neighbours(checkpoint["metadata"])
    ranges = neighbours = None
    if args.data:
        samples = dataset.load(args.data)
        if samples.size_px != size:
            raise train.TrainError(f"the data has {samples.size_px} px images, the checkpoint {size} px")
        # A pair network takes no ranges, whether or not its data holds them.
        if not model.neighbour_slots and samples.range_input != declared:
            raise train.TrainError(
                f"the data's range input is {samples.range_input or 'none'}, the checkpoint's {declared or 'none'}: "
                "check parity on the data the model was trained on"
            )
        if model.neighbour_slots and samples.neighbour_input != declared_neighbours:
            raise train.TrainError(
                f"the data's neighbour input is {samples.neighbour_input or 'none'}, the checkpoint's "
                f"{declared_neighbours}: check parity on the data the model was trained on"
            )
        pick = np.random.default_rng(args.seed).permutation(len(samples))[: train.PARITY_SAMPLES]
        occupancy = samples.occupancy[pick][:, None].astype(np.float32)
        aux = samples.aux[pick]
        if declared:
            ranges = samples.ranges[pick]
        if model.neighbour_slots:
            neighbours = samples.neighbours[pick]
    else:
        rng = np.random.default_rng(args.seed)
        occupancy = (rng.random((train.PARITY_SAMPLES, 1, size, size)) < 0.02).astype(np.float32)
        aux = np.stack([rng.uniform(-np.pi, np.pi, train.PARITY_SAMPLES), rng.uniform(0.5, 3.0, train.PARITY_SAMPLES)], 1)
        aux = aux.astype(np.float32)
        if declared:
            ranges = rng.uniform(0.0, declared.clip, (train.PARITY_SAMPLES, declared.sectors)).astype(np.float32)
        if model.neighbour_slots:
            neighbours = random_neighbours(rng, train.PARITY_SAMPLES, model.neighbour_slots, model.neighbour_features)
    output = checkpoint["metadata"].get("formation.output", export.OUTPUT_NAME)
    export.export_onnx(model, args.out, checkpoint["metadata"], output=output)
    parity = export.check_parity(model, args.out, occupancy, aux, output=output, ranges=ranges, neighbours=neighbours)
    if args.parity_out:
        n = train.PARITY_FILE_SAMPLES
        export.write_parity_file(
            args.parity_out, model, occupancy[:n], aux[:n], ranges=None if ranges is None else ranges[:n],
            neighbours=None if neighbours is None else neighbours[:n],
        )
    print(f"wrote {args.out} (onnxruntime parity {parity:.2e} on {len(aux)} samples)", flush=True)


def random_neighbours(rng, samples: int, slots: int, features: int = 4):
    """``samples`` random neighbour inputs [samples, slots, features] laid out as collection lays
    them out: a random number of detections at 0.5-3 d* in random directions, the held ones first,
    each group nearest first, then empty slots of zeros; with 6 features, a random step aside of
    up to 4 in a tenth of the slots."""
    import numpy as np

    out = np.zeros((samples, slots, features), dtype=np.float32)
    for row in out:
        count = int(rng.integers(0, slots + 1))
        distance = rng.uniform(0.5, 3.0, count)
        bearing = rng.uniform(-np.pi, np.pi, count)
        held = rng.random(count) < 0.5
        order = np.lexsort((distance, ~held))
        row[:count, 0] = (distance * np.cos(bearing))[order]
        row[:count, 1] = (distance * np.sin(bearing))[order]
        row[:count, 2] = held[order]
        row[:count, 3] = 1.0
        if features > 4:
            stepped = rng.random(count) < 0.1
            row[:count, 4:6] = rng.uniform(-4.0, 4.0, (count, 2)) * stepped[:, None]
    return out


def _d_star_range(text: str) -> tuple[float, float]:
    try:
        lo, hi = (float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected MIN,MAX in metres, got {text!r}") from None
    return lo, hi


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        if args.command == "train":
            _train(args)
        else:
            _export(args)
    except ModuleNotFoundError as e:
        print(f"missing Python dependency: {e}", file=sys.stderr)
        return MISSING_DEPENDENCY_EXIT
    except Exception as e:
        from .dataset import DatasetError
        from .export import ParityError
        from .train import TrainError

        if isinstance(e, (DatasetError, TrainError, ParityError)):
            print(f"error: {e}", file=sys.stderr)
            return USAGE_EXIT
        raise
    return 0


if __name__ == "__main__":
    sys.exit(main())
