"""The paper's policy network, with its exact layer sizes.

Input ``occupancy`` [B, 1, 50, 50] and ``aux`` [B, 2] = (delta_phi, d*); output ``wheels`` [B, 2] =
(left, right) m/s at v_train::

    Conv2d(1, 32, 8, stride 4, padding 1) ReLU   -> 32 x 12 x 12
    Conv2d(32, 16, 4, stride 2) ReLU             -> 16 x 5 x 5
    Conv2d(16, 16, 3, stride 1) ReLU             -> 16 x 3 x 3 = 144
    flatten 144, concat aux                      -> 146
    Linear(146, 32) ReLU -> Linear(32, 2)

Without ``padding=1`` on the first convolution a 50 x 50 image gives 11 x 11 and a flatten of 64,
not the paper's 144.
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


class PolicyNet(nn.Module):
    """The CNN mapping an occupancy image and (delta_phi, d*) to (left, right) wheel speeds."""

    def __init__(self, size_px: int = PAPER_SIZE_PX):
        super().__init__()
        side = conv_output_side(size_px)
        if side < 1:
            raise ValueError(f"a {size_px} x {size_px} image is too small for the network (needs >= 22 px)")
        self.size_px = size_px
        self.features = nn.Sequential(
            nn.Conv2d(1, 32, kernel_size=8, stride=4, padding=1),
            nn.ReLU(),
            nn.Conv2d(32, 16, kernel_size=4, stride=2),
            nn.ReLU(),
            nn.Conv2d(16, 16, kernel_size=3, stride=1),
            nn.ReLU(),
            nn.Flatten(),
        )
        self.flatten_width = 16 * side * side
        self.head = nn.Sequential(
            nn.Linear(self.flatten_width + 2, 32),
            nn.ReLU(),
            nn.Linear(32, 2),
        )

    def forward(self, occupancy: torch.Tensor, aux: torch.Tensor) -> torch.Tensor:
        return self.head(torch.cat([self.features(occupancy), aux], dim=1))
