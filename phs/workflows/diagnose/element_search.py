"""Searching an input element's parameters: each on a grid then refined, and a step along the zigzag of
an element's joint fit.

An input element (:class:`components.candidates.elements.InputElement`) has a numeric transform: its
parameters are searched by simulation, not differentiated.  :func:`element_search` searches them one at
a time with the model fixed; the joint fit of :mod:`phs.workflows.diagnose.hypotheses` alternates it
with refits of the model, and :func:`extrapolate` steps along a round's whole move when the two zigzag.

Examples
--------
>>> round(element_search(lambda th: (th[0] - 0.3) ** 2, [("a", 0.5, 0.0, 1.0)], [0.5])[0], 6)
0.3
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from codegen import Simulator
from phs.errors import PHSError
from phs.workflows.diagnose.scoring import weight_squared
from phs.workflows.recording import Recording

EXTRAPOLATE = (1.0, 2.0, 4.0, 8.0)
"""Multiples of a round's move tried beyond its end (:func:`extrapolate`).  Not chosen on a measurement."""


def extrapolate(cost, specs, free, bounds, start, end, c_end: float, tol: float = 0.0) -> tuple | None:
    """A step along a round's whole move, element and model together: the alternating rounds of an input
    element's joint fit zigzag when a nominal parameter absorbed part of the effect (each search moves
    the element a little, each refit the model a little, along a valley that neither follows alone); the
    move of one round points along that valley.  ``start`` and ``end``: ``(theta, values)`` before and
    after the round; tries ``end + a (end − start)`` for ``a`` in :data:`EXTRAPOLATE` (a positive
    parameter geometrically, ``v_end (v_end / v_start)^a``; clipped to the element's range and the fit's
    bounds) while the cost keeps falling by more than ``tol`` of itself, one simulation each (a step that
    gains less runs along a direction the data hardly determine, where it only drifts).  Returns
    ``(theta, values, cost)`` of the best point so found, or None.  On the 4 ms loop delay (``examples.concealed_loops``, 4 s) the
    eight rounds crept from 2.1 to 3.4 ms; with the step they reach 3.9 ms.

    Examples
    --------
    A valley along ``theta = b`` (cost ``(theta − b)² + 0.01 (theta + b − 2)²``); one round moved from
    (0.5, 0.4) to (0.6, 0.55), and the step goes on along the valley:

    >>> cost = lambda th, v: (th[0] - v["b"]) ** 2 + 0.01 * (th[0] + v["b"] - 2) ** 2
    >>> th, vals, c = extrapolate(cost, [("a", 0.5, 0.0, 5.0)], ["b"], None, ([0.5], {"b": 0.4}), ([0.6], {"b": 0.55}),
    ...                           cost([0.6], {"b": 0.55}))
    >>> th[0] > 0.6 and vals["b"] > 0.55 and c < cost([0.6], {"b": 0.55})
    True
    """
    (th0, v0), (th1, v1) = start, end
    bounds = bounds or {}
    best = None
    for a in EXTRAPOLATE:
        th = [min(max(b + a * (b - s0), spec[2]), spec[3]) for s0, b, spec in zip(th0, th1, specs, strict=True)]
        vals = dict(v1)
        for k in free:
            x0_, x1_ = float(v0[k]), float(v1[k])
            v = x1_ * (x1_ / x0_) ** a if x0_ > 0 and x1_ > 0 else x1_ + a * (x1_ - x0_)
            lo, hi = bounds.get(k, (-math.inf, math.inf))
            vals[k] = min(max(v, lo), hi)
        c = cost(th, vals)
        here = best[2] if best else c_end
        if not c < here - tol * here:
            break
        best = (th, vals, c)
    return best


REFINE_ITER = 8
"""Most cost evaluations of the bounded refinement of one parameter between two grid points (Brent's method:
the bracket shrinks to about 2 % of its width).  A screening fit, which only ranks the hypotheses and whose
chosen few are refitted from its values, refines by :data:`SCREEN_REFINE_ITER` (about 15 % of the bracket:
a grid step is a factor of 2.4 on a log-spaced range, so within about 14 % of the parameter's best value,
where the cost is flat to second order).  Chosen by that arithmetic, not on a verdict measurement."""
SCREEN_REFINE_ITER = 4
"""Most cost evaluations of a screening fit's bounded refinement (see :data:`REFINE_ITER`).  Chosen by that
arithmetic, not on a verdict measurement."""


