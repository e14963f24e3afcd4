"""Settings of the studies: the Monte Carlo study and the UWB pipeline. Plain Python (no
numpy at import), so that the command line reads every default from here."""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field, replace

from credcli.engine.config import DiagnosisConfig, Label, SlowErrors
from credcli.errors import CredcliError
from credcli.io.schema import RangeReading

CURVE_RUNS = 5000
"""Monte Carlo runs per point of the Fig. 1 curves (``simulate --curves``)."""


class Noise(str, enum.Enum):
    """The law of the whitened errors of the Monte Carlo study (``simulate --noise``).

    Attributes
    ----------
    GAUSSIAN : "gaussian"
        Standard Gaussian, as in the paper.
    STUDENT_T : "student-t"
        Multivariate Student-t, scaled to unit covariance (``student-t:NU``).
    """

    GAUSSIAN = "gaussian"
    STUDENT_T = "student-t"


MIN_NU = 4.0
"""Student-t noise needs more degrees of freedom than this: the scale test's variance is the
NEES's, which is finite only for ν > 4 (the fourth moment), so below it no level is held in
general. Measured by a review helper (100 credible trials each): ν = 2.0001 labelled 99 of
100 pessimism, ν = 2.1 and 2.5 gave 7 and 8 % false labels; ν = 3 happened to give 3 %."""


@dataclass(frozen=True)
class ErrorModel:
    """How whitened errors are drawn: Gaussian or multivariate Student-t with ``nu`` degrees
    of freedom (scaled to unit covariance), then an AR(1) filter of coefficient ``ar`` in
    time, x_k = φ x_{k−1} + √(1 − φ²) z_k with x_0 = z_0, which keeps the marginal
    covariance unchanged.

    Attributes
    ----------
    noise : Noise
        The law of z_k (default Gaussian).
    nu : float or None
        Degrees of freedom ν > :data:`MIN_NU` of the Student-t; None for Gaussian.
    ar : float
        The AR(1) coefficient φ in (−1, 1); 0 (the default) for errors independent in
        time.
    """

    noise: Noise = Noise.GAUSSIAN
    nu: float | None = None
    ar: float = 0.0

    @classmethod
    def parse(cls, noise: str = "gaussian", ar: float = 0.0) -> ErrorModel:
        """The model of a ``--noise`` text and an ``--ar`` coefficient.

        Parameters
        ----------
        noise : str
            ``gaussian`` or ``student-t:NU`` (case and surrounding blanks ignored)
            (default ``gaussian``).
        ar : float
            The AR(1) coefficient φ (default 0).

        Returns
        -------
        ErrorModel
            The model; ``str()`` of it gives the noise text back.

        Raises
        ------
        CredcliError
            If ``noise`` is neither form, NU is not a number > :data:`MIN_NU`, or ``ar`` is
            not in (−1, 1).

        Examples
        --------
        >>> model = ErrorModel.parse(" Student-T:5 ", ar=0.5)
        >>> str(model), model.nu, model.ar
        ('student-t:5', 5.0, 0.5)
        """
        text = noise.strip().lower()
        if text == Noise.GAUSSIAN.value:
            model = cls(Noise.GAUSSIAN, None, ar)
        elif text.startswith(Noise.STUDENT_T.value + ":"):
            try:
                nu = float(text.split(":", 1)[1])
            except ValueError:
                nu = float("nan")
            if not (math.isfinite(nu) and nu > MIN_NU):
                raise CredcliError(
                    f"`noise` '{noise}': the degrees of freedom must be a finite number > {MIN_NU:g} "
                    "(the scale test's level rests on a finite fourth moment), e.g. "
                    "student-t:5",
                    "noise",
                )
            model = cls(Noise.STUDENT_T, nu, ar)
        else:
            raise CredcliError(
                f"`noise` '{noise}': use gaussian or student-t:NU, e.g. student-t:5", "noise"
            )
        if not (math.isfinite(ar) and -1 < ar < 1):
            raise CredcliError(f"`ar` must be in (-1, 1); got {ar}", "ar")
        return model

    def __str__(self) -> str:
        return self.noise.value + (f":{self.nu:g}" if self.nu is not None else "")

    def draw(self, rng, n: int, dim: int):
        """Whitened errors with unit marginal covariance.

        Parameters
        ----------
        rng : numpy.random.Generator
            The random stream.
        n : int
            Number of epochs.
        dim : int
            Dimension.

        Returns
        -------
        numpy.ndarray, shape (n, dim)
            The errors: z_k (Gaussian, or Gaussian over √(χ²_ν / (ν − 2)), one mixing
            draw per epoch), then the AR(1) filter when ``ar`` is nonzero.
        """
        import numpy as np

        z = rng.standard_normal((n, dim))
        if self.noise is Noise.STUDENT_T:
            w = rng.chisquare(self.nu, size=(n, 1)) / (self.nu - 2.0)
            z /= np.sqrt(w)
        if self.ar:
            from scipy.signal import lfilter

            c = math.sqrt(1.0 - self.ar**2)
            z = lfilter([c], [1.0, -self.ar], z, axis=0, zi=((1.0 - c) * z[:1]))[0]
        return z


