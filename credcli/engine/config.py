"""The settings of a diagnosis and the names it uses: labels, variants, forms.

Plain Python (no numpy), so that the command line can read every default from here
without loading the engine.
"""

from __future__ import annotations

import enum
import math
import numbers
from dataclasses import dataclass

from credcli.errors import CredcliError


def sidak(alpha: float) -> float:
    """The level of each of two independent tests whose union has level ``alpha`` (Šidák).

    Parameters
    ----------
    alpha : float
        α, the level of the union, in (0, 1).

    Returns
    -------
    float
        1 − √(1 − α), computed as α/(1 + √(1 − α)) so that it does not round to 0 for
        tiny α.

    Examples
    --------
    >>> round(sidak(0.05), 6), sidak(1e-20)
    (0.025321, 5e-21)
    """
    return alpha / (1.0 + math.sqrt(1.0 - alpha))


DEFAULT_MAX_EPOCHS = 4000
"""Largest N whose N×N ELT matrix is formed (4000² float64 = 128 MB); larger segments are
tested on a seeded random subsample of this many epochs."""


class Label(str, enum.Enum):
    """Diagnosis labels.

    A label is a set of conditions joined by '+': a noise condition (optimism, pessimism)
    and a location condition. A label is a ``str`` and equals its text
    (``Label.CREDIBLE == "credible"``); ``insufficient-data`` says the data could answer
    neither question.

    The location conditions split the paper's SMM (Section III-C: the ELT rejects) by its
    cause, where the calibrated rule can tell it: ``bias``, the GLS mean test finds a mean
    that no covariance allows for; ``asymmetric``, the ELT rejects the errors' central
    symmetry while the mean test, run on the same segment, finds no mean (skewed errors,
    outliers on one side: non-line-of-sight ranges); ``smm``, the ELT rejects and no mean
    test could run, so the two cannot be told apart. The ``paper`` and ``ks`` variants
    (Algorithm 1) say ``smm`` for any ELT rejection.
    [paper][credcli.engine.config.Label.paper] maps every label to the paper's six.

    Examples
    --------
    >>> Label("optimism+bias").conditions == {"optimism", "bias"}
    True
    >>> str(Label.OPTIMISM_BIAS.paper), Label.OPTIMISM_BIAS.location
    ('optimism+smm', 'bias')
    """

    CREDIBLE = "credible"
    OPTIMISM = "optimism"
    PESSIMISM = "pessimism"
    SMM = "smm"
    OPTIMISM_SMM = "optimism+smm"
    PESSIMISM_SMM = "pessimism+smm"
    BIAS = "bias"
    OPTIMISM_BIAS = "optimism+bias"
    PESSIMISM_BIAS = "pessimism+bias"
    ASYMMETRIC = "asymmetric"
    OPTIMISM_ASYMMETRIC = "optimism+asymmetric"
    PESSIMISM_ASYMMETRIC = "pessimism+asymmetric"
    INSUFFICIENT = "insufficient-data"

    def __str__(self) -> str:
        """The label as every output spells it: ``str(Label.CREDIBLE) == "credible"``."""
        return self.value

    __format__ = str.__format__

    @classmethod
    def compose(cls, noise: str | None, location: str | bool | None) -> Label:
        """The label of a noise condition and a location condition.

        Parameters
        ----------
        noise : {"optimism", "pessimism"} or None
            The noise condition.
        location : {"smm", "bias", "asymmetric"}, True or None
            The location condition (one of ``LOCATION_CONDITIONS``); True for "smm".

        Returns
        -------
        Label
            The conditions joined by '+'; ``credible`` when there is neither.

        Raises
        ------
        ValueError
            If the conditions make no label.

        Examples
        --------
        >>> str(Label.compose("optimism", True)), str(Label.compose(None, None))
        ('optimism+smm', 'credible')
        """
        if location is True:
            location = SMM_CONDITION
        parts = (noise, location or None)
        return cls("+".join(p for p in parts if p) or "credible")

    @property
    def conditions(self) -> frozenset[str]:
        """The non-credibility conditions in the label.

        A noise condition and/or one of ``LOCATION_CONDITIONS``; empty for ``credible``
        and ``insufficient-data``.
        """
        if self in (Label.CREDIBLE, Label.INSUFFICIENT):
            return frozenset()
        return frozenset(self.value.split("+"))

    @property
    def location(self) -> str | None:
        """The label's location condition, or None."""
        found = self.conditions & frozenset(LOCATION_CONDITIONS)
        return next(iter(found)) if found else None

    @property
    def paper(self) -> Label:
        """The paper's label (Table III's six and insufficient-data).

        A bias or an asymmetry is the paper's SMM.
        """
        noise = next(iter(self.conditions - frozenset(LOCATION_CONDITIONS)), None)
        if self.location is None:
            return self
        return Label.compose(noise, SMM_CONDITION)


