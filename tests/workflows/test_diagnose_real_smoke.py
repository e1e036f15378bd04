"""Smoke tests of ``phs fit`` and ``phs diagnose`` on every real recording of ``../shared/data``.

Each test reads its recording in place (skipped when absent), writes a short window of it as a CSV the
way a user would export it (a time column in seconds, the recorded columns unchanged), and runs both
subcommands through :func:`phs.workflows.cli.main` with a few free parameters and two or three
candidate effects: no crash, a finite fit, a named verdict.  The nominal models follow each folder's
README; none of these recordings is one the nominal model cannot describe (their refitted nominal
correlations are 0.93-1.00, ``phs.workflows.diagnose.refusal``), so the verdict is never the refusal.
The longer diagnoses of the same recordings are ``tests/workflows/test_diagnose_real.py`` and the
scripts of ``docs/examples/diagnose_*.py``.
"""

from __future__ import annotations

import json
import math
import os

import numpy as np
import pytest

from components.candidates import LIBRARY
from phs.workflows.cli import main
from phs.workflows.diagnose.refusal import REFUSED

DATA = os.path.join(os.path.dirname(__file__), "..", "..", "..", "shared", "data")
VERDICTS = {c.effect for c in LIBRARY} | {"none", "discovered", REFUSED}

GTAU, KV, KP = 35.15065188248547, 243.45, 160.18
"""EMPS drive gain [N/V] and the cascade's velocity [V s/m] and position [1/s] gains (``emps/README.md``)."""


def emps_loop():
    """The EMPS carriage (mass, viscous friction) inside its known cascade ``vir = kv (kp (qg - qm) - v)``:
    a P position loop with ``K_p = gtau kv kp`` and ``K_d = gtau kv`` on a mass and a damper; input the
    reference ``qg`` [m], measured the position ``qm`` [m] and the loop's force ``F_c`` [N]."""
    from components import Damper, Mass
    from components.control import PositionLoop
    from phs import Measured, interconnect, series
    from phs.component import symbol_of_state

    return interconnect("emps", [Mass("m", m=95.1), Damper("b", b=203.5),
                                 PositionLoop("pd", K_p=GTAU * KV * KP, K_d=GTAU * KV, reference="qg", effort="F_c")],
                        [series("m", "b", "pd")], measured=[Measured("qm", symbol_of_state("pd.x"), "m", "carriage position")])


def _path(*parts) -> str:
    path = os.path.normpath(os.path.join(DATA, *parts))
    if not os.path.isfile(path):
        pytest.skip(f"{path} not found")
    return path


def _write(path, columns: dict) -> str:
    np.savetxt(path, np.column_stack(list(columns.values())), delimiter=",", header=",".join(columns), comments="",
               fmt="%.10g")
    return str(path)


def _fit_and_diagnose(tmp_path, model, csv, free, effects, extra=(), channels=None):
    """``phs fit`` then ``phs diagnose`` on ``csv``; returns the fit's and the diagnosis's JSON documents."""
    fit_json, diag_json = tmp_path / "fit.json", tmp_path / "diagnose.json"
    code = main(["fit", model, csv, "--free", ",".join(free), "--quiet", "--max-iter", "30", "--json", str(fit_json), *extra])
    assert code == 0
    fit = json.loads(fit_json.read_text())
    code = main(["diagnose", model, csv, "--free", ",".join(free), "--effects", ",".join(effects), "--max-effects", "1",
                 "--no-discover", "--jobs", "1", "--quiet", "--json", str(diag_json), *extra])
    diag = json.loads(diag_json.read_text())
    assert code == (1 if diag["verdict"]["effect"] == REFUSED else 0)
    assert diag["verdict"]["effect"] in VERDICTS, diag["verdict"]
    for ch in channels or diag["outputs"]:
        assert math.isfinite(diag["baseline"]["fit_percent"][ch]) and math.isfinite(diag["final"]["fit_percent"][ch])
    fits = [float(v) for v in fit["fit_percent"].values()]
    assert fits and all(math.isfinite(v) for v in fits), fit["fit_percent"]
    print(f"{os.path.basename(csv)}: fit {fit['fit_percent']}; verdict {diag['verdict']['effect']}, nominal "
          f"{diag['baseline']['fit_percent']} -> final {diag['final']['fit_percent']} (training)")
    return fit, diag


