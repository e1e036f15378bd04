"""The curling HASEL paper's sensitivity protocol (Table 5) on the model, through the library, checked
against an independent recomputation, with the ranking explained by the operating point of the input map
(docs/systems/curling_hasel.md, "Parameter sensitivity (Table 5)"; docs/examples/sensitivity_curling_hasel.py).

The input map is ``gamma1 cos(gamma2 theta)``: a relative change of gamma1 scales it by the same factor at
every angle, one of gamma2 by ``-kappa`` times that, ``kappa = gamma2 theta tan(gamma2 theta)``.  Where the
perturbation dominates the noise, the fit % drops linearly in ``|step|``, so the SD ratio gamma2/gamma1 is
the ratio of the two output sensitivities' norms, which the quasi-static argument predicts to be the mean
``kappa`` of the settled angles."""

from __future__ import annotations

import re
import statistics
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from codegen import simulate, simulator
from phs.signals import Sampled, staircase, step
from phs.workflows.identify import identify
from phs.workflows.recording import Recording
from systems.curling_hasel import curling_hasel

ROOT = Path(__file__).resolve().parents[1]
N = 4
FREE = ["R2", "C1", "K_b", "b", "gamma1", "gamma2"]
STEPS = (-0.10, -0.05, 0.0, 0.05, 0.10)
X0 = {f"seg{i}.l_p": 0.015 for i in range(1, N + 1)}


def _measure(system, t, U, seed=7):
    """Tip at 1 kHz with Gaussian noise of 0.1 % of its range (the paper's sensor accuracy); settled angles."""
    res = simulate(system, t, u={"U": U}, x0=X0)
    tip = res["tip"] + 0.001 * np.ptp(res["tip"]) * np.random.default_rng(seed).standard_normal(len(t))
    angles = np.array([res[f"seg{i}.theta"][-1] for i in range(1, N + 1)])
    return Recording.from_arrays(t, {"U": U, "tip": tip}), angles


def _fits_by_hand(system, rec, values, names):
    """Fit % (own NRMSE formula) of each parameter of ``names`` alone at STEPS, and the sample SD
    (``statistics.stdev``), re-simulated here without the identification package."""
    sim, u, y = simulator(system, energy=False), {"U": Sampled(tuple(rec.t), tuple(rec["U"]))}, rec["tip"]
    out = {}
    for k in names:
        fits = []
        for s in STEPS:
            yhat = sim.run(rec.t, u=u, x0=X0, params={**values, k: values[k] * (1 + s)})["tip"]
            fits.append(100.0 * (1.0 - np.sqrt(np.sum((y - yhat) ** 2) / np.sum((y - np.mean(y)) ** 2))))
        out[k] = (fits, statistics.stdev(fits))
    return out


def _kappa(angles, gamma2):
    return float(np.mean(gamma2 * angles * np.tan(gamma2 * angles)))


