"""Contact of the closed wound's flanks (stages 4-6).

`ContactModel` is what the wound model needs from a formulation; `FlankContact` is the
two-pass penalty on the flanks' smooth implicit surfaces (`woundsweep.contact.smooth`), whose
tangent's sparsity `CouplingPlan` plans (`woundsweep.contact.pattern`);
`ContactMultipliers` carries its multipliers through Newton (the semi-smooth contact step,
`woundsweep.contact.multipliers`); `ZoneTie` holds the closure zone's flanks together (the sutures)
(`woundsweep.contact.tie`); `Cables` are the sutures' threads (`woundsweep.contact.cable`);
`audit_interpenetration` counts flank nodes inside the other side's
deformed cells, independently of the contact (`woundsweep.contact.audit`).
"""

from .audit import AuditResult, audit_interpenetration, audit_model
from .cable import Anchor, Cables
from .geometry import orient_outward, owning_cells, split_wound_flanks
from .multipliers import ContactMultipliers
from .pattern import CouplingPlan
from .protocol import GPA_TO_KPA, ContactModel, ContactSummary, Linearization
from .smooth import FlankContact
from .tie import ZoneTie

__all__ = [
    "GPA_TO_KPA",
    "Anchor",
    "AuditResult",
    "Cables",
    "ContactModel",
    "ContactMultipliers",
    "ContactSummary",
    "CouplingPlan",
    "FlankContact",
    "Linearization",
    "ZoneTie",
    "audit_interpenetration",
    "audit_model",
    "orient_outward",
    "owning_cells",
    "split_wound_flanks",
]
