"""Integrator failures in words: what happened, where, which state, and what to try.

CVODES and IDAS stop with a return flag that CasADi reports inside a ``RuntimeError`` whose text names
a C++ source file (``CVode returned "CV_TOO_MUCH_WORK". Consult CVODES documentation.``).  This module
reads the flag (:func:`failure_code`), groups the flags into a few kinds of failure (:data:`CODES`) and
writes the message a :class:`~phs.errors.SimulationError` carries (:func:`describe`): the interval, what
happened, the state at the failure against its declared range and typical size (or the state that moves
fastest there), parameters and inputs outside their declared ranges, the fastest time constant of the
model there, and which option to change.  The flag stays at the end in parentheses.  Where no state is
known (a fit's sensitivity run, a batch's raw error), :func:`in_words` rewrites the raw text in place.
"""

from __future__ import annotations

import re

import numpy as np

from codegen._domain import fmt_state

__all__ = ["CODES", "failure_code", "describe", "in_words", "state_story"]

CODES = {
    **{f"{p}_TOO_MUCH_WORK": "work" for p in ("CV", "IDA")}, "max_num_steps": "work",
    **{f"{p}_TOO_MUCH_ACC": "accuracy" for p in ("CV", "IDA")},
    "CV_ERR_FAILURE": "error_test", "IDA_ERR_FAIL": "error_test",
    "CV_CONV_FAILURE": "convergence", "IDA_CONV_FAIL": "convergence", "IDA_NCONV_FAIL": "convergence",
    **{f"{p}_{k}": "linear" for p in ("CV", "IDA") for k in ("LINIT_FAIL", "LSETUP_FAIL", "LSOLVE_FAIL")},
    "psetup": "linear", "lsetup": "linear", "lsolve": "linear", "psolve": "linear",
    **{f"CV_{w}{k}": "nonfinite" for w in ("", "Q", "S") for k in ("RHSFUNC_FAIL", "RHSFUNC_ERR")},
    **{f"CV_{a}_{w}RHSFUNC_ERR": "nonfinite" for a in ("FIRST", "REPTD", "UNREC") for w in ("", "Q", "S")},
    "IDA_RES_FAIL": "nonfinite", "IDA_REP_RES_ERR": "nonfinite", "IDA_FIRST_RES_FAIL": "nonfinite",
    "IDA_QRHS_FAIL": "nonfinite", "IDA_SRES_FAIL": "nonfinite", "IDA_REP_SRES_ERR": "nonfinite",
    "rhs": "nonfinite", "res": "nonfinite", "nan": "nonfinite",
    "IDA_CONSTR_FAIL": "convergence", "IDA_LINESEARCH_FAIL": "convergence", "IDA_NO_RECOVERY": "nonfinite",
    "IDA_BAD_EWT": "accuracy",
    "CV_TOO_CLOSE": "too_close", "CV_ILL_INPUT": "ill_input", "IDA_ILL_INPUT": "ill_input",
}
"""SUNDIALS return flags (and CasADi's own failure words) by the kind of failure they report."""

