"""The policy networks: the paper's, with its exact layer sizes, and a wider one for teams.

Input ``occupancy`` [B, 1, 50, 50] and ``aux`` [B, 2] = (delta_phi, d*); output ``wheels`` [B, 2] =
(left, right) m/s at v_train. The paper's network (``architecture="paper"``)::

    Conv2d(1, 32, 8, stride 4, padding 1) ReLU   -> 32 x 12 x 12
    Conv2d(32, 16, 4, stride 2) ReLU             -> 16 x 5 x 5
    Conv2d(16, 16, 3, stride 1) ReLU             -> 16 x 3 x 3 = 144
    flatten 144, concat aux                      -> 146
    Linear(146, 32) ReLU -> Linear(32, 2)

Without ``padding=1`` on the first convolution a 50 x 50 image gives 11 x 11 and a flatten of 64,
not the paper's 144.

``architecture="wide"`` keeps the same convolution geometry (so the same image sizes work) with
64 channels in the second and third convolutions and a head of two 256-unit layers::

    Conv2d(1, 32, 8, stride 4, padding 1) ReLU   -> 32 x 12 x 12
    Conv2d(32, 64, 4, stride 2) ReLU             -> 64 x 5 x 5
    Conv2d(64, 64, 3, stride 1) ReLU             -> 64 x 3 x 3 = 576
    flatten 576, concat aux                      -> 578
    Linear(578, 256) ReLU -> Linear(256, 256) ReLU -> Linear(256, 2)

It costs about twice the paper's arithmetic per image. The paper's 32-unit head has to hold every
neighbour's bearing and distance error at once; with teams of 5 to 16 robots it underfits (its
training loss stops falling), which is what the wide head is for.

``architecture="wide-head"`` keeps the paper's convolutions (16 channels, flatten 144) under the
wide head (146 -> 256 -> 256 -> 2): about 1.2 times the paper's arithmetic, most of it still in the
first two convolutions. On the same 1.4 M DAgger samples of teams of 3 to 32, trained from scratch
for two epochs, its validation error was 27 % below the paper network's (0.0177 against 0.0242).

**Ranges beside the image** (``range_sectors=K``, issue 34 item 6): the model also takes the scan's
ranges, ``ranges`` [B, K] (``formation.ranges = "sectors=K,clip=C"``: each sector the mean of
``range / d*`` over its returning beams, at most C). The image resolves a neighbour to one cell,
the ranges to about a centimetre. A branch ``Linear(K, 64) ReLU`` turns them into 64 features,
concatenated after the image features and aux, so the head's first layer takes
``flatten + A + 64``::

    ranges [B, K] -> Linear(K, 64) ReLU          -> 64
    concat(image features, aux, range features)  -> flatten + 2 + 64
    head as above

Its multiply-adds for K = 100 (the P3-DX default, ``sectors=100,clip=3``) are the branch's
100 x 64 = 6,400 and the head's 64 new inputs, 64 x 256 = 16,384 under the wide head (64 x 32 =
2,048 under the paper's head). Per decision (:func:`multiply_adds`, one evaluation):

=============================  ===========  ===========================
network                        no ranges    ranges, K = 100
=============================  ===========  ===========================
paper                          525,184      533,632 (1.016 x paper)
wide-head                      623,872      646,656 (1.231 x paper)
wide                           1,659,904    1,682,688
=============================  ===========  ===========================

So the wide head with ranges stays under issue 34's cap of 1.3 x the paper network (0.683 M;
the issue rounds it to 0.69 M). The convolutions are 520,448 of them (99 % of the paper's).
A mirror-averaged export evaluates the network twice and costs twice as much.

``mirror_averaged=True`` (what ``--mirror`` trains) makes either network exactly symmetric under
the task's reflection about the robot's heading axis: the output is the mean of the network on the
input and, reflected back, on the reflected input (see :func:`mirror_inputs`). A policy that is
only trained on reflected samples is symmetric only as far as it has learned to be; the average
removes the asymmetric part of its error, at twice the arithmetic per image. The reflection of
the output depends on what it is (``output``): wheel speeds swap left and right, a formation
velocity in the robot's frame negates its sideways part. The ranges reflect with the sectors:
sector ``s`` (centred on bearing ``2 pi s / K``) becomes sector ``(K - s) % K``.
"""

from __future__ import annotations

import torch
from torch import nn

#: The image side the paper's network is defined for.
PAPER_SIZE_PX = 50
#: Width of the flattened convolutional features for 50 x 50 images.
PAPER_FLATTEN = 144


def conv_output_side(size_px: int) -> int:
    """Side of the last feature map for a ``size_px`` image (12 -> 5 -> 3 for 50)."""
    side = (size_px + 2 * 1 - 8) // 4 + 1
    side = (side - 4) // 2 + 1
    return side - 3 + 1


#: Channels of the second and third convolutions, and the hidden layers of the head, per
#: architecture name.
ARCHITECTURES: dict[str, tuple[int, tuple[int, ...]]] = {
    "paper": (16, (32,)),
    "wide": (64, (256, 256)),
    "wide-head": (16, (256, 256)),
}


#: Features of the range branch.
RANGE_FEATURES = 64