class Alignment(str, enum.Enum):
    """How an estimate's world frame is aligned with the truth's before errors are taken."""

    NONE = "none"  # the estimate is in the truth's frame already
    ORIGIN = "origin"  # its first pose onto the truth's first pose
    SE3 = "se3"  # Umeyama's rotation and translation (SE(2) in the plane)
    SIM3 = "sim3"  # Umeyama's rotation, translation and scale (Sim(2) in the plane)

    def fitted_parameters(self, dim: int) -> int:
        """Parameters fitted to the whole run: the degrees of freedom taken from the errors.

        Parameters
        ----------
        dim : int
            d, the dimension of the positions (2 or 3).

        Returns
        -------
        int
            0 for ``none`` and ``origin`` (which uses the first pose alone); d(d + 1)/2 for
            ``se3`` (d translations, d(d − 1)/2 rotation angles); one more for ``sim3``.

        Examples
        --------
        >>> Alignment.SE3.fitted_parameters(3), Alignment.SIM3.fitted_parameters(2)
        (6, 4)
        """
        if self in (Alignment.NONE, Alignment.ORIGIN):
            return 0
        rigid = dim * (dim + 1) // 2  # d translations and d(d − 1)/2 rotation angles
        return rigid + (self is Alignment.SIM3)


SMM_CONDITION = "smm"
LOCATION_CONDITIONS = (SMM_CONDITION, "bias", "asymmetric")
"""The location conditions; ``smm`` (the paper's) covers the other two (:attr:`Label.paper`)."""

DIAGNOSIS_LABELS = (
    Label.CREDIBLE,
    Label.OPTIMISM,
    Label.PESSIMISM,
    Label.SMM,
    Label.OPTIMISM_SMM,
    Label.PESSIMISM_SMM,
)
"""The six labels Algorithm 1 can output, in the paper's order."""

LABEL_ALIASES = {
    "cred": Label.CREDIBLE,
    "opt": Label.OPTIMISM,
    "pess": Label.PESSIMISM,
    "opt+smm": Label.OPTIMISM_SMM,
    "pess+smm": Label.PESSIMISM_SMM,
}
"""Short names accepted wherever a label is typed (simulate --scenario, --fail-on)."""


def parse_label(text: str) -> Label | None:
    """A label from its name or alias (case-insensitive); None when it is neither.

    Parameters
    ----------
    text : str
        A label's text (``"optimism+smm"``) or one of ``LABEL_ALIASES`` (``"opt+smm"``);
        surrounding spaces are ignored.

    Returns
    -------
    Label or None
        The label, or None when ``text`` names none.

    Examples
    --------
    >>> parse_label(" Opt+SMM "), parse_label("optimism+bias"), parse_label("fine")
    (<Label.OPTIMISM_SMM: 'optimism+smm'>, <Label.OPTIMISM_BIAS: 'optimism+bias'>, None)
    """
    text = text.strip().lower()
    if text in LABEL_ALIASES:
        return LABEL_ALIASES[text]
    try:
        return Label(text)
    except ValueError:
        return None


