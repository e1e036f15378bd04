"""The one type every locator returns: :class:`Finding`, a located mismatch of one kind, with a place and a number."""

from __future__ import annotations

from dataclasses import dataclass, field

from phs._json import jsonable as _json
from phs.errors import InputDataError

KINDS = ("time_window", "feature", "spectrum", "harmonic", "input_lag", "amplitude_scaling", "rate_scaling",
         "whiteness", "drift")
"""The kinds of :class:`Finding`, in the order :func:`phs.workflows.diagnose.locate.locate` reports them."""


@dataclass(frozen=True)
class Finding:
    """One located mismatch: a kind, the channel, a place in words and a number.

    Parameters
    ----------
    kind : str
        One of :data:`KINDS`.
    channel : str
        Output channel whose residual this is about.
    where : str
        Human-readable place ("t = 2.00–2.35 s (after the step of U at 2.00 s)", "residual ~ sign(v)").
    strength : float
        The number; its meaning per kind is tabulated in :mod:`phs.workflows.diagnose.locate`.
    meaning : str
        One sentence saying what ``strength`` means here.
    details : dict
        Further numbers (JSON-serialisable); ``details["significant"]`` is always present.

    Examples
    --------
    >>> f = Finding("whiteness", "y", "lags 1–20", 31.4, "Ljung-Box Q", {"p_value": 0.05, "significant": False})
    >>> f.to_dict()["strength"], f.significant
    (31.4, False)
    """

    kind: str
    channel: str
    where: str
    strength: float
    meaning: str
    details: dict = field(default_factory=dict, hash=False)

    def __post_init__(self):
        if self.kind not in KINDS:
            raise InputDataError(f"finding kind {self.kind!r} is not one of {', '.join(KINDS)}")

    @property
    def significant(self) -> bool:
        """Whether the finding beats its noise threshold (``details["significant"]``)."""
        return bool(self.details.get("significant", True))

    def to_dict(self) -> dict:
        """Plain JSON types (non-finite numbers become ``None``).

        Examples
        --------
        >>> import numpy as np
        >>> Finding("drift", "y", "below 0.1 Hz", float("nan"), "share", {"f": np.float64(0.1)}).to_dict()["strength"] is None
        True
        """
        return {"kind": self.kind, "channel": self.channel, "where": self.where, "strength": _json(self.strength),
                "meaning": self.meaning, "details": _json(self.details)}
