"""Format and law versions: each stored artefact records the version it was made with, and a
reader treats another version as stale (recomputed), never as valid."""

from __future__ import annotations

__all__ = [
    "FAILURE_FORMAT",
    "GP_SURROGATE_FORMAT",
    "MESH_CACHE_FORMAT",
    "MESH_LAW_VERSION",
    "MODEL_FORMAT",
    "RESULT_FORMAT_VERSION",
    "STAGES_VERSION",
    "STATISTICS_VERSION",
    "SURROGATE_FORMAT",
]

# The result file's columns (one typed column per stage diagnostic, the element degree),
# footer and fingerprint layout (`woundsweep.store.identity`).
RESULT_FORMAT_VERSION = 6
# What the six stages solve (docs/model.md, "The six stages": their loads, the closing loads of
# stages 3-6, contact and its support held per solve, tie). Part of a result's fingerprint.
STAGES_VERSION = 5
# The geometry and the mesh size law (`woundsweep.mesh.sizing`, the closure zone imprinted on
# the wound surface, edges scaled with the element degree). Part of the mesh id that names
# the cached meshes; cached meshes and results of another version are rebuilt.
MESH_LAW_VERSION = 5
# How the stored stress statistics are computed (docs/model.md, "Stress statistics": P2
# cells sampled at a degree-4 rule's points). Part of a result's fingerprint.
STATISTICS_VERSION = 3
# The per-run mesh cache's file layout (`woundsweep.mesh.cache`: files named by the mesh id,
# the element degree recorded).
MESH_CACHE_FORMAT = 2
# The trained models' metadata (`woundsweep.analysis`).
MODEL_FORMAT = "woundsweep-quantile-model/1"
SURROGATE_FORMAT = "woundsweep-stress-surrogate/2"
# The Gaussian-process surrogate's own file (`woundsweep.analysis.interpolant`): per group its
# kernel hyperparameters, training inputs and targets (no pickle; loading refits the posterior).
GP_SURROGATE_FORMAT = "woundsweep-gp-surrogate/2"
FAILURE_FORMAT = "woundsweep-failure-model/1"
