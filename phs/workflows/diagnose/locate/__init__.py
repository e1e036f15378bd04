"""Locate where a simulation and a recording differ: numbered findings from the residuals alone.

Step 2 of the diagnosis.  Nothing here knows about port-Hamiltonian models: :func:`locate` reads a
uniform time grid, the residuals (measured minus simulated, per output channel), signals of the
fitted nominal model along the recording (*features*: positions, velocities, charges, ...) and the
applied inputs, and returns :class:`Finding` objects, each with a place and a number.

Velocities: a feature is a velocity if its name starts with ``"v:"`` (the prefix is dropped in the
reported names) or is listed in ``velocities=``.  Velocities give the reversal events and the
``sign(v)`` products; the time since the last input step is computed here from the inputs.

=====================  ============================================================================
kind                   strength, and when ``details["significant"]`` is true
=====================  ============================================================================
``time_window``        share of the residual energy inside the window(s).  Single windows: where the
                       mean energy over a few periods of the residual exceeds both twice the average
                       and the surrogates' highest window.  Windows locked to events (``0-L s after
                       each step``, ``±L/2 around each reversal / input peak``): density at least 1.5
                       times the average and an excess share above the surrogates'
``feature``            R² of a straight-line fit of the residual on one regressor: a feature or input
                       ``x``, ``|x|``, ``sign(x)``, ``x²``, ``x³``, ``x·|x|``, ``x·sign(v)`` for each
                       velocity ``v``, ``dU/dt``, the time since the last input step; significant
                       above the surrogates' best R² over all regressors
``spectrum``           share of the residual power in a spectral peak (significant above a running
                       median of the spectrum, F test at 1 % over all bins), or the share of the
                       residual power coherent with an input (significant when the peak coherence
                       beats its 1 % level and the share exceeds the noise bias by 0.05)
``harmonic``           share of the residual power at the h-th multiple of the excitation's
                       fundamental (the input with 60 % of its power at one fundamental's
                       harmonics, at least 3 periods); significant when the band's peak stands out
                       of the background between harmonics (F test at 1 %) and sits on the harmonic
``input_lag``          peak of the normalised cross-correlation of the residual with an input or its
                       derivative, over lags up to a tenth of the recording; ``lag > 0`` means the
                       residual follows (lags behind) the input; significant above the surrogates'
                       peak over the same lags, input and derivative
``amplitude_scaling``  exponent p of residual RMS ∝ level^p, over the constant-level segments
                       between an input's steps or over blocks of a smooth input (amplitude
                       √2·std); significant for log-log R² >= 0.5, |p| >= 0.25 and |p| >= 3 standard
                       errors, with at least two distinct levels 1.5 times apart
``rate_scaling``       the same against the block's rate (RMS of dU/dt over RMS of U, in Hz)
``whiteness``          Ljung-Box statistic Q over lags 1..min(20, n/5) (``details["p_value"]``);
                       significant means *not* white (p < 0.01).  Always reported
``drift``              share of the residual energy below a tenth of the excitation frequency (at
                       least 2/T); significant above 0.2 and the surrogates' share when the band's
                       mean periodogram (without 0 Hz) stands out of the next bins above it, or the
                       mean (0 Hz) out of the lowest bins (F tests at 1 %).  Or the share of
                       the energy after the input steps explained by exponential tails
                       ``a_j exp(-(t - t_j)/τ)`` (one τ, an amplitude and an offset per step;
                       ``details``: ``tau_s``, amplitudes per unit step); significant when above
                       0.1 and the surrogates' gain, τ inside its range and the tails following the
                       steps' direction (75 % of them)
=====================  ============================================================================

The surrogates are the null of *stationary noise with the residual's own spectrum, unrelated to the
model signals*: :data:`N_SURROGATES` Gaussian series whose spectrum is the residual's Welch spectrum
with segments of an eighth of the recording (which smears spectral lines, so a residual locked to a
periodic excitation is not mistaken for noise).  A threshold is the :data:`NULL_QUANTILE` quantile of
a Gumbel law fitted to the surrogates' best values over all regressors, windows or lags, so it holds
for the whole family.  Measured on 300 recordings of noise (3 s at 1 kHz, a square-wave input, three
features): on white noise each analysis reports a significant finding in at most 2 % of them; on
coloured noise (first-order low-pass, 5 and 50 ms) at most 2 %, except ``drift`` (3 % at 50 ms).

``noise_std`` (the measurement noise per channel) does not change the tests; it adds
``share_above_noise`` to time windows and ``share_of_structured`` to features, and is subtracted
from the block energies of the scaling fits.

One module per kind of finding (:mod:`~phs.workflows.diagnose.locate.windows`, ``features``,
``spectrum`` (with the harmonics), ``lags``, ``scaling``, ``whiteness``, ``drift``), each returning
:class:`Finding` objects (:mod:`~phs.workflows.diagnose.locate.finding`); what they share, the
validated signals, the input events and the regressors, is prepared once per call; the figure is
:func:`plot_findings`.
"""

