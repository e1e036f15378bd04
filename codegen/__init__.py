"""Code generation: sympy -> CasADi translation, generated functions, simulation.

Public entry points: :func:`generate` (named CasADi functions of a PHSystem),
:func:`simulator` / :func:`simulate` (CVODES with restarts at input
breakpoints, per-state scaling, energy accounts) and
:func:`discrete_gradient_simulate` (structure-preserving integrator).
IDA-PBC design is the subpackage :mod:`codegen.idapbc` (``from codegen import
idapbc``), imported on first use.
"""

from codegen.discrete_gradient import discrete_gradient_simulate
from codegen.functions import GeneratedFunctions, generate
from codegen.results import SimulationResult
from codegen.simulator import Simulator, simulate, simulator

__all__ = ["generate", "GeneratedFunctions", "simulator", "simulate", "Simulator", "SimulationResult",
           "discrete_gradient_simulate"]


def __getattr__(name: str):
    """``codegen.idapbc`` (IDA-PBC controllers: ``idapbc.design``), imported on first use rather than with ``codegen``."""
    if name == "idapbc":
        import importlib

        return importlib.import_module("codegen.idapbc")
    raise AttributeError(f"module 'codegen' has no attribute {name!r}")
