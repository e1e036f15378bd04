"""The passivity certificate of one system (:class:`PassivityReport`): verdict, margin, JSON, text and HTML."""

from __future__ import annotations

import base64
import html
import json

import casadi as ca

from codegen._named import find_named
from codegen.passivity._figures import _figures, draw, drawn
from codegen.passivity._result import PassivityTest, _fmt_point, _jsonable
from phs._results import ResultMixin, draw_verdicts, finish, panels, require_pandas
from phs.errors import InputDataError
from phs.io import write_all_atomic


class PassivityReport(ResultMixin):
    """Passivity certificate of one system: the tests, their verdicts and the margin.

    ``bool(report)`` is :attr:`passive` (an undecided required test makes it False: not certified);
    ``report["storage"]`` is one :class:`PassivityTest`; ``str(report)`` is the full text, ``repr`` one line;
    :meth:`plot` draws the tests that have data, :meth:`to_pandas` gives one row per test.

    Attributes
    ----------
    passive : bool
        True when no test failed and the interconnection, dissipation, feedthrough and storage tests passed.
    tests : list of PassivityTest
    margin : float
        Smallest scaled eigenvalue of R over the box, or the (negative) one of ``[[R, P], [P^T, S]]`` when that
        has one: its sign is the dissipation verdict (scaling in :mod:`codegen.passivity`).

    Examples
    --------
    >>> from codegen.passivity import certify
    >>> from systems.examples import rlc_circuit
    >>> rep = certify(rlc_circuit(), samples=64, starts=1)
    >>> rep.passive, [t.verdict for t in rep.tests], round(rep.margin, 6)
    (True, ['pass', 'pass', 'pass', 'pass'], 1.0)
    >>> bool(rep), rep
    (True, PassivityReport('rlc', passive, margin 1; interconnection pass, dissipation pass, feedthrough pass, storage pass))
    >>> rep.to_dict()["tests"]["dissipation"]["verdict"]
    'pass'
    """

    REQUIRED = ("interconnection", "dissipation", "feedthrough", "storage")

    def __init__(self, system, tests, margin: float, box: dict, params: dict, info: dict | None = None):
        self.system = system
        self.tests = list(tests)
        self.margin = float(margin)
        self.box = dict(box)
        self.params = dict(params)
        self.info = dict(info or {})

    @property
    def passive(self) -> bool:
        names = {t.name: t for t in self.tests}
        return (all(t.verdict != "fail" for t in self.tests)
                and all(names[n].verdict == "pass" for n in self.REQUIRED if n in names))

    def __bool__(self) -> bool:
        return self.passive

    def __getitem__(self, name: str) -> PassivityTest:
        return find_named(self.tests, name, "test")

    def to_dict(self) -> dict:
        """JSON-ready summary: top-level ``passive`` and ``margin``, one entry per test under ``tests``."""
        from phs._version import __version__

        return _jsonable({
            "system": self.system.name, "model_hash": self.system.model_hash(), "passive": self.passive,
            "margin": self.margin, "box": {k: list(v) for k, v in self.box.items()}, "params": self.params,
            "tests": {t.name: t.to_dict() for t in self.tests},
            "provenance": {"phs_version": __version__, "casadi_version": ca.__version__, **self.info},
        })

    def text(self) -> str:
        head = (f"Passivity of {self.system.name!r} (model {self.system.model_hash()}): "
                f"{'PASSIVE' if self.passive else 'NOT CERTIFIED PASSIVE'}; margin {self.margin:.4g}")
        varied = [k for k in self.box if k not in self.system.state_names]
        box = (f"box: {len(self.system.states)} states" + (f" and parameters {', '.join(varied)}" if varied else "")
               + " (declared ranges unless given); other parameters at their values")
        return "\n".join([head, "  " + box] + [t.line() for t in self.tests])

    def __str__(self) -> str:
        return self.text()

    def _headline(self) -> str:
        verdicts = ", ".join(f"{t.name} {t.verdict}" for t in self.tests)
        return (f"{self.system.name!r}, {'passive' if self.passive else 'not certified passive'}, "
                f"margin {self.margin:.4g}; {verdicts}")

    def _table(self) -> tuple[list, list]:
        return (["test", "verdict", "method", "numbers", "element"],
                [(t.name, t.verdict, t.method, t.summary, t.element) for t in self.tests])

    def to_pandas(self):  # noqa: ANN201 - pandas is optional
        """One row per test (verdict, method, summary, element), indexed by the test's name; the margin in
        ``df.attrs["margin"]``.

        Needs pandas (``pip install "phs[pandas]"``); without it, an ImportError of one line says so.

        Examples
        --------
        >>> from codegen.passivity import certify
        >>> from systems.examples import rlc_circuit
        >>> certify(rlc_circuit(), samples=64, starts=1).to_pandas().loc["storage", "verdict"]  # doctest: +SKIP
        'pass'
        """
        pd = require_pandas("PassivityReport.to_pandas()")
        rows = [(t.name, t.verdict, t.method, t.summary, t.element) for t in self.tests]
        df = pd.DataFrame({c: [r[k] for r in rows] for k, c in enumerate(["verdict", "method", "summary", "element"], 1)},
                          index=pd.Index([r[0] for r in rows], name="test"))
        df.attrs["margin"], df.attrs["passive"] = self.margin, self.passive
        return df

    def plot(self, path=None, *, ax=None):  # noqa: ANN201 - matplotlib is imported on demand
        """A row of two panels per test with data (dissipation and storage over the box, the energy accounts
        of a trajectory, the frequency indices of the local test); one coloured row per test when none has.

        Parameters
        ----------
        path : str or path, optional
            Write the figure there (atomically, in the format of its suffix).
        ax : matplotlib Axes or array of Axes, optional
            Draw into these axes: two per test with data, in reading order (one when no test has data).

        Returns
        -------
        matplotlib.figure.Figure

        Examples
        --------
        >>> from codegen.passivity import certify
        >>> from systems.examples import rlc_circuit
        >>> fig = certify(rlc_circuit(), samples=64, starts=1).plot()
        >>> len(fig.axes), fig.axes[0].get_title()
        (4, 'dissipation (pass)')
        """
        tests = drawn(self)
        head = f"{self.system.name}: {'PASSIVE' if self.passive else 'NOT CERTIFIED PASSIVE'}, margin {self.margin:.4g}"
        if not tests:
            fig, grid = panels(ax, 1, figsize=(9, 0.4 * len(self.tests) + 0.9), what="PassivityReport.plot")
            draw_verdicts(grid[0, 0], [(t.name, t.verdict, t.summary) for t in self.tests], title=head)
            return finish(fig, path)
        fig, grid = panels(ax, len(tests), 2, figsize=(9, 3.4 * len(tests)), what="PassivityReport.plot")
        for t, pair in zip(tests, grid, strict=True):
            draw(t, pair)
            pair[0].set_title(f"{t.name} ({t.verdict})", fontsize=9)
        fig.suptitle(head)
        return finish(fig, path)

    _repr_pretty_ = lambda self, p, cycle: p.text(self.text())  # noqa: E731

    def figures(self) -> dict[str, bytes]:
        """PNG figures of the tests that have data to plot, by file name."""
        return _figures(self)

    def report_files(self) -> dict:
        """The files of :meth:`write_report`, rendered in memory: ``{name: text or PNG bytes}``.

        Examples
        --------
        >>> from codegen.passivity import certify
        >>> from systems.examples import rc_circuit
        >>> sorted(certify(rc_circuit(), samples=16, starts=0).report_files())
        ['dissipation.png', 'report.html', 'report.json', 'report.txt', 'storage.png']
        """
        figs = self.figures()
        return {"report.json": json.dumps(self.to_dict(), indent=1, allow_nan=False) + "\n",
                "report.txt": self.text() + "\n", "report.html": _html(self, figs), **figs}

    def write_report(self, directory) -> list[str]:
        """Write ``report.html`` (with the figures inline), ``report.json``, ``report.txt`` and the PNG figures.

        Everything is rendered in memory first and the files are written all or nothing
        (:func:`phs.io.write_all_atomic`); the directory is created if its parent exists (and removed
        again when the writing fails).  Returns the paths written.
        """
        import os

        directory = os.fspath(directory)
        parent = os.path.dirname(os.path.abspath(directory))
        if not os.path.isdir(parent):
            raise InputDataError(f"cannot write the report into {directory!r}: directory {parent!r} does not exist")
        if os.path.exists(directory) and not os.path.isdir(directory):
            raise InputDataError(f"cannot write the report into {directory!r}: it exists and is not a directory")
        files = {os.path.join(directory, name): data for name, data in self.report_files().items()}
        write_all_atomic(files, create=[directory])
        return list(files)


