"""The sensitivity table of a fit: its fit % when each fitted parameter alone moves by -10, -5, 0, +5
and +10 % (the curling HASEL paper's Table 5)."""

from __future__ import annotations

import numpy as np

from codegen.simulator import Simulator
from phs.errors import PHSError
from phs.workflows.identify.scoring import evaluate_fit


def _sensitivity_table(result, recording, steps, channel: str) -> dict:
    """``{parameter: {step: fit %, ..., "std": sd}}`` of ``channel`` for each fitted parameter of
    ``result`` (an :class:`~phs.workflows.identify.IdentificationResult`) moved alone by ``steps``
    (relative) and re-simulated on ``recording``; a failed simulation scores NaN."""
    # parameters are inputs of the generated functions: one simulator serves every variant
    sim = Simulator(result.system, energy=False)
    table = {}
    for k in result.free:
        row = {}
        for s in steps:
            try:
                fits = evaluate_fit(result.system, recording, [channel], x0=result.x0,
                                    params={**result.values, k: result.values[k] * (1 + s)}, simulator=sim)
                row[s] = fits[channel]
            except PHSError:
                row[s] = float("nan")
        row["std"] = float(np.nanstd([row[s] for s in steps], ddof=1))
        table[k] = row
    return table
