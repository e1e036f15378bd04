"""Code generation: sympy -> CasADi translation, generated functions, simulation.

Public entry points: :func:`generate` (named CasADi functions of a PHSystem),
:func:`simulator` / :func:`simulate` (CVODES with restarts at input
breakpoints, per-state scaling, energy accounts) and
:func:`discrete_gradient_simulate` (structure-preserving integrator).
"""

from codegen.discrete_gradient import discrete_gradient_simulate
from codegen.functions import GeneratedFunctions, generate
from codegen.results import SimulationResult
from codegen.simulator import Simulator, simulate, simulator

__all__ = ["generate", "GeneratedFunctions", "simulator", "simulate", "Simulator", "SimulationResult",
           "discrete_gradient_simulate"]
from codegen import idapbc  # noqa: E402,F401  (IDA-PBC controllers: idapbc.design)
