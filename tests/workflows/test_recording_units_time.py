"""Recordings' time stamps and units: jitter accepted as a uniform grid, units in headers converted to the
model's (or refused in one line), in Python (``Recording``, ``identify``, ``diagnose``) and on the command
line (``phs fit``, ``phs diagnose``, ``phs simulate --input``) alike (phs.workflows.recording, phs.workflows.inputs).

Data: the mass-spring-damper (``systems.examples.mass_spring_damper``: input ``F`` [N], measured
``position`` [m]) with stiffness 6 N/m and damping 0.7 N*s/m, simulated on 10 s at 100 Hz under a sum of two
sines, fitted from the defaults (4, 0.4); and the RC circuit (input ``U`` [V], port output ``U.i`` [A],
measured ``v_C`` [V]) for ``kV``, ``mA`` and ``mV`` headers.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from codegen import simulate
from phs.errors import InputDataError
from phs.workflows.cli import main
from phs.workflows.identify import identify
from phs.workflows.inputs import JITTER, read_input_csv, uniform_grid
from phs.workflows.recording import Recording
from systems.examples import mass_spring_damper, rc_circuit

MSD = "systems.examples:mass_spring_damper"
TRUE = {"k.K": 6.0, "b.b": 0.7}
FREE = ["k.K", "b.b"]
EMPS = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "emps"

# Two fits of the same samples whose numbers differ only by rounding (a value times 1e3 in the file, times
# 1e-3 on reading: 1 ulp) or whose grids differ by rounding (t0 + k*dt at t0 = 1234.5 s: 1e-13 s) follow the
# same trust-region path; they agree far within the fits' own convergence (ftol 1e-8 on the cost, about
# 1e-6 relative on the parameters of this well-conditioned fit).
SAME = 1e-6


@pytest.fixture(scope="module")
def msd_data():
    t = np.round(np.arange(1001) * 0.01, 12)
    f = np.sin(2 * np.pi * 0.3 * t) + 0.5 * np.sin(2 * np.pi * 0.11 * t)  # smooth: read alike however interpolated
    y = simulate(mass_spring_damper().with_params(TRUE), t, u={"F": f}, rtol=1e-10)["position"]
    return t, f, y + 1e-4 * np.random.default_rng(3).standard_normal(t.size)


def _write(path, header, *columns):
    rows = [",".join(header)] + [",".join(f"{v:.17g}" for v in row) for row in zip(*columns, strict=True)]
    Path(path).write_text("\n".join(rows) + "\n")
    return str(path)


def _fit(rec):
    return identify(mass_spring_damper(), rec, FREE, rtol=1e-9).values


def _close(a, b, rel=SAME):
    assert set(a) == set(b)
    for k in a:
        assert a[k] == pytest.approx(b[k], rel=rel), (k, a[k], b[k])


@pytest.fixture(scope="module")
def si_fit(msd_data):
    t, f, y = msd_data
    fit = _fit(Recording.from_arrays(t, {"F": f, "position": y}))
    _close(fit, TRUE, rel=0.01)  # the fit itself finds the truth (noise 1e-4 m on a response of ~0.1 m)
    return fit


# -- units ------------------------------------------------------------------------------------------------
def test_headers_in_kN_and_mm_fit_like_their_converted_twin(tmp_path, msd_data, si_fit):
    t, f, y = msd_data
    path = _write(tmp_path / "lab.csv", ["t [s]", "F [kN]", "position [mm]"], t, f / 1e3, y * 1e3)
    rec = Recording.from_csv(path)
    assert rec.units == {"F": "kN", "position": "mm"}
    assert np.allclose(rec.in_units_of(mass_spring_damper())["F"], f, rtol=1e-15)
    _close(_fit(rec), si_fit)  # identify converts on entry

    out = tmp_path / "fit.json"
    code = main(["fit", MSD, path, "--free", ",".join(FREE), "--json", str(out), "--quiet"])
    assert code == 0
    _close(json.loads(out.read_text())["values"], si_fit, rel=1e-4)  # the CLI fits at its default rtol 1e-8


def test_headers_in_kV_mA_mV_fit_like_their_converted_twin(tmp_path):
    t = np.arange(401) * 5e-5
    u = 0.5 + np.sin(2 * np.pi * 100 * t)
    res = simulate(rc_circuit().with_params({"R.R": 1500.0}), t, u={"U": u}, rtol=1e-10)
    si = Recording.from_arrays(t, {"U": u, "v_C": res["v_C"], "U.i": res["U.i"]})
    lab = Recording.from_csv(_write(tmp_path / "rc.csv", ["t [ms]", "U [kV]", "v_C [mV]", "U.i [mA]"],
                                    t * 1e3, u / 1e3, res["v_C"] * 1e3, res["U.i"] * 1e3))
    assert lab.t == pytest.approx(t, abs=1e-15)
    fits = [identify(rc_circuit(), r, ["R.R"], outputs=["v_C", "U.i"], rtol=1e-9).values for r in (si, lab)]
    _close(*fits)
    assert fits[0]["R.R"] == pytest.approx(1500.0, rel=1e-4)


def test_a_scale_takes_precedence_over_the_header(tmp_path, msd_data):
    t, f, y = msd_data
    path = _write(tmp_path / "s.csv", ["t", "F", "position [mm]"], t[:5], f[:5], y[:5] * 1e3)
    by_factor = Recording.from_csv(path, scales={"position": 1e-3}).in_units_of(mass_spring_damper())
    by_units = Recording.from_csv(path, scales={"position": ("mm", "cm")}).in_units_of(mass_spring_damper())
    assert by_factor["position"] == pytest.approx(y[:5], rel=1e-14)  # not converted a second time
    assert by_units["position"] == pytest.approx(y[:5], rel=1e-14)   # mm -> cm by the scale, cm -> m by the model
    assert by_units.units["position"] == "m"


@pytest.mark.parametrize("header, culprits", [
    ("position [s]", ["'position'", "'s'", "'m'", "different dimensions"]),
    ("position [1]", ["'position'", "'1'", "'m'", "different dimensions"]),  # a plain number is not metres
    ("position [furlong]", ["'position'", "'furlong'", "'m'", "unknown unit"]),
])
def test_a_unit_that_cannot_be_converted_is_refused_in_one_line(tmp_path, capsys, msd_data, header, culprits):
    t, f, y = msd_data
    path = _write(tmp_path / "bad.csv", ["t", "F [N]", header], t[:50], f[:50], y[:50])
    with pytest.raises(InputDataError) as err:
        identify(mass_spring_damper(), Recording.from_csv(path), FREE)
    for msg in (str(err.value), _cli_error(capsys, ["fit", MSD, path, "--free", "k.K"]),
                _cli_error(capsys, ["diagnose", MSD, path, "--free", "k.K"])):
        assert "\n" not in msg.strip() and "bad.csv" in msg, msg
        for c in culprits:
            assert c in msg, msg


def test_a_mapped_column_is_named_by_its_own_name(tmp_path, msd_data):
    t, f, y = msd_data
    path = _write(tmp_path / "m.csv", ["t", "F", "x [s]"], t[:5], f[:5], y[:5])
    rec = Recording.from_csv(path, mapping={"x": "position"})
    with pytest.raises(InputDataError, match=r"column 'x' is in 's', .* 'm', the model's unit of 'position'"):
        rec.in_units_of(mass_spring_damper())


def _cli_error(capsys, argv) -> str:
    assert main(argv) == 2
    return capsys.readouterr().err


def test_simulate_input_converts_header_units_and_refuses_others(tmp_path, capsys):
    t = np.arange(11) * 0.1
    f = np.sin(t)
    si = _write(tmp_path / "si.csv", ["t", "F"], t, f)
    lab = _write(tmp_path / "lab.csv", ["t [ms]", "F [mN]"], t * 1e3, f * 1e3)
    out = []
    for name, path in (("si", si), ("lab", lab)):
        dest = tmp_path / f"{name}_out.csv"
        assert main(["simulate", MSD, "--t-end", "1", "--dt", "0.1", "--input", path, "--out", str(dest)]) == 0
        out.append(np.loadtxt(dest, delimiter=",", skiprows=1))
    assert np.allclose(out[0], out[1], rtol=1e-12, atol=1e-15)
    capsys.readouterr()  # the runs' own stderr (k.l leaves its declared +-0.1 m: a warning) is not the refusal's
    bad = _write(tmp_path / "bad.csv", ["t", "F [m]"], t, f)
    msg = _cli_error(capsys, ["simulate", MSD, "--t-end", "1", "--input", bad, "--out", str(tmp_path / "x.csv")])
    assert "bad.csv" in msg and "'F'" in msg and "'m'" in msg and "'N'" in msg and msg.count("\n") == 1, msg
    assert not (tmp_path / "x.csv").exists()


# -- time stamps -------------------------------------------------------------------------------------------
def _jittered(t, spread=3e-5, seed=7):
    """Stamps moved by uniform noise of total relative spread ``spread`` of a step (as the EMPS logger's)."""
    dt = t[1] - t[0]
    return t + dt * spread * (np.random.default_rng(seed).random(t.size) - 0.5)


def test_jittered_stamps_are_accepted_and_fit_like_exact_ones(tmp_path, msd_data, si_fit):
    t, f, y = msd_data
    tj = _jittered(t)
    steps = np.diff(tj)
    assert 2e-5 < np.ptp(steps) / 0.01 < 6e-5  # the jitter the old check (spread 1e-6) refused
    path = _write(tmp_path / "jitter.csv", ["t", "F", "position"], tj, f, y)
    rec = Recording.from_csv(path)
    assert rec.t[0] == tj[0]  # the first stamp kept
    assert np.ptp(np.diff(rec.t)) < 1e-9 * rec.dt  # a uniform grid, to rounding
    assert np.max(np.abs(rec.t - tj)) < JITTER * rec.dt
    _close(_fit(rec), si_fit)
    # from arrays alike; and the input of `phs simulate` (the same rule)
    assert np.array_equal(Recording.from_arrays(tj, {"F": f, "position": y}).t, rec.t)
    t_in, _ = read_input_csv(path, mass_spring_damper())
    assert np.array_equal(t_in, rec.t)


def test_time_may_start_anywhere(msd_data, si_fit):
    t, f, y = msd_data
    late = Recording.from_arrays(1234.5 + _jittered(t), {"F": f, "position": y})
    assert late.t[0] == pytest.approx(1234.5, abs=1e-6) and late.dt == pytest.approx(0.01, rel=1e-6)
    _close(_fit(late), si_fit)


_ROWS = "t,y\n0,0\n0.001,1\n0.002,2\n0.003,3\n0.004,4\n0.005,5\n0.006,6\n"


@pytest.mark.parametrize("text, culprits", [
    (_ROWS.replace("0.003,3\n", ""), ["irregular sampling at row 5", "step 0.002 s", "resample"]),  # a gap
    (_ROWS.replace("0.003,3", "0.002,3"), ["row 5", "duplicated"]),                              # a repeat
    (_ROWS.replace("0.003,3", "0.0015,3"), ["row 5", "decreasing"]),                             # a reversal
    (_ROWS.replace("0.003,3", "0.00303,3"), ["irregular sampling at row 5", "step 0.00103 s"]),  # 3 % jitter
])
def test_gaps_repeats_reversals_are_refused_naming_the_row(tmp_path, text, culprits):
    path = tmp_path / "rec.csv"
    path.write_text(text)
    with pytest.raises(InputDataError) as err:
        Recording.from_csv(path)
    for c in culprits:
        assert c in str(err.value), str(err.value)


def test_a_drifting_clock_is_refused_where_it_strays():
    k = np.arange(1001)
    t = 0.001 * k * (1 + 2e-5 * k)  # each step within 2 % of the next, the last stamp 20 steps late
    with pytest.raises(InputDataError, match=r"irregular sampling at sample \d+ .* steps off the uniform grid"):
        Recording.from_arrays(t, {"y": np.zeros(k.size)})
    assert uniform_grid(t) is None


def test_the_tolerance_lies_between_jitter_and_a_missing_sample():
    t = np.arange(200) * 1e-3
    assert uniform_grid(_jittered(t, spread=2 * JITTER * 0.9)) is not None
    assert uniform_grid(np.delete(t, 100)) is None
    assert uniform_grid(t) is t  # an exact grid is kept as it is


def test_dataframe_labels_with_units_and_jitter(msd_data):
    t, f, y = msd_data

    class Frame(dict):  # stands in for a pandas DataFrame (optional): columns and to_numpy
        columns = property(lambda self: list(self))

        def __getitem__(self, k):
            v = dict.__getitem__(self, k)
            return type("Column", (), {"to_numpy": lambda _, dtype=float: np.asarray(v, dtype=dtype)})()

    rec = Recording.from_dataframe(Frame({"t [ms]": _jittered(t) * 1e3, "F [kN]": f / 1e3, "x [mm]": y * 1e3}),
                                   mapping={"x": "position"})
    si = rec.in_units_of(mass_spring_damper())
    assert si["position"] == pytest.approx(y, rel=1e-14) and np.ptp(np.diff(si.t)) < 1e-9 * si.dt


def test_the_real_emps_recording_is_accepted():
    path = EMPS / "emps_estimation.csv"
    if not path.exists():
        pytest.skip(f"{path} is absent")
    rec = Recording.from_csv(path)  # stamps from 0.00099998 to 0.00100003 s
    assert len(rec) == 24841 and rec.t[0] == 0.0
    assert rec.dt == pytest.approx(1e-3, rel=1e-6) and np.ptp(np.diff(rec.t)) < 1e-9 * rec.dt
    assert set(rec.names) == {"qg", "qm", "vir"}