def mirror_ranges(ranges: torch.Tensor) -> torch.Tensor:
    """Reflects ranges [B, K] about the robot's heading axis: sector ``s`` takes sector
    ``(K - s) % K``'s value (sector 0, straight ahead, stays; the others reverse)."""
    return torch.cat([ranges[:, :1], ranges[:, 1:].flip(1)], dim=1)


def mirror_inputs(occupancy: torch.Tensor, aux: torch.Tensor, ranges: torch.Tensor | None = None):
    """Reflects inputs about the robot's heading axis (y -> -y): the image's rows reverse and the
    heading error delta_phi changes sign; d* stays; the ranges' sectors map ``s -> (K - s) % K``.
    Returns ``(occupancy, aux)``, or ``(occupancy, aux, ranges)`` when ranges are given. The
    matching output reflection swaps the left and right wheels."""
    mirrored = (occupancy.flip(2), torch.stack([-aux[:, 0], aux[:, 1]], dim=1))
    if ranges is None:
        return mirrored
    return (*mirrored, mirror_ranges(ranges))


def multiply_adds(model: "PolicyNet") -> int:
    """Multiply-adds of one evaluation of ``model`` on one sample (convolutions and linear layers;
    a mirror-averaged model evaluates twice per decision)."""
    total = 0
    hooks = []

    def count(module, _inputs, output):
        nonlocal total
        if isinstance(module, nn.Conv2d):
            k = module.in_channels // module.groups * module.kernel_size[0] * module.kernel_size[1]
            total += output[0].numel() * k
        elif isinstance(module, nn.Linear):
            total += module.in_features * module.out_features

    for module in model.modules():
        if isinstance(module, (nn.Conv2d, nn.Linear)):
            hooks.append(module.register_forward_hook(count))
    try:
        with torch.no_grad():
            ranges = torch.zeros(1, model.range_sectors) if model.range_sectors else None
            model.raw(torch.zeros(1, 1, model.size_px, model.size_px), torch.zeros(1, 2), ranges)
    finally:
        for hook in hooks:
            hook.remove()
    return total


class PolicyNet(nn.Module):
    """The CNN mapping an occupancy image and (delta_phi, d*), and the scan's ranges where
    ``range_sectors`` is set, to (left, right) wheel speeds (or a formation velocity)."""

    def __init__(
        self,
        size_px: int = PAPER_SIZE_PX,
        architecture: str = "paper",
        mirror_averaged: bool = False,
        output: str = "wheels",
        range_sectors: int | None = None,
    ):
        super().__init__()
        if output not in ("wheels", "formation_velocity"):
            raise ValueError(f"unknown output {output!r}: choose wheels or formation_velocity")
        self.output = output
        if architecture not in ARCHITECTURES:
            names = ", ".join(ARCHITECTURES)
            raise ValueError(f"unknown network architecture {architecture!r}: choose one of {names}")
        side = conv_output_side(size_px)
        if side < 1:
            raise ValueError(f"a {size_px} x {size_px} image is too small for the network (needs >= 22 px)")
        self.size_px = size_px
        self.architecture = architecture
        self.mirror_averaged = mirror_averaged
        channels, hidden = ARCHITECTURES[architecture]
        self.features = nn.Sequential(
            nn.Conv2d(1, 32, kernel_size=8, stride=4, padding=1),
            nn.ReLU(),
            nn.Conv2d(32, channels, kernel_size=4, stride=2),
            nn.ReLU(),
            nn.Conv2d(channels, channels, kernel_size=3, stride=1),
            nn.ReLU(),
            nn.Flatten(),
        )
        self.flatten_width = channels * side * side
        if range_sectors is not None and range_sectors < 1:
            raise ValueError(f"a range input needs at least one sector, got {range_sectors}")
        self.range_sectors = range_sectors
        self.range_features = (
            nn.Sequential(nn.Linear(range_sectors, RANGE_FEATURES), nn.ReLU()) if range_sectors else None
        )
        layers: list[nn.Module] = []
        width = self.flatten_width + 2 + (RANGE_FEATURES if range_sectors else 0)
        for units in hidden:
            layers += [nn.Linear(width, units), nn.ReLU()]
            width = units
        layers.append(nn.Linear(width, 2))
        self.head = nn.Sequential(*layers)

    def raw(self, occupancy: torch.Tensor, aux: torch.Tensor, ranges: torch.Tensor | None = None) -> torch.Tensor:
        """The network itself, without the mirror average."""
        parts = [self.features(occupancy), aux]
        if self.range_features is not None:
            if ranges is None:
                raise ValueError(f"this network takes ranges of {self.range_sectors} sectors beside the image; give them")
            parts.append(self.range_features(ranges))
        elif ranges is not None:
            raise ValueError("this network takes no ranges: train it on a dataset with ranges to use them")
        return self.head(torch.cat(parts, dim=1))

    def forward(self, occupancy: torch.Tensor, aux: torch.Tensor, ranges: torch.Tensor | None = None) -> torch.Tensor:
        wheels = self.raw(occupancy, aux, ranges)
        if not self.mirror_averaged:
            return wheels
        reflected = self.raw(*mirror_inputs(occupancy, aux, ranges))
        if self.output == "formation_velocity":
            reflected = reflected * torch.tensor([1.0, -1.0], dtype=reflected.dtype, device=reflected.device)
        else:
            reflected = reflected.flip(1)
        return 0.5 * (wheels + reflected)
