"""Every public result object behaves alike: ``plot(path=None, *, ax=None)`` returns the figure and writes
``path``, ``to_pandas()`` (pandas optional: one line naming ``pip install "phs[pandas]"``), a short ``repr``,
an ``_repr_html_`` table, and a truth value exactly where a pass/fail exists.

The result classes are found in the source (a public class whose name ends in ``Result``, ``Report`` or
``Certificate``, or that derives from ``phs._results.ResultMixin``, plus ``Diagnosis``), so a new one
without a case in :data:`BUILD` fails :func:`test_every_result_class_has_a_case`.  Each case is small:
rc/msd systems, 11-51 samples; the diagnosis (about 5 s) restricts the candidates to the sensor offset.
"""

from __future__ import annotations

import ast
import importlib
import re
import sys
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from matplotlib.figure import Figure

from phs.errors import InputDataError

ROOT = Path(__file__).resolve().parents[1]
PATTERN = re.compile(r"(Result|Report|Certificate)$")
ALSO = {"phs.workflows.diagnose.result.Diagnosis"}
# public classes matching the pattern that are one line of a report, not a result of their own
EXEMPT = {"codegen.idapbc.certificates.Certificate": "one certificate of a CertificateReport (as PassivityTest, CheckItem)"}
# the truth value of each result with a pass/fail; every other result has none of its own
TRUTH = {
    "CheckReport": lambda r: r.ok,
    "PassivityReport": lambda r: r.passive,
    "CertificateReport": lambda r: r.passed,
    "Diagnosis": lambda d: d.effect == "none",  # the model passes: nothing significant is missing
}