class Variant(str, enum.Enum):
    """The decision rule (``DiagnosisConfig.variant``).

    Attributes
    ----------
    CALIBRATED : "calibrated"
        The default: α is the overall false-alarm level, split by Šidák between the ELT
        (SMM) and a χ² scale test on GLS-centred errors (optimism / pessimism), both
        adjusted for serial dependence; see ``credcli.engine.diagnosis.diagnose_errors``.
    PAPER : "paper"
        Algorithm 1 as printed (NCI against ±τ).
    KS : "ks"
        The authors' public code: `credible` also when a Kolmogorov–Smirnov test of the
        NEES values against χ²_d does not reject at ``ks_alpha``; otherwise NCI against ±τ.

    References
    ----------
    P. Yan, L.-T. Hsu and R. Sun, "Credible Uncertainty Quantification under Noise and
    System Model Mismatch", Algorithm 1.
    """

    CALIBRATED = "calibrated"
    PAPER = "paper"
    KS = "ks"


AUTO = "auto"
"""``block_length = AUTO``: estimated from the data (calibrated), 1 (paper, ks)."""

MAX_FLIPS = 10_000_000
"""Largest B: 80 MB of null distribution; more adds nothing to a p-value at level 0.01."""
MIN_ELT_EPOCHS = 100
"""Smallest ELT memory budget (max_elt_epochs)."""


MEAN_SHARE = 0.5
"""The calibrated rule's split of the location level α_L between the GLS mean test (a
constant bias, in the claimed covariance's metric, from every epoch) and the ELT (any
asymmetry of the whitened errors): half each. Either one's rejection is SMM."""


class Question(str, enum.Enum):
    """The two questions of the calibrated rule; a segment may answer one and not the other."""

    SCALE = "scale"  # is the claimed covariance too small or too large?
    LOCATION = "location"  # do the errors have a mean (SMM)?


class SrdForm(str, enum.Enum):
    """Form of the SRD of Eq. (19) (``DiagnosisConfig.srd_form``).

    Attributes
    ----------
    PRINTED : "printed"
        As printed: (c|Δ⁻| − |Δ⁺|)/|Δ⁺|.
    ABSOLUTE : "absolute"
        The absolute value of the whole ratio (the form in the authors' public code).
    """

    PRINTED = "printed"
    ABSOLUTE = "absolute"


class SlowErrors(str, enum.Enum):
    """What is known of errors slower than a segment (``DiagnosisConfig.slow_errors``).

    One segment cannot tell a constant bias from a zero-mean error slower than the
    segment, which stays near one value over its epochs: a slowly varying error under
    white noise gives an offset and a narrow spread around it, as a bias under a
    too-large covariance does. Where the offset is one that an error slower than the
    segment, holding what the claimed covariance leaves over the spread, draws at the mean
    test's level (``credcli.engine.rules.offset_covered``), the two readings disagree
    (pessimism with SMM, or credible), and this setting says which the rule may take.

    Attributes
    ----------
    AUTO : "auto"
        What the data source knows: nothing for a log (as ``possible``); ``simulate``
        knows its draws, independent epochs (``excluded``) unless ``--ar`` gives them
        memory (``possible``).
    POSSIBLE : "possible"
        The errors may hold memory slower than the segment: such a segment is
        insufficient-data, its reason saying why (windows of one run, or more runs, can
        tell the two apart); so is a bias alone on a segment shorter than
        ``credcli.engine.rules.SLOW_READING_BELOW`` epochs, or on a longer one whose
        errors support a model with more memory under which they hold fewer than
        ``credcli.engine.rules.ALTERNATIVE_EPOCHS`` independent epochs, whose slow reading
        (the offset and the spread together, ``credcli.engine.scale.slow_offset_pvalue``)
        fits with a p-value of at least ``credcli.engine.rules.SLOW_READING_FIT``, and a
        pessimism
        alone whose offset such an error draws as small or smaller with that p-value
        (``credcli.engine.rules._spread_covered``); a bias whose slow reading is not
        rejected at the mean test's level otherwise has a finding naming it.
    EXCLUDED : "excluded"
        The errors are known to hold no memory slower than the segment (independent
        Monte Carlo draws, as in the paper's Section IV): the offset is a bias
        (pessimism with SMM).
    EXPECTED : "expected"
        The errors are expected to hold memory slower than the segment (one run of a
        filter whose errors follow a slowly changing geometry): a pessimism alone unless its
        offset is too small for such an error at the mean test's level (by direction), and
        a bias alone whose slow reading is not rejected at that level, are declined as
        well; fewer false alarms on slow
        errors, less power for a small bias and a short segment's pessimism
        (docs/measured.md).
    """

    AUTO = "auto"
    POSSIBLE = "possible"
    EXCLUDED = "excluded"
    EXPECTED = "expected"


