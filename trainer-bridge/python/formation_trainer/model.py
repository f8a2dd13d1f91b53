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

``mirror_averaged=True`` (what ``--mirror`` trains) makes either network exactly symmetric under
the task's reflection about the robot's heading axis: the output is the mean of the network on the
input and, reflected back, on the reflected input (see :func:`mirror_inputs`). A policy that is
only trained on reflected samples is symmetric only as far as it has learned to be; the average
removes the asymmetric part of its error, at twice the arithmetic per image. The reflection of
the output depends on what it is (``output``): wheel speeds swap left and right, a formation
velocity in the robot's frame negates its sideways part.
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


def mirror_inputs(occupancy: torch.Tensor, aux: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Reflects inputs about the robot's heading axis (y -> -y): the image's rows reverse and the
    heading error delta_phi changes sign; d* stays. The matching output reflection swaps the
    left and right wheels."""
    return occupancy.flip(2), torch.stack([-aux[:, 0], aux[:, 1]], dim=1)


class PolicyNet(nn.Module):
    """The CNN mapping an occupancy image and (delta_phi, d*) to (left, right) wheel speeds."""

    def __init__(
        self, size_px: int = PAPER_SIZE_PX, architecture: str = "paper", mirror_averaged: bool = False, output: str = "wheels"
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
        layers: list[nn.Module] = []
        width = self.flatten_width + 2
        for units in hidden:
            layers += [nn.Linear(width, units), nn.ReLU()]
            width = units
        layers.append(nn.Linear(width, 2))
        self.head = nn.Sequential(*layers)

    def raw(self, occupancy: torch.Tensor, aux: torch.Tensor) -> torch.Tensor:
        """The network itself, without the mirror average."""
        return self.head(torch.cat([self.features(occupancy), aux], dim=1))

    def forward(self, occupancy: torch.Tensor, aux: torch.Tensor) -> torch.Tensor:
        wheels = self.raw(occupancy, aux)
        if not self.mirror_averaged:
            return wheels
        reflected = self.raw(*mirror_inputs(occupancy, aux))
        if self.output == "formation_velocity":
            reflected = reflected * torch.tensor([1.0, -1.0], dtype=reflected.dtype, device=reflected.device)
        else:
            reflected = reflected.flip(1)
        return 0.5 * (wheels + reflected)
