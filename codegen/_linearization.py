"""The result of :func:`codegen.linearize.linearize`: a named ``control.StateSpace`` that behaves as every result.

It is a ``control.StateSpace`` (``ss.A``, ``control.bode(ss)``, interconnections work as on any), with the
operating point and the conserved directions of the structure; its ``repr`` is one line (python-control's
prints every matrix), Jupyter shows its poles as a small table, :meth:`LinearizationResult.plot` draws them and
:meth:`LinearizationResult.to_pandas` gives the matrix ``[[A, B], [C, D]]`` with named rows and columns.  It is
kept apart from :mod:`codegen.linearize` so that python-control is imported only when a linearisation is made.
"""

from __future__ import annotations

import control
import numpy as np

from phs._results import ResultMixin, finish, names, panels, require_pandas


class LinearizationResult(ResultMixin, control.StateSpace):
    """A linearisation ``dx' = A dx + B du, dy = C dx + D du`` at an operating point, as a ``control.StateSpace``.

    Attributes
    ----------
    casimirs : numpy.ndarray
        Rows spanning the conserved directions at the operating point (:func:`~codegen.linearize.casimir_directions`).
    x_eq : dict of str -> float
        The operating point's state values by name.
    u_eq : dict of str -> float
        The operating point's input values by name.

    Examples
    --------
    >>> from codegen.linearize import linearize
    >>> from systems.examples import mass_spring_damper
    >>> ss = linearize(mass_spring_damper())
    >>> ss
    LinearizationResult('msd', 2 states, 1 inputs, 1 outputs; poles -0.2±1.99j; stable)
    >>> ss.poles().round(3).tolist(), ss.x_eq
    ([(-0.2+1.99j), (-0.2-1.99j)], {'m.p': 0.0, 'k.l': 0.0})
    """

    casimirs: np.ndarray = np.zeros((0, 0))
    x_eq: dict = {}
    u_eq: dict = {}

    def _poles(self) -> np.ndarray:
        ev = np.linalg.eigvals(self.A) if self.nstates else np.zeros(0, dtype=complex)
        return ev[np.lexsort((ev.imag, ev.real))[::-1]]

    def _headline(self) -> str:
        ev = self._poles()
        shown, seen = [], set()
        for e in ev:
            key = (round(e.real, 12), round(abs(e.imag), 12))
            if key in seen:
                continue
            seen.add(key)
            shown.append(f"{e.real:.3g}±{abs(e.imag):.3g}j" if abs(e.imag) > 1e-12 * max(1.0, abs(e)) else f"{e.real:.3g}")
        scale = max(1.0, float(np.max(np.abs(ev)))) if ev.size else 1.0
        stable = "stable" if np.all(ev.real < -1e-12 * scale) else ("unstable" if np.any(ev.real > 1e-12 * scale)
                                                                     else "marginally stable")
        return (f"{self.name!r}, {self.nstates} states, {self.ninputs} inputs, {self.noutputs} outputs; "
                f"poles {names(shown, 4) or 'none'}; {stable}"
                + (f"; {len(self.casimirs)} conserved directions" if len(self.casimirs) else ""))

    def _table(self) -> tuple[list, list]:
        """Each pole: real and imaginary part, natural frequency and damping ratio (at most 20)."""
        ev = self._poles()
        rows = []
        for e in ev[:20]:
            wn = abs(e)
            rows.append((e.real, e.imag, wn, -e.real / wn if wn > 0 else float("nan")))
        if len(ev) > 20:
            rows.append((f"... {len(ev) - 20} more", "", "", ""))
        return ["real [1/s]", "imag [rad/s]", "natural frequency [rad/s]", "damping ratio"], rows

    def to_pandas(self):  # noqa: ANN201 - pandas is optional
        """The matrix ``[[A, B], [C, D]]`` as a DataFrame: rows the states' rates then the outputs, columns the
        states then the inputs (named as in the model).

        Needs pandas (``pip install "phs[pandas]"``); without it, an ImportError of one line says so.

        Examples
        --------
        >>> from codegen.linearize import linearize
        >>> from systems.examples import mass_spring_damper
        >>> float(linearize(mass_spring_damper()).to_pandas().loc["k.l", "m.p"])  # doctest: +SKIP
        1.0
        """
        pd = require_pandas("LinearizationResult.to_pandas()")
        M = np.block([[self.A, self.B], [self.C, self.D]])
        rows = list(self.state_labels) + list(self.output_labels)
        cols = list(self.state_labels) + list(self.input_labels)
        return pd.DataFrame(M, index=pd.Index(rows, name="row"), columns=cols)

    def plot(self, path=None, *, ax=None):  # noqa: ANN201 - matplotlib is imported on demand
        """The poles (eigenvalues of ``A``) in the complex plane.

        Parameters
        ----------
        path : str or path, optional
            Write the figure there (atomically, in the format of its suffix).
        ax : matplotlib Axes, optional
            Draw into this axes.

        Returns
        -------
        matplotlib.figure.Figure

        Examples
        --------
        >>> from codegen.linearize import linearize
        >>> from systems.examples import mass_spring_damper
        >>> fig = linearize(mass_spring_damper()).plot()
        >>> fig.axes[0].get_xlabel(), len(fig.axes[0].collections[0].get_offsets())
        ('real part [1/s]', 2)
        """
        fig, grid = panels(ax, 1, figsize=(5, 4), what="LinearizationResult.plot")
        a = grid[0, 0]
        ev = self._poles()
        a.scatter(ev.real, ev.imag, marker="x", s=40, label="poles")
        a.axvline(0.0, color="k", lw=0.6)
        a.axhline(0.0, color="k", lw=0.6)
        a.set_xlabel("real part [1/s]")
        a.set_ylabel("imaginary part [rad/s]")
        a.grid(True, alpha=0.3)
        a.set_title(f"{self.name}: linearisation" + (f" ({len(self.casimirs)} conserved directions: poles at 0)"
                                                       if len(self.casimirs) else ""), fontsize=9)
        return finish(fig, path)