from __future__ import annotations

import math

import numpy as np

from phs.workflows.diagnose.locate._common import N_SURROGATES, NULL_QUANTILE, _surrogates
from phs.workflows.diagnose.locate._context import _prepare, _validate
from phs.workflows.diagnose.locate.drift import _drift
from phs.workflows.diagnose.locate.features import _feature_findings
from phs.workflows.diagnose.locate.finding import KINDS, Finding
from phs.workflows.diagnose.locate.lags import _lags
from phs.workflows.diagnose.locate.plot import plot_findings
from phs.workflows.diagnose.locate.scaling import _scaling
from phs.workflows.diagnose.locate.spectrum import _spectral
from phs.workflows.diagnose.locate.whiteness import _whiteness
from phs.workflows.diagnose.locate.windows import _time_windows


def locate(t, residuals: dict, features: dict, inputs: dict, *, noise_std: dict | None = None, velocities=(),
           max_findings_per_kind: int = 3, significant_only: bool = True, seed: int = 0) -> list[Finding]:
    """Locate where the residuals concentrate, what they depend on, and how they scale.

    Parameters
    ----------
    t : array_like
        Uniform time grid (n >= 16 samples).
    residuals : dict of str to array_like
        Output channel -> measured minus simulated.  A channel whose residual is zero gives no finding.
    features : dict of str to array_like
        Signals of the fitted nominal model along the recording (states, velocities, charges, input
        voltages...).  Names starting with ``"v:"`` are velocities.
    inputs : dict of str to array_like
        Applied inputs; steps, peaks, the excitation's fundamental and the levels are detected from them.
    noise_std : dict of str to float, optional
        Measurement-noise standard deviation per channel; subtracted from the energies of the time
        windows and the scaling fits.
    velocities : sequence of str
        Further feature names to treat as velocities.
    max_findings_per_kind : int
        Most findings of one kind per channel.
    significant_only : bool
        Keep only findings that beat their noise threshold (the whiteness finding is always kept).
    seed : int
        Seed of the noise surrogates (results are reproducible).

    Returns
    -------
    list of Finding
        Per channel, in the order of :data:`KINDS`, strongest first within a kind.

    Raises
    ------
    InputDataError
        Naming the signal that is not finite, has the wrong length, or is not a feature.

    Examples
    --------
    >>> t = np.arange(0, 4, 1e-3)
    >>> v = np.cos(2 * np.pi * t)                      # a velocity of the nominal model
    >>> r = 0.2 * np.sign(v) + 0.01 * np.random.default_rng(1).standard_normal(t.size)
    >>> found = locate(t, {"y": r}, {"x": np.sin(2 * np.pi * t), "v:v": v}, {"U": np.sin(2 * np.pi * t)})
    >>> best = next(f for f in found if f.kind == "feature")
    >>> best.where, round(best.strength, 2)
    ('residual ~ sign(v)', 1.0)
    """
    t, dt, res, feats, ins, vel, sig = _validate(t, residuals, features, inputs, velocities, noise_std)
    kmax = int(max_findings_per_kind)
    ctx = _prepare(t, dt, feats, ins, vel)
    out = []
    for ci, (ch, r) in enumerate(res.items()):
        ms = float(np.mean(r**2))
        if ms == 0:
            continue
        sigma = sig.get(ch, 0.0)
        rc = r - r.mean()
        found = []
        if rc.std() > 1e-9 * math.sqrt(ms):
            sur, sur_spec = _surrogates(rc, np.random.default_rng([seed, ci]))
            found += _time_windows(ch, rc, ctx, sigma, sur)
            found += _feature_findings(ch, r, rc, ctx, sur, sigma, kmax)
            found += _spectral(ch, rc, ctx)
            found += _lags(ch, rc, ctx, sur_spec)
            found += _scaling(ch, r, ctx, sigma)
            found += _whiteness(ch, rc, ctx)
            found += _drift(ch, r, ctx, sur, sur_spec)
        else:
            found += _drift(ch, r, ctx)
        for kind in KINDS:
            of = [f for f in found if f.kind == kind and (f.significant or not significant_only or kind == "whiteness")]
            out += of[:kmax]
    return out


__all__ = ["Finding", "KINDS", "N_SURROGATES", "NULL_QUANTILE", "locate", "plot_findings"]
