"""Is the model adequate? Chi-square against its band, the noise level, held-out residuals.

One chi-square rule serves every verdict (``hostpc diagnose``, the push guard rail of
``hostpc calibrate``, the report): a fit explains its measurements when the upper-tail
probability of a chi-square as large as its own is at least ``ADEQUACY_P_MIN``
(``chi2_adequate``), i.e. when chi2/dof is at most ``chi2_dof_upper(dof)``. A chi2/dof
below the band is no sign of a missing effect (the stated covariances are pessimistic); one
*far* below it (``chi2_far_below``) is no adequate model either: the stated noise is not the
instrument's, or the model absorbs the data. Neither is a fitted table length that moved by
more than any calibration corrects (``implausible_geometry``): the numbers are in another
unit, or of another robot. Those two make diagnose's verdict NOT adequate; the push's rule is
``chi2_adequate`` alone.

All lengths in metres (SI); the CLI and the report convert to mm. ``m`` is the size of one
measurement (3 for a stereo point, 1 for a probe contact distance).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from hostpc.diagnostics.distributions import chi2_isf, chi2_ppf, chi2_sf
from hostpc.diagnostics.outliers import Outlier, n_repeated_poses
from hostpc.fitting import FitResult
from hostpc.fitting.fitting import held_out_by_fold
from hostpc.fitting.identifiability import WEAK_SIGMA_LIMIT
from hostpc.model.layout import Problem

_TABLE_LENGTH = re.compile(r"geometry\.(?P<kind>a|d)(?P<joint>\d+)$")

ADEQUACY_P_MIN = 1e-3
"""A fit is adequate (chi-square test) when P(chi2 this large | model right) >= this."""
FAR_BELOW_NOISE_FACTOR = 10.0
"""chi2/dof is far below its band when it is still in the band's lower tail with the stated
noise divided by this: residuals more than ten times smaller than the stated noise, beyond
chance. A stated noise two or three times the real one is common pessimism (a datasheet
figure, the import's default 0.1 mm: adequate); ten times is not an instrument's noise."""
IMPLAUSIBLE_LENGTH_M = WEAK_SIGMA_LIMIT["m"]
"""A fitted change of a DH/MDH table length (geometry.aJ, geometry.dJ) beyond this (50 mm,
the largest length a real robot could need calibrated: ``detectable.PLAUSIBLE_SIZE``) is
implausible: manufacturing and assembly move a link by millimetres (FIGAROH's TIAGo and
TALOS: up to 16 and 27 mm); numbers read in the wrong unit move it by its whole length."""


@dataclass(frozen=True, eq=False)  # holds arrays: compared by identity (__init__.py)
class HeldOut:
    """Residuals of every sample predicted by a fit that did not see it (k-fold).

    raw: (N, m) held-out residuals (m); whitened: (N, m); folds: how many folds.
    """

    raw: np.ndarray
    whitened: np.ndarray
    folds: int
    #: the components that are lengths (the norms in m are taken over them); None: all
    length_columns: np.ndarray | None = None

    @property
    def norms(self) -> np.ndarray:
        """(N,) norm of each held-out residual (m)."""
        raw = self.raw if self.length_columns is None else self.raw[:, self.length_columns]
        return np.linalg.norm(raw, axis=1)

    @property
    def rms(self) -> float:
        return float(np.sqrt(np.mean(self.norms**2)))

    @property
    def max(self) -> float:
        return float(np.max(self.norms))

    @property
    def whitened_rms(self) -> float:
        """RMS of the whitened held-out residual per scalar row (1 at the noise level)."""
        return float(np.sqrt(np.mean(self.whitened**2)))


def held_out_residuals(problem: Problem, x: np.ndarray, free: np.ndarray, folds: int,
                       max_iterations: int = 30) -> HeldOut | None:
    """k-fold held-out residuals: each fold's fit is the linearised leave-fold-out update
    of the full fit's x (``hostpc.fitting.fitting.held_out_by_fold``).

    Same folds and computation as ``hostpc.fit`` (so the RMS equals ``FitResult.cv_rms`` for
    a linear loss); None when there are too few samples for ``folds`` folds.

    The latest one of each problem is kept on its memo (read-only): a model's check, its
    candidates' ranking and the ladder step that adopts a candidate's fit ask again for
    the same x and free parameters.
    """
    key = f"held out {folds} {max_iterations}"
    kept = problem.memo.recall(key)
    if kept is not None and np.array_equal(kept[0], x) and np.array_equal(kept[1], free):
        return kept[2]
    held = held_out_by_fold(problem, x, free, folds, max_iterations=max_iterations)
    result = None
    if held is not None:
        raw, whitened = held
        raw.setflags(write=False)
        whitened.setflags(write=False)
        result = HeldOut(raw=raw, whitened=whitened, folds=folds,
                         length_columns=problem.length_columns)
    problem.memo.remember(key, (np.array(x), np.array(free), result))
    return result


@dataclass(frozen=True)
class Adequacy:
    """The verdict on one fitted model.

    chi2, dof, chi2_dof: of the whitened residuals; chi2_band: (low, high) edges of chi2/dof
    for dof degrees of freedom, each leaving ``alpha`` in its tail (``chi2_band``); chi2_ok:
    ``chi2_adequate`` (chi2/dof at most the upper edge);
    p_value: upper-tail probability of a chi2 this large if the model and the stated
    covariances were right; noise_scale: sqrt(chi2/dof), the measured noise relative to the
    stated one (corrected for the parameters fitted); noise_rms: the RMS residual norm
    corrected for the parameters fitted (m); expected_noise_rms: the RMS norm the stated
    covariances predict (m); rms, max: in-sample residual norms (m); cv_rms, cv_max:
    held-out ones (m, None without cross-validation); adequate: the verdict; reasons:
    plain sentences why not (empty when adequate).
    """

    chi2: float
    dof: int
    chi2_dof: float
    chi2_band: tuple[float, float]
    p_value: float
    chi2_ok: bool
    noise_scale: float
    noise_rms: float
    expected_noise_rms: float
    rms: float
    max: float
    cv_rms: float | None
    cv_max: float | None
    cv_whitened_rms: float | None
    cv_folds: int
    adequate: bool
    reasons: tuple[str, ...]
    chi2_dof_with_calibration: float | None = None
    """The chi2/dof with the dataset's rig / head-camera calibration covariance inside
    (`hostpc.fitting.shared_chi2`), which `p_value` and `chi2_ok` judge, as the push guard
    does; None without a `rig_uncertainty` block (then the plain chi2 is judged)."""


def chi2_band(dof: int, p_min: float = ADEQUACY_P_MIN) -> tuple[float, float]:
    """The band of chi2/dof for dof degrees of freedom: each edge leaves ``p_min`` in its
    tail, so the upper edge is ``chi2_dof_upper(dof, p_min)``. NaN for dof < 1."""
    if dof <= 0:
        return (float("nan"), float("nan"))
    return (float(chi2_ppf(p_min, dof) / dof), chi2_dof_upper(dof, p_min))


def chi2_dof_upper(dof: int, p_min: float = ADEQUACY_P_MIN) -> float:
    """Upper edge of the chi2/dof band: the chi-square upper ``p_min`` quantile over dof
    (a larger chi2/dof: the model does not explain the measurements). NaN for dof < 1."""
    if dof <= 0:
        return float("nan")
    return float(chi2_isf(p_min, dof) / dof)


def chi2_p_value(chi2: float, dof: int) -> float:
    """P(a chi-square with dof degrees of freedom >= chi2); NaN for dof < 1."""
    return chi2_sf(chi2, dof) if dof > 0 else float("nan")


def chi2_adequate(chi2: float, dof: int, p_min: float = ADEQUACY_P_MIN) -> bool:
    """THE chi-square rule (diagnose, push, report): True when dof >= 1 and the upper-tail
    p-value of ``chi2`` is at least ``p_min``. A small chi2 passes (pessimistic covariances
    are not a missing effect); no degrees of freedom: False (nothing can be judged)."""
    p_value = chi2_p_value(chi2, dof)
    return bool(dof > 0 and p_value >= p_min)


def chi2_far_below(chi2: float, dof: int, p_min: float = ADEQUACY_P_MIN) -> bool:
    """True when ``chi2`` is in the lower ``p_min`` tail of its band even with the stated
    noise divided by ``FAR_BELOW_NOISE_FACTOR`` (chi2 times its square): the residuals are
    far smaller than the stated noise (the noise is stated in another unit or far too
    large, or the model absorbs the data). False without degrees of freedom."""
    return bool(dof > 0 and chi2 * FAR_BELOW_NOISE_FACTOR**2 < chi2_ppf(p_min, dof))


def implausible_geometry(result: FitResult) -> str | None:
    """The sentence naming the fitted table lengths (geometry.aJ, geometry.dJ) that moved by
    more than ``IMPLAUSIBLE_LENGTH_M``, largest first with their nominal values, or None
    (also without a geometry effect)."""
    chain = result.problem.context.chain
    moved = []
    for k, name in enumerate(result.names):
        match = _TABLE_LENGTH.match(name)
        if match is None or result.fixed[k] or not abs(result.x[k]) > IMPLAUSIBLE_LENGTH_M:
            continue
        joint = int(match["joint"])
        if not 1 <= joint <= chain.n:
            continue
        nominal = float(getattr(chain, match["kind"])[joint - 1])
        moved.append((abs(float(result.x[k])), name, float(result.x[k]), nominal))
    if not moved:
        return None
    listed = ", ".join(f"{name} {value * 1e3:+.1f} mm (nominal {nominal * 1e3:.1f} mm)"
                       for _, name, value, nominal in sorted(moved, reverse=True))
    return (f"the fitted geometry is implausible: {listed} moved by more than "
            f"{IMPLAUSIBLE_LENGTH_M * 1e3:.0f} mm, beyond any correction a calibration "
            "makes: check the length and joint units of the data (hostpc import warns of a "
            "unit slip) and the robot model")


def far_below_reason(chi2_dof: float, band: tuple[float, float], dof: int) -> str:
    """The sentence for a chi2/dof far below its band, with the next step."""
    times = 1.0 / max(float(np.sqrt(max(chi2_dof, 0.0))), 1e-300)
    return (f"chi2/dof {chi2_dof:.3g} is far below its band [{band[0]:.3f}, {band[1]:.3f}] "
            f"for {dof} degrees of freedom: the residuals are {times:.3g} times smaller than "
            f"the stated noise (more than {FAR_BELOW_NOISE_FACTOR:g} times, beyond chance), "
            "so the stated noise is far too large or the model absorbs the data; next: check "
            "the data's length and joint units (hostpc import warns of a unit slip), then "
            "state the instrument's noise (hostpc import --sigma)")


def expected_noise_rms(problem: Problem) -> float:
    """RMS residual norm (m) the stated covariances predict: sqrt(mean trace(cov))."""
    W = problem.sqrt_information
    cov = np.linalg.inv(np.einsum("nji,njk->nik", W, W))  # (W^T W)^-1
    lengths = problem.length_columns
    return float(np.sqrt(np.mean(np.sum(cov[:, lengths, lengths], axis=1))))


def outlier_reason(outliers: tuple[Outlier, ...], n_samples: int, n_poses: int = 0) -> str:
    """The sentence that names the outliers (most significant first); n_poses: the poses
    read more than once, tested as one each (``outliers.repeated_poses``)."""
    listed = ", ".join(f"#{o.sample} ({o.sigma:.3g} sigma, p = {o.p_value:.2g})"
                       for o in outliers)
    head = (f"sample {listed} is an outlier" if len(outliers) == 1
            else f"samples {listed} are outliers")
    if not n_poses:
        return (f"{head} (leave-one-out residual against the noise of the other samples, "
                f"Bonferroni over {n_samples} samples)")
    return (f"{head} (leave-one-out residual of a sample, or of every sample of a pose, "
            f"against the noise of the other samples, Bonferroni over {n_samples} samples "
            f"and {n_poses} pose{'s' if n_poses > 1 else ''} read more than once)")


def too_few_reason(result: FitResult) -> str:
    """The sentence for a fit that leaves no degrees of freedom."""
    n_samples, m = result.residuals_raw.shape
    free = int(result.residuals_raw.size - result.dof)
    return (f"too few samples: {n_samples} samples give {n_samples * m} numbers for "
            f"{free} fitted parameters, so no degrees of freedom are left")


def assess(result: FitResult, held_out: HeldOut | None, alpha: float = ADEQUACY_P_MIN,
           missing: tuple[str, ...] = (), outliers: tuple[Outlier, ...] = ()) -> Adequacy:
    """The verdict: no sample is an outlier (``outliers``), the chi-square passes
    ``chi2_adequate`` at ``alpha`` (by default ``ADEQUACY_P_MIN``, the push's threshold;
    ``hostpc diagnose --alpha`` changes it for the diagnosis only) and is not far below its
    band (``chi2_far_below``), no fitted table length is implausible
    (``implausible_geometry``) and no missing effect was found significant (``missing``:
    sentences naming what was). Reasons in that order."""
    dof = result.dof
    chi2_dof = result.chi2_dof
    with_calibration = result.chi2_dof_with_calibration
    tested = result.chi2 if with_calibration is None else with_calibration * dof
    p_value = chi2_p_value(tested, dof)
    chi2_ok = chi2_adequate(tested, dof, alpha)
    m = result.residuals_raw.shape[1]
    sum_squares = float(np.sum(result.residuals_raw[:, result.problem.length_columns]**2))
    noise_rms = float(np.sqrt(sum_squares * m / dof)) if dof > 0 else float("nan")
    band = chi2_band(dof, alpha)
    reasons: list[str] = []
    if outliers:
        reasons.append(outlier_reason(outliers, result.residuals_raw.shape[0],
                                      n_repeated_poses(result.problem)))
    if dof <= 0:
        reasons.append(too_few_reason(result))
    elif not chi2_ok:
        inside = ("" if with_calibration is None else
                  f" ({with_calibration:.3f} with the camera calibration's covariance)")
        reasons.append(f"chi2/dof {chi2_dof:.3f}{inside} is above its band "
                       f"[{band[0]:.3f}, {band[1]:.3f}] for {dof} degrees of freedom "
                       f"(p = {p_value:.2g})")
    elif chi2_far_below(tested, dof, alpha):
        reasons.append(far_below_reason(tested / dof, band, dof))
    geometry = implausible_geometry(result)
    if geometry is not None:
        reasons.append(geometry)
    reasons.extend(missing)
    return Adequacy(
        chi2=result.chi2, dof=dof, chi2_dof=chi2_dof, chi2_band=band, p_value=p_value,
        chi2_ok=chi2_ok, noise_scale=float(np.sqrt(chi2_dof)) if dof > 0 else float("nan"),
        noise_rms=noise_rms, expected_noise_rms=expected_noise_rms(result.problem),
        rms=result.rms, max=result.max,
        cv_rms=None if held_out is None else held_out.rms,
        cv_max=None if held_out is None else held_out.max,
        cv_whitened_rms=None if held_out is None else held_out.whitened_rms,
        cv_folds=0 if held_out is None else held_out.folds,
        adequate=not reasons, reasons=tuple(reasons),
        chi2_dof_with_calibration=with_calibration,
    )