class MetricsLevel(str, enum.Enum):
    """Which NLL/ES probes are computed (``DiagnosisConfig.metrics``).

    Attributes
    ----------
    NEEDED : "needed"
        The NLL/ES probes only where Algorithm 1 reaches them.
    ALL : "all"
        Always.
    """

    NEEDED = "needed"
    ALL = "all"


@dataclass(frozen=True)
class DiagnosisConfig:
    """Every setting of the diagnosis.

    Frozen, and checked when made. τ, α and c are the paper's (Section IV-A: τ_NCI =
    0.5 dB, α_sig = 0.05, c = 2); B the number of sign flips of its Section III-A
    (B >= 1000).

    Parameters
    ----------
    tau_nci : float
        τ (dB): the NCI threshold of ``paper`` and ``ks``; in the calibrated variant the
        relevance floor of the scale label, |10 log₁₀ κ̂| > τ.
    alpha : float
        In the calibrated variant, the overall false-alarm level on credible data, split
        as α_L = α_S = 1 − √(1 − α); in ``paper`` and ``ks``, the ELT's level α_sig.
    c : float
        The probe factor of Eq. (18), > 1.
    n_flips : int
        B, the number of sign flips of the ELT (at most ``MAX_FLIPS``).
    block_length : int or "auto"
        Epochs per ELT sign block, or ``"auto"`` (estimated from the data in the
        calibrated variant, 1 in ``paper`` and ``ks``). A fixed 1 in the calibrated
        variant declares the epochs independent: the scale test is then the exact
        χ²_{(N−1)d}.
    variant : Variant or str
        The decision rule: ``"calibrated"``, ``"paper"`` or ``"ks"``.
    srd_form : SrdForm or str
        The form of the SRD of Eq. (19): ``"printed"`` or ``"absolute"``.
    ks_alpha : float
        The level of the Kolmogorov–Smirnov test of the ``ks`` variant.
    nees_alpha : float
        The level of the NEES baseline's two-sided χ² test (and of the NEES plot's
        interval).
    min_epochs : int
        Segments with fewer epochs (or fewer than ``d + 2``, or too few sign blocks) get
        ``insufficient-data``: with 5 independent signs the sign-flip null has 16
        distinct values, so p < 0.05 is impossible, and the MSE matrix needs N > d
        errors. At least 2.
    max_elt_epochs : int
        The ELT's memory budget: larger segments are tested on a seeded random subsample
        of this many epochs (at least ``MIN_ELT_EPOCHS``, 100).
    metrics : MetricsLevel or str
        ``"needed"``: the NLL/ES probes only where Algorithm 1 reaches them; ``"all"``.
    exact_pvalue : bool
        Evaluate all B sign flips. By default flipping stops once the ELT can no longer
        reject at its level (the decision is the exhaustive test's; the p-value is then
        the sequential one, and ``elt_flips_used`` says how many flips were evaluated).
    slow_errors : SlowErrors or str
        ``"auto"``, ``"possible"``, ``"excluded"`` or ``"expected"``: whether a segment
        whose offset the claimed covariance covers may be an error slower than the
        segment, so that the calibrated rule declines it, or is a bias (``SlowErrors``).

    Raises
    ------
    CredcliError
        For a setting of the wrong type or out of its range, or a ``variant``,
        ``srd_form``, ``metrics`` or ``slow_errors`` that is not one of its names, naming it
        (``parameter``); for an ``alpha`` too small to test with ``MAX_FLIPS`` sign
        flips, or ``n_flips`` too few for the ELT's p-value to reach its level.

    References
    ----------
    P. Yan, L.-T. Hsu and R. Sun, "Credible Uncertainty Quantification under Noise and
    System Model Mismatch", Sections III-A and IV-A.

    Examples
    --------
    >>> config = DiagnosisConfig(alpha=0.01)
    >>> round(config.scale_level, 5), config.min_blocks, config.min_n(2)
    (0.00501, 11, 10)
    >>> DiagnosisConfig(n_flips=5)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    credcli.errors.CredcliError: invalid setting: `n_flips` 5 is too few: ... with B >= 78
    """

    tau_nci: float = 0.5
    alpha: float = 0.05
    c: float = 2.0
    n_flips: int = 1000
    block_length: int | str = AUTO
    variant: Variant = Variant.CALIBRATED
    srd_form: SrdForm = SrdForm.PRINTED
    ks_alpha: float = 0.01
    nees_alpha: float = 0.05
    min_epochs: int = 10
    max_elt_epochs: int = DEFAULT_MAX_EPOCHS
    metrics: MetricsLevel = MetricsLevel.NEEDED
    exact_pvalue: bool = False
    slow_errors: SlowErrors = SlowErrors.AUTO

    def __post_init__(self) -> None:
        reals = ("tau_nci", "alpha", "c", "ks_alpha", "nees_alpha")
        integers = ("n_flips", "min_epochs", "max_elt_epochs")
        for name in reals:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise CredcliError(
                    f"invalid setting: `{name}` must be a number; got {value!r}", name
                )
        for name in integers:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, numbers.Integral):
                raise CredcliError(
                    f"invalid setting: `{name}` must be an integer; got {value!r}", name
                )
        if not isinstance(self.exact_pvalue, bool):
            raise CredcliError(
                f"invalid setting: `exact_pvalue` must be true or false; got {self.exact_pvalue!r}",
                "exact_pvalue",
            )
        for name, kind in (
            ("variant", Variant),
            ("srd_form", SrdForm),
            ("metrics", MetricsLevel),
            ("slow_errors", SlowErrors),
        ):
            value = getattr(self, name)
            try:
                object.__setattr__(self, name, kind(value))
            except ValueError:
                names = ", ".join(v.value for v in kind)
                raise CredcliError(
                    f"invalid setting: `{name}` must be one of {names}; got {value!r}", name
                ) from None
        checks = [
            (0 < self.tau_nci < math.inf, "tau_nci", "must be finite and > 0 (dB)"),
            (0 < self.alpha < 1, "alpha", "must be in (0, 1)"),
            (1 < self.c < math.inf, "c", "must be finite and > 1 (the probe factor of Eq. (18))"),
            (
                self.n_flips <= MAX_FLIPS,
                "n_flips",
                f"{self.n_flips} would need {self.n_flips * 8 / 2**30:.3g} GiB for the "
                f"null distribution alone; at most {MAX_FLIPS:,} are allowed (the p-value's "
                "Monte Carlo error is already below 1e-4 there)",
            ),
            (
                self.block_length == AUTO
                or (
                    isinstance(self.block_length, numbers.Integral)
                    and not isinstance(self.block_length, bool)
                    and self.block_length >= 1
                ),
                "block_length",
                f"must be 'auto' or an integer >= 1; got {self.block_length!r}",
            ),
            (0 < self.ks_alpha < 1, "ks_alpha", "must be in (0, 1)"),
            (0 < self.nees_alpha < 1, "nees_alpha", "must be in (0, 1)"),
            (self.min_epochs >= 2, "min_epochs", "must be >= 2"),
            (
                self.max_elt_epochs >= MIN_ELT_EPOCHS,
                "max_elt_epochs",
                f"must be >= {MIN_ELT_EPOCHS}: a smaller budget leaves the ELT "
                f"almost no power; got {self.max_elt_epochs}",
            ),
        ]
        for ok, name, message in checks:
            if not ok:
                raise CredcliError(f"invalid setting: `{name}` {message}", name)
        level = self.elt_level
        if not level * (MAX_FLIPS + 1) > 1.0:  # 1/level overflows for a subnormal α
            smallest = MAX_FLIPS + 1
        else:
            smallest = math.ceil(1.0 / level - 1e-9) - 1
        if smallest > MAX_FLIPS:
            raise CredcliError(
                f"invalid setting: `alpha` {self.alpha:g} is too small to test: the ELT's p-value "
                f"can only reach its level {level:.3g} with more than {MAX_FLIPS:,} sign flips",
                "alpha",
            )
        if self.n_flips < smallest:
            raise CredcliError(
                f"invalid setting: `n_flips` {self.n_flips} is too few: the ELT's p-value "
                f"(1 + count)/(B + 1) can only fall below its level {level:.3g} with "
                f"B >= {smallest}",
                "n_flips",
            )

    @property
    def calibrated(self) -> bool:
        """Whether the variant is the calibrated rule."""
        return self.variant is Variant.CALIBRATED

    @property
    def location_level(self) -> float:
        """The ELT's level: α_L = 1 − √(1 − α) (Šidák) in the calibrated variant, else α."""
        return sidak(self.alpha) if self.calibrated else self.alpha

    @property
    def mean_level(self) -> float:
        """The GLS mean test's share of α_L when the ELT runs beside it (calibrated):
        α_L·MEAN_SHARE, and the ELT's the rest (Bonferroni: their union has level at most
        α_L). A test that cannot run leaves its share to the other."""
        return self.location_level * MEAN_SHARE

    @property
    def elt_level(self) -> float:
        """The ELT's level beside the GLS mean test: α_L·(1 − MEAN_SHARE) (calibrated);
        α in ``paper`` and ``ks``, where the ELT alone answers the location question."""
        if not self.calibrated:
            return self.location_level
        return self.location_level * (1.0 - MEAN_SHARE)

    @property
    def scale_level(self) -> float:
        """The scale test's two-sided level α_S = 1 − √(1 − α) (Šidák)."""
        return sidak(self.alpha)

    @property
    def fixed_block_length(self) -> int | None:
        """The block length when it is not estimated from the data, else None."""
        if self.block_length != AUTO:
            return int(self.block_length)
        return None if self.calibrated else 1

    @property
    def min_blocks(self) -> int:
        """Fewest sign blocks the ELT needs: 6 in ``paper``/``ks``; in the calibrated
        variant the fewest m whose smallest exact p-value, 2^{1−m}, is at most half the
        ELT's level (its share of α_L, [elt_level][credcli.engine.diagnosis.DiagnosisConfig.elt_level])."""
        if not self.calibrated:
            return 6
        return max(6, math.ceil(math.log2(4.0 / self.elt_level) - 1e-12))

    def min_n(self, dim: int) -> int:
        """Smallest segment size that is diagnosed.

        At least min_epochs and d + 2; in ``paper`` and ``ks`` also the fewest epochs that
        make min_blocks sign blocks of the fixed block length (or 1), (m − 1)L + 1, since
        the ELT alone answers their location question. (The calibrated rule answers it
        with the GLS mean test when the ELT cannot run.)

        Parameters
        ----------
        dim : int
            The state dimension d.

        Returns
        -------
        int
            The fewest epochs N of a segment that gets a verdict.
        """
        if self.calibrated:
            return max(self.min_epochs, dim + 2)
        length = self.fixed_block_length or 1
        return max(self.min_epochs, dim + 2, (self.min_blocks - 1) * length + 1)


