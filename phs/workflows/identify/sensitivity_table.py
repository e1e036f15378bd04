"""The sensitivity table of a fit: its fit % when each fitted parameter alone moves by -10, -5, 0, +5
and +10 % (the curling HASEL paper's Table 5), and the table as markdown."""

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


def sensitivity_markdown(tables: dict, result=None) -> str:
    """The ±5/±10 % sensitivity tables (one per channel) as markdown.

    Parameters
    ----------
    tables : dict
        ``{channel: {parameter: {step: fit %, ..., "std": sd}}}`` as returned per channel by
        ``IdentificationResult.sensitivity_table``.
    result : IdentificationResult, optional
        Adds the fitted values to the table.

    Examples
    --------
    >>> row = {-0.1: 80.0, -0.05: 90.0, 0.0: 95.0, 0.05: 90.0, 0.1: 80.0, "std": 6.52}
    >>> print(sensitivity_markdown({"tip": {"K_b": row}}))  # doctest: +NORMALIZE_WHITESPACE
    ## Sensitivity of the fit of `tip` (NRMSE fit %)
    <BLANKLINE>
    | parameter | -10 % | -5 % | 0 % | +5 % | +10 % | SD |
    | --- | ---: | ---: | ---: | ---: | ---: | ---: |
    | `K_b` | 80.00 | 90.00 | 95.00 | 90.00 | 80.00 | 6.5200 |
    <BLANKLINE>
    """
    out = []
    for ch, table in tables.items():
        steps = sorted(k for row in table.values() for k in row if k != "std")
        steps = list(dict.fromkeys(steps))
        cols = [f"{s * 100:+.0f} %".replace("+0 %", "0 %") for s in steps]
        fitted = result is not None
        out.append(f"## Sensitivity of the fit of `{ch}` (NRMSE fit %)\n")
        out.append("| parameter" + (" | fitted value" if fitted else "") + " | " + " | ".join(cols) + " | SD |")
        out.append("| ---" + (" | ---:" if fitted else "") + " | ---:" * (len(cols) + 1) + " |")
        for name, row in sorted(table.items(), key=lambda kv: -np.nan_to_num(kv[1]["std"], nan=-1.0)):
            value = f" | {result.values[name]:.6g}" if fitted else ""
            out.append(f"| `{name}`{value} | " + " | ".join(f"{row[s]:.2f}" for s in steps) + f" | {row['std']:.4f} |")
        out.append("")
    if result is not None:
        out.append("Each row moves one fitted parameter alone by the given relative step and re-simulates; "
                   "SD is the sample standard deviation of the five fits (the curling HASEL paper's Table 5). "
                   "Rows are sorted from the most to the least sensitive parameter.\n")
    return "\n".join(out)