def result_classes(root: Path = ROOT) -> set[str]:
    """Dotted names of the result classes defined at the top of the modules of phs and codegen."""
    found = set()
    for pkg in ("phs", "codegen", "components", "systems"):
        for path in sorted((root / pkg).rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            for node in ast.parse(path.read_text()).body:
                if not isinstance(node, ast.ClassDef) or node.name.startswith("_"):
                    continue
                bases = {b.id if isinstance(b, ast.Name) else getattr(b, "attr", "") for b in node.bases}
                if PATTERN.search(node.name) or "ResultMixin" in bases:
                    found.add(".".join(parts + [node.name]))
    return (found | ALSO) - set(EXEMPT)


# -- small instances ---------------------------------------------------------------------------------------
def _rc_recording():
    from codegen import simulate
    from phs.workflows.recording import Recording
    from systems.examples import rc_circuit

    t = np.linspace(0, 0.02, 401)
    u = np.sin(2 * np.pi * 150 * t)
    return Recording.from_arrays(t, {"U": u, "v_C": simulate(rc_circuit(), t, u={"U": u})["v_C"] + 0.05})


def _hardening():
    from components import Damper, ForceSource, Mass, NonlinearSpring
    from phs import interconnect, series

    q = sp.Symbol("q", real=True)
    comps = [ForceSource("F"), Mass("m", m=1.0), NonlinearSpring("s", force=q + q**3 / 2, variable=q), Damper("b", b=0.5)]
    return interconnect("hard", comps, [series("F", "m", "s", "b")])


def _simulation():
    from codegen import simulate
    from systems.examples import mass_spring_damper

    return simulate(mass_spring_damper(), np.linspace(0, 1, 11), u={"F": 1.0})


def _batch():
    from codegen.batch import BatchSimulator
    from systems.examples import rc_circuit

    return BatchSimulator(rc_circuit(), np.linspace(0, 1e-3, 11), threads=1).run([{"R.R": 1e3}, {"R.R": 2e3}], u={"U": 1.0})


def _controller():
    from codegen.idapbc import design
    from systems.examples import mass_spring_damper

    return design(mass_spring_damper(), {"position": 0.5}, damping=1.0)


def _identification():
    from phs.workflows.identify import identify
    from systems.examples import rc_circuit

    return identify(rc_circuit(R=1.2e3), _rc_recording(), ["R.R"], progress=False)


def _diagnosis():
    from components.candidates import Offset
    from phs.workflows.diagnose import diagnose
    from systems.examples import rc_circuit

    return diagnose(rc_circuit(), _rc_recording(), free=["R.R"], candidates=[Offset()], n_jobs=1)


def _trials():
    from components.candidates import Offset
    from phs.workflows.diagnose.trials import diagnose_trials
    from systems.examples import rc_circuit

    rec = _rc_recording()
    return diagnose_trials(rc_circuit(), {"a": rec, "b": rec}, free=["R.R"], candidates=[Offset()], n_jobs=1)


def _study():
    from phs.workflows.sweep import Study, sweep
    from systems.examples import rc_circuit

    study = Study(rc_circuit(), np.linspace(0, 1e-3, 11), u={"U": 1.0}, grid={"R.R": [1e3, 2e3]}, metrics=["final:v_C"])
    return sweep(study, threads=1, progress=False)


def _passivity():
    from codegen.passivity import certify
    from systems.examples import rlc_circuit

    return certify(rlc_circuit(), samples=64, starts=1)


def _equilibrium():
    from phs import equilibrium

    return equilibrium(_hardening(), u={"F": 2.0})


def _linearization():
    from phs import linearize

    return linearize(_hardening(), _equilibrium())


def _check():
    from systems.examples import rc_circuit

    return rc_circuit().check()


BUILD = {
    "codegen.results.SimulationResult": _simulation,
    "codegen._batch_result.BatchResult": _batch,
    "codegen.idapbc.closed_loop.ClosedLoopResult": lambda: _controller().simulate(np.linspace(0, 5, 51)),
    "codegen.idapbc.certificates.CertificateReport": lambda: _controller().certify(rays=8, simulations=2),
    "phs.workflows.identify.result.IdentificationResult": _identification,
    "phs.workflows.diagnose.result.Diagnosis": _diagnosis,
    "phs.workflows.sweep.result.StudyResult": _study,
    "phs.workflows.diagnose.trials_summary.Trials": _trials,
    "codegen.passivity.report.PassivityReport": _passivity,
    "phs.equilibria.EquilibriumResult": _equilibrium,
    "codegen._linearization.LinearizationResult": _linearization,
    "phs.checks.CheckReport": _check,
}
_BUILT: dict = {}


def built(name: str):
    """The instance of ``name``, built once per test process (each is a few seconds at most)."""
    if name not in _BUILT:
        _BUILT[name] = BUILD[name]()
        mod, _, cls = name.rpartition(".")
        assert type(_BUILT[name]) is getattr(importlib.import_module(mod), cls)
    return _BUILT[name]


CASES = sorted(BUILD)
IDS = [n.rpartition(".")[2] for n in CASES]


def test_every_result_class_has_a_case():
    found = result_classes()
    assert found - set(BUILD) == set(), f"result classes without a case in BUILD: {sorted(found - set(BUILD))}"
    assert set(BUILD) - found == set(), f"cases for classes no longer found: {sorted(set(BUILD) - found)}"


def test_the_discovery_finds_a_new_result_class(tmp_path):
    (tmp_path / "phs").mkdir()
    (tmp_path / "phs" / "fits.py").write_text("class FitResult:\n    pass\n\nclass _Private(Report):\n    pass\n"
                                              "class Plain(ResultMixin):\n    pass\n")
    for pkg in ("codegen", "components", "systems"):
        (tmp_path / pkg).mkdir()
    assert result_classes(tmp_path) == {"phs.fits.FitResult", "phs.fits.Plain"} | ALSO


# -- the behaviour ---------------------------------------------------------------------------------------
def _panels(fig) -> list:
    """The data axes of a figure (colorbars excluded)."""
    return [a for a in fig.axes if a.get_label() != "<colorbar>"]


def _drawn(ax) -> bool:
    return bool(ax.lines or ax.collections or ax.patches or ax.texts or ax.images)


@pytest.mark.parametrize("name", CASES, ids=IDS)
def test_plot_writes_a_png_and_returns_the_figure(name, tmp_path):
    res = built(name)
    path = tmp_path / "result.png"
    fig = res.plot(path)
    assert isinstance(fig, Figure)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert _panels(fig) and all(_drawn(a) for a in _panels(fig))
    assert [p.name for p in tmp_path.iterdir()] == ["result.png"]  # written atomically: no temporary left


@pytest.mark.parametrize("name", CASES, ids=IDS)
def test_plot_draws_into_given_axes(name):
    res = built(name)
    n = len(_panels(res.plot()))
    host = Figure()
    axes = host.subplots(n, 1, squeeze=False)[:, 0] if n > 1 else host.subplots()
    fig = res.plot(ax=axes)
    assert fig is host
    assert all(_drawn(a) for a in np.ravel(axes))
    if n > 1:  # too few axes: one line naming the call
        with pytest.raises(InputDataError, match=r"plot\(ax=\.\.\.\): this figure has \d+ panels, ax= gives 1 axes"):
            res.plot(ax=Figure().subplots())


@pytest.mark.parametrize("name", CASES, ids=IDS)
def test_to_pandas(name):
    pd = pytest.importorskip("pandas")
    df = built(name).to_pandas()
    assert isinstance(df, pd.DataFrame) and len(df) > 0


@pytest.mark.parametrize("name", CASES, ids=IDS)
def test_to_pandas_without_pandas_says_so_in_one_line(name, monkeypatch):
    monkeypatch.setitem(sys.modules, "pandas", None)
    with pytest.raises(ImportError) as exc:
        built(name).to_pandas()
    msg = str(exc.value)
    assert 'pip install "phs[pandas]"' in msg and "\n" not in msg and "to_pandas()" in msg


@pytest.mark.parametrize("name", CASES, ids=IDS)
def test_repr_is_short_and_shows_no_array(name):
    text = repr(built(name))
    cls = name.rpartition(".")[2]
    assert text.startswith(f"{cls}(") and len(text) < 400 and "\n" not in text, text
    assert "array(" not in text and "[[" not in text and "dtype" not in text, text


@pytest.mark.parametrize("name", CASES, ids=IDS)
def test_repr_html_is_a_table(name):
    html = built(name)._repr_html_()
    assert isinstance(html, str) and "<table" in html and "</table>" in html


@pytest.mark.parametrize("name", CASES, ids=IDS)
def test_truth_value_exactly_where_a_pass_fail_exists(name):
    res = built(name)
    cls = type(res)
    if cls.__name__ in TRUTH:
        assert "__bool__" in vars(cls)
        assert bool(res) is bool(TRUTH[cls.__name__](res))
    else:  # the default truth (or that of __len__): no verdict is claimed
        assert not any("__bool__" in vars(k) for k in cls.__mro__ if k is not object), cls


def test_the_truth_values_follow_the_verdicts():
    assert bool(built("phs.checks.CheckReport")) and bool(built("codegen.passivity.report.PassivityReport"))
    assert bool(built("codegen.idapbc.certificates.CertificateReport"))
    d = built("phs.workflows.diagnose.result.Diagnosis")
    assert d.effect == "offset" and not d  # an effect was named: the nominal model does not pass


def test_a_failed_check_is_false():
    from phs.checks import CheckItem, CheckReport

    rep = CheckReport("s", (CheckItem("J skew-symmetric", "pass", "symbolic", ""), CheckItem("units", "fail", "", "N")))
    assert not rep and CheckReport("s", (CheckItem("units", "undecided", "", ""),))


# -- earlier call forms ------------------------------------------------------------------------------------
def test_closed_loop_plot_takes_a_path_and_the_earlier_figure_forms(tmp_path):
    res = built("codegen.idapbc.closed_loop.ClosedLoopResult")
    assert isinstance(res.plot(str(tmp_path / "cl.png")), Figure) and (tmp_path / "cl.png").exists()
    host = Figure()
    assert res.plot(host) is host and len(host.axes) == 3  # plot(fig), positional
    host = Figure()
    assert res.plot(fig=host) is host and len(host.axes) == 3


def test_simulation_plot_keeps_its_fig_argument():
    host = Figure()
    assert built("codegen.results.SimulationResult").plot(None, host) is host and len(host.axes) == 3


def test_plot_refuses_what_is_no_axes():
    with pytest.raises(InputDataError, match=r"CheckReport.plot\(ax=\.\.\.\): expected a matplotlib Axes"):
        built("phs.checks.CheckReport").plot(ax="left")


def test_recording_repr_shows_no_samples():
    rec = _rc_recording()
    text = repr(rec)
    assert text == "Recording('<arrays>', 401 samples, t=0..0.02 s, dt=5e-05 s; signals U, v_C)"


# -- linearize at an equilibrium -----------------------------------------------------------------------------
def test_linearize_at_an_equilibrium_result_uses_its_state_and_input():
    """On the hardening spring F = q + q^3/2 under F = 2 N, the equilibrium solves q + q^3/2 = 2 (q = 1.1795),
    and the linearised stiffness is 1 + 3 q^2 / 2 = 3.087 N/m (1 N/m at rest, where a linearisation that
    ignored the equilibrium would sit).  Tolerance 1e-9: the equilibrium's residual is ~1e-13."""
    from phs import equilibrium, linearize

    s = _hardening()
    eq = equilibrium(s, u={"F": 2.0})
    q = eq["s.q"]
    assert q + q**3 / 2 == pytest.approx(2.0, rel=1e-9)
    ss = linearize(s, eq)
    assert ss.A[0, 1] == pytest.approx(-(1 + 1.5 * q**2), rel=1e-9)
    assert ss.x_eq == pytest.approx(eq.as_dict()) and ss.u_eq == {"F": 2.0}
    np.testing.assert_array_equal(ss.A, linearize(s, eq.as_dict(), {"F": 2.0}).A)
    assert linearize(s, eq, {"F": 2.0}).u_eq == {"F": 2.0}  # the same input given twice is accepted


def test_linearize_refuses_a_differing_input_or_another_systems_equilibrium():
    from phs import equilibrium, linearize
    from systems.examples import rc_circuit

    s = _hardening()
    eq = equilibrium(s, u={"F": 2.0})
    with pytest.raises(InputDataError, match=r"u_eq \{'F': 1.0\} differs from the input of the equilibrium"):
        linearize(s, eq, {"F": 1.0})
    with pytest.raises(InputDataError, match=r"x_eq: the equilibrium of 'hard' has states m.p, s.q; 'rc' has C.Q"):
        linearize(rc_circuit(), eq)