_WHAT = {
    "work": "it took its maximum number of internal steps{max_steps} within one output interval",
    "accuracy": "it could not reach the requested accuracy (the tolerance is too small for the size of the state)",
    "error_test": "its error test failed repeatedly with the smallest step (the solution changes abruptly or without bound)",
    "convergence": "the Newton iterations of its implicit steps failed repeatedly (the dynamics are very stiff or not smooth there)",
    "linear": "the linear solver failed (the Jacobian of the dynamics is singular or not finite there)",
    "nonfinite": "the model's equations gave NaN or Inf at the states it tried",
    "too_close": "the output interval is too short for the size of the time",
    "ill_input": "it refused its inputs (a non-finite initial state, parameter or input, or a bad tolerance)",
    None: "it stopped",
}
_TRY = {
    "work": "try a finer output step (--dt, or more points in t: the step limit counts per output interval){dt}, "
            "a shorter run (--t-end), or a parameter that does not make the model this fast",
    "accuracy": "try a larger --rtol (or --atol)",
    "error_test": "try a smaller --rtol, an input without jumps between its breakpoints, or parameters that keep the model bounded",
    "convergence": "try a smaller --rtol, or a parameter that does not make the model this stiff",
    "linear": "keep the state, the inputs and the parameters inside the ranges the model declares",
    "nonfinite": "keep the initial state, the inputs and the parameters inside the ranges the model declares (or a smaller --rtol)",
    "too_close": "try a coarser output step (--dt) or times nearer zero",
    "ill_input": "check the initial state, the parameters and --rtol/--atol",
    None: "try a smaller --rtol or a finer output step (--dt)",
}
RUNAWAY = 1e3
"""A state this many times its typical size at a failure has run away: the message says to look at what
drives it rather than at the output step or the tolerance."""
INPUT_SURGE = 1e3
"""An input whose magnitude within the failed interval exceeds this many times both its median there and
its value at the interval's start is named as growing (an input with a pole, such as ``1/(T - t)``)."""
_LABEL = {"psetup": "CasADi: psetup failed", "lsetup": "CasADi: lsetup failed", "lsolve": "CasADi: lsolve failed",
          "psolve": "CasADi: psolve failed", "rhs": "CasADi: rhs failed", "res": "CasADi: res failed",
          "nan": "CasADi: NaN or Inf in evaluation", "max_num_steps": "CasADi: max_num_steps"}
"""How a failure named by CasADi's own words (no SUNDIALS flag) is labelled at the end of a message."""
_FLAG = re.compile(r'returned "?([A-Z][A-Z_]+)"?')
_CASADI_WORD = re.compile(r"\b(psetup|lsetup|lsolve|psolve|rhs|res)B? failed")
_NAMED = re.compile(r"\b((?:CV|IDA)_[A-Z_]+)\b")
_RAW = re.compile(r"(?:\S+\.(?:cpp|hpp|c|h):\d+:\s*)|(?:Error in Function::\S+ for '[^']*' \[\w+\] at )"
                  r"|(?:\s*Consult \w+ documentation\.)")


def failure_code(text) -> str | None:
    """The integrator's return flag, or CasADi's own failure word, named in an error text (None if none).

    Examples
    --------
    >>> failure_code('.../cvodes_interface.cpp:403: CVode returned "CV_TOO_MUCH_WORK". Consult CVODES documentation.')
    'CV_TOO_MUCH_WORK'
    >>> failure_code("psetup failed: NaN"), failure_code("division by zero") is None
    ('psetup', True)
    """
    text = str(text)
    for rx in (_FLAG, _NAMED):
        m = rx.search(text)
        if m and (m.group(1) in CODES or m.group(1)[:3] in ("CV_", "IDA")):  # an unlisted flag: "it stopped"
            return m.group(1)
    m = _CASADI_WORD.search(text)
    if m:
        return m.group(1)
    if "max_num_steps" in text:
        return "max_num_steps"
    if re.search(r"\b(nan|NaN|inf|Inf)\b", text) and re.search(r"[Ii]ntegrat|(?:Cvodes|Idas)Interface", text):
        return "nan"
    return None