def _linear_model(tmp_path, y, u, fs) -> str:
    """A mass-spring-damper started from a second-order ARX least-squares fit of ``u`` to ``y`` (as in
    ``test_diagnose_real.py``), saved as a model file: built with these values, its parameters' declared
    ranges are centred on them (a ``--param`` override keeps the ranges of the defaults)."""
    from systems.examples import mass_spring_damper

    A = np.column_stack([y[1:-1], y[:-2], u[1:-1], u[:-2]])
    a1, a2, b1, b2 = np.linalg.lstsq(A, y[2:], rcond=None)[0]
    s = np.log(np.roots([1.0, -a1, -a2])[0]) * fs
    wn, zeta = abs(s), -s.real / abs(s)
    k = (1 - a1 - a2) / (b1 + b2)
    path = str(tmp_path / "msd.json")
    mass_spring_damper(m=k / wn**2, k=k, b=2 * zeta * k / wn).save(path)
    return path


def test_silverbox(tmp_path):
    raw = np.genfromtxt(_path("silverbox", "SNLS80mV.csv"), delimiter=",", skip_header=1, usecols=(0, 1))
    fs = 1e7 / 2**14
    v1, v2 = raw[:, 0] - raw[:, 0].mean(), raw[:, 1] - raw[:, 1].mean()  # offsets removed (the data's README)
    w = slice(40000 - 400, 40000)  # the end of the "arrow": large amplitude
    csv = _write(tmp_path / "silverbox.csv", {"t": np.arange(400) / fs, "V1": v1[w], "V2": v2[w]})
    model = _linear_model(tmp_path, v2[w], 1e5 * v1[w], fs)
    _, diag = _fit_and_diagnose(tmp_path, model, csv, ["m.m", "k.K", "b.b"], ["cubic_stiffness", "offset"],
                                ["--map", "V1=F", "--map", "V2=position", "--scale", "V1=1e5"])
    assert diag["verdict"]["effect"] != REFUSED, diag["verdict"]


def test_bouc_wen(tmp_path):
    path = _path("bouc_wen", "boucwen_val_multisine.csv")
    raw = np.genfromtxt(path, delimiter=",", skip_header=1, max_rows=600)
    csv = _write(tmp_path / "bouc_wen.csv", {"t_s": raw[:, 0], "u_force_N": raw[:, 1], "y_disp_m": raw[:, 2]})
    model = _linear_model(tmp_path, raw[:, 2], raw[:, 1], 750.0)
    _, diag = _fit_and_diagnose(tmp_path, model, csv, ["m.m", "k.K", "b.b"], ["cubic_stiffness", "offset"],
                                ["--time", "t_s", "--map", "u_force_N=F", "--map", "y_disp_m=position"])
    assert diag["verdict"]["effect"] != REFUSED, diag["verdict"]


def test_cascaded_tanks(tmp_path):
    raw = np.genfromtxt(_path("cascaded_tanks", "dataBenchmark.csv"), delimiter=",", skip_header=1, usecols=(0, 1, 2, 3))
    n = 256
    t = np.arange(n) * 4.0  # Ts = 4 s (the data's README)
    train = _write(tmp_path / "tanks_est.csv", {"t": t, "u": raw[:n, 0], "level2": raw[:n, 2]})
    val = _write(tmp_path / "tanks_val.csv", {"t": t, "u": raw[:n, 1], "level2": raw[:n, 3]})
    y_m, u_m = float(raw[:n, 2].mean()), float(raw[:n, 0].mean())
    _, diag = _fit_and_diagnose(tmp_path, "systems.lab:cascaded_tanks", train, ["k1", "k2", "k4"], ["input_saturation", "offset"],
                                ["--validate", val, "--param", "k1=0.02", "--param", "k2=0.02",
                                 "--param", f"k4={0.02 * np.sqrt(y_m) / u_m:.6g}",
                                 "--x0", f"V1={y_m:.6g}", "--x0", f"V2={raw[0, 2]:.6g}"])
    assert diag["verdict"]["effect"] != REFUSED, diag["verdict"]


def test_pneumatic_chamber_leak(tmp_path):
    """A leaking chamber against the closed-chamber model: the simulated pressure stays at rest (fit 0 %),
    which is the missing leak, not a model that cannot describe the recording."""
    raw = np.genfromtxt(_path("pneumatic_actuator_tudelft", "chamber_leak_Ultimaker_015.csv"), delimiter=",", names=True)
    t, p = raw["time_ms"] / 1000.0, raw["pressure_bar"] * 1e5
    early = t <= 20.0
    i0 = int(np.nonzero(early & (p >= p[early].max() - 1e3))[0][-1])  # the supply valve closes
    keep = (t >= t[i0]) & (t <= t[i0] + 30.0)
    csv = _write(tmp_path / "chamber.csv", {"t": t[keep] - t[i0], "q": 0 * t[keep], "pressure": p[keep]})
    C = 5e-7
    _, diag = _fit_and_diagnose(tmp_path, "systems.lab:air_chamber", csv, ["C"], ["leakage", "offset"],
                                ["--resample", "0.1", "--x0", f"V_a={p[i0] * C:.6g}"])
    assert diag["verdict"]["effect"] == "leakage", diag["verdict"]


