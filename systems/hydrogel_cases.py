"""Table II of Doroudchi et al.: the eight open-loop cases of the hydrogel arm, the readings of eq. 7 and
Table I, and the lever arms fitted to the table.

Each case drives a set of SVAs with one 15 s voltage pulse (Sec. V-B: "square signals of voltage ... all
applied for 15 seconds"); the table reports the tip's range ``|X| = X_max - X_min`` [mm] during the test
and the RMSE of the paper's simulation.  :func:`case_ranges` simulates the eight cases on one arm carrying
all 16 SVAs (the idle ones are present, as on the robot) for 40 s each and returns the eight ranges.
:func:`fit_levers` fits the lever arms of the two rows to them through :func:`phs.identify`: the table is
eight runs known by one statistic each (:func:`table_summaries`: the run's inputs, a 15 s pulse in a 40 s
run, and the measured ``range(tip)``), fitted as relative errors (the paper normalises each case's error by
its ``|X|``: its RMSE are 5-9 % of ``|X|``) on :func:`table_arm`, whose rows' lever arms are two shared
parameters ``r_upper`` and ``r_lower``.  :func:`fit_levers_least_squares` is the same fit computed
independently (scipy's least squares over :func:`case_ranges`, finite-difference Jacobian), the check of
the identification route.

:func:`eq7_readings` enumerates the readings of the garbled eq. 7 and of Table I (bracket sign, where the
time multiplies, the prefactor, which pair of Table I belongs to which ``b_i`` and which member of a pair
multiplies V) and checks each against what the paper says of the force (starts at zero and stays
tensile; grows with V; at 1.08 V a force range of at least 0.052 N, as an RMSE of 0.0026 N below 5 % of
it requires, and below the load cell's 100 g) and against Table II's voltage ratio (2.19 and 2.01 for
the two rows, 3.6 V against 1.8 V).  None passes all of them (``docs/systems/hydrogel_arm.md``).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from components.hydrogel import TABLE_I
from phs import Param, PHSystem
from phs.errors import ParameterError
from systems.hydrogel_arm import hydrogel_arm

TABLE_II = (
    (1, tuple(range(1, 9)), 1.8, 0.28, 4.09),
    (2, tuple(range(1, 9)), 3.6, 0.69, 8.96),
    (3, tuple(range(9, 17)), 1.8, 0.39, 6.51),
    (4, tuple(range(9, 17)), 3.6, 0.63, 13.06),
    (5, (3, 4, 5), 3.6, 0.36, 4.98),
    (6, (14, 15, 16), 3.6, 0.16, 2.01),
    (7, (7, 8, 11, 12, 13), 3.6, 0.49, 5.15),
    (8, (4, 9, 15), 3.6, 0.32, 3.52),
)
"""Table II: (case, SVAs driven, voltage [V], RMSE of the paper's simulation [mm], measured |X| [mm])."""
MEASURED = np.array([row[4] for row in TABLE_II])
PULSE, DURATION = 15.0, 40.0  # s
T_95 = 2.4469  # Student t, 97.5 % quantile, 6 degrees of freedom (8 cases - 2 lever arms)
FITTED = {"V_t": 1.08, "levers": (2.93e-5, 4.64e-5)}
"""The lever arms [m] of the upper and the lower row fitted to Table II with eq. 8's time coefficients at
``V_t`` [V] (``docs/examples/hydrogel_arm_cases.py``: 95 % intervals [0.0237, 0.0350] mm and
[0.0401, 0.0527] mm, NRMSE 11.0 %)."""
LEVER_RANGE = (1e-7, 1e-2)  # m, declared range of the fitted lever arms


def table_arm(per_segment: int = 1, V_t: float | None = FITTED["V_t"], levers: tuple[float, float] = FITTED["levers"]) -> PHSystem:
    """The arm of the Table II cases: all 16 SVAs, the rows' lever arms two shared parameters.

    Parameters
    ----------
    per_segment : int
        Rod elements per segment (1: the reduced arm, 8 rod elements; 2: 16).
    V_t : float or None
        Voltage of eq. 8's time coefficients (None: Table I as read, the coefficients at the amplitude).
    levers : (float, float)
        Values [m] of ``r_upper`` (SVAs 1-8) and ``r_lower`` (SVAs 9-16; their lever arm is ``-r_lower``).

    Returns
    -------
    PHSystem

    Examples
    --------
    >>> arm = table_arm()
    >>> arm.param("r_upper").value, arm.param("r_lower").unit, len(arm.states)
    (2.93e-05, 'm', 80)
    """
    rows = (Param("r_upper", float(levers[0]), "m", "effective lever arm of the upper row's SVAs (1-8)", LEVER_RANGE),
            Param("r_lower", float(levers[1]), "m", "effective lever arm of the lower row's SVAs (9-16)", LEVER_RANGE))
    return hydrogel_arm(per_segment=per_segment, V_t=V_t, lever=rows)


def table_summaries(t=None) -> list:
    """Table II as eight :class:`~phs.workflows.identify.Summary` runs: each the run's 16 heater inputs (a
    15 s pulse of the case's voltage on its SVAs, held between the samples, 0 on the others), the measured
    ``range(tip)`` [mm] and the case's operating amplitude ``sva{i}.V_a``.

    Parameters
    ----------
    t : array, optional
        Time grid [s] (default 0..40 s at 10 Hz).

    Returns
    -------
    list of Summary

    Examples
    --------
    >>> cases = table_summaries()
    >>> cases[3].name, cases[3].measured, cases[3].params["sva1.V_a"], len(cases[3].recording.t)
    ('case4', {'range(tip)': 13.06}, 3.6, 401)
    """
    import phs  # the workflows' door: phs.Summary, phs.Recording (systems import no workflow module)

    t = np.linspace(0.0, DURATION, int(DURATION * 10) + 1) if t is None else np.asarray(t, dtype=float)
    out = []
    for case, svas, V, _, measured in TABLE_II:
        u = {f"V{i}": np.where(t < PULSE, V, 0.0) if i in svas else np.zeros(len(t)) for i in range(1, 17)}
        rec = phs.Recording.from_arrays(t, u, source=f"Table II case {case}", holds=dict.fromkeys(u, "zoh"))
        out.append(phs.Summary(rec, {"range(tip)": measured}, {f"sva{i}.V_a": V for i in range(1, 17)}, f"case{case}"))
    return out


def case_ranges(sim, levers: tuple[float, float], t=None, params=None) -> np.ndarray:
    """Tip ranges ``X_max - X_min`` [mm] of the eight Table II cases.

    Parameters
    ----------
    sim : codegen.Simulator
        A simulator of ``hydrogel_arm(svas=1..16)`` (all SVAs present; the cases choose which are driven).
    levers : (float, float)
        Lever arms [m] of the upper and the lower row.
    t : array, optional
        Time grid [s] (default 0..40 s at 10 Hz); the pulse is 15 s long.
    params : dict, optional
        Further parameter overrides.

    Returns
    -------
    numpy.ndarray
        Eight ranges [mm], in the order of :data:`TABLE_II`.

    Examples
    --------
    >>> from codegen import simulator
    >>> from systems.hydrogel_arm import hydrogel_arm
    >>> sim = simulator(hydrogel_arm(per_segment=1), rtol=1e-7)
    >>> np.round(case_ranges(sim, (2.9e-4, 2.9e-4))[:2], 2)  # Table I as read: 3.6 V bends less than 1.8 V
    array([16.53, 11.76])
    """
    from phs.signals import Piecewise

    if len(levers) != 2 or not all(r > 0 for r in levers):
        raise ParameterError(f"case_ranges: levers must be two positive lever arms (upper, lower) in m, got {levers!r}")
    t = np.linspace(0.0, DURATION, int(DURATION * 10) + 1) if t is None else np.asarray(t, dtype=float)
    out = []
    for _, svas, V, _, _ in TABLE_II:
        p = {f"sva{i}.V_a": V for i in range(1, 17)}
        p.update({f"sva{i}.r": levers[0] if i <= 8 else -levers[1] for i in range(1, 17)})
        p.update(params or {})
        u = {f"V{i}": Piecewise([0.0, PULSE], [V, 0.0]) if i in svas else 0.0 for i in range(1, 17)}
        out.append(float(np.ptp(sim.run(t, u=u, params=p)["tip"])))
    return np.array(out)


@dataclass(frozen=True)
class LeverFit:
    """Lever arms fitted to Table II, with 95 % intervals, and the fitted model's eight ranges
    (``identification``: the :func:`phs.identify` result, where the fit went through it)."""

    levers: tuple[float, float]
    stderr: tuple[float, float]
    interval: tuple[tuple[float, float], tuple[float, float]]
    correlation: float
    ranges: np.ndarray
    relative_errors: np.ndarray
    identification: object = None

    @property
    def nrmse(self) -> float:
        """RMS of the eight relative errors ``(X_model - X_table)/X_table`` (the paper's normalisation)."""
        return float(np.sqrt(np.mean(self.relative_errors**2)))

    def __str__(self) -> str:
        (lo_u, hi_u), (lo_l, hi_l) = self.interval
        return (f"r_upper = {1e3 * self.levers[0]:.4f} mm [{1e3 * lo_u:.4f}, {1e3 * hi_u:.4f}], "
                f"r_lower = {1e3 * self.levers[1]:.4f} mm [{1e3 * lo_l:.4f}, {1e3 * hi_l:.4f}] (95 %), "
                f"correlation {self.correlation:+.2f}, NRMSE {100 * self.nrmse:.1f} %")


def fit_levers(arm, start: tuple[float, float] = (2.9e-4, 2.9e-4), t=None, rtol: float = 1e-7) -> LeverFit:
    """Fit the two rows' lever arms to Table II's eight ranges through :func:`phs.identify`.

    The eight cases are :func:`table_summaries` (each run's inputs and its measured ``range(tip)``), fitted as
    relative errors (identify's default for summaries) with exact CVODES sensitivities, the lever arms in
    linear coordinates; the covariance is ``s² (JᵀJ)⁻¹`` over 8 − 2 degrees of freedom and the 95 % intervals
    use Student's t with 6 degrees of freedom, as in :func:`fit_levers_least_squares`.

    Parameters
    ----------
    arm : PHSystem
        :func:`table_arm` (the rows' lever arms the shared parameters ``r_upper``, ``r_lower``).
    start : (float, float)
        Starting lever arms [m].
    t : array, optional
        Time grid [s] of the runs (default 0..40 s at 10 Hz).
    rtol : float
        Integration tolerance.

    Returns
    -------
    LeverFit

    Examples
    --------
    On the reduced arm (8 rod elements), from the lever arms of :data:`FITTED` (rounded to 3 digits):

    >>> fit = fit_levers(table_arm(), start=FITTED["levers"])
    >>> [round(1e6 * r, 1) for r in fit.levers], round(100 * fit.nrmse, 1), fit.identification.dof  # µm, %, t's dof
    ([29.3, 46.4], 11.0, 6)
    """
    import phs  # the workflows' door (systems import no workflow module)

    fit = phs.identify(arm, table_summaries(t), ["r_upper", "r_lower"], initial={"r_upper": start[0], "r_lower": start[1]},
                       log_scale=(), rtol=rtol)
    levers = (fit.values["r_upper"], fit.values["r_lower"])
    se = (fit.std_errors["r_upper"], fit.std_errors["r_lower"])
    interval = (fit.intervals["r_upper"], fit.intervals["r_lower"])
    return LeverFit(levers, se, interval, float(fit.correlation[0, 1]), fit.modelled, fit.relative_errors, fit)


def fit_levers_least_squares(sim, start: tuple[float, float] = (2.9e-4, 2.9e-4), t=None) -> LeverFit:
    """The fit of :func:`fit_levers` computed independently: scipy's least squares of the relative errors
    of :func:`case_ranges` (the arm with per-SVA lever arms, the pulses as :class:`~phs.signals.Piecewise`
    inputs), its Jacobian by finite differences.

    The covariance is ``s² (JᵀJ)⁻¹`` with ``s²`` the residual variance over 8 − 2 degrees of freedom
    and ``J`` the Jacobian of the relative errors (finite differences of :func:`case_ranges`); the 95 %
    intervals use Student's t with 6 degrees of freedom.

    Examples
    --------
    A stand-in for the arm's simulator whose tip range is linear in the lever arms and the voltage (each
    driven SVA bends the tip by ``r V`` times its distance in segments from the tip):

    >>> class Linear:
    ...     def run(self, t, u, params):
    ...         driven = [int(k[1:]) for k, v in u.items() if not isinstance(v, float)]
    ...         tip = sum(params[f"sva{i}.r"] * params[f"sva{i}.V_a"] * (8.5 - (i - 1) % 8) for i in driven)
    ...         return {"tip": 1e3 * tip * np.asarray(t) / t[-1]}
    >>> fit = fit_levers_least_squares(Linear(), start=(0.1, 0.1))
    >>> [round(1e6 * r, 2) for r in fit.levers], round(100 * fit.nrmse, 1)  # micrometres, per cent
    ([61.54, 93.84], 17.3)
    """
    from scipy.optimize import least_squares

    def residual(log_r):
        return case_ranges(sim, tuple(np.exp(log_r)), t) / MEASURED - 1.0

    sol = least_squares(residual, np.log(np.asarray(start, dtype=float)), diff_step=1e-4, xtol=1e-10, ftol=1e-10)
    levers = np.exp(sol.x)
    jac = sol.jac / levers  # d(residual)/d(r)
    s2 = float(sol.fun @ sol.fun) / (len(MEASURED) - 2)
    cov = s2 * np.linalg.inv(jac.T @ jac)
    se = np.sqrt(np.diag(cov))
    corr = float(cov[0, 1] / (se[0] * se[1]))
    interval = tuple((float(r - T_95 * s), float(r + T_95 * s)) for r, s in zip(levers, se))
    ranges = MEASURED * (1.0 + sol.fun)
    return LeverFit(tuple(float(r) for r in levers), tuple(float(s) for s in se), interval, corr, ranges, sol.fun)


@dataclass(frozen=True)
class Reading:
    """One reading of eq. 7 and Table I and the paper's statements it satisfies."""

    pairs: tuple[int, int, int]
    swapped: tuple[bool, bool, bool]
    sign: int
    time: str
    prefactor: str
    starts_at_zero: bool
    grows_with_V: bool
    fig4_range: float
    ratio: float

    @property
    def force_ok(self) -> bool:
        """Starts at zero, stays tensile, grows with V, and Fig. 4's range is within [0.052, 0.98] N."""
        return self.starts_at_zero and self.grows_with_V and 0.052 <= self.fig4_range <= 0.98

    @property
    def table_ok(self) -> bool:
        """Table II's voltage ratio: 3.6 V over 1.8 V within [1.8, 2.5] (the table gives 2.19 and 2.01)."""
        return 1.8 <= self.ratio <= 2.5

    def describe(self) -> str:
        names = ("d11,d12", "d21,d22", "d31,d32")
        rows = ", ".join(f"b{i}<-{names[p]}{' swapped' if s else ''}" for i, (p, s) in enumerate(zip(self.pairs, self.swapped)))
        return f"{rows}; 1{'+' if self.sign > 0 else '-'}...; {self.time}; prefactor {self.prefactor}"


def reading_force(reading: Reading, V: float, t) -> np.ndarray:
    """Force [N] of an SVA ``t`` s after a step of ``V`` volts under ``reading`` (NaN where it is not real).

    Examples
    --------
    >>> as_fixed = [r for r in eq7_readings() if r.describe() == AS_FIXED][0]
    >>> round(float(reading_force(as_fixed, 1.08, np.array([40.0]))[0]), 5)
    0.04795
    """
    pairs = [(TABLE_I["d11"], TABLE_I["d12"]), (TABLE_I["d21"], TABLE_I["d22"]), (TABLE_I["d31"], TABLE_I["d32"])]
    b = []
    for role, (p, s) in enumerate(zip(reading.pairs, reading.swapped)):
        a, c = pairs[p][::-1] if s else pairs[p]
        b.append(a * V**2 + c if role == 1 else a * V + c)
    b0, b1, b2 = b
    t = np.asarray(t, dtype=float)
    w = np.sqrt(complex(b1**2 / 4 - b2))
    arg = w * t if reading.time == "sqrt(b1^2/4-b2)*t" else np.sqrt((b1**2 / 4 - b2 * t).astype(complex))
    with np.errstate(all="ignore"):
        shape = np.cosh(arg) + b1 / (2 * w) * np.sinh(arg)
        f = (b0 / b2 if reading.prefactor == "b0/b2" else b0) * (1 + reading.sign * np.exp(-b1 * t / 2) * shape)
    return np.where(np.isfinite(f.real) & (np.abs(f.imag) <= 1e-9 * (1 + np.abs(f.real))), f.real, np.nan)


AS_FIXED = "b0<-d11,d12, b1<-d21,d22, b2<-d31,d32; 1-...; sqrt(b1^2/4-b2)*t; prefactor b0/b2"
"""The reading the actuator element uses (:func:`components.hydrogel.step_force`)."""


def eq7_readings() -> list[Reading]:
    """All 384 readings: 6 assignments of Table I's pairs to ``b0, b1, b2`` × 8 orders within the pairs ×
    the bracket's sign × where ``t`` multiplies × the prefactor ``b0/b2`` or ``b0``.

    Examples
    --------
    >>> readings = eq7_readings()
    >>> len(readings), sum(r.force_ok and r.table_ok for r in readings)
    (384, 0)
    """
    t = np.linspace(0.0, 40.0, 4001)
    k15 = int(np.searchsorted(t, PULSE))
    volts = 0.18 * np.arange(1, 21)  # the 20 amplitudes of Fig. 3
    out = []
    for pairs, swapped, sign, time, pref in itertools.product(
            itertools.permutations(range(3)), itertools.product((False, True), repeat=3), (-1, 1),
            ("sqrt(b1^2/4-b2)*t", "sqrt(b1^2/4-b2*t)"), ("b0/b2", "b0")):
        r = Reading(pairs, swapped, sign, time, pref, False, False, np.nan, np.nan)
        f18, f36, f108 = (reading_force(r, V, t) for V in (1.8, 3.6, 1.08))
        real = all(np.all(np.isfinite(f)) for f in (f18, f36, f108))
        zero = real and max(abs(f18[0]), abs(f36[0]), abs(f108[0])) < 1e-12 and min(f18.min(), f36.min(), f108.min()) > -1e-12
        final = np.array([reading_force(r, V, t[-1:])[0] for V in volts])
        grows = bool(np.all(np.isfinite(final)) and np.all(np.diff(final) > 0))
        ratio = float(f36[k15] / f18[k15]) if real and f18[k15] != 0 else np.nan
        out.append(Reading(pairs, tuple(swapped), sign, time, pref, bool(zero), grows,
                           float(np.ptp(f108)) if real else np.nan, ratio))
    return out


__all__ = ["TABLE_II", "MEASURED", "FITTED", "case_ranges", "table_arm", "table_summaries", "fit_levers",
           "fit_levers_least_squares", "LeverFit", "Reading", "reading_force", "eq7_readings",
           "AS_FIXED", "PULSE", "DURATION"]
