"""The evidence layer of ``mmac``: whose is a deviation, and is compensating it doing harm?

:class:`EvidenceLayer` composes the pieces — the increment product and the creep, the pressure
test, the do-no-harm monitor, the jump attribution, the still sensor — and runs them in one
fixed order per fresh sample (:mod:`.layer`); :class:`Attribution` is what it concludes.
"""

from .layer import Attribution, EvidenceLayer, Hypothesis
from .monitor import FallbackReason

__all__ = ["Attribution", "EvidenceLayer", "FallbackReason", "Hypothesis"]