def test_emps(tmp_path):
    """The carriage in its position loop, 1.5 s of the estimation record with its own time stamps (steps
    of 0.00099998 to 0.00100003 s); the controller output ``vir`` [V] read as the loop's force by
    ``--scale vir=gtau``."""
    path = _path("emps", "emps_estimation.csv")
    raw = np.genfromtxt(path, delimiter=",", names=True, max_rows=1500)
    csv = _write(tmp_path / "emps.csv", {"t": raw["t"], "qg": raw["qg"], "qm": raw["qm"], "vir": raw["vir"]})
    _, diag = _fit_and_diagnose(tmp_path, f"{os.path.abspath(__file__)}:emps_loop", csv, ["m.m", "b.b"],
                                ["coulomb_friction", "offset"],
                                ["--map", "vir=F_c", "--scale", f"vir={GTAU!r}", "--x0", f"pd.x={raw['qm'][0]:.6g}"])
    assert diag["verdict"]["effect"] != REFUSED, diag["verdict"]


def _seal_friction_csv(tmp_path, seconds: float) -> tuple[str, list]:
    """``seconds`` of the O-ring record at 7 bar on a 50 Hz grid as ``docs/examples/diagnose_seal_friction.py``
    prepares it (pressure in Pa, the drive's velocity from the position, the rod force), and the start."""
    from scipy.signal import savgol_filter

    raw = np.genfromtxt(_path("pneumatic_actuator_tudelft", "friction_O-ring257_7bar.csv"), delimiter=",", names=True)
    t_raw, dt = raw["time_ms"] / 1000.0, 0.02
    t = np.arange(0.0, seconds, dt)
    pos = np.interp(t, t_raw, raw["position_mm"]) * 1e-3
    P, force = np.interp(t, t_raw, raw["pressure_bar"]) * 1e5, np.interp(t, t_raw, raw["force_N"])
    csv = _write(tmp_path / "friction.csv", {"t": t, "P": P, "v": -savgol_filter(pos, 5, 2, deriv=1, delta=dt), "force": force})
    return csv, ["--param", f"A={float(np.median(force / P)):.6g}", "--x0", f"q={force[0] / 2e5:.6g}"]


@pytest.mark.slow  # 49 s wall under load, 23 s CPU: every sample of the drive's velocity is a kink of the input
def test_pneumatic_seal_friction(tmp_path):
    """10 s of the O-ring record at 7 bar (measured: nominal 84.0 %, verdict coulomb_friction)."""
    csv, extra = _seal_friction_csv(tmp_path, 10.0)
    _, diag = _fit_and_diagnose(tmp_path, "systems.lab:seal_friction_rig", csv, ["A", "b"], ["coulomb_friction", "offset"], extra)
    assert diag["verdict"]["effect"] != REFUSED, diag["verdict"]


FILES = [("silverbox", "SNLS80mV.csv"), ("silverbox", "Schroeder80mV.csv"), ("cascaded_tanks", "dataBenchmark.csv"),
         ("bouc_wen", "boucwen_val_multisine.csv"), ("emps", "emps_estimation.csv"), ("emps", "emps_validation_pulses.csv"),
         ("pneumatic_actuator_tudelft", "chamber_leak_Formlabs.csv"), ("pneumatic_actuator_tudelft", "friction_X-ring257_1bar.csv")]


@pytest.mark.parametrize("folder,name", FILES)
def test_every_kind_of_file_is_read_in_place_or_refused_in_one_line(folder, name):
    """Each file as it lies: read, or refused with a one-line InputDataError naming the file (no time column
    ``t`` in the Silverbox and tanks files; the pneumatic files' millisecond stamps with late samples)."""
    from phs.errors import InputDataError
    from phs.workflows.recording import Recording

    path = _path(folder, name)
    time_column = {"emps": "t", "bouc_wen": "t_s", "pneumatic_actuator_tudelft": "time_ms"}.get(folder, "t")
    try:
        rec = Recording.from_csv(path, time_column=time_column)
    except InputDataError as exc:
        assert "\n" not in str(exc) and name in str(exc), str(exc)
        return
    assert len(rec) > 100 and all(np.all(np.isfinite(rec[n])) for n in rec.names)