LOCAL_SHARE = 1 / 8
"""Half-width of a later round's first bracket around its start, as a share of the grid's step (of its
logarithm on a log-spaced grid: about ±11 % of the value on a three-decade range).  A joint fit's later
rounds move an element a few per cent (the model's refit moved its optimum a little): three evaluations
around the start and parabolic steps find it where the bracket of the two neighbouring grid points (a
factor 2.4 either side) took Brent's method eight.  Chosen by that arithmetic, not on a verdict measurement."""
LOCAL_GROWTH = 1.618
"""Factor by which the local search's steps grow while the cost keeps falling toward the grid's
neighbouring points (a golden-section expansion, as in :func:`scipy.optimize.bracket`)."""


def _parabola(u, f):
    """The vertex of the parabola through three points ``u[0] < u[1] < u[2]`` with ``f[1]`` lowest and the
    parabola's value there, or the middle point and its value when they are collinear or the vertex falls
    outside."""
    (a, b, c), (fa, fb, fc) = u, f
    den = (b - a) * (fb - fc) - (b - c) * (fb - fa)
    if den == 0 or not math.isfinite(den):
        return b, fb
    v = b - 0.5 * ((b - a) ** 2 * (fb - fc) - (b - c) ** 2 * (fb - fa)) / den
    if not a < v < c:
        return b, fb
    # Lagrange's form of the parabola through the three points, at v
    fv = (fa * (v - b) * (v - c) / ((a - b) * (a - c)) + fb * (v - a) * (v - c) / ((b - a) * (b - c))
          + fc * (v - a) * (v - b) / ((c - a) * (c - b)))
    return v, fv


def _local(g, u0: float, lo: float, hi: float, delta: float, steps: int, resolution: float = 0.0):
    """A bounded minimum of ``g`` near ``u0`` within ``[lo, hi]``: the points ``u0 ± delta``, then steps
    growing by :data:`LOCAL_GROWTH` downhill until the cost rises (a bracket), then ``steps`` parabolic
    steps inside it, each only while the parabola promises a decrease of more than ``resolution``.
    Returns ``(u, g(u), side)``: ``side`` 0 for a minimum inside, −1 or +1 when the cost still falls at
    ``lo`` or ``hi`` (then ``u`` is that end: no valley inside, the caller searches beyond it)."""
    pts = {u0: g(u0)}

    def at(u):
        u = min(max(u, lo), hi)
        if u not in pts:
            pts[u] = g(u)
        return u

    left, right = at(u0 - delta), at(u0 + delta)
    mid = u0
    if not pts[mid] <= min(pts[left], pts[right]):  # downhill to one side: walk until the cost rises
        sign = -1.0 if pts[left] < pts[right] else 1.0
        prev, cur, step = mid, (left if sign < 0 else right), delta
        while True:
            if cur in (lo, hi) and pts[cur] < pts[prev]:
                return cur, pts[cur], (-1 if cur == lo else 1)
            step *= LOCAL_GROWTH
            nxt = at(cur + sign * step)
            if not pts[nxt] < pts[cur]:
                left, mid, right = (nxt, cur, prev) if sign < 0 else (prev, cur, nxt)
                break
            prev, cur = cur, nxt
    for _ in range(steps):
        v, promised = _parabola((left, mid, right), (pts[left], pts[mid], pts[right]))
        if abs(v - mid) <= 1e-3 * (right - left) or not pts[mid] - promised > resolution:
            break
        v = at(v)
        if pts[v] < pts[mid]:  # the new best: the bracket closes on it
            left, right = (mid, right) if v > mid else (left, mid)
            mid = v
        else:
            left, right = (left, v) if v > mid else (v, right)
    return mid, pts[mid], 0


