"""Contact of the closed wound's flanks (stages 4-6).

`ContactModel` is what the wound model needs from a formulation; `FlankContact` is the
two-pass penalty formulation on the faceted flanks (`woundsweep.contact.penalty`).
"""

from .geometry import orient_outward, owning_cells, split_wound_flanks
from .penalty import FlankContact
from .protocol import GPA_TO_KPA, ContactModel, ContactPairs, ContactSummary

__all__ = [
    "GPA_TO_KPA",
    "ContactModel",
    "ContactPairs",
    "ContactSummary",
    "FlankContact",
    "orient_outward",
    "owning_cells",
    "split_wound_flanks",
]
