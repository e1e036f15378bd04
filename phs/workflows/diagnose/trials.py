"""Diagnosing many recordings of one model (trials at several amplitudes, frequencies, loads, devices) and
saying which effects recur across them.

:func:`diagnose_trials` runs :func:`~phs.workflows.diagnose.diagnose` on each trial, in forked processes or on
the workers of a Dask cluster (:func:`~phs.workflows.diagnose.pool.on_cluster`), keeps each trial's diagnosis as
JSON in ``out/trials/`` as it finishes, and resumes: a trial whose stored identity (model hash, parameters,
options, the digest of its recording as read) matches is not run again, one that differs is refused.
Parameters shared by every trial (``shared``) are first fitted jointly (:func:`fit_shared`), then held at
those values in every trial's diagnosis.  :class:`~phs.workflows.diagnose.trials_summary.Trials` gathers the
verdicts: which effects recur, and the spread of their parameters.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import sys

import numpy as np

from phs.errors import InputDataError, ParameterError, PHSError, SimulationError
from phs.workflows.diagnose.pool import on_cluster, run_forked
from phs.workflows.diagnose.trials_summary import Trials, trial_record

TRIALS_DIR = "trials"
"""Subdirectory of ``out`` holding one ``NAME.json`` per finished trial."""


def recording_digest(rec) -> str:
    """SHA-256 (16 hex digits) of a recording as a diagnosis reads it: its times, every signal by name and
    how each input behaves between samples.

    Examples
    --------
    >>> import numpy as np
    >>> from phs.workflows.recording import Recording
    >>> a = Recording.from_arrays(np.arange(3.0), {"U": np.zeros(3)})
    >>> b = Recording.from_arrays(np.arange(3.0), {"U": np.ones(3)})
    >>> len(recording_digest(a)), recording_digest(a) == recording_digest(b)
    (16, False)
    """
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(np.asarray(rec.t, dtype=float)).tobytes())
    for name in sorted(rec.signals):
        h.update(name.encode())
        h.update(np.ascontiguousarray(np.asarray(rec.signals[name], dtype=float)).tobytes())
    for name in sorted(rec.holds):
        v = rec.holds[name]
        h.update(f"{name}={v if isinstance(v, str) else re.sub(' at 0x[0-9a-f]+', '', repr(v))}".encode())
    return h.hexdigest()[:16]


def fit_shared(system, recordings: dict, shared, free=(), *, outputs=None, x0=None, rtol: float = 1e-7,
               max_iter: int = 100) -> dict:
    """Fit the parameters ``shared`` jointly on every recording, and ``free`` separately on each.

    Each recording is simulated on its own (from ``x0``, with its own inputs); the output-error residuals
    of all recordings, each channel weighted by ``1 / std`` of that recording's channel, form one least
    squares whose unknowns are the shared parameters and one copy of ``free`` per recording, with the exact
    sensitivities of :func:`phs.identify` (its residual of one recording, stacked).  This is not a fit on the
    concatenated recordings: no trajectory runs from one recording's end into the next one's start.

    Parameters
    ----------
    system : PHSystem
    recordings : dict of str -> Recording
    shared : sequence of str
        Parameters with one value for every recording.
    free : sequence of str
        Parameters fitted per recording at the same time.
    outputs, x0, rtol, max_iter
        As for :func:`phs.identify`.

    Returns
    -------
    dict
        ``shared`` (name -> value), ``local`` (recording -> name -> value), ``cost``, ``evaluations``,
        ``message``.

    Examples
    --------
    >>> import numpy as np
    >>> from codegen import simulate
    >>> from phs.workflows.recording import Recording
    >>> from systems.examples import rc_circuit
    >>> t = np.linspace(0, 0.01, 201)
    >>> recs = {f"a{a}": Recording.from_arrays(t, {"U": a * (t > 0.002), "v_C": simulate(rc_circuit().with_params(
    ...         {"R.R": 2e3}), t, u={"U": a * (t > 0.002)})["v_C"]}, holds={"U": "linear"}) for a in (1.0, 2.0)}
    >>> round(fit_shared(rc_circuit(), recs, ["R.R"])["shared"]["R.R"])
    2000
    """
    import scipy.optimize

    from codegen.simulator import Simulator
    from phs.workflows.identify.coordinates import _bounds, _channel_weights, _log_scaled
    from phs.workflows.identify.sensitivities import _Problem

    shared, free = list(shared), [k for k in free if k not in shared]
    if not shared:
        raise ParameterError("fit_shared: name at least one shared parameter")
    if not recordings:
        raise InputDataError("fit_shared: no recording")
    names = list(recordings)
    allf = shared + free
    for k in allf:
        system.param(k)  # ParameterError naming it
    log_scaled = _log_scaled(system, allf, None)
    x0v = Simulator(system, rtol=rtol).initial_state(x0)
    probs = []
    for name in names:
        rec = recordings[name].in_units_of(system)
        _, outs = rec.check_for(system, outputs)
        args = (system, rec, allf, log_scaled, outs, _channel_weights(rec, outs, None), x0v, [], rtol, None)
        try:
            probs.append(_Problem(*args, params=system.param_vector()))
        except SimulationError:  # compiling is only a speed-up (as in identify)
            probs.append(_Problem(*args, compile=False, params=system.param_vector()))
    ns, nf, n = len(shared), len(free), len(names)
    lo, hi = _bounds(system, allf, log_scaled, probs[0].nominal, None, (), None)
    lo, hi = lo[:ns] + lo[ns:] * n, hi[:ns] + hi[ns:] * n
    z0 = [0.0 if k in log_scaled else 1.0 for k in allf]
    z0 = np.clip(np.array(z0[:ns] + z0[ns:] * n), np.array(lo) + 1e-12, np.array(hi) - 1e-12)
    rows = [p.n_rows for p in probs]
    edges = np.concatenate([[0], np.cumsum(rows)])

    def part(z, i):
        return np.concatenate([z[:ns], z[ns + i * nf: ns + (i + 1) * nf]])

    def fun(z):
        try:
            return np.concatenate([np.asarray(p.res(part(z, i))).reshape(-1) for i, p in enumerate(probs)])
        except RuntimeError:  # a simulation failed at this trial point: a large residual rejects it
            return np.full(int(edges[-1]), 1e6)

    def jac(z):
        J = np.zeros((int(edges[-1]), len(z)))
        for i, p in enumerate(probs):
            try:
                Ji = np.asarray(p.jac(part(z, i))[1])
            except RuntimeError as exc:
                raise SimulationError(f"fit_shared: the sensitivity simulation of {names[i]!r} failed "
                                      f"({str(exc).splitlines()[-1]})") from None
            J[edges[i]:edges[i + 1], :ns] = Ji[:, :ns]
            J[edges[i]:edges[i + 1], ns + i * nf: ns + (i + 1) * nf] = Ji[:, ns:]
        return J

    sol = scipy.optimize.least_squares(fun, z0, jac=jac, bounds=(lo, hi), method="trf", x_scale="jac", ftol=1e-8,
                                       xtol=1e-10, gtol=1e-10, max_nfev=max_iter)
    values = [probs[i].values(part(sol.x, i), log_scaled, allf) for i in range(n)]
    return {"shared": {k: values[0][k] for k in shared}, "local": {names[i]: {k: values[i][k] for k in free}
            for i in range(n)}, "cost": float(sol.cost), "evaluations": int(sol.nfev), "message": str(sol.message)}


def default_free(system) -> list[str]:
    """The nominal parameters a diagnosis refits when none are named: those with a declared range and a
    non-zero value, at most 8 (as :func:`~phs.workflows.diagnose.diagnose` chooses them).

    Examples
    --------
    >>> from systems.examples import rc_circuit
    >>> default_free(rc_circuit())
    ['R.R', 'C.C']
    """
    return [p.name for p in system.params if p.range is not None and p.value not in (None, 0)][:8]


def _one_trial(system, name, rec, options: dict, n_jobs: int) -> dict:
    """One trial's diagnosis as a JSON-ready record (run in a worker; a failure is its message)."""
    from phs.workflows.diagnose import diagnose

    try:
        d = diagnose(system, rec, n_jobs=n_jobs, **options)
    except PHSError as exc:
        return {"trial": name, "status": "failed", "error": str(exc)}
    return trial_record(name, d)


