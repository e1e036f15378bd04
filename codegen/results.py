"""Simulation results: named signals on the time grid, energy and power accounts."""

from __future__ import annotations

import io
from functools import cached_property
from typing import TYPE_CHECKING

import casadi as ca
import numpy as np

from codegen.functions import generate
from phs._results import ResultMixin, finish, panels
from phs.errors import InputDataError
from phs.io import write_atomic

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.figure import Figure


_MAPPED: dict = {}
"""Functions mapped over a number of samples, by (function, number), oldest dropped beyond :data:`_MAPPED_KEPT`."""
_MAPPED_KEPT = 64


def _mapped(f, n: int):
    """``f`` with dense inputs and outputs, mapped serially over ``n`` samples (built once per function and
    length: building a map of 20 000 samples costs as much as calling it ten times).

    Examples
    --------
    >>> x = ca.SX.sym("x", 2)
    >>> f = ca.Function("f", [x], [ca.vertcat(x[0] * x[1], 0)])
    >>> _mapped(f, 3)(np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])).full().tolist()
    [[4.0, 10.0, 18.0], [0.0, 0.0, 0.0]]
    """
    key = (id(f), n)
    hit = _MAPPED.get(key)
    if hit is not None and hit[0] is f:
        return hit[1]
    args = [ca.MX.sym(f"a{i}", f.size1_in(i), f.size2_in(i)) for i in range(f.n_in())]
    outs = f.call(args)
    dense = ca.Function(f"{f.name()}_dense", args, [ca.densify(o) for o in outs])
    fm = dense.map(n) if n > 1 else dense
    while len(_MAPPED) >= _MAPPED_KEPT:
        _MAPPED.pop(next(iter(_MAPPED)))
    _MAPPED[key] = (f, fm)
    return fm


