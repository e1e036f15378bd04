"""The figure of the located mismatch: residual, best regressor, spectrum and cross-correlation per channel."""

from __future__ import annotations

import io
import os

import numpy as np
import scipy.fft as sfft
from scipy import signal

from phs.errors import InputDataError
from phs.io import write_atomic
from phs.workflows.diagnose.locate._common import _welch_len
from phs.workflows.diagnose.locate._context import _merge_steps, _steps, _validate
from phs.workflows.diagnose.locate.features import _regressor


def plot_findings(t, residuals: dict, features: dict, inputs: dict, findings, path) -> str:
    """Figure of the located mismatch, one row per channel, written atomically to ``path`` (.png, .svg, .pdf).

    Columns: residual against time with the found windows shaded and the input steps marked; residual
    against its best regressor with the fitted line; residual spectrum with the found frequencies;
    cross-correlation with the input of the strongest lag finding (or the first input) and its threshold.

    Returns
    -------
    str
        ``path``.

    Raises
    ------
    InputDataError
        For malformed signals, an unsupported extension or a missing directory (nothing is written).

    Examples
    --------
    >>> import tempfile, os
    >>> from phs.workflows.diagnose.locate import locate
    >>> t = np.arange(0, 2, 1e-3); U = np.sign(np.sin(2 * np.pi * t))
    >>> r = 0.1 * U**3 + 0.01 * np.random.default_rng(0).standard_normal(t.size)
    >>> found = locate(t, {"y": r}, {}, {"U": U})
    >>> with tempfile.TemporaryDirectory() as d:
    ...     p = plot_findings(t, {"y": r}, {}, {"U": U}, found, os.path.join(d, "locate.png"))
    ...     os.path.getsize(p) > 1000
    True
    """
    t, dt, res, feats, ins, vel, _ = _validate(t, residuals, features, inputs)
    ext = os.path.splitext(os.fspath(path))[1].lower().lstrip(".")
    if ext not in ("png", "svg", "pdf"):
        raise InputDataError(f"cannot write {os.fspath(path)!r}: the figure format must be .png, .svg or .pdf")
    folder = os.path.dirname(os.path.abspath(os.fspath(path)))
    if not os.path.isdir(folder):  # checked before the (slow) drawing; write_atomic checks again
        raise InputDataError(f"cannot write {os.fspath(path)!r}: directory {folder!r} does not exist")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    steps = {k: _steps(u) for k, u in ins.items()}
    merged = _merge_steps(steps)
    chans = list(res) or ["(no residual)"]
    fig = Figure(figsize=(17, 3.2 * len(chans)), constrained_layout=True)
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(chans), 4, squeeze=False)
    f0 = next((f.details.get("fundamental_hz") for f in findings if f.kind == "harmonic"), None)
    for row, ch in enumerate(chans):
        ax = axes[row]
        r = res.get(ch, np.zeros_like(t))
        mine = [f for f in findings if f.channel == ch]
        ax[0].plot(t, r, lw=0.6, color="C0")
        for f in mine:
            if f.kind == "time_window":
                for a, b in f.details.get("windows", [])[:100]:
                    ax[0].axvspan(a, b, color="C3", alpha=0.2, lw=0)
        for i, _, _ in merged[:200]:
            ax[0].axvline(t[i], color="0.6", lw=0.5, ls=":")
        ax[0].set(title=f"{ch}: residual (shaded: concentrated energy)", xlabel="t [s]")
        feat = next((f for f in mine if f.kind == "feature"), None)
        known = feat is not None and (feat.details["source"] == "events" or feat.details["base"] in
                                      (ins if feat.details["source"] == "input" else feats)) \
            and feat.details.get("velocity") in (None, *feats)
        if known:
            x = _regressor(feat.details, t, feats, ins, merged)
            k = max(1, t.size // 4000)
            ax[1].plot(x[::k], r[::k], ".", ms=2, alpha=0.5)
            xs = np.linspace(x.min(), x.max(), 50)
            ax[1].plot(xs, feat.details["intercept"] + feat.details["coefficient"] * xs, "C3")
            ax[1].set(title=f"vs {feat.details['regressor']} (R² {feat.strength:.3f})", xlabel=feat.details["regressor"])
        else:
            ax[1].text(0.5, 0.5, "no significant feature" if feat is None else f"{feat.details['regressor']}: signal not given",
                       ha="center", va="center", transform=ax[1].transAxes)
        rc = r - r.mean()
        if np.any(rc):
            fw, P = signal.welch(rc, 1 / dt, nperseg=_welch_len(t.size, 1 / dt, f0))
            ax[2].semilogy(fw[1:], P[1:], lw=0.8)
            for f in mine:
                if f.kind in ("harmonic", "spectrum") and "frequency_hz" in f.details:
                    ax[2].axvline(f.details["frequency_hz"], color="C3" if f.kind == "harmonic" else "C2", lw=0.8, alpha=0.7)
        ax[2].set(title="residual spectrum (Welch)", xlabel="f [Hz]", xscale="log")
        lagf = next((f for f in mine if f.kind == "input_lag"), None)
        name = lagf.details["input"] if lagf else next((k for k, u in ins.items() if np.ptp(u) > 0), None)
        if name is not None and np.any(rc):
            x = np.gradient(ins[name], dt) if lagf and lagf.details["derivative"] else ins[name]
            x = x - x.mean()
            m = int(min(t.size // 4, max(20, t.size // 10)))
            if np.any(x):
                nfft = sfft.next_fast_len(2 * t.size)
                cc = sfft.irfft(sfft.rfft(rc, nfft) * np.conj(sfft.rfft(x, nfft)), nfft)
                c = np.concatenate([cc[nfft - m:], cc[:m + 1]]) / (t.size * rc.std() * x.std())
                ax[3].plot(np.arange(-m, m + 1) * dt, c, lw=0.8)
                if lagf:
                    th = lagf.details["threshold"]
                    ax[3].axhspan(-th, th, color="0.85")
                    ax[3].axvline(lagf.details["lag_s"], color="C3", lw=0.8)
                ax[3].set(title=f"cross-correlation with {'d' + name + '/dt' if lagf and lagf.details['derivative'] else name}")
        ax[3].set(xlabel="lag [s] (> 0: residual follows)")
        for a in ax:
            a.grid(True, alpha=0.3)
    buf = io.BytesIO()
    fig.savefig(buf, format=ext, dpi=90)
    write_atomic(path, buf.getvalue())
    return os.fspath(path)
