# %% [markdown]
# The catheter bender's left-out effects found by diagnosis: stress relaxation and hysteresis.
# The paper's force regression has no memory: its authors name the hysteresis and the stress
# relaxation of the elastomer as what it leaves out.  Here each is put into the bender (a truth the
# nominal model lacks), recorded under the paper's volume chirp at its 83 Hz, with noise, and
# `phs.diagnose` is given the nominal bender and the recording.
# Run: python docs/examples/diagnose_catheter_bender.py [--quick] [relaxation] [hysteresis]
# Writes docs/figures/catheter_bender_diagnose_{relaxation,hysteresis}_{fits,hypotheses,locate}.png.

# %%
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.abspath(os.path.join(HERE, "..", "..")))

from codegen import simulator  # noqa: E402
from components.candidates import Hysteresis, Scales, ViscoelasticCreep  # noqa: E402
from phs import equilibrium  # noqa: E402
from phs.workflows.diagnose import diagnose  # noqa: E402
from phs.workflows.diagnose.report import write_figures  # noqa: E402
from phs.workflows.recording import Recording  # noqa: E402
from systems.catheter_bender import ML, catheter_bender, volume_chirp  # noqa: E402

QUICK = "--quick" in sys.argv
OUT = os.environ.get("PHS_DOCS_OUT") or os.path.join(HERE, "..", "figures")
DURATION = 40.0 if QUICK else 120.0  # the chirp's sweep time (the paper: 1800 s)
FS = 83.0                            # the paper's sampling rate [Hz]
FREE = ["k1", "K_b", "b"]


def truth_of(effect):
    """The bender with its stress relaxation (a Maxwell arm at the tip: 40 % of the bending
    stiffness relaxing in 2 s) or a hysteresis of the elastomer at the tip (a Dahl/Bouc-Wen element of
    20 mN whose loop spans the motion: pre-sliding stiffness 40 N/m, so it saturates after about
    0.6 mm, the tip's stroke)."""
    s = catheter_bender()
    sc = Scales.of(s)
    if effect == "viscoelastic_creep":
        aug = ViscoelasticCreep().augment(s, "tip.p", sc)
        return aug.system.with_params({"viscoelastic_creep.k_m": 0.4 * 1500.0, "viscoelastic_creep.tau": 2.0})
    aug = Hysteresis().augment(s, "tip.p", sc)
    vals = {k: aug.system.param(k).value for k in aug.free}
    vals.update({"hysteresis.k_h": 40.0, "hysteresis.F_h": 0.02})
    return aug.system.with_params(vals)


def record(system, seed, f1):
    """The volume chirp 0.01 -> f1 Hz about 5 mL (4 mL amplitude), sampled at 83 Hz; volume and force
    with 0.5 % and 1 % noise of their standard deviations."""
    t = np.arange(0.0, DURATION, 1.0 / FS)
    _, q = volume_chirp(5 * ML, 4 * ML, 0.01, f1, DURATION)
    x0 = equilibrium(system, u={"q": 0.0}, x0={"chamber.V": 5 * ML}).as_dict()
    res = simulator(system).run(t, u={"q": q}, x0=x0)
    rng = np.random.default_rng(seed)
    sig = {"q": np.asarray(q(t), float) * np.ones_like(t)}
    for ch, share in (("volume", 0.005), ("force", 0.01)):
        y = np.asarray(res[ch], float)
        sig[ch] = y + share * np.std(y) * rng.standard_normal(t.size)
    return Recording.from_arrays(t, sig, source=f"bender truth (seed {seed})", units={"q": "m**3/s", "volume": "m**3", "force": "N"}), x0


verdicts = {}
CASES = [c for c in (("viscoelastic_creep", "relaxation"), ("hysteresis", "hysteresis")) if c[1] in sys.argv[1:]] or [
    ("viscoelastic_creep", "relaxation"), ("hysteresis", "hysteresis")]
for effect, name in CASES:
    truth = truth_of(effect)
    train, x0 = record(truth, 1, 2.0)
    val, _ = record(truth, 2, 3.0)
    nominal = catheter_bender()
    x0n = {k: v for k, v in x0.items() if k in nominal.state_names}
    wall = time.perf_counter()
    d = diagnose(nominal, train, validation=val, free=FREE, outputs=["volume", "force"], x0=x0n)
    print(d)
    print(f"{name}: verdict {d.effect} ({time.perf_counter() - wall:.1f} s wall)")
    verdicts[effect] = d.effect
    for path in write_figures(d, OUT, f"catheter_bender_diagnose_{name}"):
        print(f"wrote {path}")
print("verdicts:", ", ".join(f"{k} -> {v}" for k, v in verdicts.items()))