class SimulationResult(ResultMixin):
    """Trajectory of a system on a time grid, indexed by signal name.

    ``res["seg2.theta"]`` gives a state, input, port output (``"U.i"``),
    measured output, energy term or one of ``"H"`` [J], ``"dissipated"`` (the
    dissipated power [W]), ``"supplied"`` (the supplied power ``y^T u`` [W]),
    ``"dHdt"`` [W].  Energies over time are ``E_supplied`` and ``E_dissipated``
    [J] (:attr:`quadratures` of a CVODES run, or :meth:`energy_accounts`).
    :meth:`unit` gives each signal's unit; :meth:`to_csv` writes headers
    ``name [unit]``; :meth:`plot` draws the run, :meth:`to_pandas` gives a DataFrame.

    Parameters
    ----------
    system : PHSystem
    t : array (nt,)
    x : array (nt, nx)
    u : array (nt, nu)
        Inputs evaluated on the grid.
    p : array (np,)
        Parameter values used.

    Examples
    --------
    >>> import numpy as np
    >>> from codegen import simulate
    >>> from systems.examples import mass_spring_damper
    >>> res = simulate(mass_spring_damper(), np.linspace(0, 2, 21), u={"F": 1.0})
    >>> res.columns[:3], res["position"].shape
    (['m.p', 'k.l', 'F'], (21,))
    >>> res.unit("m.p"), res.unit("H"), res.unit("dissipated")
    ('kg*m/s', 'J', 'W')
    """

    def __init__(self, system, t, x, u, p, stats: dict | None = None):
        self.system = system
        self.t = np.asarray(t, dtype=float)
        self.x = np.asarray(x, dtype=float)
        self.u = np.asarray(u, dtype=float).reshape(len(self.t), len(system.inputs))
        self.p = np.asarray(p, dtype=float)
        self.stats = dict(stats or {})
        self.quadratures: dict[str, np.ndarray] = {}

    # -- derived signals, evaluated in one vectorised call each -----------------------
    def _map(self, f):
        """``f(x, u, p)`` at every sample, one ``(nt, k)`` array per output of ``f``: one call of ``f`` mapped
        over the samples (:func:`_mapped`), reading and writing numpy memory directly."""
        n = len(self.t)
        fm = _mapped(f, n)
        buf, trigger = fm.buffer()
        args = [np.ascontiguousarray(self.x, dtype=float), np.ascontiguousarray(self.u, dtype=float),
                np.ascontiguousarray(np.broadcast_to(self.p, (n, len(self.p))), dtype=float)]
        for i, a in enumerate(args):  # C-ordered (n, k) is CasADi's column-major (k, n)
            buf.set_arg(i, memoryview(a))
        outs = [np.empty((n, f.sparsity_out(i).numel())) for i in range(f.n_out())]
        for i, o in enumerate(outs):
            buf.set_res(i, memoryview(o))
        trigger()
        return outs

    @cached_property
    def _power(self):
        dHdt, diss, sup = self._map(generate(self.system).power_balance)
        return dHdt[:, 0], diss[:, 0], sup[:, 0]

    @cached_property
    def H(self) -> np.ndarray:
        """Hamiltonian along the trajectory."""
        return self._map(generate(self.system).hamiltonian)[0][:, 0]

    @cached_property
    def energy_terms(self) -> np.ndarray:
        return self._map(generate(self.system).energy_terms)[0]

    @property
    def dissipated(self) -> np.ndarray:
        """Dissipated power z^T [[R, P], [P^T, S]] z [W]."""
        return self._power[1]

    @property
    def supplied(self) -> np.ndarray:
        """Supplied power y^T u [W]."""
        return self._power[2]

    @property
    def dHdt(self) -> np.ndarray:
        """Rate of change of the stored energy dH/dt [W]."""
        return self._power[0]

    def energy_accounts(self) -> tuple[np.ndarray, np.ndarray]:
        """``(E_supplied, E_dissipated)``: supplied and dissipated energy since ``t[0]`` [J].

        The integrator's own quadratures when the run has them (CVODES), otherwise the
        trapezoidal rule on the grid applied to :attr:`supplied` and :attr:`dissipated`.

        Examples
        --------
        >>> import numpy as np
        >>> from codegen import simulate
        >>> from systems.examples import rc_circuit
        >>> E_in, E_out = simulate(rc_circuit(), np.linspace(0, 5e-3, 51), u={"U": 1.0}).energy_accounts()
        >>> float(E_in[0]), bool(E_in[-1] > E_out[-1] > 0)
        (0.0, True)
        """
        q = self.quadratures
        if "E_supplied" in q and "E_dissipated" in q:
            return np.asarray(q["E_supplied"]), np.asarray(q["E_dissipated"])

        def cumulative(f):
            return np.concatenate([[0.0], np.cumsum(np.diff(self.t) * (f[1:] + f[:-1]) / 2)])

        return cumulative(self.supplied), cumulative(self.dissipated)

    @cached_property
    def y(self) -> np.ndarray:
        """Power-conjugate outputs (nt, nu)."""
        return self._map(generate(self.system).output)[0]

    @cached_property
    def measured(self) -> np.ndarray:
        """Measured outputs (nt, n_measured)."""
        return self._map(generate(self.system).measured)[0]

    @cached_property
    def dissipator_powers(self) -> dict[str, np.ndarray]:
        """Power dissipated by each resistive element."""
        out = self._map(generate(self.system).dissipators)[0]
        return {label: out[:, k] for k, (label, _) in enumerate(self.system.dissipators)}

    def energy_balance_error(self) -> float:
        """Largest mismatch of H(t) - H(0) and the integral of (supplied - dissipated) power,
        relative to the energy exchanged.

        The integrals are the integrator's own quadratures when available (CVODES runs),
        otherwise the trapezoidal rule on the grid.
        """
        dH = self.H - self.H[0]
        E_supplied, E_dissipated = self.energy_accounts()
        integral = E_supplied - E_dissipated
        if self.quadratures:
            scale = np.max(np.abs(E_supplied)) + np.max(np.abs(E_dissipated))
        else:
            scale = np.trapezoid(np.abs(self.supplied) + np.abs(self.dissipated), self.t)
        scale = max(scale, np.max(np.abs(dH)), 1e-300)
        return float(np.max(np.abs(dH - integral)) / scale)

    # -- names ------------------------------------------------------------------------
    @property
    def columns(self) -> list[str]:
        """Every signal name, in the order used by :meth:`table`."""
        s = self.system
        return (s.state_names + s.input_names + s.output_names + s.measured_names
                + ["H", "dissipated", "supplied"])

    def __getitem__(self, name: str) -> np.ndarray:
        s = self.system
        labels = [t.label for t in s.energy_terms]
        extra = {label: (lambda label=label: self.dissipator_powers[label]) for label, _ in s.dissipators}
        extra.update({label: (lambda k=k: self.energy_terms[:, k]) for k, label in reversed(list(enumerate(labels)))})
        extra.update({key: (lambda key=key: getattr(self, key)) for key in ("H", "dissipated", "supplied", "dHdt")})
        return signal(s, name, x=self.x, u=self.u, y=lambda: self.y, measured=lambda: self.measured, extra=extra,
                      known=self.columns, where=f" in the result of {s.name!r}")

    def unit(self, name: str) -> str:
        """Unit of the signal ``name`` (``"s"`` for the time ``t``).

        Raises
        ------
        KeyError
            When ``name`` is no signal of the result.
        """
        s = self.system
        units = {"t": "s", "H": "J", "dissipated": "W", "supplied": "W", "dHdt": "W"}
        units.update({t.label: "J" for t in s.energy_terms})
        units.update({label: "W" for label, _ in s.dissipators})
        units.update({st.name: st.unit for st in s.states})
        units.update({i.name: i.unit for i in s.inputs})
        units.update({i.output: i.output_unit for i in s.inputs})
        units.update({m.name: m.unit for m in s.measured})
        if name not in units:
            raise KeyError(f"no signal {name!r} in the result of {s.name!r}; known: {', '.join(['t', *self.columns])}")
        return units[name]

    def table(self) -> tuple[list[str], np.ndarray]:
        """Header (with ``t`` first) and the (nt, 1 + ncolumns) array of every signal."""
        cols = self.columns
        data = np.column_stack([self.t] + [self[c] for c in cols])
        return ["t"] + cols, data

    def to_csv(self, path, between: dict | None = None) -> None:
        """Write every signal to CSV atomically (a temporary file renamed into place).

        The header names each column with its unit, ``t [s],C.Q [C],...``;
        :meth:`phs.workflows.recording.Recording.from_csv` reads such headers by name.  ``between`` maps an
        input's name to how it behaved between the samples of this run, written after its unit in braces
        (``U [V] {square(1500, 3)}``, ``F [N] {zoh}``: :mod:`phs.workflows.between`), so that a fit of the file
        replays the run exactly; ``phs simulate --out`` writes it for every input.

        Examples
        --------
        >>> import os, tempfile
        >>> from systems.examples import rc_circuit
        >>> from codegen import simulate
        >>> res = simulate(rc_circuit(), np.linspace(0, 1e-3, 5), u={"U": 1.0})
        >>> with tempfile.TemporaryDirectory() as d:
        ...     res.to_csv(os.path.join(d, "r.csv"), between={"U": "1.0"})
        ...     open(os.path.join(d, "r.csv")).readline().split(",")[:3]
        ['t [s]', 'C.Q [C]', 'U [V] {1.0}']
        """
        header, data = self.table()
        notes = dict(between or {})
        unknown = [k for k in notes if k not in self.system.input_names]
        if unknown:
            raise InputDataError(f"to_csv: between= names {unknown[0]!r}, which is not an input of {self.system.name!r}")
        write_csv_atomic(path, [f"{name} [{self.unit(name)}]" + (f" {{{notes[name]}}}" if name in notes else "")
                                for name in header], data)

    def to_pandas(self) -> pd.DataFrame:
        """Every signal as a pandas DataFrame indexed by time ``t``; units in ``df.attrs["units"]``.

        Needs pandas (``pip install "phs[pandas]"``); without it, an ImportError of one line says so.

        Examples
        --------
        >>> import numpy as np
        >>> from codegen import simulate
        >>> from systems.examples import rc_circuit
        >>> df = simulate(rc_circuit(), np.linspace(0, 1e-3, 5), u={"U": 1.0}).to_pandas()  # doctest: +SKIP
        >>> float(df["v_C"].iloc[-1]), df.attrs["units"]["v_C"]  # doctest: +SKIP
        (0.6321..., 'V')
        """
        from codegen.tables import require_pandas

        pd = require_pandas("SimulationResult.to_pandas()")
        header, data = self.table()
        df = pd.DataFrame({name: data[:, k] for k, name in enumerate(header) if name != "t"},
                          index=pd.Index(self.t, name="t"))
        df.attrs["units"] = {name: self.unit(name) for name in header}
        return df

    def plot(self, path=None, fig=None, *, ax=None) -> Figure:
        """States (each divided by its typical size), measured outputs (a panel per unit) and the
        energy accounts (H - H(0), supplied and dissipated energy, and the balance residual).

        Parameters
        ----------
        path : str or path, optional
            Write the figure there (atomically, in the format of its suffix).
        fig : matplotlib Figure, optional
            Draw the panels on this figure.
        ax : matplotlib Axes or array of Axes, optional
            Draw into these axes instead, one per panel (1 + number of measured units + 1).

        Returns
        -------
        matplotlib.figure.Figure

        Examples
        --------
        >>> import numpy as np
        >>> from codegen import simulate
        >>> from systems.examples import mass_spring_damper
        >>> fig = simulate(mass_spring_damper(), np.linspace(0, 1, 11), u={"F": 1.0}).plot()
        >>> [ax.get_ylabel() for ax in fig.axes]
        ['state / scale [1]', 'measured [m]', 'energy [J]']
        """
        s = self.system
        measured_units = list(dict.fromkeys(mo.unit for mo in s.measured))   # one panel per unit
        kinds = ["states"] + measured_units + ["energy"]
        if fig is not None and ax is None:
            axes = fig.subplots(len(kinds), 1, sharex=True, squeeze=False)[:, 0]
        else:
            fig, grid = panels(ax, len(kinds), figsize=(8, 2.6 * len(kinds)), sharex=True, what="SimulationResult.plot")
            axes = grid[:, 0]
        for ax_, panel in zip(axes, kinds, strict=True):
            if panel == "states":
                for st in s.states:
                    ax_.plot(self.t, self[st.name] / st.typical, label=f"{st.name} / {st.typical:g} {st.unit}")
                ax_.set_ylabel("state / scale [1]")
            elif panel != "energy":
                for mo in s.measured:
                    if mo.unit == panel:
                        ax_.plot(self.t, self[mo.name], label=mo.name)
                ax_.set_ylabel(f"measured [{panel}]")
            else:
                E_supplied, E_dissipated = self.energy_accounts()
                ax_.plot(self.t, self.H - self.H[0], label="H - H(0)")
                ax_.plot(self.t, E_supplied, label="E_supplied (∫ supplied power dt)")
                ax_.plot(self.t, E_dissipated, label="E_dissipated (∫ dissipated power dt)")
                ax_.plot(self.t, self.H - self.H[0] - E_supplied + E_dissipated, "k:", label="balance residual")
                ax_.set_ylabel("energy [J]")
            ax_.legend(loc="best", fontsize="small")
            ax_.grid(True, alpha=0.3)
        axes[-1].set_xlabel("t [s]")
        fig.suptitle(f"{s.name}: simulation")
        return finish(fig, path, dpi=110)

    def _headline(self) -> str:
        return f"{self.system.name!r}, {len(self.t)} samples, t={self.t[0]:g}..{self.t[-1]:g}"

    def _table(self) -> tuple[list, list]:
        """Each state, input and measured output with its unit, first, last, smallest and largest value."""
        s = self.system
        shown = (s.state_names + s.input_names + s.measured_names)[:20]
        rows = []
        for name in shown:
            v = self[name]
            rows.append((name, self.unit(name), v[0], v[-1], np.min(v), np.max(v)))
        rest = len(s.state_names + s.input_names + s.measured_names) - len(shown)
        if rest:
            rows.append((f"... {rest} more signals", "", "", "", "", ""))
        return ["signal", "unit", "first", "last", "min", "max"], rows