def in_words(text, hint: str | None = None) -> str:
    """``text`` with a raw integrator failure (C++ file, flag, "Consult ... documentation") put in words:
    what happened and, unless ``hint`` is given instead (``""``: none), what to try.

    Examples
    --------
    >>> print(in_words('fit failed: .../cvodes_interface.cpp:403: CVode returned "CV_REPTD_RHSFUNC_ERR". '
    ...                'Consult CVODES documentation.', hint="at parameter values the fit tried"))  # doctest: +NORMALIZE_WHITESPACE
    fit failed: the integrator failed: the model's equations gave NaN or Inf at the states it tried,
    at parameter values the fit tried (CV_REPTD_RHSFUNC_ERR)
    >>> print(in_words("Integrator failed: CV_TOO_MUCH_ACC", hint=""))  # doctest: +NORMALIZE_WHITESPACE
    the integrator failed: it could not reach the requested accuracy (the tolerance is too small for the
    size of the state) (CV_TOO_MUCH_ACC)
    >>> in_words("the step from t=0 failed") == "the step from t=0 failed"   # nothing raw: unchanged
    True
    """
    text = str(text)
    code = failure_code(text)
    if code is None or re.search(r"[(;] ?" + re.escape(_LABEL.get(code, code)) + r"\)", text):  # nothing raw, or in words
        return text
    if not (code[:3] in ("CV_", "IDA") or _RAW.search(text)):  # CasADi's own words without a source file
        return text
    kind = CODES.get(code)
    lines = [ln for ln in text.splitlines() if not ln.strip().startswith("Error in Function::")] or [text]
    head = _RAW.sub(" ", " ".join(lines))
    head = re.sub(r"\s*(?:\w+ )?returned \"?[A-Z_]+\"?\.?|\b" + re.escape(code) + r"\b", "", head).strip(" :.")
    head = re.sub(r"(?i)^(?:cvodes|idas|integrator|the integrator)(?: failed)?$", "", head.strip())
    tail = _TRY[kind].format(dt="") if hint is None else hint
    words = (f"the integrator failed: {_WHAT[kind].format(max_steps='')}" + (f", {tail}" if tail else "")
             + f" ({_LABEL.get(code, code)})")
    return f"{head}: {words}" if head else words


def state_story(system, x, xdot=None, h=None, u=None, p=None) -> str:
    """What the state ``x`` says about a failure: non-finite states, states outside their declared range
    or far above their typical size, else the state moving fastest (``xdot`` over an interval ``h``);
    inputs and parameters outside declared ranges are added.  Always names at least one state.

    Examples
    --------
    >>> from systems.examples import mass_spring_damper
    >>> state_story(mass_spring_damper(), [3e6, 0.1])
    'm.p = 3e+06 is outside its range [-10, 10] kg*m/s'
    >>> state_story(mass_spring_damper(), [0.0, 0.1], xdot=[-5.0, 0.0], h=1.0)
    'm.p moves fastest (rate -5 kg*m/s per s: its typical size 10 in 2 s)'
    """
    return _story(system, x, xdot, u, p)[0]


def _story(system, x, xdot=None, u=None, p=None) -> tuple[str, float]:
    """:func:`state_story` and the largest ratio of a state to its typical size (inf for a non-finite one)."""
    x = np.asarray(x, dtype=float).reshape(-1)
    states = system.states
    typical = np.array([s.typical for s in states])
    ratio = np.abs(x) / typical
    far = float(np.max(np.where(np.isfinite(ratio), ratio, np.inf))) if len(x) else 0.0
    parts = [f"{s.name} = {v:.4g} is not finite" for s, v in zip(states, x) if not np.isfinite(v)]
    out = []
    for s, v in zip(states, x):
        lo, hi = s.range
        if np.isfinite(v) and not lo <= v <= hi:
            out.append((max(lo - v, v - hi) / max(hi - lo, 1e-300), f"{s.name} = {v:.4g} is outside its range "
                        f"[{lo:.4g}, {hi:.4g}]" + (f" {s.unit}" if s.unit not in ("", "1") else "")))
    parts += [w for _, w in sorted(out, key=lambda o: -o[0])[:2]]
    if not parts and len(x):
        k = int(np.argmax(ratio))
        if ratio[k] > 10:
            parts.append(f"{states[k].name} = {x[k]:.4g} is {ratio[k]:.3g} times its typical size {typical[k]:.4g}")
        elif xdot is not None and np.all(np.isfinite(xdot)):
            r = np.abs(np.asarray(xdot, dtype=float).reshape(-1)) / typical
            k = int(np.argmax(np.where(np.isfinite(r), r, np.inf)))
            unit = states[k].unit if states[k].unit not in ("", "1") else "units"
            parts.append(f"{states[k].name} moves fastest (rate {float(np.ravel(xdot)[k]):.3g} {unit} per s: its typical "
                         f"size {typical[k]:.4g} in {1 / r[k] if r[k] > 0 else np.inf:.3g} s)")
        else:
            parts.append(f"every state inside its range (the largest against its typical size: {states[k].name} = "
                         f"{x[k]:.4g}, {ratio[k]:.2g} of it)")
    parts += _outside(system.params, p, "parameter")
    return "; ".join(parts), far