def element_search(cost, specs, theta, local: bool = False, refine_iter: int = REFINE_ITER,
                   resolution: float = 0.0) -> list[float]:
    """Each of an input element's parameters in turn: a coarse grid over its range (log-spaced where the
    range is positive, with 0 when the range starts there), then a bounded refinement around the best grid
    point; never ends above the cost of ``theta`` itself.  ``local``: a search near ``theta`` only (a later
    round of a joint fit, where the model's refit moved the element's optimum a little): the points
    :data:`LOCAL_SHARE` of a grid step either side, steps downhill until the cost rises, then parabolic
    steps (one per four of ``refine_iter``), never beyond the grid points either side of ``theta``; the
    grid from such a point on when the cost still falls there (no valley inside: the minimum lies that
    way; that point itself when it is the grid's end), the whole grid when ``theta`` lies outside it.
    ``resolution``: the least decrease of the cost a parabolic step of the local search must promise to be
    taken (a smaller one moves the parameter within what the data resolve).  A parameter whose range is a
    single point is not searched: it stays where ``theta`` holds it.  A search over the grids of more than
    one parameter sweeps them again, locally, while a sweep moves one (:data:`SWEEPS`)."""
    theta = _sweep(cost, specs, theta, local, refine_iter, resolution)
    for _ in range(SWEEPS - 1 if not local and searched(specs) > 1 else 0):  # parameters that set each other's optimum
        before = list(theta)
        theta = _sweep(cost, specs, theta, True, refine_iter, resolution)
        if theta == before:
            break
    return theta


SWEEPS = 3
"""Most sweeps over an element's parameters in a search over their grids (:func:`element_search`): the grid
sweep, then local sweeps while one moves a parameter.  One parameter's optimum may depend on another's
value: a saturation's compression does not pay at the hard clip its sharpness starts at when the truth
compresses gradually, and the sharpness, searched at no compression, moves to the gradual end where the
compression then pays.  Not chosen on a measurement."""


