"""Results in notebooks: ``to_pandas()`` (pandas is optional: a one-line error without it), ``plot()``
and ``_repr_html_`` (small tables, every string escaped)."""

from __future__ import annotations

import dataclasses
import sys
import types

import numpy as np
import pytest

from codegen import simulate
from codegen.tables import html_table
from phs.workflows.bundled import recording_path
from phs.workflows.recording import Recording
from phs.workflows.sweep import StudyResult
from systems.examples import mass_spring_damper


class _FakeFrame:
    """Stands in for pandas.DataFrame where pandas is not installed: keeps the columns, index and attrs."""

    def __init__(self, data, index=None):
        self.data, self.index, self.attrs = {k: np.asarray(v) for k, v in data.items()}, index, {}

    @property
    def columns(self):
        return list(self.data)


class _FakeIndex:
    def __init__(self, values, name=None):
        self.values, self.name = list(values), name


@pytest.fixture
def fake_pandas(monkeypatch):
    mod = types.ModuleType("pandas")
    mod.DataFrame, mod.Index = _FakeFrame, _FakeIndex
    monkeypatch.setitem(sys.modules, "pandas", mod)
    return mod


@pytest.fixture
def no_pandas(monkeypatch):
    monkeypatch.setitem(sys.modules, "pandas", None)


@pytest.fixture(scope="module")
def res():
    return simulate(mass_spring_damper(), np.linspace(0, 1, 11), u={"F": 1.0})


@pytest.fixture(scope="module")
def fit():
    from phs.workflows.identify import identify

    return identify(mass_spring_damper(), Recording.from_csv(recording_path("msd_two_tone")), ["k.K", "b.b"],
                    progress=False)


@pytest.fixture(scope="module")
def diagnosis():
    from components.candidates import LIBRARY
    from phs.workflows.diagnose import diagnose

    rec = Recording.from_csv(recording_path("msd_two_tone"))
    return diagnose(mass_spring_damper(), rec, free=["k.K", "b.b"],
                    candidates=[c for c in LIBRARY if c.effect == "coulomb_friction"], n_jobs=1, progress=False)


def _study():
    cols = {"run": np.arange(2), "R.R": np.array([1e3, 2e3]), "final_v_C": np.array([0.6, 0.4]),
            "status": np.array(["ok", "ok"], dtype=object), "error": np.array(["", ""], dtype=object)}
    return StudyResult(cols, ["R.R"], ["final_v_C"], units={"R.R": "Ohm", "final_v_C": "V"})


def test_simulation_to_pandas_has_every_signal_and_units(res, fake_pandas):
    df = res.to_pandas()
    assert df.columns == res.columns
    assert df.index.name == "t" and df.index.values == res.t.tolist()
    np.testing.assert_array_equal(df.data["position"], res["position"])
    assert df.attrs["units"]["t"] == "s" and df.attrs["units"]["m.p"] == "kg*m/s" and df.attrs["units"]["H"] == "J"


@pytest.mark.parametrize("call", [lambda r, f: r.to_pandas(), lambda r, f: f.to_pandas(),
                                  lambda r, f: _study().to_pandas()], ids=["simulation", "identification", "study"])
def test_without_pandas_one_line_names_pip_install(res, fit, no_pandas, call):
    with pytest.raises(ImportError) as exc:
        call(res, fit)
    assert 'pip install "phs[pandas]"' in str(exc.value) and "\n" not in str(exc.value)


def test_identification_to_pandas_one_row_per_parameter(fit, fake_pandas):
    df = fit.to_pandas()
    assert df.index.values == ["k.K", "b.b"] and df.index.name == "parameter"
    assert df.columns == ["unit", "initial", "fitted", "std_error", "ci_low", "ci_high"]
    np.testing.assert_allclose(df.data["fitted"], [fit.values["k.K"], fit.values["b.b"]])
    assert df.attrs["units"] == {"k.K": "N/m", "b.b": "N*s/m"}


def test_study_to_pandas_carries_units(fake_pandas):
    df = _study().to_pandas()
    assert df.columns[:3] == ["run", "R.R", "final_v_C"]
    assert df.attrs["units"] == {"R.R": "Ohm", "final_v_C": "V"}


def test_with_real_pandas(res, fit):
    pd = pytest.importorskip("pandas")
    df = res.to_pandas()
    assert isinstance(df, pd.DataFrame) and df.index.name == "t" and df.attrs["units"]["position"] == "m"
    assert list(fit.to_pandas().index) == ["k.K", "b.b"]
    assert _study().to_pandas().attrs["units"]["R.R"] == "Ohm"


def test_simulation_plot_draws_panels_and_writes_atomically(res, tmp_path):
    fig = res.plot(tmp_path / "sim.png")
    assert len(fig.axes) == 3  # states, measured [m], energy
    assert (tmp_path / "sim.png").read_bytes()[:4] == b"\x89PNG"
    assert [p.name for p in tmp_path.iterdir()] == ["sim.png"]


def test_html_table_escapes_every_string():
    text = html_table(["<th>"], [["<script>alert(1)</script>", 0.5]], caption="a<b")
    assert "<script>" not in text and "&lt;script&gt;" in text and "a&lt;b" in text and "&lt;th&gt;" in text


def test_identification_repr_html(fit):
    text = fit._repr_html_()
    assert text.count("<table>") == 2 and "k.K" in text and "N/m" in text and "position" in text
    evil = dataclasses.replace(fit, fit_percent={"<img src=x>": 50.0})
    assert "<img" not in evil._repr_html_() and "&lt;img src=x&gt;" in evil._repr_html_()


def test_diagnosis_repr_html(diagnosis):
    text = diagnosis._repr_html_()
    assert text.count("<table>") == 2 and "coulomb_friction" in text and "verdict none" in text
    evil = dataclasses.replace(diagnosis, verdict={**diagnosis.verdict, "explanation": "<script>x</script>"})
    assert "<script>" not in evil._repr_html_() and "&lt;script&gt;x" in evil._repr_html_()
