"""Recordings of a positioning stage under a stiff digital servo loop, integrated outside the framework.

The shape of a real positioning stage (the EMPS benchmark, ``docs/workflows/closed_loop.md`` §6) rather
than of the project's own loop cases (:mod:`examples.concealed_loops`): a carriage with no spring of its own
(mass :data:`M`, viscous friction :data:`B`) held by a loop whose virtual stiffness is the only one, a
digital controller that reads the position at each sample, filters it over two samples, differentiates it
by a backward difference, and holds its command until the next sample; the drive clips the command at
:data:`DRIVE_LIMIT` when the case says so.  The truth is integrated by :func:`simulate_servo` (classical
Runge-Kutta, :data:`SUBSTEPS` steps per sample, the command held over each sample), never by the
framework's simulator.

The nominal model (:func:`nominal`) is the continuous PD loop of :class:`components.PositionLoop` (no
filter, no sampling) on a mass with viscous friction, the gains known, the mass and the viscous friction
free (:data:`NOMINAL_FREE`); its measured channels are the position and the controller's force ``u_c``.

Cases (:data:`CASES`):

``stiff_friction``
    dry friction ``F_c v / sqrt(v² + v_s²)`` on the carriage; point-to-point moves with rests.  The loop's
    virtual stiffness is 10⁵ times what a 1 Hz spring on the carriage would be.
``stiff_saturation``
    no friction; a reference of steps that makes the command exceed the drive's limit at every step.

Examples
--------
>>> rec, info = generate("stiff_saturation", seconds=1.0)
>>> sorted(rec.signals), info["effects"]
(['position', 'r', 'u_c'], ['input_saturation'])
>>> bool(np.max(np.abs(rec["u_c"])) > 2 * DRIVE_LIMIT)     # the limit is actually reached
True
"""

from __future__ import annotations

import numpy as np

from components import Damper, Mass, PositionLoop
from phs import Measured, Param, interconnect, series, symbol_of_state
from phs.errors import InputDataError
from phs.workflows.recording import Recording

M, B = 2.0, 5.0                  # carriage [kg], viscous friction [N s/m]
KP, KD = 2.0e5, 800.0            # the loop's virtual stiffness [N/m] and damping [N s/m] (known)
F_C, V_S = 3.0, 2e-3             # dry friction [N] and its smoothing speed [m/s] (stiff_friction)
DRIVE_LIMIT = 400.0              # [N] (stiff_saturation)
DT, SUBSTEPS = 1e-3, 10
NOMINAL_FREE = ("cart.m", "fv.b")
CASES = ("stiff_friction", "stiff_saturation")
_EFFECTS = {"stiff_friction": ["coulomb_friction"], "stiff_saturation": ["input_saturation"]}


def nominal():
    """Carriage with viscous friction under the continuous PD loop (``u_c`` its force, ``position`` measured)."""
    return interconnect(
        "stage",
        [Mass("cart", m=Param("cart.m", M, "kg", "carriage mass", range=(0.2, 20.0))),
         Damper("fv", b=Param("fv.b", B, "N*s/m", "viscous friction", range=(0.1, 100.0))),
         PositionLoop("pd", K_p=KP, K_d=KD, effort="u_c", range=(-0.2, 0.2))],
        [series("cart", "fv", "pd")],
        measured=[Measured("position", symbol_of_state("pd.x"), "m", "carriage position")],
    )


def reference(t: np.ndarray, seed: int, steps: bool = False, validation: bool = False) -> np.ndarray:
    """Point-to-point moves (raised-cosine, 0.25 s) between random set points within ±20 mm, a rest of
    0.25 s after each; ``steps``: the set points as steps (no move profile)."""
    rng = np.random.default_rng(seed)
    period = 0.4 if validation else 0.5
    n = int(t[-1] / period) + 2
    levels = np.concatenate([[0.0], rng.uniform(-0.02, 0.02, size=n)])
    k = np.minimum((t / period).astype(int), n - 1)
    if steps:
        return levels[k + 1]
    s = np.clip((t - k * period) / (0.5 * period), 0.0, 1.0)
    return levels[k] + (levels[k + 1] - levels[k]) * 0.5 * (1 - np.cos(np.pi * s))


def simulate_servo(t: np.ndarray, r: np.ndarray, *, friction: float = 0.0, limit: float | None = None):
    """Position and command of the carriage under the digital loop: at each sample the controller reads the
    position, averages it with the previous reading, differentiates the average by a backward difference
    and commands ``KP (r − x_f) − KD v_f``, held until the next sample; the drive clips it at ``±limit``.
    From rest at the first reference value.

    Examples
    --------
    >>> t = np.arange(0.0, 1.0, DT)
    >>> x, u = simulate_servo(t, reference(t, seed=3))
    >>> bool(np.max(np.abs(x - reference(t, seed=3))) < 1e-3)     # the stiff loop tracks within a millimetre
    True
    """
    h = DT / SUBSTEPS
    y = np.array([float(r[0]), 0.0])  # position, velocity
    x_prev = xf_prev = float(r[0])     # the previous reading and the previous filtered position
    pos, cmd = np.zeros(len(t)), np.zeros(len(t))

    def rate(y, f):
        v = y[1]
        dry = friction * v / np.sqrt(v * v + V_S * V_S) if friction else 0.0
        return np.array([v, (f - B * v - dry) / M])

    for i in range(len(t)):
        xf = 0.5 * (y[0] + x_prev)
        vf = (xf - xf_prev) / DT
        u = KP * (r[i] - xf) - KD * vf
        pos[i], cmd[i] = y[0], u
        x_prev, xf_prev = float(y[0]), xf
        f = float(np.clip(u, -limit, limit)) if limit is not None else u
        for _ in range(SUBSTEPS):
            k1 = rate(y, f)
            k2 = rate(y + h / 2 * k1, f)
            k3 = rate(y + h / 2 * k2, f)
            k4 = rate(y + h * k3, f)
            y = y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return pos, cmd


def generate(case: str, seconds: float = 4.0, seed: int = 1, validation: bool = False):
    """A 1 kHz recording of ``case`` (:data:`CASES`): the reference ``r``, the position with noise of 0.5 % of
    its range and the command ``u_c`` with 2 % of its standard deviation; and a dict of what the truth was
    (``info["place"]``: where an element between the controller and the drive belongs)."""
    if case not in CASES:
        raise InputDataError(f"concealed servo: unknown case {case!r}; known: {', '.join(CASES)}")
    t = np.arange(0.0, seconds, DT)
    r = reference(t, seed=10 * seed + (5 if validation else 0), steps=case == "stiff_saturation", validation=validation)
    info = {"case": case, "effects": list(_EFFECTS[case]), "M": M, "B": B}
    if case == "stiff_friction":
        pos, uc = simulate_servo(t, r, friction=F_C)
        info.update(F_c=F_C, v_s=V_S)
    else:
        pos, uc = simulate_servo(t, r, limit=DRIVE_LIMIT)
        info.update(F_max=DRIVE_LIMIT, place="u_c")
    rng = np.random.default_rng(1000 * seed + (7 if validation else 3))
    pos_m = pos + 0.005 * np.ptp(pos) * rng.standard_normal(t.size)
    uc_m = uc + 0.02 * np.std(uc) * rng.standard_normal(t.size)
    rec = Recording.from_arrays(t, {"r": r, "position": pos_m, "u_c": uc_m},
                                source=f"concealed servo {case} (seed {seed}{', validation' if validation else ''})",
                                units={"r": "m", "position": "m", "u_c": "N"},
                                holds={"r": "zoh"} if case == "stiff_saturation" else None)
    return rec, info