def given_config(config) -> DiagnosisConfig:
    """The configuration a caller gave: ``config`` itself, the defaults for None.

    Parameters
    ----------
    config : DiagnosisConfig or None
        What the caller passed as ``config``.

    Returns
    -------
    DiagnosisConfig
        The configuration to diagnose with.

    Raises
    ------
    TypeError
        For anything else, naming ``config`` (a string or a dict went on to fail as an
        AttributeError deep in the engine).
    """
    if config is None:
        return DiagnosisConfig()
    if not isinstance(config, DiagnosisConfig):
        raise TypeError(
            f"config: expected a DiagnosisConfig or None; got {type(config).__name__}"
            + (" (DiagnosisConfig(**settings) makes one)" if isinstance(config, dict) else "")
        )
    return config


class States(str, enum.Enum):
    """Which error of a pose log is diagnosed (and which block of its 6×6 covariance)."""

    POSITION = "position"  # x, y, z (d = 3)
    ORIENTATION = "orientation"  # SO(3) logarithm (d = 3)
    POSE = "pose"  # both (d = 6)
    PLANAR = "planar"  # x, y, yaw (d = 3)


class Perturbation(str, enum.Enum):
    """Where the orientation error acts: R_true = Exp(δ) R_est (left, world frame, ROS's
    fixed axes) or R_true = R_est Exp(δ) (right, body frame)."""

    LEFT = "left"
    RIGHT = "right"
