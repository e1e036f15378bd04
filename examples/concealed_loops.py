"""Recordings of an actuator under feedback whose truth holds physics the nominal model lacks.

The plant is a mass on a spring with viscous damping, driven by a known PD position loop with a
reference filter (:class:`components.control.PositionLoop`); the recorded input is the reference
``r`` [m], the recorded channels the position [m] and the controller's output force ``u_c`` [N].
The nominal model (:func:`nominal`) is plant + controller with the plant's mass, stiffness and
damping free (:data:`NOMINAL_FREE`); the controller's gains are known (firmware).

Cases (:data:`CASES`; each names the effects the diagnosis should find, ``info["effects"]``):

``closed_loop``
    dry friction ``F_c v / sqrt(v² + v_s²)`` (a smooth sign, not the library's ``tanh``), position
    with 1 % noise of its range, controller force with 2 % of its standard deviation.
``quantised_encoder``
    the same friction, the position read by an encoder of 2⁻²⁰ of the travel per count (no other
    noise: about 10⁻⁶ of the range) beside a controller force with 3 % noise.
``absorbed``
    a strong friction on a plant with little viscous damping: the nominal fit raises the damping
    several-fold to absorb it (``info["absorbed"]``: the nominal damping the refit reaches).
``two_effects``
    friction and a hardening spring ``K₃ x³`` at once.
``loop_delay``
    no friction; the force reaches the plant :data:`LOOP_DELAY` after the controller computed it (a
    digital loop's computation and transport delay): ``F(t) = F_c(t − τ)``, the recorded ``u_c`` being
    the command ``F_c``.  Position with 1 % noise, command with 2 %.
``drive_saturation``
    no friction; the drive delivers at most :data:`DRIVE_LIMIT`: ``F = clip(F_c, −F_max, F_max)``
    (the command's transients after each step of the reference exceed it); the recorded ``u_c`` is the
    command before the limit.

The last two are not port-Hamiltonian (a delay or a clip inside the loop): their truth is integrated
by :func:`simulate_loop` (classical Runge-Kutta, ten steps per sample, the command held over each).

:func:`generate` returns a :class:`phs.workflows.recording.Recording` and what the truth was (for the
elements inside the loop, ``info["place"]``: where the diagnosis should put them, the command ``u_c``).
Training references: held set points every 0.5 s plus a slow sine; validation: other set points
and a faster sine.  Sampled at 1 kHz.
"""

from __future__ import annotations

import numpy as np

from components import Damper, LinearSpring, Mass, PositionLoop
from components.mechanical import Potential
from phs import Measured, Param, interconnect, series, symbol_of_state
from phs.errors import InputDataError
from phs.workflows.recording import Recording

M, K, B = 0.5, 40.0, 1.0          # plant: mass [kg], spring [N/m], viscous damping [N s/m]
KP, KD, TAU = 400.0, 6.0, 0.01    # controller gains and reference filter (known)
DT = 1e-3
NOMINAL_FREE = ("m.m", "k.K", "b.b")
CASES = ("closed_loop", "quantised_encoder", "absorbed", "two_effects", "loop_delay", "drive_saturation")
LOOP_DELAY = 0.004                # [s] between the controller's command and the force on the plant
DRIVE_LIMIT = 6.0                 # [N] the drive's limit (the command's step transients reach 18 to 21 N)
_TRUTH = {  # case: viscous damping, friction force, smoothing speed, cubic stiffness [N/m^3]
    "closed_loop": (B, 0.4, 2e-3, 0.0),
    "quantised_encoder": (B, 0.4, 2e-3, 0.0),
    "absorbed": (0.1, 1.2, 2e-3, 0.0),
    "two_effects": (B, 0.4, 2e-3, 2.5e5),
    "loop_delay": (B, 0.0, 2e-3, 0.0),
    "drive_saturation": (B, 0.0, 2e-3, 0.0),
}
_EFFECTS = {"closed_loop": ["coulomb_friction"], "quantised_encoder": ["coulomb_friction"],
            "absorbed": ["coulomb_friction"], "two_effects": ["coulomb_friction", "cubic_stiffness"],
            "loop_delay": ["time_delay"], "drive_saturation": ["input_saturation"]}


def plant(*, b: float = B, friction: tuple | None = None, k3: float = 0.0):
    """Plant + PD loop; ``friction=(F_c, v_s)`` adds ``F_c v / sqrt(v² + v_s²)``, ``k3`` a cubic spring term."""
    comps = [Mass("m", m=M), LinearSpring("k", K=K), Damper("b", b=b),
             PositionLoop("pd", K_p=KP, K_d=KD, tau=TAU, position="k.l", effort="u_c")]
    members, params = ["m", "k", "b", "pd"], []
    if k3:  # a hardening spring: energy K3 l^4 / 4 on the spring's own elongation
        k3p = Param("K3", k3, "N/m**3", "cubic stiffness")
        comps.append(Potential("hard", k3p.symbol * symbol_of_state("k.l") ** 4 / 4, params=[k3p]))
    if friction is not None:
        fc, vs = Param("F_c", friction[0], "N", "dry friction force"), Param("v_s", friction[1], "m/s", "friction smoothing speed")
        v = symbol_of_state("m.p") / M
        comps.append(Damper("dry", b=fc.symbol / (v**2 + vs.symbol**2) ** 0.5))
        members.append("dry")
        params = [fc, vs]
    return interconnect("servo", comps, [series(*members)], params=params,
                        measured=[Measured("position", symbol_of_state("k.l"), "m", "position of the mass")],
                        description="mass-spring-damper under PD position control on a filtered reference")


