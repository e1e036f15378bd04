"""phs: port-Hamiltonian modelling, simulation, identification and control.

The core (this package without :mod:`phs.workflows`) depends on sympy, numpy
and scipy only.  Workflows that run models (simulation, identification,
diagnosis, sweeps, linearisation) are exposed lazily so ``import phs`` never imports casadi.
"""

from phs import signals
from phs._version import __version__  # noqa: F401  (re-exported)
from phs.component import Component, symbol_of_input, symbol_of_output, symbol_of_state
from phs.equilibria import EquilibriumResult, equilibrium
from phs.errors import (
    DomainError,
    EquilibriumError,
    InputDataError,
    InterconnectionError,
    ModelError,
    ParameterError,
    PHSError,
    SimulationError,
    UnitError,
)
from phs.feedback import feedback
from phs.interconnect import interconnect
from phs.junctions import bond, feedback_link, parallel, series
from phs.params import Condition, InputInfo, Measured, Param, StateInfo
from phs.system import PHSystem

__all__ = [
    "Component", "symbol_of_input", "symbol_of_output", "symbol_of_state", "DomainError", "EquilibriumError", "InputDataError",
    "InterconnectionError", "ModelError", "ParameterError", "PHSError", "SimulationError", "UnitError",
    "bond", "feedback_link", "feedback", "parallel", "series", "Condition", "InputInfo", "Measured", "Param", "StateInfo", "PHSystem",
    "interconnect", "equilibrium", "EquilibriumResult", "signals", "simulate", "identify", "diagnose", "sweep", "Recording", "load",
    "Summary",
    "linearize",
]


def load(path) -> PHSystem:
    """Load a system saved with :meth:`PHSystem.save`.

    Examples
    --------
    >>> import os, tempfile
    >>> from systems.examples import rc_circuit
    >>> with tempfile.TemporaryDirectory() as d:
    ...     rc_circuit().with_params({"R.R": 2e3}).save(os.path.join(d, "rc.json"))
    ...     load(os.path.join(d, "rc.json")).param("R.R").value
    2000.0
    """
    return PHSystem.load(path)


_LAZY = ("simulate", "identify", "diagnose", "sweep", "Recording", "linearize", "Summary")


def __dir__():
    """Module names, including the workflows loaded on first use, so tab completion finds them.

    Examples
    --------
    >>> import phs
    >>> {"simulate", "identify", "diagnose", "sweep", "Recording", "linearize"} <= set(dir(phs))
    True
    """
    return sorted(set(globals()) | set(_LAZY))


def __getattr__(name):
    """Workflows are imported on first use, so ``import phs`` never imports casadi."""
    if name == "simulate":
        from codegen.simulator import simulate

        return simulate
    if name == "linearize":
        from codegen.linearize import linearize

        return linearize
    if name == "identify":
        from phs.workflows.identify import identify

        return identify
    if name == "Recording":
        from phs.workflows.recording import Recording

        return Recording
    if name == "Summary":
        from phs.workflows.identify.summaries import Summary

        return Summary
    if name == "diagnose":
        from phs.workflows.diagnose import diagnose

        return diagnose
    if name == "sweep":
        from phs.workflows.sweep import sweep

        return sweep
    raise AttributeError(f"module 'phs' has no attribute {name!r}")
