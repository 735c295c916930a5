"""Contact of the closed wound's flanks (stages 4-6).

`ContactModel` is what the wound model needs from a formulation; `FlankContact` is the
two-pass penalty on the flanks' smooth implicit surfaces (`woundsweep.contact.smooth`).
"""

from .geometry import orient_outward, owning_cells, split_wound_flanks
from .protocol import GPA_TO_KPA, ContactModel, ContactSummary
from .smooth import FlankContact

__all__ = [
    "GPA_TO_KPA",
    "ContactModel",
    "ContactSummary",
    "FlankContact",
    "orient_outward",
    "owning_cells",
    "split_wound_flanks",
]
