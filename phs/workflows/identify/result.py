"""The outcome of an identification: fitted values, their uncertainty, and the fit per channel."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from codegen.simulator import simulate
from phs.signals import Sampled
from phs.workflows.identify.scoring import evaluate_fit, nrmse_fit
from phs.workflows.identify.sensitivity_table import _sensitivity_table


@dataclass
class IdentificationResult:
    """Outcome of :func:`identify` (values in the parameters' own units)."""

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

    @property
    def fitted_system(self):
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
        for a, b, c in self.flagged_pairs:
            lines.append(f"  warning: {a} and {b} are strongly correlated ({c:+.3f}): not separately identifiable")
        return "\n".join(lines)

    __str__ = summary

    def to_dict(self) -> dict:
        return {
            "system": self.system.name, "model_hash": self.system.model_hash(), "free": self.free,
            "values": self.values, "initial": self.initial, "std_errors": self.std_errors,
            "intervals": {k: list(v) for k, v in self.intervals.items()},
            "correlation": self.correlation.tolist(), "flagged_pairs": [list(p) for p in self.flagged_pairs],
            "fit_percent": self.fit_percent, "validation_fit_percent": self.validation_fit_percent,
            "cost": self.cost, "iterations": self.iterations, "seconds": self.seconds, "outputs": self.outputs,
            "log_scaled": self.log_scaled, "message": self.message,
            "sensitivity": {k: {str(s): f for s, f in v.items()} for k, v in self.sensitivity.items()},
        }

    def validate(self, recording) -> dict:
        """Fit % per channel of the fitted model on another recording (stored in ``validation_fit_percent``)."""
        fits = evaluate_fit(self.fitted_system, recording, self.outputs, x0=self.x0)
        self.validation_fit_percent = fits
        return fits

    def sensitivity_table(self, recording=None, steps=(-0.10, -0.05, 0.0, 0.05, 0.10), channel: str | None = None):
        """Fit % when each fitted parameter alone moves by ``steps`` (relative), and the standard deviation.

        Returns ``{parameter: {step: fit %, ..., "std": sd}}`` for ``channel`` (default the first output).
        """
        rec = recording if recording is not None else self._recording
        self.sensitivity = _sensitivity_table(self, rec, steps, channel or self.outputs[0])
        return self.sensitivity

    def plot(self, path=None, recording=None):
        """Measured versus simulated for each channel (and residuals); returns the matplotlib figure.

        Axes are labelled ``name [unit]``; with ``path`` the figure is saved atomically in the format of
        its suffix (either the whole file appears or, on any failure, nothing changes).
        """
        import matplotlib

        from phs.workflows.figures import axis_label, save_figure

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        rec = recording if recording is not None else self._recording
        res = simulate(self.fitted_system, rec.t, u={u: Sampled(tuple(rec.t), tuple(rec[u])) for u in
                                                     self.system.input_names}, x0=self.x0)
        fig, axes = plt.subplots(len(self.outputs), 1, figsize=(8, 2.6 * len(self.outputs)), sharex=True, squeeze=False)
        for ax, ch in zip(axes[:, 0], self.outputs, strict=True):
            ax.plot(rec.t, rec[ch], lw=1, label="measured")
            ax.plot(rec.t, res[ch], lw=1, label=f"model (fit {nrmse_fit(rec[ch], res[ch]):.1f} %)")
            ax.set_ylabel(axis_label(ch, {m.name: m.unit for m in self.system.measured}.get(ch, "")))
            ax.legend(fontsize=8)
        axes[-1, 0].set_xlabel("t [s]")
        fig.tight_layout()
        if path is not None:
            save_figure(fig, path, dpi=90)
        return fig


def _uncertainty(r, J, values: dict, nominal, free: list, log_scaled: list):
    """Standard errors, 95 % intervals, correlation matrix and strongly correlated pairs of the fitted
    parameters from the output residual ``r`` and its Jacobian ``J`` in fit coordinates at the optimum
    (``nominal``: the parameters' starting values, the unit of their linear coordinates)."""
    n_res, n_par = len(r), J.shape[1]
    sigma2 = float(r @ r) / max(n_res - n_par, 1)
    try:
        cov = sigma2 * np.linalg.pinv(J.T @ J)
    except np.linalg.LinAlgError:
        cov = np.full((n_par, n_par), np.nan)
    se_z = np.sqrt(np.maximum(np.diag(cov), 0))
    std, ci = {}, {}
    for i, k in enumerate(free):
        v = values[k]
        if k in log_scaled:
            std[k] = abs(v) * se_z[i]
            # an unidentifiable parameter has a huge log-scale error: its interval is (0, inf)
            spread = float(np.exp(min(1.96 * se_z[i], 700.0)))
            ci[k] = (v / spread, v * spread if spread < 1e300 else float("inf"))
        else:
            std[k] = abs(nominal[i]) * se_z[i]
            ci[k] = (v - 1.96 * std[k], v + 1.96 * std[k])
    dd = np.sqrt(np.maximum(np.diag(cov)[:len(free)], 1e-300))
    corr = cov[: len(free), : len(free)] / np.outer(dd, dd)
    flagged = [(free[a], free[b], float(corr[a, b])) for a in range(len(free)) for b in range(a + 1, len(free))
               if abs(corr[a, b]) > 0.95]
    return std, ci, corr, flagged
