"""Distributions and sampling of a study's variables (see :mod:`phs.workflows.sweep`).

Per-variable laws (:class:`Uniform`, :class:`LogUniform`, :class:`Normal`,
:class:`LogNormal`), a joint :class:`MultivariateNormal` (e.g. from an
identification's covariance, :func:`from_fit`), and the unit-cube samples
(Latin hypercube or plain random) that every law transforms through its
quantile function.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from phs.errors import InputDataError


def _ndtri(q):
    from scipy.special import ndtri

    return ndtri(q)


@dataclass(frozen=True)
class Uniform:
    """Uniform distribution on ``[low, high]``.

    Examples
    --------
    >>> Uniform(1.0, 3.0).transform(np.array([[0.0], [0.5], [1.0]]))[:, 0].tolist()
    [1.0, 2.0, 3.0]
    """

    low: float
    high: float
    dim = 1

    def __post_init__(self):
        if not (math.isfinite(self.low) and math.isfinite(self.high) and self.low < self.high):
            raise InputDataError(f"Uniform({self.low}, {self.high}): need finite low < high")

    def transform(self, q: np.ndarray) -> np.ndarray:
        """Values at the quantiles ``q`` (n, 1)."""
        return self.low + (self.high - self.low) * q


@dataclass(frozen=True)
class LogUniform:
    """Log-uniform distribution on ``[low, high]`` (``low > 0``), for parameters spanning decades.

    Examples
    --------
    >>> round(float(LogUniform(1.0, 100.0).transform(np.array([[0.5]]))[0, 0]), 12)
    10.0
    """

    low: float
    high: float
    dim = 1

    def __post_init__(self):
        if not (0 < self.low < self.high < math.inf):
            raise InputDataError(f"LogUniform({self.low}, {self.high}): need 0 < low < high")

    def transform(self, q: np.ndarray) -> np.ndarray:
        """Values at the quantiles ``q`` (n, 1)."""
        return np.exp(np.log(self.low) + (np.log(self.high) - np.log(self.low)) * q)


@dataclass(frozen=True)
class Normal:
    """Normal distribution of mean ``mean`` and standard deviation ``std``.

    Examples
    --------
    >>> float(Normal(1.0, 0.1).transform(np.array([[0.5]]))[0, 0])
    1.0
    """

    mean: float
    std: float
    dim = 1

    def __post_init__(self):
        if not (math.isfinite(self.mean) and 0 < self.std < math.inf):
            raise InputDataError(f"Normal({self.mean}, {self.std}): need a finite mean and std > 0")

    def transform(self, q: np.ndarray) -> np.ndarray:
        """Values at the quantiles ``q`` (n, 1)."""
        return self.mean + self.std * _ndtri(q)


@dataclass(frozen=True)
class LogNormal:
    """Log-normal distribution: ``median * exp(sigma * N(0, 1))`` (positive parameters with relative spread).

    Examples
    --------
    >>> float(LogNormal(2.0, 0.1).transform(np.array([[0.5]]))[0, 0])
    2.0
    """

    median: float
    sigma: float
    dim = 1

    def __post_init__(self):
        if not (0 < self.median < math.inf and 0 < self.sigma < math.inf):
            raise InputDataError(f"LogNormal({self.median}, {self.sigma}): need median > 0 and sigma > 0")

    def transform(self, q: np.ndarray) -> np.ndarray:
        """Values at the quantiles ``q`` (n, 1)."""
        return self.median * np.exp(self.sigma * _ndtri(q))


@dataclass(frozen=True)
class MultivariateNormal:
    """Joint normal distribution of several variables (``log[i]``: variable ``i`` is log-normal).

    Parameters
    ----------
    mean : sequence of float
        Mean, in log coordinates (``log(value)``) for the variables flagged in ``log``.
    cov : array (k, k)
        Covariance, in the same coordinates; symmetric positive semi-definite.
    log : sequence of bool, optional
        Which variables are sampled in log coordinates.

    Examples
    --------
    >>> d = MultivariateNormal([0.0, 1.0], [[1.0, 0.0], [0.0, 4.0]])
    >>> d.transform(np.array([[0.5, 0.5]])).tolist()
    [[0.0, 1.0]]
    """

    mean: tuple
    cov: tuple
    log: tuple = ()

    def __post_init__(self):
        mean = np.asarray(self.mean, dtype=float).reshape(-1)
        cov = np.asarray(self.cov, dtype=float)
        k = len(mean)
        if cov.shape != (k, k) or not np.all(np.isfinite(cov)) or not np.all(np.isfinite(mean)):
            raise InputDataError(f"MultivariateNormal: mean of {k} values needs a finite {k}x{k} covariance, "
                                 f"got shape {cov.shape}")
        if not np.allclose(cov, cov.T, rtol=1e-10, atol=1e-300):
            raise InputDataError("MultivariateNormal: the covariance is not symmetric")
        ev = np.linalg.eigvalsh(cov)
        if ev.min() < -1e-10 * max(ev.max(), 1e-300):
            raise InputDataError(f"MultivariateNormal: the covariance is not positive semi-definite (eigenvalue {ev.min():.3g})")
        log = tuple(bool(v) for v in self.log) or (False,) * k
        if len(log) != k:
            raise InputDataError(f"MultivariateNormal: log has {len(log)} flags for {k} variables")
        object.__setattr__(self, "mean", tuple(mean.tolist()))
        object.__setattr__(self, "cov", tuple(map(tuple, cov.tolist())))
        object.__setattr__(self, "log", log)

    @property
    def dim(self) -> int:
        return len(self.mean)

    def transform(self, q: np.ndarray) -> np.ndarray:
        """Values at the quantiles ``q`` (n, k) of independent standard normals, correlated by the covariance."""
        cov = np.asarray(self.cov)
        w, V = np.linalg.eigh(cov)  # a square root that exists for semi-definite covariances too
        L = V * np.sqrt(np.maximum(w, 0.0))
        z = _ndtri(q) @ L.T + np.asarray(self.mean)
        log = np.asarray(self.log)
        z[:, log] = np.exp(z[:, log])
        return z


def from_fit(fit) -> dict:
    """Joint distribution of the fitted parameters of an identification, for Monte Carlo studies.

    ``fit`` is an :class:`~phs.workflows.identify.IdentificationResult` or the dict of its JSON
    (``phs fit --json``).  Parameters fitted in log scale are log-normal; the covariance is the
    fit's (standard errors and correlation) in the fit's coordinates.  Returns
    ``{(names...): MultivariateNormal}``, to merge into a study's ``distributions``.

    Raises
    ------
    InputDataError
        When the fit carries no finite standard errors (it did not converge to an identifiable point).

    Examples
    --------
    >>> fit = {"free": ["K_b", "b"], "values": {"K_b": 0.04, "b": 0.003}, "std_errors": {"K_b": 0.004, "b": 0.0003},
    ...        "correlation": [[1.0, 0.5], [0.5, 1.0]], "log_scaled": ["b"]}
    >>> (names, dist), = from_fit(fit).items()
    >>> names, dist.log, round(dist.cov[1][1], 6)
    (('K_b', 'b'), (False, True), 0.01)
    """
    d = fit if isinstance(fit, Mapping) else fit.to_dict()
    names = tuple(d["free"])
    values = np.array([float(d["values"][k]) for k in names])
    se = np.array([float(d["std_errors"][k]) if d["std_errors"][k] is not None else np.nan for k in names])
    corr = np.array(d["correlation"], dtype=float)
    log = tuple(k in set(d.get("log_scaled", ())) for k in names)
    if not (np.all(np.isfinite(se)) and np.all(np.isfinite(corr))):
        raise InputDataError(f"from_fit: the fit of {', '.join(names)} has no finite standard errors or correlation")
    mean = np.where(log, np.log(np.abs(values)), values)
    sd = np.where(log, se / np.abs(values), se)  # the standard error of log(value) is the relative one
    return {names: MultivariateNormal(mean, corr * np.outer(sd, sd), log)}


def _unit_samples(n: int, dim: int, sampling: str, seed: int) -> np.ndarray:
    """``n`` points in the open unit cube ``(0, 1)^dim``: Latin hypercube or plain random."""
    rng = np.random.default_rng(seed)
    if sampling == "lhs":
        from scipy.stats import qmc

        try:
            q = qmc.LatinHypercube(d=dim, rng=rng).random(n)
        except TypeError:  # scipy < 1.15 names it seed
            q = qmc.LatinHypercube(d=dim, seed=rng).random(n)
    else:
        q = rng.random((n, dim))
    return np.clip(q, 1e-12, 1 - 1e-12)  # normal quantiles stay finite