def nominal():
    """The nominal model: plant (no friction, linear spring) + the known controller."""
    return plant()


def reference(t: np.ndarray, seed: int, validation: bool = False) -> np.ndarray:
    """Held set points every 0.5 s (within ±20 mm) plus a sine (0.7 Hz; validation 1.9 Hz)."""
    rng = np.random.default_rng(seed)
    levels = rng.uniform(-0.02, 0.02, size=int(t[-1] / 0.5) + 1)
    return levels[(t / 0.5).astype(int)] + 0.005 * np.sin(2 * np.pi * (1.9 if validation else 0.7) * t)


def simulate_loop(t: np.ndarray, r: np.ndarray, *, delay: float = 0.0, limit: float | None = None, substeps: int = 10):
    """Position and controller command of the plant under the PD loop with a reference filter (the law of
    :class:`components.control.PositionLoop`) when the force reaching the plant is the command delayed by
    ``delay`` (a whole number of substeps; the first command is held before it) and clipped to
    ``±limit``.  Classical Runge-Kutta with ``substeps`` steps per sample, the reference interpolated
    linearly and the applied force held over each step; from rest.

    Examples
    --------
    >>> from codegen import simulator
    >>> t = np.arange(0.0, 1.0, DT)
    >>> r = reference(t, seed=10)
    >>> x, uc = simulate_loop(t, r)
    >>> res = simulator(nominal()).run(t, u={"r": r})
    >>> bool(np.max(np.abs(x - res["position"])) < 1e-3 * np.ptp(x)), bool(np.max(np.abs(uc - res["u_c"])) < 2e-3 * np.ptp(uc))
    (True, True)
    """
    h = float(t[1] - t[0]) / substeps
    n = (len(t) - 1) * substeps + 1
    rr = np.interp(np.arange(n) * h, t, r)
    lag = int(round(delay / h))
    y = np.zeros(3)  # position, velocity, filtered reference
    cmd, pos = np.zeros(n), np.zeros(n)

    def command(y, rk):
        return KP * (y[2] - y[0]) + KD * ((rk - y[2]) / TAU - y[1])

    for k in range(n):
        cmd[k], pos[k] = command(y, rr[k]), y[0]
        if k == n - 1:
            break
        f = cmd[max(k - lag, 0)]
        f = float(np.clip(f, -limit, limit)) if limit is not None else f

        def rate(y, rk=rr[k], f=f):
            return np.array([y[1], (f - K * y[0] - B * y[1]) / M, (rk - y[2]) / TAU])

        k1 = rate(y)
        k2 = rate(y + h / 2 * k1)
        k3 = rate(y + h / 2 * k2)
        k4 = rate(y + h * k3)
        y = y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return pos[::substeps], cmd[::substeps]


def generate(case: str, seconds: float = 4.0, seed: int = 1, validation: bool = False):
    """A recording of ``case`` (:data:`CASES`) and a dict of what the truth was.

    Examples
    --------
    >>> rec, info = generate("quantised_encoder", seconds=0.5)
    >>> info["effects"], sorted(rec.signals)
    (['coulomb_friction'], ['position', 'r', 'u_c'])
    >>> step = np.diff(np.unique(rec["position"])).min()        # the encoder's count
    >>> bool(abs(step - info["count"]) < 1e-12)
    True
    """
    if case not in CASES:
        raise InputDataError(f"concealed loops: unknown case {case!r}; known: {', '.join(CASES)}")
    b, fc, vs, k3 = _TRUTH[case]
    t = np.arange(0.0, seconds, DT)
    r = reference(t, seed=10 * seed + (5 if validation else 0), validation=validation)
    info = {"case": case, "effects": list(_EFFECTS[case]), "b": b, "F_c": fc, "v_s": vs, "K3": k3}
    if case == "loop_delay":
        pos, uc = simulate_loop(t, r, delay=LOOP_DELAY)
        info["tau_d"], info["place"] = LOOP_DELAY, "u_c"
    elif case == "drive_saturation":
        pos, uc = simulate_loop(t, r, limit=DRIVE_LIMIT)
        info["F_max"], info["place"] = DRIVE_LIMIT, "u_c"
    else:
        from codegen import simulator

        res = simulator(plant(b=b, friction=(fc, vs), k3=k3)).run(t, u={"r": r})
        pos, uc = np.asarray(res["position"]), np.asarray(res["u_c"])
    rng = np.random.default_rng(1000 * seed + (7 if validation else 3))
    if case == "quantised_encoder":
        count = 0.08 / 2**20  # 2^-20 of an 80 mm travel per count
        pos_m = np.round(pos / count) * count
        uc_m = uc + 0.03 * np.std(uc) * rng.standard_normal(t.size)
        info["count"] = count
    else:
        pos_m = pos + 0.01 * np.ptp(pos) * rng.standard_normal(t.size)
        uc_m = uc + 0.02 * np.std(uc) * rng.standard_normal(t.size)
    rec = Recording.from_arrays(t, {"r": r, "position": pos_m, "u_c": uc_m},
                                source=f"concealed loop {case} (seed {seed}{', validation' if validation else ''})",
                                units={"r": "m", "position": "m", "u_c": "N"})
    return rec, info