def _outside(infos, values, what) -> list[str]:
    if values is None:
        return []
    out = []
    for info, v in zip(infos, np.asarray(values, dtype=float).reshape(-1)):
        rng = getattr(info, "range", None)
        if not np.isfinite(v):
            out.append(f"{what} {info.name} = {v:.4g} is not finite")
        elif rng is not None and not rng[0] <= v <= rng[1]:
            out.append(f"{what} {info.name} = {v:.4g} is outside its range [{rng[0]:.4g}, {rng[1]:.4g}]")
    return out


def _inputs_story(system, inputs) -> list[str]:
    """Inputs that are not finite, or outside their declared range, somewhere in ``inputs`` (``(times, U)``):
    the first time each is."""
    if inputs is None or not len(system.inputs):
        return []
    times, U = np.asarray(inputs[0], dtype=float), np.asarray(inputs[1], dtype=float).reshape(len(inputs[0]), -1)
    out = []
    for j, info in enumerate(system.inputs):
        rng = info.range if info.range is not None else (-np.inf, np.inf)
        with np.errstate(invalid="ignore"):
            bad = ~np.isfinite(U[:, j]) | (U[:, j] < rng[0]) | (U[:, j] > rng[1])
        if np.any(bad):
            k = int(np.argmax(bad))
            out.append(f"input {info.name} = {U[k, j]:.4g} at t={times[k]:.6g} is "
                       + ("not finite" if not np.isfinite(U[k, j]) else f"outside its range [{rng[0]:.4g}, {rng[1]:.4g}]"))
            continue
        size = np.abs(U[:, j])
        k = int(np.argmax(size))
        if size[k] > INPUT_SURGE * max(float(np.median(size)), float(size[0])):
            out.append(f"input {info.name} grows to {U[k, j]:.4g} at t={times[k]:.6g} (from {U[0, j]:.4g} at t={times[0]:.6g})")
    return out


def _fastest(functions, x, u, p) -> tuple[float, float] | None:
    """``(fastest time constant, largest growth rate)`` of the linearised dynamics at ``x`` (None if unknown)."""
    if functions is None or len(x) == 0:
        return None
    try:
        A = np.asarray(functions.jac_rhs(x, u, p)[0], dtype=float)
        lam = np.linalg.eigvals(A)
    except (RuntimeError, ValueError, np.linalg.LinAlgError):
        return None
    if not np.all(np.isfinite(lam)) or not np.any(lam != 0):
        return None
    return 1.0 / float(np.max(np.abs(lam))), float(np.max(lam.real))


