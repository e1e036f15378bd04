"""Grey-box identification: output-error fit of chosen parameters to a recording.

CVODES integrates the model over the whole recording with the recorded inputs
linearly interpolated (restarted at the input's kinks; smooth stretches of a
finely sampled input by a cubic spline, see ``codegen.simulator.step_windows``), the measured outputs are
evaluated on the recording's grid, and the residual's Jacobian with respect to
the free parameters (and optionally free initial states) comes from CVODES
forward sensitivities integrated with the state (exact to the integration
tolerance, not finite differences), chained through the output functions'
Jacobians.  The least squares are solved by a trust-region reflective method
(``scipy``) with that Jacobian; parameters spanning decades are fitted in log
scale.  Large fits run the dynamics, their derivatives and the output functions
as compiled C, cached on disk by a hash of the model.

Reported: fitted values, standard errors and 95 % intervals from the
Jacobian (infinite for parameters along a direction the data do not determine, with the products
of powers of them that the data do determine), the correlation matrix with strongly correlated pairs flagged, NRMSE
fit % per output channel (``100 (1 - ||y - yhat|| / ||y - mean y||)``) on the
training and validation recordings, residuals, iterations, time, and the
sensitivity table of the curling HASEL paper (fit % at -10, -5, 0, +5, +10 %
of each parameter and the standard deviation of those fits).

Modules: :mod:`~phs.workflows.identify.solve` (the driver, :func:`identify`),
:mod:`~phs.workflows.identify.sensitivities` (the residual and its Jacobian, segment by segment),
:mod:`~phs.workflows.identify.c_library` (their compiled C), :mod:`~phs.workflows.identify.coordinates`
(log scaling, bounds, channel weights), :mod:`~phs.workflows.identify.result`
(:class:`IdentificationResult`, uncertainty), :mod:`~phs.workflows.identify.identifiability` (the
Jacobian's numerical rank, the identified and free combinations), :mod:`~phs.workflows.identify.scoring` (NRMSE fit %),
:mod:`~phs.workflows.identify.summaries` (fits to summary statistics of runs: means, ranges, final values, as a
paper's table reports them) and
:mod:`~phs.workflows.identify.sensitivity_table` (the ±5/±10 % table).
"""

from phs.workflows.identify.result import IdentificationResult
from phs.workflows.identify.scoring import evaluate_fit, nrmse_fit
from phs.workflows.identify.sensitivity_table import sensitivity_markdown
from phs.workflows.identify.solve import identify
from phs.workflows.identify.summaries import Summary, SummaryFit

__all__ = ["identify", "Summary", "SummaryFit", "IdentificationResult", "nrmse_fit", "evaluate_fit", "sensitivity_markdown"]
