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

**The pair network** (:class:`PairNet`, ``architecture="pair"``, issue 34) takes the neighbours
the robot detects in its own scan, ``neighbours`` [B, K, 4] (``formation.neighbours =
"slots=K,threshold=T,nearest=M"``: per slot ``(x / d*, y / d*, held, present)``; ``[B, K, 6]``
with ``,hidden=1``, below), and answers the
formation velocity in the robot's frame as a sum of one learned term per neighbour::

    per slot: (a, b) = phi([x, y, r - 1, held])   r = |(x, y)|, phi: Linear(4, 64) SiLU
                                                                     Linear(64, 64) SiLU
                                                                     Linear(64, 4)
              (a, b) = phi's first pair if held, else its second
              term = (a * e + b * e_left) * present   e = (x, y) / r, e_left = (-y, x) / r
    f = d* * sum over slots                          -> [B, 2] m/s

That is the structure of the teacher's law (``expert/src/controller.rs`` ``add_pair_term``,
``expert/src/own_scan.rs``): with ``u = x / d*`` per neighbour, ``f / d* = k * sum over held
neighbours of 2 (|u|^4 - 1) / |u|^4 * u`` (``k`` the team gain ``k_formation_graph``, 1.0), a
function of the slots alone, and ``held`` (the
robot's own Gabriel rule on its detections, computed, not learned) says which terms count. A
network fitted to the summed label meets a slope ceiling of about 0.3 on small corrections at 16
robots; one that sums per-neighbour terms reaches 0.8-1.0 (docs/src/training.md). It takes the
image and aux as every model does; it uses aux's d* and leaves the image and delta_phi unused
(the exporter keeps an unused input as a graph input). Each term is written along the line to
its neighbour and across it, so that the teacher's term, ``2 (r^4 - 1) / r^3`` along that line
and nothing across, is a function of ``r`` alone; ``r - 1`` (the edge's relative error) is
centred where the law changes sign; and a held neighbour and another get separate outputs of
the same layers, so that learning which terms count costs nothing. On synthetic neighbour sets
(the tests'), 300 Adam steps of 256 samples at lr 1e-2 fit the law to a slope of 1.05 in every
bin of the correction's size, and each choice matters: without the centring the same steps reach
0.57; with one output for both kinds of neighbour, 400 steps at lr 3e-3 reach 0.05 (0.89 with
two); a term written as a plain (x, y) vector, with neither, stayed at zero response for 1,500
steps. Its multiply-adds are ``K * 4,608`` (its layers, once a slot; the few products and sums
after them are not counted): 73,728 for K = 16, a seventh of the paper network's 525,184.
The neighbours reflect with ``y -> -y``; the flags and the slots' order stay.

``hidden_pairs=True`` takes the declaration's ``hidden=1``: each slot carries two more numbers,
``(hx, hy)``, the step aside that the pairs of detections the robot hides from each other ask of it
(``formation_perception::hidden_pairs``, half a pair's on each of its two slots, in d*). A sum of
one term per slot cannot compute that step: it depends on two detections at once, and the robot
between them is the only one that sees them both. The network adds ``g * (hx, hy)`` to each slot's
term, with one learned gain ``g``, started at the teacher's team gain, 1.0. ``hy`` reflects with
``y``.

``potential=True`` (``architecture="pair-potential"``) multiplies a held neighbour's (a, b) by the
law's pair profile ``(r^4 - 1) / r^3`` (:func:`pair_profile`): the layers then learn its weight,
which for the teacher is a constant, and the profile its shape in distance. So a held neighbour at
d* adds nothing whatever the layers' error (the smallest corrections keep their slope however
large the fit's error on large ones), and one closer than any sample repels as the law does
instead of as the layers extrapolate. A neighbour the robot does not hold keeps the plain term
(the teacher gives it no weight; a profile growing with r would turn the layers' small residual
on each far neighbour into a pull towards the team, which slowed convergence five-fold in a
first model). Same multiply-adds.
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

#: The scalars of the ``aux`` input, in order (``formation.aux``; ``formation_proto::AuxLayout``).
AUX_NAMES = ("delta_phi", "d_star")
#: Where d* sits in ``aux``.
D_STAR_INDEX = AUX_NAMES.index("d_star")
#: Numbers per neighbour slot: ``x / d*``, ``y / d*``, ``held``, ``present``.
NEIGHBOUR_FEATURES = 4
#: Numbers per neighbour slot with ``hidden=1``: then also ``hx``, ``hy``.
HIDDEN_NEIGHBOUR_FEATURES = 6
#: The pair network's name (``formation.train.architecture``).
PAIR_ARCHITECTURE = "pair"
#: The pair network whose terms are scaled by the law's pair profile (``potential=True``).
PAIR_POTENTIAL_ARCHITECTURE = "pair-potential"
#: Both pair networks' names.
PAIR_ARCHITECTURES = (PAIR_ARCHITECTURE, PAIR_POTENTIAL_ARCHITECTURE)
#: Hidden layers of the pair network's per-neighbour term.
PAIR_HIDDEN = (64, 64)
#: The distance [d*] below which a neighbour's direction is not computed (an empty slot's is 0).
MIN_NEIGHBOUR_DISTANCE = 1e-6
#: Every network this trainer builds: the CNNs, then the pair network.
ARCHITECTURE_NAMES = (*ARCHITECTURES, *PAIR_ARCHITECTURES)
#: The distance [d*] below which the pair profile is held at its value there (a detection is
#: never this close: two bodies touch at about 0.4 d* for the smallest d*).
MIN_PROFILE_DISTANCE = 0.1


def pair_profile(r: torch.Tensor) -> torch.Tensor:
    """The shape every pair term of the expert's law has along the line to its neighbour,
    ``(r^4 - 1) / r^3`` (``r`` in d*; ``expert/src/controller.rs`` ``add_pair_term``): zero at
    d*, growing as ``r`` beyond it and as ``-1 / r^3`` closer."""
    r = torch.clamp(r, min=MIN_PROFILE_DISTANCE)
    return (r**4 - 1.0) / r**3


def mirror_ranges(ranges: torch.Tensor) -> torch.Tensor:
    """Reflects ranges [B, K] about the robot's heading axis: sector ``s`` takes sector
    ``(K - s) % K``'s value (sector 0, straight ahead, stays; the others reverse)."""
    return torch.cat([ranges[:, :1], ranges[:, 1:].flip(1)], dim=1)


def mirror_neighbours(neighbours: torch.Tensor) -> torch.Tensor:
    """Reflects neighbours [B, K, 4 or 6] about the robot's heading axis: every ``y / d*`` (and
    ``hy``) changes sign; ``x / d*``, the flags and the slots' order stay (the reflection keeps
    every distance)."""
    signs = [1.0, -1.0, 1.0, 1.0, 1.0, -1.0][: neighbours.shape[-1]]
    sign = torch.tensor(signs, dtype=neighbours.dtype, device=neighbours.device)
    return neighbours * sign


def mirror_inputs(
    occupancy: torch.Tensor,
    aux: torch.Tensor,
    ranges: torch.Tensor | None = None,
    neighbours: torch.Tensor | None = None,
):
    """Reflects inputs about the robot's heading axis (y -> -y): the image's rows reverse and the
    heading error delta_phi changes sign; d* stays; the ranges' sectors map ``s -> (K - s) % K``;
    the neighbours' ``y`` changes sign. Returns ``(occupancy, aux)``, followed by the ranges and
    then the neighbours where they are given. The matching output reflection swaps the left and
    right wheels (negates a formation velocity's sideways part)."""
    mirrored = (occupancy.flip(2), torch.stack([-aux[:, 0], aux[:, 1]], dim=1))
    if ranges is not None:
        mirrored = (*mirrored, mirror_ranges(ranges))
    if neighbours is not None:
        mirrored = (*mirrored, mirror_neighbours(neighbours))
    return mirrored


def mirror_output(output: torch.Tensor, kind: str) -> torch.Tensor:
    """Reflects a model's output about the robot's heading axis: a formation velocity negates its
    sideways part, wheel speeds swap left and right."""
    if kind == "formation_velocity":
        return output * torch.tensor([1.0, -1.0], dtype=output.dtype, device=output.device)
    return output.flip(1)


def multiply_adds(model: "PolicyNet | PairNet") -> int:
    """Multiply-adds of one evaluation of ``model`` on one sample (convolutions and linear layers,
    a linear layer once for each row it maps, so the pair network's once per slot; the pair
    network's few element-wise products and sums are not counted; a mirror-averaged model
    evaluates twice per decision)."""
    total = 0
    hooks = []

    def count(module, _inputs, output):
        nonlocal total
        if isinstance(module, nn.Conv2d):
            k = module.in_channels // module.groups * module.kernel_size[0] * module.kernel_size[1]
            total += output[0].numel() * k
        elif isinstance(module, nn.Linear):
            total += output.numel() * module.in_features

    for module in model.modules():
        if isinstance(module, (nn.Conv2d, nn.Linear)):
            hooks.append(module.register_forward_hook(count))
    try:
        with torch.no_grad():
            occupancy, aux = torch.zeros(1, 1, model.size_px, model.size_px), torch.zeros(1, 2)
            if isinstance(model, PairNet):
                model.raw(occupancy, aux, torch.zeros(1, model.neighbour_slots, model.neighbour_features))
            else:
                ranges = torch.zeros(1, model.range_sectors) if model.range_sectors else None
                model.raw(occupancy, aux, ranges)
    finally:
        for hook in hooks:
            hook.remove()
    return total


class PolicyNet(nn.Module):
    """The CNN mapping an occupancy image and (delta_phi, d*), and the scan's ranges where
    ``range_sectors`` is set, to (left, right) wheel speeds (or a formation velocity)."""

    #: A CNN takes no neighbours.
    neighbour_slots = None

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
        reflected = mirror_output(self.raw(*mirror_inputs(occupancy, aux, ranges)), self.output)
        return 0.5 * (wheels + reflected)


class PairNet(nn.Module):
    """The network that sums one learned term per detected neighbour (see the module): inputs
    ``occupancy`` [B, 1, S, S] (unused), ``aux`` [B, 2] (its d*) and ``neighbours`` [B, K, 4]
    ([B, K, 6] with ``hidden_pairs``);
    output the formation velocity [B, 2] in the robot's frame, in m/s."""

    #: The pair network takes no ranges.
    range_sectors = None

    def __init__(
        self,
        slots: int,
        size_px: int = PAPER_SIZE_PX,
        mirror_averaged: bool = False,
        output: str = "formation_velocity",
        hidden: tuple[int, ...] = PAIR_HIDDEN,
        potential: bool = False,
        hidden_pairs: bool = False,
    ):
        super().__init__()
        if output != "formation_velocity":
            raise ValueError(
                f"the pair network answers a formation velocity, not {output!r}: train it with --output formation_velocity"
            )
        if not isinstance(slots, int) or slots < 1:
            raise ValueError(f"the pair network needs at least one neighbour slot, got {slots!r}")
        if size_px < 1:
            raise ValueError(f"the image side must be at least 1 px, got {size_px}")
        self.output = output
        self.size_px = size_px
        self.mirror_averaged = mirror_averaged
        self.neighbour_slots = slots
        self.hidden = tuple(int(h) for h in hidden)
        self.potential = bool(potential)
        self.architecture = PAIR_POTENTIAL_ARCHITECTURE if self.potential else PAIR_ARCHITECTURE
        layers: list[nn.Module] = []
        width = NEIGHBOUR_FEATURES
        for units in self.hidden:
            layers += [nn.Linear(width, units), nn.SiLU()]
            width = units
        layers.append(nn.Linear(width, 4))
        # The term of one neighbour from (x / d*, y / d*, |(x, y)| / d* - 1, held): its parts
        # along and across the line to the neighbour, once for a held neighbour, once for another.
        self.pair_term = nn.Sequential(*layers)
        self.hidden_pairs = bool(hidden_pairs)
        if self.hidden_pairs:
            # The gain on each slot's share of its hidden pairs' step aside, learned from the
            # teacher's team gain: hidden pairs are rare in demonstrations, so a gain started at
            # zero stays short of it (0.60 after the recipe's 6 epochs).
            self.hidden_pair_gain = nn.Parameter(torch.ones(1))

    @property
    def neighbour_features(self) -> int:
        """Numbers per slot: 6 with ``hidden_pairs``, else 4."""
        return HIDDEN_NEIGHBOUR_FEATURES if self.hidden_pairs else NEIGHBOUR_FEATURES

    def terms(self, neighbours: torch.Tensor) -> torch.Tensor:
        """Each slot's term [B, K, 2] in units of d* (zero for an empty slot)."""
        features = self.neighbour_features
        if neighbours.dim() != 3 or tuple(neighbours.shape[1:]) != (self.neighbour_slots, features):
            raise ValueError(
                f"this network takes neighbours [B, {self.neighbour_slots}, {features}], "
                f"got {list(neighbours.shape)}"
            )
        x, y = neighbours[..., 0:1], neighbours[..., 1:2]
        held, present = neighbours[..., 2:3], neighbours[..., 3:4]
        r = torch.sqrt(x * x + y * y)
        # One row a slot: on rows the exporter writes each layer as a Gemm that keeps the
        # parameter's name (a warm start from the .onnx reads them back).
        rows = torch.cat([x, y, r - 1.0, held], dim=-1).reshape(-1, NEIGHBOUR_FEATURES)
        both = self.pair_term(rows).reshape(-1, self.neighbour_slots, 4)
        # The term of a held neighbour and that of one the robot does not hold, chosen by `held`.
        held_term, other_term = both[..., 0:2], both[..., 2:4]
        if self.potential:
            # For a held neighbour the layers give the term's weight and the law's profile its
            # shape in r, so a neighbour at d* adds nothing whatever the layers' error, and a
            # close one repels as the law does (beyond the samples, where the layers alone would
            # extrapolate). A neighbour the robot does not hold keeps the plain term: the law
            # gives it no weight, and the profile, which grows with r, would amplify the layers'
            # residual on every far neighbour into one pull towards the team.
            held_term = held_term * pair_profile(r)
        along_across = held * held_term + (1.0 - held) * other_term
        # The unit vector to the neighbour and the one a quarter turn to its left (both zero in an
        # empty slot, where r is zero).
        safe = torch.clamp(r, min=MIN_NEIGHBOUR_DISTANCE)
        ux, uy = x / safe, y / safe
        along, across = along_across[..., 0:1], along_across[..., 1:2]
        term = torch.cat([along * ux - across * uy, along * uy + across * ux], dim=-1)
        if self.hidden_pairs:
            term = term + self.hidden_pair_gain * neighbours[..., 4:6]
        return term * present

    def raw(self, occupancy: torch.Tensor, aux: torch.Tensor, neighbours: torch.Tensor | None = None) -> torch.Tensor:
        """The network itself, without the mirror average."""
        if neighbours is None:
            raise ValueError(f"this network takes the detected neighbours ({self.neighbour_slots} slots); give them")
        return self.terms(neighbours).sum(dim=1) * aux[:, D_STAR_INDEX : D_STAR_INDEX + 1]

    def forward(self, occupancy: torch.Tensor, aux: torch.Tensor, neighbours: torch.Tensor | None = None) -> torch.Tensor:
        velocity = self.raw(occupancy, aux, neighbours)
        if not self.mirror_averaged:
            return velocity
        reflected = self.raw(*mirror_inputs(occupancy, aux, neighbours=neighbours))
        return 0.5 * (velocity + mirror_output(reflected, self.output))
