"""Figures of a passivity report: the box tests over their sample, the energy accounts, the frequency indices."""

from __future__ import annotations

import io

import numpy as np

from codegen.passivity._result import PassivityTest


def _pair(fig):
    """Two side-by-side axes of ``fig``, or ``fig`` itself when it is already a pair of axes."""
    return fig.subplots(1, 2) if hasattr(fig, "subplots") else tuple(fig)


def drawn(report) -> list:
    """The tests of ``report`` that :func:`draw` has a figure for."""
    return [t for t in report.tests if t.series and t.name in ("dissipation", "storage", "trajectory", "local")]


def draw(test: PassivityTest, fig):
    """Draw ``test`` on ``fig`` (a figure or a pair of axes) with the plot of its kind."""
    if test.name in ("dissipation", "storage"):
        return plot_box(test, fig)
    return plot_energy(test, fig) if test.name == "trajectory" else plot_local(test, fig)


def _figures(report) -> dict[str, bytes]:
    """PNG figures of the tests of a :class:`PassivityReport` that have data to plot, by file name."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    out = {}
    for t in drawn(report):
        fig = Figure(figsize=(9, 3.4), constrained_layout=True)
        FigureCanvasAgg(fig)
        draw(t, fig)
        fig.suptitle(f"{report.system.name}: {t.name} ({t.verdict})")
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=100)
        out[f"{t.name}.png"] = buf.getvalue()
    return out


def plot_box(test: PassivityTest, fig):
    """Plot a box test (``dissipation`` or ``storage``): the sampled values against the most influential
    variable, and sorted, with the optimised points; returns the figure.

    Examples
    --------
    >>> from matplotlib.figure import Figure
    >>> from codegen.passivity import certify
    >>> from systems.examples import mass_spring_damper
    >>> rep = certify(mass_spring_damper(), samples=32, starts=1)
    >>> len(plot_box(rep["storage"], Figure()).axes)
    2
    """
    key = "lambda" if test.name == "dissipation" else "H"
    vals, V, names = test.series[key], test.series["V"], test.series["names"]
    ok = np.isfinite(vals)
    corr = [abs(np.corrcoef(V[ok, j], vals[ok])[0, 1]) if np.ptp(V[ok, j]) > 0 and np.ptp(vals[ok]) > 0 else 0.0
            for j in range(V.shape[1])]
    j = int(np.argmax(np.nan_to_num(corr)))
    ax1, ax2 = _pair(fig)
    neg = ok & (vals < 0) if key == "lambda" else np.zeros_like(ok)
    ax1.scatter(V[ok & ~neg, j], vals[ok & ~neg], s=6, alpha=0.5, label="samples")
    if np.any(neg):
        ax1.scatter(V[neg, j], vals[neg], s=6, color="tab:red", label="negative")
    if key == "lambda":
        wx, wv = test.numbers.get("full_form_point", {}).get(names[j]), test.numbers.get("full_form_min_eigenvalue")
    else:
        wx, wv = test.worst.get(names[j]), test.numbers.get("H_min")
    if wx is not None and wv is not None:
        ax1.plot([wx], [wv], "kx", ms=10, mew=2, label="worst point" if key == "lambda" else "argmin")
    ax1.set_xlabel(names[j])
    ax1.set_ylabel("smallest scaled eigenvalue of D" if key == "lambda" else "H [J]")
    if key == "lambda":
        ax1.axhline(0.0, color="k", lw=0.6)
    ax1.legend(fontsize=7)
    srt = np.sort(vals[ok])
    ax2.plot(np.arange(len(srt)) / max(len(srt) - 1, 1), srt)
    if wv is not None:
        ax2.axhline(wv, color="k", ls=":", lw=0.8, label="optimised minimum")
        ax2.legend(fontsize=7)
    ax2.set_xlabel("fraction of the valid sample")
    ax2.set_ylabel("sorted values")
    return fig


def plot_energy(test: PassivityTest, fig):
    """Plot the energy accounts of a ``trajectory`` test: supplied, stored, dissipated, the split per element
    and the slack of the dissipation inequality; returns the figure.

    Examples
    --------
    >>> import numpy as np
    >>> from matplotlib.figure import Figure
    >>> from codegen.passivity import dissipation_inequality
    >>> from systems.examples import rc_circuit
    >>> test = dissipation_inequality(rc_circuit(), np.linspace(0, 5e-3, 51), u={"U": 1.0})
    >>> len(plot_energy(test, Figure()).axes)
    2
    """
    s = test.series
    t = s["t"]
    ax1, ax2 = _pair(fig)
    ax1.plot(t, s["supplied"], label="supplied ∫yᵀu dt")
    ax1.plot(t, s["stored"], label="stored H − H(0)")
    ax1.plot(t, s["dissipated"], label="dissipated")
    ax1.plot(t, s["supplied"] - s["stored"], "k:", label="supplied − stored")
    ax1.set_xlabel("t [s]")
    ax1.set_ylabel("energy [J]")
    ax1.legend(fontsize=7)
    parts = s["parts"]
    if parts:
        order = sorted(parts, key=lambda n: -abs(parts[n][-1]))
        shown = order[:7]
        curves = [parts[n] for n in shown]
        labels = list(shown)
        if len(order) > 7:
            curves.append(np.sum([parts[n] for n in order[7:]], axis=0))
            labels.append(f"{len(order) - 7} others")
        if all(np.all(c >= -1e-12 * max(1.0, float(np.max(np.abs(c))))) for c in curves):
            ax2.stackplot(t, *curves, labels=labels, alpha=0.8)  # the top of the stack is the total
        else:
            for c, lab in zip(curves, labels):
                ax2.plot(t, c, label=lab)
            ax2.axhline(0.0, color="k", lw=0.6)
    ax2.set_xlabel("t [s]")
    ax2.set_ylabel("dissipated per element [J]")
    ax2.legend(fontsize=7)
    return fig


def plot_local(test: PassivityTest, fig):
    """Plot a ``local`` test: ``λ_min(He G(jω))`` and ``λ_min(He G(jω)^-1)`` against ω with the indices.

    Examples
    --------
    >>> from matplotlib.figure import Figure
    >>> from codegen.passivity import local_passivity
    >>> from systems.examples import rlc_circuit
    >>> test = local_passivity(rlc_circuit(), cross_check=False).test()
    >>> len(plot_local(test, Figure()).axes)
    2
    """
    s = test.series
    w = s["omega"]
    ax1, ax2 = _pair(fig)
    ax1.semilogx(w, s["nu_curve"])
    ax1.axhline(test.numbers["input_index"], color="k", ls=":", label=f"ν = {test.numbers['input_index']:.4g}")
    ax1.set_xlabel("ω [rad/s]")
    ax1.set_ylabel(f"λ_min He G(jω) [{test.numbers['input_index_unit']}]")
    ax1.legend(fontsize=7)
    rho = np.where(np.isfinite(s["rho_curve"]), s["rho_curve"], np.nan)
    ax2.semilogx(w, rho)
    ax2.axhline(test.numbers["output_index"], color="k", ls=":", label=f"ρ = {test.numbers['output_index']:.4g}")
    ax2.set_xlabel("ω [rad/s]")
    ax2.set_ylabel(f"λ_min He G(jω)⁻¹ [{test.numbers['output_index_unit']}]")
    ax2.legend(fontsize=7)
    return fig
