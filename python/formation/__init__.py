"""formation in Python: the Rust simulator, sensing, expert, neighbour rule and metrics.

Nothing here simulates: the native module ``formation._native`` (PyO3, the ``formation-python``
crate) runs the world, the scenarios, the occupancy rendering, the expert and the metrics of the
Rust crates, so run ``R`` of seed ``S`` here is run ``R`` of ``formation eval --seed S``.

* :class:`Scenario`: a scenario file, validated with the CLI's messages, with overrides.
* :class:`Batch`: ``B`` runs stepped together in parallel in Rust, numpy in and out.
* :func:`detect_neighbours`: the neighbours one robot detects in its own scan, as the agent does.
* :func:`formation.env.parallel_env`: the PettingZoo ``ParallelEnv`` of one run.
* :class:`formation.model.ModelSpec`: what a policy model declares (its ``formation.*`` metadata).
"""

from formation._native import Batch, EpisodeOver, Scenario, ScenarioError, detect_neighbours
from formation.model import ModelSpec

__all__ = ["Batch", "EpisodeOver", "ModelSpec", "Scenario", "ScenarioError", "detect_neighbours"]
