"""Model-mismatch diagnosis: where a model and a recording disagree, which physics is missing, and the fix.

:func:`diagnose` (1) fits the nominal model on the training recording, (2) locates the mismatch in the
residuals (:mod:`phs.workflows.diagnose.locate`: time windows, state/input features, spectrum,
lags, amplitude scaling, whiteness, drift), (3) attaches every candidate of the library
(:mod:`components.candidates`) at every place it fits, (4) fits each augmented model (the new
parameters together with the nominal free ones) and ranks them by validation fit and BIC, keeping the
simplest sufficient explanation and trying a second effect only when the first leaves a structured
residual, (5) when the residual stays structured, discovers a passive correction outside the library
(:mod:`phs.workflows.diagnose.discover`: an added energy or dissipation sparse over the model's own
states), and (6) explains the verdict in words, with the share of the mismatch it explains, the
augmented model's structural checks (J skew, R positive semi-definite) and the fit before and after.

Acceptance rule of a hypothesis (documented in ``docs/explanation/diagnosis.md``, "The steps"): its training BIC is at
least :data:`MIN_BIC_GAIN` below the nominal model's, and its validation residual (sum over channels of
RSS / variance) at least :data:`MIN_VALIDATION_GAIN` (relative) below the nominal model's, and it lowers no
channel's validation fit beyond what that channel's noise allows (:func:`~phs.workflows.diagnose.ranking.worsened`).  Hypotheses
whose validation residual is within :data:`SUFFICIENT_MARGIN` of the best accepted one, and whose training
residual is within it of the best of those, count as equally good; among them the one with the fewest
parameters wins (then BIC).

The parts, each importing only those listed after it: :mod:`~phs.workflows.diagnose.run` (:func:`diagnose`),
:mod:`~phs.workflows.diagnose.screening` (fitting the hypotheses of a round),
:mod:`~phs.workflows.diagnose.result` (:class:`Diagnosis` and its verdict),
:mod:`~phs.workflows.diagnose.report` (words, figures, JSON and HTML),
:mod:`~phs.workflows.diagnose.mismatch` (noise level, model signals, located mismatch),
:mod:`~phs.workflows.diagnose.ranking` (scores, acceptance, choice),
:mod:`~phs.workflows.diagnose.calibration` (the confidence's calibration, cross-validated on the stored diagnoses),
:mod:`~phs.workflows.diagnose.hypotheses` (fitting one model, never worse than its neutral point),
:mod:`~phs.workflows.diagnose.retry` (retrying a failing fit), :mod:`~phs.workflows.diagnose.locate` and
:mod:`~phs.workflows.diagnose.discover` (corrections outside the library).

A hypothesis is never lost: a failing fit is retried (neutral start, tighter bounds, continuation), a
fit ending worse than the nominal model is replaced by its neutral point, and one that fails after every
retry is named with its reason; each such failure scales the confidence by :data:`FAILED_FACTOR`.
"""

from __future__ import annotations

from phs.workflows.diagnose.mismatch import noise_level
from phs.workflows.diagnose.ranking import (
           FAILED_FACTOR,
           FRICTION_LIKE,
           MIN_BIC_GAIN,
           MIN_VALIDATION_GAIN,
           SUFFICIENT_MARGIN,
           presliding_share,
)
from phs.workflows.diagnose.result import Diagnosis
from phs.workflows.diagnose.run import SPLIT, diagnose

__all__ = ["diagnose", "Diagnosis", "noise_level", "presliding_share", "MIN_BIC_GAIN", "MIN_VALIDATION_GAIN", "SUFFICIENT_MARGIN",
           "FRICTION_LIKE", "FAILED_FACTOR", "SPLIT"]