def _html(report: PassivityReport, figs: dict[str, bytes]) -> str:
    esc = html.escape
    rows = []
    for t in report.tests:
        color = {"pass": "#2a7", "fail": "#c33", "undecided": "#c90"}[t.verdict]
        rows.append(f"<tr><td>{esc(t.name)}</td><td style='color:{color};font-weight:bold'>{t.verdict}</td>"
                    f"<td>{esc(t.summary)}</td><td>{esc(t.element)}</td><td>{esc(_fmt_point(t.worst))}</td>"
                    f"<td>{esc(t.method)}</td></tr>")
    imgs = "".join(f"<h2>{esc(n[:-4])}</h2><img alt='{esc(n)}' src='data:image/png;base64,"
                   f"{base64.b64encode(png).decode()}'/>" for n, png in figs.items())
    verdict = "PASSIVE" if report.passive else "NOT CERTIFIED PASSIVE"
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>Passivity of {esc(report.system.name)}</title>"
            "<style>body{font-family:sans-serif;margin:2em}td,th{border:1px solid #ccc;padding:4px;vertical-align:top}"
            "table{border-collapse:collapse}</style></head><body>"
            f"<h1>Passivity of {esc(report.system.name)}: {verdict}</h1>"
            f"<p>model hash {esc(report.system.model_hash())}; margin {report.margin:.4g} (smallest scaled eigenvalue "
            f"of [[R, P], [P^T, S]] over the box)</p>"
            "<table><tr><th>test</th><th>verdict</th><th>numbers</th><th>element</th><th>worst point</th><th>method</th></tr>"
            + "".join(rows) + "</table>" + imgs
            + f"<h2>JSON</h2><pre>{esc(json.dumps(report.to_dict(), indent=1))}</pre></body></html>\n")