def describe(error, system, *, t0=None, t1=None, t=None, x=None, u=None, p=None, functions=None, max_steps=None,
             dt=None, inputs=None, subject=None) -> str:
    """The message of an integrator failure ``error`` (a ``RuntimeError`` or its text) of ``system``.

    Parameters
    ----------
    error : Exception or str
        What CasADi raised.
    system : PHSystem
    t0, t1 : float, optional
        The output interval the integrator failed in.
    t, x : float and array, optional
        The time the integrator reached and the state there (default ``t0``).
    u, p : array, optional
        Inputs and parameters at ``t``, checked against their declared ranges.
    functions : GeneratedFunctions, optional
        The system's generated functions: the state's rates and the fastest time constant there.
    max_steps : int, optional
        The integrator's limit of internal steps per output interval.
    dt : float, optional
        An output step that passed from the failing state (too much work: the step suggested).
    inputs : (array, array), optional
        Times and inputs (rows) across the failed interval: a non-finite input, or one outside its declared
        range, is named with the first time it is.
    subject : str, optional
        Default ``"simulation of '<name>'"``.

    Examples
    --------
    >>> from systems.examples import rc_circuit
    >>> err = RuntimeError('.../cvodes_interface.cpp:403: CVode returned "CV_TOO_MUCH_WORK". Consult CVODES documentation.')
    >>> print(describe(err, rc_circuit(), t0=0.0, t1=1e6, t=1.0, x=[1e-6], max_steps=20000, dt=0.5))
    ... # doctest: +NORMALIZE_WHITESPACE
    simulation of 'rc': the integrator failed between t=0 and t=1e+06 (reached t=1): it took its maximum
    number of internal steps (20000) within one output interval; at t=1: every state inside its range (the
    largest against its typical size: C.Q = 1e-06, 0.1 of it); try a finer output step (--dt, or more
    points in t: the step limit counts per output interval) of 0.5 s or less, a shorter run (--t-end), or
    a parameter that does not make the model this fast (state: C.Q=1e-06; CV_TOO_MUCH_WORK)
    """
    code = failure_code(error)
    kind = CODES.get(code) if code else None
    where = ""
    if t0 is not None:
        where = f" between t={t0:.6g} and t={t1:.6g}" if t1 is not None else f" at t={t0:.6g}"
    t = t0 if t is None else t
    if t is not None and t0 is not None and t != t0:
        where += f" (reached t={t:.6g})"
    msg = (f"{subject or f'simulation of {system.name!r}'}: the integrator failed{where}: "
           + _WHAT[kind].format(max_steps=f" ({max_steps})" if max_steps else ""))
    h = (t1 - t0) if t0 is not None and t1 is not None else None
    runaway = False
    p_out = _outside(system.params, p, "parameter")
    if x is not None:
        x = np.asarray(x, dtype=float).reshape(-1)
        xdot = fast = None
        if functions is not None and u is not None and p is not None and np.all(np.isfinite(x)):
            try:
                xdot = np.asarray(functions.rhs(x, u, p), dtype=float).reshape(-1)
            except RuntimeError:
                xdot = None
            fast = _fastest(functions, x, u, p)
        story, far = _story(system, x, xdot, u, p)
        msg += f"; at t={t:.6g}: {story}" if t is not None else f"; {story}"
        runaway = far > RUNAWAY
        if fast is not None and h is not None:
            tau, grow = fast
            if grow > 0 and grow * h > 50:
                msg += f"; the model is unstable there (it grows by a factor e every {1 / grow:.3g} s)"
                runaway = runaway or far > 1
            elif h / tau > 0.1 * (max_steps or 1e4):
                msg += f"; its fastest time constant there is {tau:.3g} s against an output step of {h:.3g} s"
    elif p_out:
        msg += "; " + "; ".join(p_out)
    u_out = _inputs_story(system, inputs if inputs is not None else (None if u is None else ([t], [u])))
    if u_out:
        msg += "; " + "; ".join(u_out)
    if u_out and kind != "ill_input":
        hint = ("keep the inputs finite and inside the ranges the model declares (an input growing without bound "
                "cannot be followed by a finer --dt or another --rtol)")
    elif runaway and kind in ("work", "error_test", "convergence", "nonfinite", "linear", None):
        hint = ("the solution runs away, which a finer --dt or another --rtol will not cure: check the parameters, "
                "the input amplitude and the initial state that drive it (or a model valid that far)")
    else:
        hint = _TRY[kind].format(dt=f" of {dt:.2g} s or less" if dt else "")
        if kind == "work" and p_out:
            hint = hint.replace("a parameter that does not make the model this fast",
                                "the parameters outside their range brought back in")
    msg += f"; {hint}"
    tail = [f"state: {fmt_state(system, x)}"] if x is not None and 0 < len(x) <= 12 else []
    tail.append(_LABEL.get(code, code) if code else _short(error))
    return msg + " (" + "; ".join(t for t in tail if t) + ")"


def _short(error) -> str:
    """The last line of a raw error without C++ file names, shortened (for a failure of no known flag)."""
    lines = [ln for ln in str(error).strip().splitlines() if ln.strip()]
    return _RAW.sub(" ", lines[-1]).strip(" :")[:160] if lines else type(error).__name__
