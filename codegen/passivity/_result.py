"""One test of a passivity certificate (:class:`PassivityTest`) and the JSON and text forms of its numbers."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from phs._json import jsonable as _jsonable

_VERDICTS = ("pass", "fail", "undecided")


@dataclass(frozen=True)
class PassivityTest:
    """One test of a passivity certificate: verdict, method, numbers, worst point and the element responsible.

    Attributes
    ----------
    name : str
        ``interconnection``, ``dissipation``, ``feedthrough``, ``storage``, ``trajectory`` or ``local``.
    verdict : str
        ``pass``, ``fail`` or ``undecided``.
    method : str
        How it was decided (symbolic, sampled, optimised, simulated, frequency sweep ...).
    summary : str
        One sentence with the numbers.
    numbers : dict
        The numbers by name (JSON-ready).
    worst : dict
        The state/parameter point where the test is tightest (or fails).
    element : str
        The element responsible for a failure (or the tightest one), else ``""``.
    series : dict
        Arrays for the report's plots (not part of :meth:`to_dict`).

    Examples
    --------
    >>> t = PassivityTest("storage", "pass", "sampled", "H >= 0 J", {"H_min": 0.0})
    >>> t.to_dict()["verdict"], t.passed
    ('pass', True)
    """

    name: str
    verdict: str
    method: str
    summary: str
    numbers: dict = field(default_factory=dict)
    worst: dict = field(default_factory=dict)
    element: str = ""
    series: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self):
        if self.verdict not in _VERDICTS:
            raise ValueError(f"verdict must be one of {_VERDICTS}, got {self.verdict!r}")

    @property
    def passed(self) -> bool:
        return self.verdict == "pass"

    def to_dict(self) -> dict:
        return _jsonable({"name": self.name, "verdict": self.verdict, "method": self.method, "summary": self.summary,
                          "numbers": self.numbers, "worst": self.worst, "element": self.element})

    def line(self) -> str:
        out = f"  [{self.verdict:^9}] {self.name}: {self.summary}"
        if self.element and self.verdict != "pass":
            out += f"\n              element responsible: {self.element}"
        if self.worst:
            out += "\n              at " + _fmt_point(self.worst)
        return out + f"\n              ({self.method})"


def _fmt_point(point: dict) -> str:
    return ", ".join(f"{k}={v:.6g}" if isinstance(v, (float, int, np.floating)) else f"{k}={v}" for k, v in point.items())