def signal(system, name: str, *, x, u, y=None, measured=None, extra=None, known=(), where: str = "") -> np.ndarray:
    """One named signal of a trajectory: a state, input, port output, measured output or an extra signal.

    The names are looked up in that order: ``system.state_names`` (a column of ``x``), ``input_names`` (of ``u``),
    ``output_names`` (of ``y``, when given), ``measured_names`` (of ``measured``, when given), then the keys of
    ``extra``.  ``y``, ``measured`` and the values of ``extra`` may be zero-argument callables, evaluated only
    when the name is theirs (derived signals cost a CasADi evaluation over the whole grid).

    Parameters
    ----------
    system : PHSystem
    name : str
    x, u : array (nt, nx), (nt, nu)
    y, measured : array (nt, k) or callable, optional
    extra : dict, optional
        ``{name: array or callable}`` for other signals (energies, powers, controller states).
    known : sequence of str
        The names listed by the ``KeyError``.
    where : str
        Inserted after the name in the ``KeyError`` (e.g. ``" in the result of 'msd'"``).

    Raises
    ------
    KeyError
        ``no signal 'name'{where}; known: ...`` when the name is none of these.

    Examples
    --------
    >>> import numpy as np
    >>> from systems.examples import mass_spring_damper
    >>> msd = mass_spring_damper()
    >>> x, u = np.array([[0.0, 0.1], [0.2, 0.3]]), np.zeros((2, 1))
    >>> signal(msd, "k.l", x=x, u=u).tolist(), float(signal(msd, "E", x=x, u=u, extra={"E": lambda: 2.0}))
    ([0.1, 0.3], 2.0)
    >>> signal(msd, "v", x=x, u=u, known=["m.p", "k.l", "F"])
    Traceback (most recent call last):
    ...
    KeyError: "no signal 'v'; known: m.p, k.l, F"
    """
    value = lambda v: v() if callable(v) else v  # noqa: E731
    s = system
    if name in s.state_names:
        return x[:, s.state_names.index(name)]
    if name in s.input_names:
        return u[:, s.input_names.index(name)]
    if y is not None and name in s.output_names:
        return value(y)[:, s.output_names.index(name)]
    if measured is not None and name in s.measured_names:
        return value(measured)[:, s.measured_names.index(name)]
    if extra and name in extra:
        return value(extra[name])
    raise KeyError(f"no signal {name!r}{where}; known: {', '.join(known)}")


def write_csv_atomic(path, header, data) -> None:
    """Write a CSV file so that either the whole file appears or nothing does (:func:`phs.io.write_atomic`)."""
    import csv

    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow(header)  # a cell with a comma (a law in braces) is quoted
    np.savetxt(buf, data, delimiter=",", comments="", fmt="%.17g")
    write_atomic(path, buf.getvalue())