@dataclass(frozen=True)
class ScenarioSpec:
    """How one group of trials is drawn; ``rho`` and ``bias`` are uniform ranges
    (a bias range of (0, 0) means no bias).

    Attributes
    ----------
    rho : tuple of float
        Range (lo, hi) of the covariance scale ρ, Σ̂ = ρΣ; (1, 1) for no noise mismatch.
    bias : tuple of float
        Range (lo, hi) of the bias norm ‖μ‖ (its direction is uniform); (0, 0) for none.
    """

    rho: tuple[float, float]
    bias: tuple[float, float]

    @property
    def truth(self) -> Label:
        """The label a perfect diagnosis would give these trials."""
        lo, hi = self.rho
        if lo < 1 < hi or (lo < 1 and hi == 1) or (lo == 1 and hi > 1):
            raise CredcliError(f"a ρ range must not straddle 1; got [{lo:g}, {hi:g}]")
        noise = "optimism" if hi < 1 else "pessimism" if lo > 1 else None
        smm = self.bias[1] > 0
        if smm and self.bias[0] <= 0:
            raise CredcliError(f"a bias range must be all zero or all positive; got {self.bias}")
        return Label.compose(noise, smm)


@dataclass(frozen=True)
class SimulationConfig:
    """Every setting of the study. Defaults are the paper's Section IV-A.

    Attributes
    ----------
    trials : int
        Trials per scenario, 1 … 1,000,000 (default 50).
    n : int
        Epochs per trial, 2 … 10,000,000 and at least the smallest segment that is
        diagnosed (default 100).
    dim : int
        State dimension d, 1 … 64 (default 2).
    rho_optimism : tuple of float
        Range of ρ in the optimism scenarios, inside (0, 1) (default (0.1, 0.8)).
    rho_pessimism : tuple of float
        Range of ρ in the pessimism scenarios, above 1 (default (1.25, 10)).
    bias : tuple of float
        Range of the bias norm ‖μ‖ in the SMM scenarios, positive (default (1.6, 2.4)).
    eigenvalues : tuple of float
        Range of the eigenvalues λ_i of Σ_true, positive (default (0.5, 2)).
    seed : int
        Seed of every trial's random stream, >= 0 (default 0).
    ar : float
        AR(1) coefficient of the whitened errors in time, in (−1, 1) (default 0).
    noise : str
        ``gaussian`` or ``student-t:NU`` (see :class:`ErrorModel`) (default ``gaussian``).
    diagnosis : DiagnosisConfig
        The settings of the rule that labels each trial.

    Raises
    ------
    CredcliError
        On construction, if a setting is out of its range (named in the error).
    """

    trials: int = 50
    n: int = 100
    dim: int = 2
    rho_optimism: tuple[float, float] = (0.1, 0.8)
    rho_pessimism: tuple[float, float] = (1.25, 10.0)
    bias: tuple[float, float] = (1.6, 2.4)
    eigenvalues: tuple[float, float] = (0.5, 2.0)
    seed: int = 0
    ar: float = 0.0
    noise: str = "gaussian"
    diagnosis: DiagnosisConfig = field(default_factory=DiagnosisConfig)

    @property
    def error_model(self) -> ErrorModel:
        """The :class:`ErrorModel` of ``noise`` and ``ar``."""
        return ErrorModel.parse(self.noise, self.ar)

    @property
    def judged_by(self) -> DiagnosisConfig:
        """The rule's settings for this study's trials: ``diagnosis``, with ``slow_errors``
        auto resolved from what the study draws. Independent epochs (``ar`` 0, Section
        IV's protocol) hold no memory slower than a trial, so an offset the claim covers
        is a bias (excluded); AR(1) errors may (possible)."""
        if self.diagnosis.slow_errors is not SlowErrors.AUTO:
            return self.diagnosis
        known = SlowErrors.EXCLUDED if self.ar == 0 else SlowErrors.POSSIBLE
        return replace(self.diagnosis, slow_errors=known)

    def __post_init__(self) -> None:
        checks = [
            (
                1 <= self.trials <= 1_000_000,
                "trials",
                f"`trials` must be 1 … 1,000,000; got {self.trials}",
            ),
            (2 <= self.n <= 10_000_000, "n", f"`n` must be 2 … 10,000,000; got {self.n}"),
            (1 <= self.dim <= 64, "dim", f"`dim` must be 1 … 64; got {self.dim}"),
            (
                0 < self.rho_optimism[0] <= self.rho_optimism[1] < 1,
                "rho_optimism",
                f"the optimism ρ range must lie in (0, 1); got {self.rho_optimism}",
            ),
            (
                1 < self.rho_pessimism[0] <= self.rho_pessimism[1] < math.inf,
                "rho_pessimism",
                f"the pessimism ρ range must lie above 1 and be finite; got {self.rho_pessimism}",
            ),
            (
                0 < self.bias[0] <= self.bias[1] < math.inf,
                "bias",
                f"the bias range must be positive and finite; got {self.bias}",
            ),
            (
                0 < self.eigenvalues[0] <= self.eigenvalues[1] < math.inf,
                "eigenvalues",
                f"the eigenvalue range must be positive and finite; got {self.eigenvalues}",
            ),
            (self.seed >= 0, "seed", f"`seed` must be >= 0; got {self.seed}"),
        ]
        for ok, name, message in checks:
            if not ok:
                raise CredcliError(message, name)
        self.error_model  # noqa: B018 (validates noise and ar)
        smallest = self.diagnosis.min_n(self.dim)
        if self.n < smallest:
            raise CredcliError(
                f"`n` {self.n} is below the smallest segment that is diagnosed ({smallest} "
                f"epochs for d = {self.dim}); every trial would be insufficient-data",
                "n",
            )

    def spec(self, scenario: Label) -> ScenarioSpec:
        """How the trials of one of the paper's scenarios are drawn.

        Parameters
        ----------
        scenario : Label
            One of the paper's six labels (an SMM scenario names the condition ``smm``).

        Returns
        -------
        ScenarioSpec
            ``rho_optimism``, ``rho_pessimism`` or (1, 1) as ρ range, and ``bias`` or
            (0, 0) as bias range, after the label's conditions.
        """
        conditions = scenario.conditions
        rho = (
            self.rho_optimism
            if "optimism" in conditions
            else self.rho_pessimism
            if "pessimism" in conditions
            else (1.0, 1.0)
        )
        return ScenarioSpec(rho, self.bias if "smm" in conditions else (0.0, 0.0))