def diagnose_trials(system, recordings, *, shared=None, free=None, outputs=None, candidates=None, x0=None,
                    max_effects: int = 2, discover: bool | None = None, rtol: float = 1e-7, weights=None,
                    out=None, resume: bool = False, scheduler=None, n_jobs: int | None = None,
                    progress: bool = False) -> Trials:
    """Diagnose every recording of ``recordings`` with ``system``; say which effects recur across them.

    Parameters
    ----------
    system : PHSystem
    recordings : dict of str -> Recording, or sequence of Recording
        The trials (a sequence is named after each recording's source file, without its suffix).
    shared : sequence of str, optional
        Nominal parameters with one value for every trial: fitted jointly on all trials first
        (:func:`fit_shared`, with the other free parameters per trial), then held at those values in each
        trial's diagnosis.
    free, outputs, candidates, x0, max_effects, discover, rtol, weights
        As for :func:`~phs.workflows.diagnose.diagnose` (``free`` without the shared parameters).
    out : str, optional
        Directory keeping ``trials/NAME.json`` (each trial's diagnosis, written as it finishes), ``shared.json``
        (the joint fit) and ``summary.json``, ``summary.csv``.  Without it nothing is written.
    resume : bool
        Continue the trials in ``out``: a trial whose stored identity matches is read back, not run again.
        Without it, an ``out`` holding trials is an error (nothing is overwritten).
    scheduler : str or distributed.Client, optional
        Run the trials on this Dask cluster (one task per trial); default: forked local processes.
    n_jobs : int, optional
        Local processes (default: CPUs, at most 4): trials side by side, and each trial's hypotheses on
        what is left over.
    progress : bool
        One line per finished trial on stderr.

    Returns
    -------
    Trials

    Raises
    ------
    InputDataError
        An ``out`` holding trials without ``resume``; with ``resume``, a stored trial (or joint fit) of other
        options, model or data (one line naming what differs); two trials of one name.

    Examples
    --------
    >>> import numpy as np
    >>> from codegen import simulate
    >>> from components.candidates import Offset
    >>> from phs.workflows.recording import Recording
    >>> from systems.examples import rc_circuit
    >>> t = np.linspace(0, 0.02, 401); u = np.sin(2 * np.pi * 150 * t)
    >>> recs = {f"o{c}": Recording.from_arrays(t, {"U": u, "v_C": simulate(rc_circuit(), t, u={"U": u})["v_C"] + c})
    ...         for c in (0.04, 0.05)}
    >>> res = diagnose_trials(rc_circuit(), recs, free=["R.R"], candidates=[Offset()], n_jobs=1)
    >>> res.recurring()[0]["effect"], res.recurring()[0]["trials"]
    ('offset', ['o0.04', 'o0.05'])
    """
    from components.candidates import LIBRARY
    from phs.workflows.sweep.study import identity_differences

    recordings = _named(recordings)
    if n_jobs is None:
        n_jobs = max(1, min(4, os.cpu_count() or 1))
    if resume and out is None:
        raise InputDataError("resume needs out (the directory of the trials to continue)")
    shared = list(shared or [])
    free = list(free) if free is not None else default_free(system)
    free = [k for k in free if k not in shared]
    for k in shared + free:
        system.param(k)  # ParameterError naming it
    if not free:
        raise ParameterError(f"diagnose: --shared {','.join(shared)} leaves no parameter to refit in each trial; "
                             "name one with --free")
    cands = list(LIBRARY if candidates is None else candidates)
    digests = {name: recording_digest(rec) for name, rec in recordings.items()}
    base = {"model_hash": system.model_hash(), "params": {k: float(v) for k, v in system.param_values().items()},
            "free": free, "shared": shared, "outputs": list(outputs) if outputs else None,
            "effects": sorted(c.effect for c in cands), "max_effects": max_effects, "discover": discover,
            "x0": {k: float(v) for k, v in (x0 or {}).items()} or None, "rtol": rtol,
            "weights": weights if weights is None or isinstance(weights, str) else {k: float(v) for k, v in weights.items()}}
    folder = os.path.join(out, TRIALS_DIR) if out is not None else None
    if out is not None:
        if os.path.exists(out) and not os.path.isdir(out):
            raise InputDataError(f"--out {out!r} exists and is not a directory")
        if not resume and os.path.isdir(folder) and any(f.endswith(".json") for f in os.listdir(folder)):
            raise InputDataError(f"{out!r} holds trials of an earlier run: resume them (--resume), or choose another directory")
        os.makedirs(folder, exist_ok=True)

    def refuse(what, stored, wanted):
        diff = identity_differences(stored, wanted)
        if diff:
            raise InputDataError(f"{what} holds another diagnosis ({'; '.join(diff)}): resume only the same trials "
                                 "with the same options, or choose another directory")

    joint = None
    if shared:
        ident = {**base, "data_sha256": digests}
        path = os.path.join(out, "shared.json") if out is not None else None
        if resume and path is not None and os.path.exists(path):
            stored = _read_json(path)
            refuse(path, stored.get("identity", {}), ident)
            joint = stored["fit"]
        else:
            if progress:
                print(f"diagnose {system.name}: fitting {', '.join(shared)} jointly on {len(recordings)} trials",
                      file=sys.stderr, flush=True)
            joint = fit_shared(system, recordings, shared, free, outputs=outputs, x0=x0, rtol=rtol)
            if path is not None:
                _write_json(path, {"identity": ident, "fit": joint})
    options = {"free": free, "outputs": outputs, "candidates": candidates, "x0": x0, "max_effects": max_effects,
               "discover": discover, "rtol": rtol, "weights": weights}
    records, todo = {}, []
    for name in recordings:
        # the channels a diagnosis fits (outputs=None: every measured output the recording has), as stored
        channels = recordings[name].in_units_of(system).check_for(system, outputs)[1]
        ident = {**base, "trial": name, "data_sha256": digests[name], "outputs": list(channels),
                 "shared_values": joint["shared"] if joint else None}
        path = os.path.join(folder, f"{name}.json") if folder is not None else None
        if resume and path is not None and os.path.exists(path):
            stored = _read_json(path)
            refuse(path, stored.get("identity", {}), ident)
            records[name] = stored
            continue
        todo.append((name, ident, path))
    inner = 1 if scheduler is not None else max(1, n_jobs // max(1, min(n_jobs, len(todo))))

    def start(name):
        if joint is None:
            return system
        return system.with_params({**joint["shared"], **joint["local"][name]})

    calls = [(start(name), name, recordings[name], options, inner) for name, _, _ in todo]

    def done(k, i, result):
        name, ident, path = todo[i]
        result = {"identity": ident, **result}
        records[name] = result
        if path is not None and result.get("status") != "failed":
            _write_json(path, result)
        if progress:
            said = result.get("error") or f"{result['verdict']['effect']} ({result['seconds']:.1f} s)"
            print(f"diagnose {system.name}: trial {k}/{len(todo)} {name}: {said}", file=sys.stderr, flush=True)

    with on_cluster(scheduler):
        run_forked(_one_trial, calls, n_jobs, done)
    res = Trials(system.name, [records[name] for name in recordings], joint, ran=len(todo))
    if out is not None:
        from phs.io import write_atomic

        write_atomic(os.path.join(out, "summary.json"), res.to_json())
        write_atomic(os.path.join(out, "summary.csv"), res.to_csv())
    return res


def _named(recordings) -> dict:
    """Trials by name: a dict as given, a sequence named after each recording's source file."""
    if isinstance(recordings, dict):
        named = dict(recordings)
    else:
        named = {}
        for rec in recordings:
            name = os.path.splitext(os.path.basename(str(rec.source)))[0] or "trial"
            if name in named:
                raise InputDataError(f"two trials are named {name!r} ({named[name].source} and {rec.source}): "
                                     "give the recordings distinct file names")
            named[name] = rec
    if not named:
        raise InputDataError("diagnose: no recording to diagnose")
    for name in named:
        if not re.fullmatch(r"[A-Za-z0-9_.+=-]+", name) or name.startswith("."):
            raise InputDataError(f"trial name {name!r}: use letters, digits and _ . + = - (it names the trial's JSON file)")
    return named


def _read_json(path) -> dict:
    try:
        with open(path, encoding="utf-8") as fh:
            return json.load(fh)
    except (OSError, ValueError) as exc:
        raise InputDataError(f"{path}: cannot read the stored trial ({exc}); remove it to run that trial again") from None


def _write_json(path, doc) -> None:
    from phs.io import write_atomic

    write_atomic(path, json.dumps(doc, indent=2))