def _sweep(cost, specs, theta, local, refine_iter, resolution) -> list[float]:
    """One sweep of :func:`element_search` over the parameters in turn."""
    import scipy.optimize

    theta = [float(v) for v in theta]
    for k, (_name, _start, lo, hi) in enumerate(specs):
        if not hi > lo:  # a parameter whose range is one point is held there (a reference level, an unused side)
            continue
        grid = np.geomspace(max(lo, 1e-3 * hi), hi, 9) if lo >= 0 else np.linspace(lo, hi, 9)
        if lo == 0:
            grid = np.concatenate([[0.0], grid])

        def f1(v, k=k):
            th = list(theta)
            th[k] = v
            return cost(th)

        def refine(a, c):
            r = scipy.optimize.minimize_scalar(f1, bounds=(a, c), method="bounded",
                                               options={"xatol": 1e-3 * (c - a), "maxiter": refine_iter})
            return float(r.x), float(r.fun)

        best, beyond = None, ()
        if local and grid[1] <= theta[k] <= grid[-1]:
            i = int(np.argmin(np.abs(grid - theta[k]))) if lo < 0 else int(np.argmin(np.abs(np.log(grid[1:] / theta[k])))) + 1
            a, c = grid[max(i - 1, 1 if grid[0] == 0 else 0)], grid[min(i + 1, len(grid) - 1)]
            if lo < 0:  # the search in the parameter itself
                u, cu, side = _local(f1, theta[k], a, c, LOCAL_SHARE * (grid[1] - grid[0]), max(1, refine_iter // 4),
                                     resolution)
            else:  # in its logarithm
                u0, ua, uc = math.log(theta[k]), math.log(a), math.log(c)

                def value(u, x=theta[k], u0=u0, ua=ua, uc=uc, a=a, c=c):
                    """The start and the bracket's ends themselves, bit for bit (points the grid shares)."""
                    return x if u == u0 else a if u == ua else c if u == uc else math.exp(u)

                u, cu, side = _local(lambda u, value=value: f1(value(u)), u0, ua, uc,
                                     LOCAL_SHARE * math.log(grid[2] / grid[1]), max(1, refine_iter // 4), resolution)
                u = value(u)
            # the cost still falls at an end of the bracket: the grid from that end on, the way it falls, or
            # that end itself when it is the grid's (the range's) end
            beyond = () if side == 0 else grid[grid >= c] if side > 0 else grid[grid <= a]
            if len(beyond) < 2:
                best = (float(u), cu)
        if best is None:
            if len(beyond) >= 2:
                grid = beyond
            vals = [f1(g) for g in grid]
            b = int(np.argmin(vals))
            best = (float(grid[b]), vals[b])
            a, c = grid[max(b - 1, 0)], grid[min(b + 1, len(grid) - 1)]
            if c > a:
                x, fx = refine(a, c)
                if fx <= best[1]:
                    best = (x, fx)
        if best[1] <= f1(theta[k]):
            theta[k] = best[0]
    return theta


def _transformed(rec: Recording, element, where: str, theta) -> Recording:
    """``rec`` with the model inputs the input element (parameters ``theta``) sets at its place
    (:meth:`~components.candidates.elements.InputElement.drive`): the transformed command of every input
    of the place (one input, or several driven together), or, between a controller and the plant, the
    element's deviation from the recorded command; with its course between the samples where the element
    gives one (:meth:`~components.candidates.elements.InputElement.course`: a delay by a fraction of a
    sample), which every simulation then reads (:attr:`~phs.workflows.recording.Recording.between`)."""
    if element is None:
        return rec
    sig = dict(rec.signals)
    driven = element.drive(rec.t, sig, where, theta)
    # an input the element sets follows its new course, or the line through its new samples; one that followed a
    # course already (an element accepted before: a delay by a fraction of a sample) is transformed along that
    # course (the line through its new samples would drop the kinks between the samples: on a stepping command,
    # most of a capacitive load's current)
    between = {k: v for k, v in rec.between.items() if k not in driven}
    for k in driven:
        if k in rec.between:
            times, values = rec.between[k]
            between[k] = element.course(times, values, theta) or (times, element.transform(times, values, theta))
    between.update({k: v for k, v in element.drive_between(rec.t, sig, where, theta).items() if k not in rec.between})
    sig.update(driven)
    # the other inputs keep how they behave between samples (a disturbance held by a DAC stays held); an input the
    # element sets keeps a declared hold ("zoh": the element maps held samples to held samples) but not a declared
    # law, which its new samples no longer follow
    holds = {k: h for k, h in rec.holds.items() if k not in driven or isinstance(h, str)}
    return replace(rec, signals=sig, between=between, holds=holds)


def _simulate(system, rec: Recording, x0, params=None, sim=None):
    u = {n: rec.input_signal(n) for n in system.input_names}
    sim = sim or Simulator(system, energy=False)
    return sim.run(rec.t, u=u, x0=x0, params=params)


def channel_weights(data) -> dict:
    """``w_ch`` per output channel of ``data``: the square root of
    :func:`~phs.workflows.diagnose.scoring.weight_squared` on the whole training recording (the user's
    weight, else one over the channel's standard deviation); what :func:`weighted_residual` multiplies by.

    Examples
    --------
    >>> from phs.workflows.diagnose.hypotheses import Data
    >>> rec = Recording.from_arrays(np.linspace(0, 1, 4), {"y": np.array([0.0, 4.0, 0.0, 4.0])})
    >>> data = Data(rec, rec, np.ones(4, bool), None, ["y"], [], {}, [], None)
    >>> channel_weights(data), channel_weights(replace(data, weights={"y": 3.0}))
    ({'y': 0.5}, {'y': 3.0})
    """
    return {ch: math.sqrt(weight_squared(data.weights, ch, data.recording[ch])) for ch in data.outputs}


def weighted_residual(system, rec: Recording, x0, w: dict, params=None, sim=None) -> np.ndarray:
    """The residual of ``system`` simulated on ``rec``'s inputs from ``x0`` (``params`` overriding its values),
    ``w_ch (y_ch − ŷ_ch)`` stacked over the channels of ``w`` (:func:`channel_weights`): its square sum is the
    training cost ``Σ_ch w_ch² RSS_ch``.  A failed simulation raises (``PHSError`` or ``RuntimeError``); a
    residual that left the finite numbers is returned as it is.

    Examples
    --------
    >>> from systems.examples import rc_circuit
    >>> t = np.linspace(0, 0.01, 101)
    >>> rec = Recording.from_arrays(t, {"U": np.ones(101), "v_C": np.ones(101)})
    >>> r = weighted_residual(rc_circuit(), rec, [0.0], {"v_C": 2.0})
    >>> float(r[0]), bool(0 < r[-1] < r[0])
    (2.0, True)
    """
    s = _simulate(system, rec, x0, params=params, sim=sim)
    return np.concatenate([(np.asarray(rec[ch], float) - np.asarray(s[ch], float)) * w[ch] for ch in w])


def trial_cost(system, x0, rec: Recording, element, where: str, data, rtol: float, profile=None) -> Callable:
    """The training cost of an input element's trials on ``rec`` with ``system`` (its parameters fixed, or
    set per call): ``cost(theta, values=None)``, the weighted residual sum of squares
    ``Σ_ch w_ch² Σ (y_ch − ŷ_ch)²`` (the weights of ``data``'s training recording, ``rec`` its window or
    itself) of the model driven through the element at ``theta`` (infinite when the
    simulation fails).  One simulation per distinct input the model receives: the neutral point is often
    on the grid, and parameters that do not act (a saturation's sharpness while it compresses nothing)
    give the input of a trial already run (:func:`input_key`).

    With a ``profile`` (:func:`nominal_profile`), the cost is the one left after the model's free
    parameters re-adjust to first order (:meth:`Profile.left`), ``cost.step(theta)`` gives that
    re-adjustment, and the profile's own simulation (the element's neutral point) is not run again.
    ``cost.raw`` is the cost without the re-adjustment, from the same simulations.

    Examples
    --------
    >>> from components.candidates import TimeDelay
    >>> from systems.examples import rc_circuit
    >>> from phs.workflows.diagnose.hypotheses import Data
    >>> t = np.linspace(0, 0.02, 401); u = np.where(t > 0.005, 1.0, 0.0)
    >>> late = Recording.from_arrays(t, {"U": np.where(t > 0.006, 1.0, 0.0), "v_C": np.zeros(401)})
    >>> late = replace(late, signals={**late.signals, "v_C": _simulate(rc_circuit(), late, [0.0])["v_C"]})
    >>> rec = replace(late, signals={**late.signals, "U": u})
    >>> data = Data(rec, rec, np.ones(401, bool), None, ["v_C"], [], {}, [], None)
    >>> cost = trial_cost(rc_circuit(), [0.0], rec, TimeDelay(), "U", data, 1e-8)
    >>> cost([0.001]) < 1e-8 < cost([0.0])
    True
    """
    sim = Simulator(system, rtol=rtol, energy=False)
    w = channel_weights(data)  # the whole training recording's
    seen: dict = {}
    if profile is not None and profile.base is not None:  # the profile's own simulation: the element's neutral point
        seen[(input_key(rec, profile.rec), ())] = (float(profile.base @ profile.base), profile.coefficients(profile.base))

    def evaluate(theta, values=None):
        params = tuple(sorted({k: float(values[k]) for k in data.free}.items())) if values is not None else ()
        key = tuple(float(v) for v in theta) + params
        if key not in seen:
            r = _transformed(rec, element, where, theta)
            same = (input_key(rec, r), params)
            if same not in seen:
                try:
                    res = weighted_residual(system, r, x0, w, params=dict(params) if values is not None else None, sim=sim)
                    c = float(res @ res)
                    seen[same] = (c, profile.coefficients(res) if profile is not None else None) if math.isfinite(c) else (math.inf, None)
                except (PHSError, RuntimeError):
                    seen[same] = (math.inf, None)
            seen[key] = seen[same]
        return seen[key]

    def cost(theta, values=None):
        c, a = evaluate(theta, values)
        return c if a is None else profile.left(c, a)

    def raw(theta, values=None):
        return evaluate(theta, values)[0]

    cost.step = lambda theta: profile.step(evaluate(theta)[1]) if profile is not None and evaluate(theta)[1] is not None else {}
    cost.raw = raw
    return cost


PROFILE_STEP = 1e-3
"""Relative step of the finite differences that give the free parameters' first-order directions
(:func:`nominal_profile`; an absolute ``1e-3`` for a parameter at zero).  Large beside the integration's
tolerance (at most ``1e-6`` relative, so a direction is resolved to about ``1e-3``), small beside the moves the
profile stands for.  Not chosen on a measurement."""
PROFILE_RCOND = 1e-6
"""Directions whose singular value is below this share of the largest are left out of the profile (free
parameters that act alike on the recording).  A numerical margin, not a measurement."""
PROFILE_TRUST = 0.5
"""Largest relative change of a free parameter in the step :meth:`Profile.step` proposes (the whole step
scaled down to it): the first-order model holds near where it was made.  Not chosen on a measurement."""


class Profile:
    """The free parameters' first-order directions on a recording: ``D`` (columns ``r(p + h_k e_k) − r(p)``,
    weighted and stacked over the channels, for the steps ``h``), factored once.  :meth:`left` is the cost
    of a residual after the best re-adjustment along them (``‖r‖² − ‖Uᵀ r‖²``, with ``U`` the left singular
    vectors kept), :meth:`step` the re-adjustment of the parameters itself (``−D⁺ r``, scaled to
    :data:`PROFILE_TRUST`, within ``bounds``).

    Examples
    --------
    >>> D = np.array([[1.0], [1.0], [0.0]])
    >>> pr = Profile(D, {"k": 2.0}, {"k": 0.1}, {"k": (0.0, 10.0)})
    >>> r = np.array([0.3, 0.3, 0.4])
    >>> round(pr.left(float(r @ r), pr.coefficients(r)), 12), round(pr.step(pr.coefficients(r))["k"], 12)
    (0.16, 1.97)
    """

    def __init__(self, D: np.ndarray, values: dict, steps: dict, bounds: dict):
        U, s, Vt = np.linalg.svd(D, full_matrices=False)
        # (and none whose inverse overflows: a direction of subnormal size carries nothing)
        keep = s > max(PROFILE_RCOND * s[0], np.finfo(float).tiny) if s.size else np.zeros(s.shape, bool)
        self.U = U[:, keep]
        self.map = Vt[keep].T / s[keep]  # D⁺ = V Σ⁻¹ Uᵀ: coefficients Uᵀ r to steps in units of h
        self.values, self.steps, self.bounds = dict(values), dict(steps), dict(bounds)
        self.base, self.rec = None, None  # the residual at ``values`` and the recording it was simulated on

    def coefficients(self, r: np.ndarray) -> np.ndarray:
        return self.U.T @ r

    def left(self, c: float, a: np.ndarray) -> float:
        return max(c - float(a @ a), 0.0)

    def step(self, a: np.ndarray) -> dict:
        names = list(self.steps)
        delta = -(self.map @ a) * np.array([self.steps[k] for k in names])
        if not np.all(np.isfinite(delta)):  # no first-order step to take
            return {}
        rel = max((abs(d) / abs(self.values[k]) for k, d in zip(names, delta, strict=True) if self.values[k] != 0), default=0.0)
        if rel > PROFILE_TRUST:
            delta = delta * (PROFILE_TRUST / rel)
        out = {}
        for k, d in zip(names, delta, strict=True):
            lo, hi = self.bounds.get(k, (-math.inf, math.inf))
            out[k] = float(min(max(self.values[k] + d, lo), hi))
        return out


def nominal_profile(system, x0, rec: Recording, data, values: dict, bounds: dict, rtol: float) -> Profile | None:
    """The first-order directions of the free parameters ``data.free`` of ``system`` at ``values`` on
    ``rec`` (the recording as the model receives it: an input element at its neutral point), by forward
    differences (:data:`PROFILE_STEP`, away from a bound of ``bounds``): one simulation per parameter.
    ``None`` without free parameters or when the simulation at ``values`` fails; a parameter whose
    stepped simulation fails is left out.

    An input element's parameters are searched with the model's fixed (one simulation per trial); a
    nominal parameter may have absorbed part of the effect (a gain the compression of a saturation), so
    that the element alone, the model held, lowers nothing.  Searched on the cost left after the model's
    first-order re-adjustment (:class:`Profile`), the element is ranked on what it adds once the model
    re-adjusts, as a jointly fitted candidate is.
    """
    free = [k for k in data.free if k in values]
    if not free:
        return None
    sim = Simulator(system, rtol=rtol, energy=False)
    w = channel_weights(data)  # the whole training recording's

    def residual(vals):
        r = weighted_residual(system, rec, x0, w, params=vals, sim=sim)
        return r if np.all(np.isfinite(r)) else None

    base_vals = {k: float(values[k]) for k in free}
    try:
        base = residual(base_vals)
    except (PHSError, RuntimeError):
        return None
    if base is None:
        return None
    cols, steps, used = [], {}, {}
    for k in free:
        v = base_vals[k]
        lo, hi = bounds.get(k, (-math.inf, math.inf))
        h = PROFILE_STEP * (abs(v) if v != 0 else 1.0)
        if v + h > hi:
            h = -h
        try:
            r = residual({**base_vals, k: v + h})
        except (PHSError, RuntimeError):
            r = None
        if r is not None:
            cols.append(r - base)
            steps[k], used[k] = h, v
    if not cols:
        return None
    prof = Profile(np.column_stack(cols), used, steps, {k: tuple(bounds.get(k, (-math.inf, math.inf))) for k in used})
    prof.base, prof.rec = base, rec
    return prof


def searched(specs) -> int:
    """How many of an input element's parameters ``(name, start, lo, hi)`` are searched: those whose range
    is more than a point (:func:`element_search` holds the others); what a hypothesis' parameter count
    takes from its element.

    Examples
    --------
    >>> searched([("c", 0.0, 0.0, 0.8), ("ref", 2.0, 2.0, 2.0)])
    1
    """
    return sum(1 for _name, _start, lo, hi in specs if hi > lo)


def input_key(rec, transformed) -> tuple:
    """What an input element changed in a recording (``transformed`` from ``rec``), as a hashable key: the
    bytes of every signal and course between samples that is not ``rec``'s own object.  Two trials with
    the same key drive the model alike, so one simulation serves both.

    Examples
    --------
    >>> from types import SimpleNamespace as NS
    >>> u = np.zeros(3)
    >>> rec = NS(signals={"U": u, "y": u}, between={})
    >>> a, b = NS(signals={"U": np.ones(3), "y": u}, between={}), NS(signals={"U": np.ones(3), "y": u}, between={})
    >>> input_key(rec, a) == input_key(rec, b) != input_key(rec, rec)
    True
    """
    def digest(v) -> bytes:
        arrays = v if isinstance(v, tuple) else (v,)
        return b"".join(np.ascontiguousarray(a, dtype=float).tobytes() for a in arrays)

    changed = [(k, digest(v)) for k, v in transformed.signals.items() if v is not rec.signals.get(k)]
    between = [(k, digest(v)) for k, v in transformed.between.items() if v is not rec.between.get(k)]
    return tuple(sorted(changed)), tuple(sorted(between))


PRESSED = 1e-6
"""A fitted value within this share of its range's width (of its logarithm's, for a positive range spanning
decades) of an end lies on that bound (:func:`_pressed`).  A numerical margin, not a measurement."""


def _pressed(values: dict, data, system) -> list[str]:
    """The free parameters of ``system`` whose fitted ``values`` lie on a bound of the fit (``data.bounds``,
    else their declared range) and whose value the model was built with (``data.given``) lies inside it: a nominal fit
    pressed against a bound is absorbing something the model lacks (a loop's delay absorbed by a damping
    at its lower end), and an input element's alternating fit from there stays in that corner.

    Examples
    --------
    >>> from phs.workflows.recording import Recording
    >>> from phs.workflows.diagnose.hypotheses import Data
    >>> rec = Recording.from_arrays(np.linspace(0, 1, 11), {"y": np.zeros(11)})
    >>> d = Data(rec, rec, np.ones(11, bool), None, ["y"], ["b", "k"], {"b": (0.1, 10.0), "k": (1.0, 100.0)}, [], None,
    ...          given={"b": 1.0, "k": 40.0})
    >>> _pressed({"b": 0.1, "k": 39.9}, d, None), _pressed({"b": 0.5, "k": 39.9}, d, None)
    (['b'], [])
    """
    out = []
    for k in data.free:
        if not data.given or k not in data.given or k not in values:
            continue
        lo, hi = (data.bounds or {}).get(k) or (system.param(k).range if system is not None else None) or (None, None)
        if lo is None or hi is None or not lo < hi:
            continue
        v, g = float(values[k]), float(data.given[k])
        f = (lambda x: math.log(x)) if lo > 0 and hi / lo >= 10**1.5 else (lambda x: x)
        width = f(hi) - f(lo)
        on = min(abs(f(v) - f(lo)), abs(f(hi) - f(v))) <= PRESSED * width if v > 0 or f is not math.log else False
        if on and lo < g < hi and abs(f(g) - f(v)) > 10 * PRESSED * width:
            out.append(k)
    return out