class RobustLoss(str, enum.Enum):
    """Loss of the per-packet position solve."""

    NONE = "none"  # weighted least squares
    HUBER = "huber"  # iteratively reweighted, Huber's ψ at k = 1.345 (95 % Gaussian efficiency)


STD_ESTIMATE = "estimate"
"""--std value that estimates each anchor's range std from the data (MAD of range − gt_range)."""


@dataclass(frozen=True)
class UwbSettings:
    """Settings of the UWB pipeline (defaults are the paper's Section V-A, plus screening).

    Attributes
    ----------
    range_column : str
        The column of ranges used (default ``range_calib``).
    std : float or None
        A fixed range std (m) for files without a ``std`` column (default None).
    packet_window : float
        Ranges from distinct anchors within this window (s) form a packet (default 0.03).
    min_anchors : int
        Fewest distinct anchors of a packet, >= 3 for a 2-D fix (default 3).
    max_speed : float
        A period is static while the rig's 3-D speed stays below this (m/s) (default
        0.1) ...
    min_static : float
        ... for at least this long (s) (default 4).
    wls_iterations : int
        Most Gauss–Newton iterations of each start of a packet's solve (default 20).
    std_by_anchor : tuple of (int, float)
        A range std (m) per anchor id, over ``std`` and the column (default none).
    std_estimate : bool
        Estimate each anchor's range std from the data (MAD of range − gt_range)
        (default False).
    screen : bool
        Drop stale packets and packets that fail the residual test (default True).
    residual_level : float
        Level of the residual test, in (0, 1) (default 1e-6: a gross outlier against the
        run's own residual spread; real radios have heavy tails, which are evidence, not
        noise to remove).
    robust : RobustLoss
        Loss of the per-packet solve (default none: weighted least squares).
    anchor_map : tuple of (int, int)
        (log id, marker id) pairs for a markers file (default none).
    anchor_rms_warn : float
        Warn when given anchors disagree with the log's gt_range by more than this RMS
        (m) (default 0.02).

    Raises
    ------
    CredcliError
        On construction, if a std is not positive, ``packet_window``, ``max_speed`` or
        ``min_static`` is not positive, ``min_anchors`` < 3, or ``residual_level`` is not
        in (0, 1).
    """

    range_column: str = RangeReading.range_column
    std: float | None = RangeReading.std  # fixed range std (m) for files without a `std` column
    packet_window: float = 0.03  # s: ranges from distinct anchors within this window
    min_anchors: int = 3  # for a 2-D fix
    max_speed: float = 0.1  # m/s: static if the rig's 3-D speed stays below ...
    min_static: float = 4.0  # s: ... for at least this long
    wls_iterations: int = 20
    std_by_anchor: tuple[tuple[int, float], ...] = RangeReading.std_by_anchor
    std_estimate: bool = RangeReading.std_estimate
    screen: bool = True
    residual_level: float = 1e-6
    robust: RobustLoss = RobustLoss.NONE
    anchor_map: tuple[tuple[int, int], ...] = ()
    anchor_rms_warn: float = 0.02

    @property
    def reading(self) -> RangeReading:
        """What the STAR-loc reader takes of these settings."""
        return RangeReading(self.range_column, self.std, self.std_by_anchor, self.std_estimate)

    def __post_init__(self) -> None:
        object.__setattr__(self, "robust", RobustLoss(self.robust))
        checks = [
            (self.std is None or self.std > 0, "std", f"`std` must be > 0; got {self.std}"),
            (
                all(v > 0 for _, v in self.std_by_anchor),
                "std",
                f"`std` of every anchor must be > 0; got {dict(self.std_by_anchor)}",
            ),
            (
                self.packet_window > 0,
                "packet_window",
                f"`packet_window` must be > 0; got {self.packet_window}",
            ),
            (
                self.min_anchors >= 3,
                "min_anchors",
                f"`min_anchors` must be >= 3 for a 2-D fix; got {self.min_anchors}",
            ),
            (self.max_speed > 0, "max_speed", f"`max_speed` must be > 0; got {self.max_speed}"),
            (
                self.min_static > 0,
                "min_static",
                f"`min_static` must be > 0; got {self.min_static}",
            ),
            (
                0 < self.residual_level < 1,
                "residual_level",
                f"`residual_level` must be in (0, 1); got {self.residual_level}",
            ),
        ]
        for ok, name, message in checks:
            if not ok:
                raise CredcliError(message, name)
