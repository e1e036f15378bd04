"""The outcome of an identification: fitted values, their uncertainty, and the fit per channel."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from codegen.simulator import simulate
from phs._results import ResultMixin, finish, names, panels
from phs.workflows.identify.identifiability import analyse, combinations, rank_tolerance, unidentified
from phs.workflows.identify.scoring import evaluate_fit, nrmse_fit
from phs.workflows.identify.sensitivity_table import _sensitivity_table

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.figure import Figure

    from phs.system import PHSystem

_COLUMNS = ("parameter", "unit", "initial", "fitted", "std_error", "ci_low", "ci_high")


@dataclass(repr=False)
class IdentificationResult(ResultMixin):
    """Outcome of :func:`identify` (values in the parameters' own units).

    :meth:`summary` is the readable report, :meth:`plot` the fit per channel, :meth:`to_pandas` one row per
    fitted parameter; ``repr`` is one line and Jupyter shows small tables.

    Examples
    --------
    >>> import numpy as np
    >>> from codegen import simulate
    >>> from phs.workflows.identify import identify
    >>> from phs.workflows.recording import Recording
    >>> from systems.examples import rc_circuit
    >>> t = np.linspace(0, 0.01, 201); u = np.sin(2 * np.pi * 300 * t)
    >>> rec = Recording.from_arrays(t, {"U": u, "v_C": simulate(rc_circuit(), t, u={"U": u})["v_C"]})
    >>> identify(rc_circuit(R=1.2e3), rec, ["R.R"])  # doctest: +ELLIPSIS
    IdentificationResult('rc', fitted R.R, fit v_C 100.0 %, ... iterations)
    """

    system: object
    free: list
    values: dict
    initial: dict
    std_errors: dict
    intervals: dict
    correlation: np.ndarray
    flagged_pairs: list
    fit_percent: dict
    validation_fit_percent: dict
    residuals: dict
    cost: float
    iterations: int
    seconds: float
    x0: np.ndarray
    outputs: list
    weights: dict
    log_scaled: list
    message: str = ""
    sensitivity: dict = field(default_factory=dict)
    _recording: object = None
    compiled: bool = False  # whether the fit ran compiled C (see ``identify(compile=...)``)
    # products of powers of the parameters that the data determine / leave free, among parameters
    # that are not identifiable separately (see :mod:`phs.workflows.identify.identifiability`)
    identifiable: list = field(default_factory=list)
    unidentifiable: list = field(default_factory=list)
    # the triangular factor of the Jacobian in relative coordinates (``relative_factor``): columns the free
    # parameters, then the estimated initial and window states
    factor: np.ndarray | None = field(default=None, repr=False)
    rtol: float = 1e-8
    # the cost's resolution at the fit's end: about the integration's error in ``cost`` (the difference of the
    # state integrated alone and with its sensitivities; ``phs.workflows.identify.solve.RESOLVED``)
    cost_resolution: float = 0.0

    def undetermined_beyond(self, names) -> list[str]:
        """The parameters among ``names`` that the data do not tell apart from a re-adjustment of the other
        fitted parameters and estimated states: along a direction their sensitivities leave undetermined
        once the others' span is projected out (:func:`~phs.workflows.identify.identifiability.undetermined_beyond`,
        with the rank threshold of the fit's integration tolerance).  A direction the others leave
        undetermined among themselves does not count.

        Examples
        --------
        >>> import numpy as np
        >>> from codegen import simulate
        >>> from phs.workflows.identify import identify
        >>> from phs.workflows.recording import Recording
        >>> from systems.examples import rc_circuit
        >>> t = np.linspace(0, 0.01, 401); u = np.where((t % 0.004) < 0.002, 1.0, -0.5)
        >>> rec = Recording.from_arrays(t, {"U": u, "v_C": simulate(rc_circuit(), t, u={"U": u})["v_C"]})
        >>> fit = identify(rc_circuit(R=1.2e3), rec, ["R.R", "C.C"])   # v_C determines R C only
        >>> fit.undetermined_beyond(["C.C"]), identify(rc_circuit(R=1.2e3), rec, ["R.R"]).undetermined_beyond(["R.R"])
        (['C.C'], [])
        """
        from phs.workflows.identify.identifiability import rank_tolerance, undetermined_beyond

        names = [k for k in names if k in self.free]
        if self.factor is None or not names:
            return []
        flags = undetermined_beyond(self.factor, [self.free.index(k) for k in names], rank_tolerance(self.rtol))
        return [k for k, f in zip(names, flags, strict=True) if f]

    @property
    def fitted_system(self) -> PHSystem:
        """The system with the fitted parameter values."""
        return self.system.with_params({k: v for k, v in self.values.items() if k in self.system.param_names})

    def summary(self) -> str:
        lines = [f"Identification of {self.system.name!r}: {len(self.free)} parameter{'s' if len(self.free) != 1 else ''}, "
                 f"cost {self.cost:.6g}, "
                 f"{self.iterations} iterations, {self.seconds:.2f} s ({self.message})"]
        lines.append(f"  {'parameter':<14}{'initial':>12}{'fitted':>14}{'std error':>12}   95 % interval")
        for k in self.free:
            lo, hi = self.intervals[k]
            lines.append(f"  {k:<14}{self.initial[k]:>12.5g}{self.values[k]:>14.6g}{self.std_errors[k]:>12.3g}"
                         f"   [{lo:.5g}, {hi:.5g}]" + ("  (log scale)" if k in self.log_scaled else ""))
        for ch, v in self.fit_percent.items():
            val = self.validation_fit_percent.get(ch)
            lines.append(f"  fit {ch}: {v:.2f} % (training)" + (f", {val:.2f} % (validation)" if val is not None else ""))
        lines += [f"  {line}" for line in self.identifiability_sentences()]
        grouped = {k for c in self.unidentifiable for k in c.group}
        for a, b, c in self.flagged_pairs:
            if a in grouped and b in grouped:
                continue  # said above
            lines.append(f"  warning: {a} and {b} are strongly correlated ({c:+.3f}): not separately identifiable")
        return "\n".join(lines)

    __str__ = summary

    def to_pandas(self) -> pd.DataFrame:
        """One row per free parameter (initial, fitted, std error, 95 % interval) as a pandas DataFrame
        indexed by parameter name; the parameters' units in ``df.attrs["units"]``.

        Needs pandas (``pip install "phs[pandas]"``); without it, an ImportError of one line says so.

        Examples
        --------
        >>> from phs.workflows.bundled import recording_path
        >>> from phs.workflows.identify import identify
        >>> from phs.workflows.recording import Recording
        >>> from systems.examples import mass_spring_damper
        >>> fit = identify(mass_spring_damper(), Recording.from_csv(recording_path("msd_two_tone")), ["k.K"])
        >>> round(float(fit.to_pandas().loc["k.K", "fitted"]), 1)  # doctest: +SKIP
        5.1
        """
        from codegen.tables import require_pandas

        pd = require_pandas("IdentificationResult.to_pandas()")
        rows = self._rows()
        df = pd.DataFrame({c: [r[k + 1] for r in rows] for k, c in enumerate(_COLUMNS[1:])},
                          index=pd.Index([r[0] for r in rows], name="parameter"))
        df.attrs["units"] = {k: self._unit(k) for k in self.free}
        df.attrs["fit_percent"] = dict(self.fit_percent)
        return df

    def _unit(self, name: str) -> str:
        return self.system.param(name).unit if name in self.system.param_names else ""

    def _rows(self) -> list[tuple]:
        return [(k, self._unit(k), float(self.initial[k]), float(self.values[k]), float(self.std_errors[k]),
                 float(self.intervals[k][0]), float(self.intervals[k][1])) for k in self.free]

    def _repr_html_(self) -> str:
        """Jupyter: the parameters and the fit per channel as small HTML tables (every string escaped)."""
        from codegen.tables import html_table

        head = (f"Identification of {self.system.name!r}: cost {self.cost:.6g}, {self.iterations} iterations, "
                f"{self.seconds:.2f} s")
        fits = [(ch, v, self.validation_fit_percent.get(ch, "")) for ch, v in self.fit_percent.items()]
        return (html_table(_COLUMNS, self._rows(), caption=head)
                + html_table(["output", "fit % (training)", "fit % (validation)"], fits))

    def identifiability_sentences(self) -> list[str]:
        """One sentence per group of parameters that are not identifiable separately: which they are,
        and the combinations of them that the data determine, with values and 95 % intervals."""
        out = []
        for group in dict.fromkeys(c.group for c in self.unidentifiable):
            if len(group) == 1:
                out.append(f"{group[0]} is not identifiable from these data (the fitted outputs do not depend on it).")
                continue
            known = [c for c in self.identifiable if c.group == group]
            said = [f"their {'product' if all(e == 1 for e in c.exponents.values()) else 'combination'} {c.text()} is identified"
                    for c in known]
            out.append(f"{', '.join(group[:-1])} and {group[-1]} are not identifiable separately from these data"
                       + ("; " + "; ".join(said) if said else " (no combination of them is determined)") + ".")
        return out

    def to_dict(self) -> dict:
        return {
            "system": self.system.name, "model_hash": self.system.model_hash(), "free": self.free,
            "values": self.values, "initial": self.initial, "std_errors": self.std_errors,
            "intervals": {k: list(v) for k, v in self.intervals.items()},
            "correlation": self.correlation.tolist(), "flagged_pairs": [list(p) for p in self.flagged_pairs],
            "fit_percent": self.fit_percent, "validation_fit_percent": self.validation_fit_percent,
            "cost": self.cost, "iterations": self.iterations, "seconds": self.seconds, "outputs": self.outputs,
            "log_scaled": self.log_scaled, "message": self.message,
            "identifiable": [c.to_dict() for c in self.identifiable],
            "unidentifiable": [c.to_dict() for c in self.unidentifiable],
            "sensitivity": {k: {str(s): f for s, f in v.items()} for k, v in self.sensitivity.items()},
        }

    def validate(self, recording) -> dict:
        """Fit % per channel of the fitted model on another recording (stored in ``validation_fit_percent``)."""
        fits = evaluate_fit(self.fitted_system, recording, self.outputs, x0=self.x0)
        self.validation_fit_percent = fits
        return fits

    def sensitivity_table(self, recording=None, steps=(-0.10, -0.05, 0.0, 0.05, 0.10), channel: str | None = None) -> dict[str, dict]:
        """Fit % when each fitted parameter alone moves by ``steps`` (relative), and the standard deviation.

        Returns ``{parameter: {step: fit %, ..., "std": sd}}`` for ``channel`` (default the first output).
        """
        rec = recording if recording is not None else self._recording
        self.sensitivity = _sensitivity_table(self, rec, steps, channel or self.outputs[0])
        return self.sensitivity

    def plot(self, path=None, recording=None, *, ax=None) -> Figure:
        """Measured versus simulated for each fitted channel, with the fit % in the legend.

        Parameters
        ----------
        path : str or path, optional
            Write the figure there (atomically, in the format of its suffix: either the whole file appears
            or, on any failure, nothing changes).
        recording : Recording, optional
            The data to compare with (default: the training recording).
        ax : matplotlib Axes or array of Axes, optional
            Draw into these axes, one per fitted channel.

        Returns
        -------
        matplotlib.figure.Figure
            Axes labelled ``name [unit]``.

        Examples
        --------
        >>> import numpy as np
        >>> from codegen import simulate
        >>> from phs.workflows.identify import identify
        >>> from phs.workflows.recording import Recording
        >>> from systems.examples import rc_circuit
        >>> t = np.linspace(0, 0.01, 201); u = np.sin(2 * np.pi * 300 * t)
        >>> rec = Recording.from_arrays(t, {"U": u, "v_C": simulate(rc_circuit(), t, u={"U": u})["v_C"]})
        >>> [a.get_ylabel() for a in identify(rc_circuit(R=1.2e3), rec, ["R.R"]).plot().axes]
        ['v_C [V]']
        """
        from phs.workflows.figures import axis_label

        rec = recording if recording is not None else self._recording
        res = simulate(self.fitted_system, rec.t, u={u: rec.input_signal(u) for u in self.system.input_names}, x0=self.x0)
        fig, grid = panels(ax, len(self.outputs), figsize=(8, 2.6 * len(self.outputs)), sharex=True,
                           what="IdentificationResult.plot")
        for a, ch in zip(grid[:, 0], self.outputs, strict=True):
            a.plot(rec.t, rec[ch], lw=1, label="measured")
            a.plot(rec.t, res[ch], lw=1, label=f"model (fit {nrmse_fit(rec[ch], res[ch]):.1f} %)")
            a.set_ylabel(axis_label(ch, {m.name: m.unit for m in self.system.measured}.get(ch, "")))
            a.legend(fontsize=8)
        grid[-1, 0].set_xlabel("t [s]")
        return finish(fig, path, dpi=90)

    def _headline(self) -> str:
        fits = ", ".join(f"{ch} {v:.1f} %" for ch, v in list(self.fit_percent.items())[:4])
        return (f"{self.system.name!r}, fitted {names(self.free, 4)}, fit {fits or 'none'}, "
                f"{self.iterations} iterations")


def _relative_scale(n_col: int, values: dict, nominal, free: list, log_scaled: list) -> np.ndarray:
    """Column scale ``D`` from the fit's coordinates to relative ones: ``p / nominal -> log |p|`` for a
    linear parameter (``p / nominal``), 1 for log-scaled parameters and estimated states."""
    n_par = len(free)
    pv = np.array([values[k] for k in free], dtype=float)
    nom = np.asarray(nominal, dtype=float)
    D = np.ones(n_col)
    lin = np.array([k not in log_scaled for k in free], dtype=bool)
    ok = lin & (pv != 0) & (nom != 0)
    D[:n_par][ok] = pv[ok] / nom[ok]
    return D


def relative_factor(J, values: dict, nominal, free: list, log_scaled: list) -> np.ndarray:
    """The triangular factor ``R`` of the fit's Jacobian in relative coordinates (``J D = Q R``, ``D`` of
    :func:`_relative_scale`): ``n × n`` for ``n`` fitted columns, it holds every angle and length between
    the columns, so rank questions about any subset of them need no more than it
    (:func:`~phs.workflows.identify.identifiability.undetermined_beyond`).

    Examples
    --------
    >>> J = np.array([[1.0, 2.0], [0.0, 2.0], [0.0, 0.0]])
    >>> np.round(np.abs(relative_factor(J, {"a": 1.0, "b": 2.0}, [1.0, 1.0], ["a", "b"], [])), 6).tolist()
    [[1.0, 4.0], [0.0, 4.0]]
    """
    J = np.asarray(J, dtype=float)
    Jr = J * _relative_scale(J.shape[1], values, nominal, free, log_scaled)
    if Jr.size == 0 or not np.all(np.isfinite(Jr)):
        return np.full((J.shape[1], J.shape[1]), np.nan)
    R = np.linalg.qr(Jr, mode="r")
    return np.vstack([R, np.zeros((J.shape[1] - R.shape[0], J.shape[1]))]) if R.shape[0] < J.shape[1] else R


def _uncertainty(r, J, values: dict, nominal, free: list, log_scaled: list, n_channels: int = 1,
                 rtol: float = 1e-8, units: dict | None = None):
    """Standard errors, 95 % intervals, correlation matrix, strongly correlated pairs and the
    identifiability analysis of the fitted parameters.

    ``r`` is the weighted output residual at the optimum, channel by channel (``n_channels`` blocks
    of equal length), ``J`` its Jacobian in fit coordinates (``nominal``: the parameters' starting
    values, the unit of their linear coordinates; columns after ``len(free)`` are estimated states).
    The rank of ``J`` is decided in relative coordinates with the threshold
    :func:`~phs.workflows.identify.identifiability.rank_tolerance` of the integration tolerance
    ``rtol``; a parameter with a component along an unidentifiable direction gets an infinite standard
    error and interval.  The covariance of the rest is the rank-truncated sandwich
    ``H⁺ (Σ_c s_c² J_cᵀ J_c) H⁺`` (``H = JᵀJ``, ``s_c²`` the residual variance of channel ``c``):
    with one channel it is ``s² H⁺``; with several it stays right when their weighted noise levels
    differ.  Returns ``(std, ci, corr, flagged, identifiable, unidentifiable)``.
    """
    n_res, n_col = len(r), J.shape[1]
    n_par = len(free)
    D = _relative_scale(n_col, values, nominal, free, log_scaled)
    Hp, P, rank = analyse(J, D, rank_tolerance(rtol))
    dof = n_res / max(n_res - rank, 1)
    B = np.zeros((n_col, n_col))
    for rc, Jc in zip(np.array_split(r, n_channels), np.array_split(J, n_channels), strict=True):
        B += float(rc @ rc) / max(len(rc), 1) * dof * (Jc.T @ Jc)
    cov = Hp @ B @ Hp
    free_dir = unidentified(P, n_par)  # parameters along an unidentifiable direction
    se_z = np.sqrt(np.maximum(np.diag(cov), 0))
    std, ci = {}, {}
    for i, k in enumerate(free):
        v = values[k]
        if free_dir[i]:
            std[k] = float("inf")
            ci[k] = (0.0, float("inf")) if k in log_scaled else (float("-inf"), float("inf"))
        elif k in log_scaled:
            std[k] = abs(v) * se_z[i]
            spread = float(np.exp(min(1.96 * se_z[i], 700.0)))
            ci[k] = (v / spread, v * spread if spread < 1e300 else float("inf"))
        else:
            std[k] = abs(nominal[i]) * se_z[i]
            ci[k] = (v - 1.96 * std[k], v + 1.96 * std[k])
    # correlation: of the estimates on the identifiable part; between two parameters along an
    # unidentifiable direction, the limit as its variance grows without bound (the null directions'
    # projector); between one such and a determined parameter, 0
    dd = np.sqrt(np.maximum(np.diag(cov)[:n_par], 1e-300))
    corr = cov[:n_par, :n_par] / np.outer(dd, dd)
    pn = np.sqrt(np.maximum(np.diag(P)[:n_par], 1e-300))
    sgn = np.sign(D[:n_par])
    corr_free = P[:n_par, :n_par] / np.outer(pn, pn) * np.outer(sgn, sgn)
    corr = np.where(np.outer(free_dir, free_dir), corr_free, np.where(np.add.outer(free_dir, free_dir), 0.0, corr))
    np.fill_diagonal(corr, 1.0)
    flagged = [(free[a], free[b], float(corr[a, b])) for a in range(n_par) for b in range(a + 1, n_par)
               if abs(corr[a, b]) > 0.95]
    cov_rel = cov[:n_par, :n_par] / np.outer(D[:n_par], D[:n_par])
    ident, unident = combinations(P, cov_rel, free, values, dict(units or {}))
    return std, ci, corr, flagged, ident, unident
