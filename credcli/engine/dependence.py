"""What a segment's serial dependence implies for its tests: the screening of the
whitened errors (whether they are dependent, and the variance ratios τ that set batch and
sign-block lengths), built on the estimators of :mod:`credcli.engine.correlation`."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from credcli.engine import batches, correlation


class SerialDependence(NamedTuple):
    """What the segment's serial dependence implies for its tests (:func:`serial_dependence`).

    Attributes
    ----------
    dependent : bool
        Whether the scale (and, for paper/ks, the ELT) refer to dependent epochs.
    tau_point : numpy.ndarray, shape (d,)
        The kernel τ̂ per component (the reported effective N); ones if not dependent.
    tau : numpy.ndarray, shape (d,)
        τ per component for the lengths of batches and sign blocks, the neighbour
        correction and the centring; ones if not dependent.
    tau_q : float
        τ of the squared errors q, for the scale's batches; 1 if not dependent.
    weak_tau : numpy.ndarray or None
        τ per component of weak evidence where no batches fit (the location question's);
        None otherwise.
    """

    dependent: bool
    tau_point: np.ndarray
    tau: np.ndarray
    tau_q: float
    weak_tau: np.ndarray | None


def serial_dependence(
    s: np.ndarray, q: np.ndarray, r1: np.ndarray | None = None
) -> SerialDependence:
    """Whether the whitened errors ``s`` are serially dependent, and their variance ratios.

    Dependent (:func:`credcli.engine.correlation.serially_dependent`) at
    ``DEPENDENCE_LEVEL`` (1 %), or at ``SCREENING_LEVEL`` (20 %) where the batch-means
    tests fit in the segment. The tests for independent epochs lose their level on weak
    dependence that a 1 % test misses (docs/measured.md), while batch means on
    independent epochs lose only some power. Where no batches fit, weak evidence keeps the
    independent-epoch tests rather than leaving the segment untested; its τ is
    ``weak_tau``, which the calibrated rule's location question uses
    (:func:`location_dependence`).

    Parameters
    ----------
    s : numpy.ndarray, shape (N, d)
        The whitened errors.
    q : numpy.ndarray, shape (N,)
        Their squared norms (the GLS-centred NEES).
    r1 : numpy.ndarray, shape (d,), optional
        The lag-1 autocorrelations of ``s``, if already computed.

    Returns
    -------
    SerialDependence
        If dependent, the kernel τ̂ of each component and, for the lengths of batches and
        sign blocks, the neighbour correction and the centring of κ̄, the larger of τ̂ and
        the bias-corrected AR(1) τ; for the squared errors q also at least the τ that the
        errors' own τ implies for a Gaussian AR(1). On independent epochs all are 1.
    """
    r1 = correlation.autocorrelation(s) if r1 is None else r1
    n, d = s.shape
    ones = np.ones(d)
    if not correlation.serially_dependent(r1, n, correlation.SCREENING_LEVEL):
        return SerialDependence(False, ones, ones, 1.0, None)
    tau_point = correlation.variance_ratio(s)
    tau = np.maximum(tau_point, correlation.ar1_variance_ratio(r1, n))
    tau_q = max(
        float(correlation.variance_ratio(q)[0]),
        float(correlation.ar1_variance_ratio(correlation.autocorrelation(q), n)[0]),
        correlation.squared_variance_ratio(tau),
    )
    if not correlation.serially_dependent(r1, n) and not batches_fit(n, d, tau, tau_q):
        return SerialDependence(False, ones, ones, 1.0, tau)  # weak, and no batches fit
    return SerialDependence(True, tau_point, tau, tau_q, None)


def location_dependence(s: np.ndarray, r1: np.ndarray, dep: SerialDependence):
    """Whether the calibrated rule's location question refers to batch means, and its τ.

    Under the location's null hypothesis the errors have mean zero, so their dependence is
    screened once more by the lag-1 autocorrelation about zero
    (:func:`credcli.engine.correlation.autocorrelation`), at ``SCREENING_LEVEL``.
    The centred one misses exactly the windows that matter: a slow excursion of weakly
    dependent errors shifts their sample mean and, once that is removed, leaves little
    lag-1 correlation, so such windows would pass the centred screening alone and go to
    the tests for independent epochs, which find a "bias" in them. A window flagged either
    way goes to batch means where they fit; where they do not, the tests for independent
    epochs run with its τ: the ELT in blocks, the mean test's T² divided by max_i τ_i. The
    lengths come from the centred estimate (the bias-corrected AR(1) τ): a real bias
    inflates the uncentred autocorrelation. Measurements: docs/measured.md.

    Parameters
    ----------
    s : numpy.ndarray, shape (N, d)
        The whitened errors.
    r1 : numpy.ndarray, shape (d,)
        Their (centred) lag-1 autocorrelations.
    dep : SerialDependence
        The segment's screening (:func:`serial_dependence`).

    Returns
    -------
    dependent : bool
        Whether the location tests refer to batch means: the segment's screening found
        dependence, or the screening about zero (or weak evidence) flags it and the mean
        test's batches fit.
    tau : numpy.ndarray, shape (d,)
        τ per component for the location's sign blocks and batches (``dep.tau`` when
        already dependent, or when nothing is flagged).
    """
    if dep.dependent:
        return True, dep.tau
    n, d = s.shape
    about_zero = correlation.serially_dependent(
        correlation.autocorrelation(s, about_zero=True), n, correlation.SCREENING_LEVEL
    )
    if dep.weak_tau is None and not about_zero:
        return False, dep.tau
    tau = (
        dep.weak_tau
        if dep.weak_tau is not None
        else np.maximum(dep.tau, correlation.ar1_variance_ratio(r1, n))
    )
    length = batches.batch_length(float(np.max(tau)))
    fits = batches.batch_count(n, length, batches.min_location_batches(d))
    return bool(fits), tau


def batches_fit(n: int, d: int, tau: np.ndarray, tau_q: float) -> bool:
    """Whether the batch-means scale test and mean test both fit in ``n`` epochs.

    Parameters
    ----------
    n : int
        Epochs in the segment.
    d : int
        The state dimension (the mean test needs d + 3 batches).
    tau : numpy.ndarray, shape (d,)
        τ per component; the largest sets the mean test's batch length.
    tau_q : float
        τ of the squared errors, which sets the scale test's batch length.

    Returns
    -------
    bool
        True when at least ``MIN_SCALE_BATCHES`` scale batches and
        ``min_location_batches(d)`` mean-test batches fit.
    """
    scale = batches.batch_count(n, batches.batch_length(tau_q), batches.MIN_SCALE_BATCHES)
    worst = float(np.max(tau))
    mean = batches.batch_count(n, batches.batch_length(worst), batches.min_location_batches(d))
    return bool(scale) and bool(mean)