def test_sensitivity_ranking_of_the_model_through_the_library():
    """Dataset #1 compressed to 3 s (five -500 V steps every 0.5 s from 0.5 s), 1 kHz, 0.1 % noise; the six
    parameters of Table 5 identified (from the truth) and their table computed by
    ``IdentificationResult.sensitivity_table``.  Checked: every fit % against the recomputation by hand, the
    ranking against the recomputation's, and gamma1 ahead of gamma2 because the settled angles at -2.5 kV
    have mean kappa < 1 (and the staircase, visiting lower levels with smaller kappa, has a ratio below it).
    Then two operating points (single steps to -2 kV and -5 kV, 3 s): the SD ratio gamma2/gamma1 follows
    kappa, and the order of gamma1 and gamma2 flips with it."""
    truth = curling_hasel(N)
    gamma2 = truth.param("gamma2").value
    t = np.arange(3001) / 1000.0
    rec, angles = _measure(truth, t, staircase(-500.0, every=0.5, n_steps=5, start=0.5)(t))
    fit = identify(truth, rec, FREE, x0=X0, outputs=["tip"])
    table = fit.sensitivity_table(channel="tip")
    hand = _fits_by_hand(truth, rec, fit.values, FREE)
    for k in FREE:
        # same equations and CVODES tolerances on both sides: only rounding may differ
        assert np.allclose([table[k][s] for s in STEPS], hand[k][0], rtol=0, atol=1e-6), k
        assert table[k]["std"] == pytest.approx(hand[k][1], abs=1e-6), k
    # a parameter's value baked into the system gives the fits of the parameter overridden at run time
    for s in (-0.10, 0.10):
        moved = fit.fitted_system.with_params(gamma2=fit.values["gamma2"] * (1 + s))
        yhat = simulate(moved, t, u={"U": Sampled(tuple(t), tuple(rec["U"]))}, x0=X0)["tip"]
        y = rec["tip"]
        assert 100 * (1 - np.linalg.norm(y - yhat) / np.linalg.norm(y - y.mean())) == pytest.approx(table["gamma2"][s], abs=1e-5)
    sd = {k: table[k]["std"] for k in FREE}
    ranking = sorted(FREE, key=lambda k: -sd[k])
    assert ranking == sorted(FREE, key=lambda k: -hand[k][1])
    kappa_top = _kappa(angles, gamma2)
    assert kappa_top < 1.0 and sd["gamma2"] / sd["gamma1"] < kappa_top, (kappa_top, sd)
    assert ranking[:2] == ["gamma1", "gamma2"], sd

    values = {k: truth.param(k).value for k in FREE}
    for amplitude in (2000.0, 5000.0):
        r, ang = _measure(truth, t, step(-amplitude, at=0.5)(t))
        two = _fits_by_hand(truth, r, values, ["gamma1", "gamma2"])
        ratio, kappa = two["gamma2"][1] / two["gamma1"][1], _kappa(ang, gamma2)
        # quasi-static prediction, unweighted over the segments: the inner segments (smaller kappa) move the
        # tip more and the transient passes through smaller angles, both pulling the ratio below the mean
        # kappa; measured 5 % (2 kV) and 4 % (5 kV) below it on 3 s records
        assert ratio == pytest.approx(kappa, rel=0.10), (amplitude, ratio, kappa)
        assert (ratio > 1.0) == (kappa > 1.0), (amplitude, ratio, kappa)


def _table(out: str) -> dict:
    rows = [line.split("|") for line in out.splitlines() if line.startswith("| `")]
    return {row[1].strip().strip("`"): float(row[7]) for row in rows}


# the script at test size (about 30 s on 2 loaded cores, hence slow) and the full-size protocol (12 s of
# Dataset #1, identification from starts 30 % off, eight step amplitudes; about 3 minutes)
@pytest.mark.slow
@pytest.mark.parametrize("size", ["--quick", "full"])
def test_sensitivity_example(size, tmp_path):
    flags = ["--quick"] if size == "--quick" else []
    proc = subprocess.run([sys.executable, str(ROOT / "docs" / "examples" / "sensitivity_curling_hasel.py"), *flags,
                           "--out", str(tmp_path)], cwd=ROOT, capture_output=True, text=True, timeout=1800)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    out = proc.stdout
    assert (tmp_path / "sensitivity_curling_hasel.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    if size == "full":
        # identification recovers every parameter (measured: within 0.6 %, C1 +0.93 %; 3 s of --quick cannot
        # pin the drift pair, whose time constant is about 10 s)
        for k, tol in (("K_b", 0.02), ("b", 0.02), ("gamma1", 0.02), ("gamma2", 0.02), ("C1", 0.05), ("R2", 0.05)):
            line = next(line for line in out.splitlines() if line.startswith(f"{k} "))
            assert abs(float(line.split()[-1].rstrip("%")) / 100) < tol, line
    assert float(re.search(r"largest difference of a fit %: ([0-9.e+-]+)", out).group(1)) < 1e-6
    sd = _table(out)
    printed = next(line for line in out.splitlines() if line.startswith("ranking, model:"))
    assert [k.strip() for k in printed.split(":")[1].split(">")] == sorted(sd, key=lambda k: -sd[k])
    # single steps: where the fit drop is linear in the step (amplitude >= 1.5 kV), the SD ratio follows kappa
    for line in out.splitlines():
        m = re.match(r"\| (\d+) V \| [0-9.]+ \| [0-9.]+ \| ([0-9.]+) \| ([0-9.]+) \| ([0-9.]+) \|", line)
        if m and float(m.group(1)) >= 1500:
            kappa, ratio = float(m.group(2)), float(m.group(4)) / float(m.group(3))
            assert ratio == pytest.approx(kappa, rel=0.10), line
            if abs(kappa - 1) > 0.10:  # the order of gamma1 and gamma2 follows kappa outside the prediction's 10 %
                assert (ratio > 1) == (kappa > 1), line  # (at 3 kV, kappa 1.037 and ratio 0.993: a tie within it)
