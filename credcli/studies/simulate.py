"""The Monte Carlo study of Section IV (Tables II and III), sweeps, and the Fig. 1 curves.

Each trial draws Σ_true = Q diag(λ) Qᵀ (Q from the QR decomposition of a standard Gaussian
matrix, λ_i ~ U[0.5, 2]), a covariance scale ρ and a bias μ (‖μ‖ ~ U[lo, hi] in a uniform
direction), then N errors. Every trial has its own random stream, keyed by the seed, the
scenario and the trial number, so results do not depend on how trials are spread over
processes.
"""

from __future__ import annotations

import enum
import math
import zlib
from dataclasses import dataclass, replace

import numpy as np

from credcli.engine import metrics
from credcli.engine.diagnosis import (
    DIAGNOSIS_LABELS,
    LABEL_ALIASES,
    Label,
    Variant,
    diagnose_variants,
    parse_label,
)
from credcli.errors import CredcliError, plain
from credcli.schedule.pool import ordered_map, prepare_worker
from credcli.studies.settings import (  # noqa: F401 (re-exported)
    CURVE_RUNS,
    ErrorModel,
    Noise,
    ScenarioSpec,
    SimulationConfig,
)

BASELINES = ("nees", "nci")
"""The single-metric columns of Table II, after the variants of the rule."""

Method = enum.Enum(
    "Method",
    [(v.name, v.value) for v in (Variant.CALIBRATED, Variant.KS, Variant.PAPER)]
    + [(name.upper(), name) for name in BASELINES],
    type=str,
    module=__name__,
    qualname="Method",
)
Method.__doc__ = """A column of Table II: each variant of the rule (its value spelled once,
in :class:`credcli.engine.config.Variant`), then the single-metric baselines."""


VARIANT_ORDER = (Variant.KS, Variant.PAPER, Variant.CALIBRATED)
"""Order in which a trial is diagnosed: ks first, so its sign flips are drawn exactly as
in credcli 0.1 and the paper's variants reproduce their earlier figures seed for seed."""


def parse_scenarios(text: str) -> list[Label]:
    """The scenarios of a ``--scenario`` text.

    Parameters
    ----------
    text : str
        'all', a label name or a short alias (``LABEL_ALIASES``), or a comma-separated
        list of them (case-insensitive).

    Returns
    -------
    list of Label
        The paper's scenarios in the order given, each once (a ``bias`` is its SMM); all
        six for 'all'.

    Raises
    ------
    CredcliError
        If an item is no diagnosis label or alias (``insufficient-data`` included).

    Examples
    --------
    >>> [s.value for s in parse_scenarios("opt, bias, smm")]
    ['optimism', 'smm']
    """
    if text.strip().lower() == "all":
        return list(DIAGNOSIS_LABELS)
    out = []
    for item in (t.strip().lower() for t in text.split(",")):
        label = parse_label(item)
        if label is None or label is Label.INSUFFICIENT:
            names = ", ".join([lab.value for lab in DIAGNOSIS_LABELS] + list(LABEL_ALIASES))
            raise CredcliError(
                f"`scenario`: unknown scenario '{item}'; choose all, {names}", "scenario"
            )
        label = label.paper  # the paper's scenarios: a bias is its SMM (constant offset)
        if label not in out:
            out.append(label)
    return out


def draw_trial(
    spec: ScenarioSpec,
    n: int,
    dim: int,
    eigenvalues,
    rng: np.random.Generator,
    model: ErrorModel | None = None,
):
    """Errors (n, dim) and claimed covariances (n, dim, dim) of one trial.

    x_k ~ N(0, Σ), x̂_k ~ N(x_k + μ, Σ) gives e_k = x_k − x̂_k ~ N(−μ, Σ); every metric depends
    on x and x̂ only through e, so e is drawn directly. Σ̂_k = ρΣ. ``model`` replaces the
    Gaussian whitened errors (heavy tails, AR(1) in time) with the same covariance Σ.

    Parameters
    ----------
    spec : ScenarioSpec
        The ranges of ρ and of the bias norm ‖μ‖.
    n : int
        Number of epochs N.
    dim : int
        Dimension d.
    eigenvalues : tuple of float
        Range (lo, hi) of the uniform eigenvalues λ_i of Σ.
    rng : numpy.random.Generator
        The trial's random stream; drawn in the order Q, λ, ρ, μ (if biased), errors.
    model : ErrorModel, optional
        The law of the whitened errors; standard Gaussian when None.

    Returns
    -------
    errors : numpy.ndarray, shape (n, dim)
        The errors e_k.
    cov : numpy.ndarray, shape (n, dim, dim)
        The claimed covariances ρΣ (a read-only broadcast view).

    Notes
    -----
    Section IV-A: Σ = Q diag(λ) Qᵀ with Q from the QR decomposition of a standard Gaussian
    matrix, λ_i ~ U[eigenvalues], ρ ~ U[spec.rho], and, when ``spec.bias`` is not (0, 0),
    μ in a uniform direction with ‖μ‖ ~ U[spec.bias].
    """
    q, _ = np.linalg.qr(rng.standard_normal((dim, dim)))
    lam = rng.uniform(*eigenvalues, size=dim)
    sigma = (q * lam) @ q.T
    rho = rng.uniform(*spec.rho)
    mu = np.zeros(dim)
    if spec.bias[1] > 0:
        direction = rng.standard_normal(dim)
        mu = direction / np.linalg.norm(direction) * rng.uniform(*spec.bias)
    z = rng.standard_normal((n, dim)) if model is None else model.draw(rng, n, dim)
    errors = -mu - z @ (q * np.sqrt(lam)).T
    cov = np.broadcast_to(rho * sigma, (n, dim, dim))
    return errors, cov


def trial_seed(seed: int, group: int, trial: int) -> np.random.SeedSequence:
    """The random stream of one trial, keyed by the study's seed, its group and its number.

    Parameters
    ----------
    seed : int
        The study's seed (``SimulationConfig.seed``).
    group : int
        The group's stream key (a CRC-32 of its ρ and bias ranges).
    trial : int
        The trial's number in its group.

    Returns
    -------
    numpy.random.SeedSequence
        ``SeedSequence(entropy=seed, spawn_key=(group, trial))``.
    """
    return np.random.SeedSequence(entropy=seed, spawn_key=(group, trial))


@dataclass(frozen=True)
class TrialResult:
    """The label of each method on one trial (attributes named as Method values).

    Attributes
    ----------
    calibrated : Label
        The calibrated variant's label, as the paper's (a bias or asymmetry is SMM).
    ks, paper : Label
        The labels of the ``ks`` and ``paper`` variants.
    nees, nci : Label
        The single-metric baselines' labels (from the ``ks`` diagnosis).
    """

    calibrated: Label
    ks: Label
    paper: Label
    nees: Label
    nci: Label


def _run_chunk(args) -> list[TrialResult]:
    """Worker: run trials [start, stop) of one group (top level, so processes can pickle it)."""
    spec, start, stop, config = args
    stream = _stream_key(spec)
    model = config.error_model
    model = None if model == ErrorModel() else model
    judged_by = config.judged_by
    out = []
    for trial in range(start, stop):
        gen = np.random.default_rng(trial_seed(config.seed, stream, trial))
        errors, cov = draw_trial(spec, config.n, config.dim, config.eigenvalues, gen, model)
        labels = diagnose_variants(errors, cov, VARIANT_ORDER, judged_by, gen)
        ks = labels[Variant.KS]
        out.append(
            TrialResult(
                calibrated=labels[Variant.CALIBRATED].label.paper,  # the paper's six
                ks=ks.label,
                paper=labels[Variant.PAPER].label,
                nees=ks.nees_label,
                nci=ks.nci_label,
            )
        )
    return out


def _run_chunk_on_worker(args) -> list[TrialResult]:
    """Cluster worker: :func:`_run_chunk`, after the worker's one-time set-up."""
    prepare_worker()
    return _run_chunk(args)


def _stream_key(spec: ScenarioSpec) -> int:
    """A stable number for a group's random streams, from its parameters."""
    return zlib.crc32(repr((spec.rho, spec.bias)).encode())


def run_groups(
    specs: list[ScenarioSpec], config: SimulationConfig, jobs: int = 1, progress=None, runner=None
) -> list[list[TrialResult]]:
    """Run ``config.trials`` trials of each spec; ``jobs`` processes (or the Dask
    ``runner``) share the work.

    Parameters
    ----------
    specs : list of ScenarioSpec
        The groups.
    config : SimulationConfig
        Trials, epochs, dimension, error model, seed and diagnosis settings.
    jobs : int
        Worker processes (default 1: in this process); the results do not depend on it.
    progress : callable, optional
        Called as ``progress(done, total)`` with counts of trials as tasks finish.
    runner : DaskRunner, optional
        A :class:`credcli.schedule.cluster.DaskRunner` that runs the tasks on its cluster instead
        of local processes (``jobs`` then only sets the trials per task).

    Returns
    -------
    list of list of TrialResult
        Per spec, the trial results in trial order.
    """
    return run_group_sets([(specs, config)], jobs, progress, runner)[0]


def _chunk_size(trials: int, jobs: int) -> int:
    """Trials per task: about two tasks per process, at most 25."""
    return max(1, min(25, math.ceil(trials / max(1, 2 * jobs))))


def run_group_sets(
    plans: list[tuple[list[ScenarioSpec], SimulationConfig]],
    jobs: int = 1,
    progress=None,
    runner=None,
) -> list[list[list[TrialResult]]]:
    """The trials of every (specs, config) plan (e.g. every point of a sweep) as one set of
    tasks, so that processes or cluster workers share all of them; per plan, per spec, the
    trial results in trial order. Each trial's random stream comes from (seed, group,
    trial), so the results do not depend on how the trials are split into tasks.

    Parameters
    ----------
    plans : list of (list of ScenarioSpec, SimulationConfig)
        The plans: groups and the configuration they are run with.
    jobs : int
        Worker processes (default 1: in this process); the results do not depend on it.
    progress : callable, optional
        Called as ``progress(done, total)`` with counts of trials as tasks finish.
    runner : DaskRunner, optional
        A :class:`credcli.schedule.cluster.DaskRunner` that runs the tasks on its cluster instead
        of local processes (``jobs`` then only sets the trials per task).

    Returns
    -------
    list of list of list of TrialResult
        Per plan, per spec, the trial results in trial order.
    """
    tasks, owners = [], []
    for p, (specs, config) in enumerate(plans):
        chunk = _chunk_size(config.trials, jobs)
        for g, spec in enumerate(specs):
            for a in range(0, config.trials, chunk):
                tasks.append((spec, a, min(a + chunk, config.trials), config))
                owners.append((p, g))
    total = sum(len(specs) * config.trials for specs, config in plans)
    out: list[list[list[TrialResult]]] = [[[] for _ in specs] for specs, _ in plans]
    if runner is not None:
        sizes = [t[2] - t[1] for t in tasks]  # trials per task
        outputs = iter(runner.map(_run_chunk_on_worker, tasks, progress, sizes))
        progress = None
    else:
        outputs = ordered_map(_run_chunk, tasks, jobs)
    done = 0
    try:
        for (p, g), result in zip(owners, outputs):  # in task order
            out[p][g].extend(result)
            done += len(result)
            if progress is not None:
                progress(done, total)
    finally:
        close = getattr(outputs, "close", None)
        if close is not None:
            close()
    return out


CONFUSION_LABELS = DIAGNOSIS_LABELS + (Label.INSUFFICIENT,)
"""Columns of Table III: the six diagnoses, and insufficient-data (calibrated variant)."""


@dataclass(frozen=True)
class StudyResult:
    """Tables II and III for a set of scenarios; Table III is of ``variant``.

    Attributes
    ----------
    scenarios : list of Label
        The true label of each group, in order.
    accuracy : dict of Method to dict of Label to float
        Table II: per method and true label, the fraction of trials labelled correctly.
    confusion : dict of Label to dict of Label to int
        Table III: per true label, the count of each diagnosed label of
        ``CONFUSION_LABELS`` (the six and insufficient-data).
    trials : int
        Trials per group (0 without groups).
    variant : Variant
        The variant whose labels ``confusion`` counts (default calibrated).
    """

    scenarios: list[Label]
    accuracy: dict[Method, dict[Label, float]]
    confusion: dict[Label, dict[Label, int]]
    trials: int
    variant: Variant = Variant.CALIBRATED


def summarise(
    truths: list[Label], groups: list[list[TrialResult]], variant: Variant = Variant.CALIBRATED
) -> StudyResult:
    """Accuracy of every method and the confusion counts of ``variant``, per group.

    Parameters
    ----------
    truths : list of Label
        The true label of each group.
    groups : list of list of TrialResult
        The trial results of each group, as :func:`run_groups` gives them.
    variant : Variant
        The variant whose confusion counts are kept (default calibrated).

    Returns
    -------
    StudyResult
        Tables II and III of the groups.
    """
    variant = Variant(variant)
    accuracy = {
        m: {
            t: float(np.mean([getattr(r, m.value) is t for r in g])) for t, g in zip(truths, groups)
        }
        for m in Method
    }
    confusion = {
        t: {lab: sum(getattr(r, variant.value) is lab for r in g) for lab in CONFUSION_LABELS}
        for t, g in zip(truths, groups)
    }
    return StudyResult(truths, accuracy, confusion, len(groups[0]) if groups else 0, variant)


def run_study(
    config: SimulationConfig, scenarios: list[Label], jobs: int = 1, progress=None, runner=None
) -> StudyResult:
    """Tables II and III: every listed scenario, ``config.trials`` trials each.

    Parameters
    ----------
    config : SimulationConfig
        The study's settings (Section IV-A by default).
    scenarios : list of Label
        The paper's scenarios to run (see :func:`parse_scenarios`).
    jobs : int
        Worker processes (default 1: in this process); the results do not depend on it.
    progress : callable, optional
        Called as ``progress(done, total)`` with counts of trials as tasks finish.
    runner : DaskRunner, optional
        A :class:`credcli.schedule.cluster.DaskRunner` that runs the tasks on its cluster instead
        of local processes (``jobs`` then only sets the trials per task).

    Returns
    -------
    StudyResult
        Accuracy per method and the confusion matrix of ``config.diagnosis.variant``.
    """
    specs = [config.spec(s) for s in scenarios]
    groups = run_groups(specs, config, jobs, progress, runner)
    return summarise(scenarios, groups, config.diagnosis.variant)


MAX_SWEEP_VALUES = 1000
"""Most values one sweep may hold."""


class SweepParameter(str, enum.Enum):
    """A parameter ``simulate --sweep`` varies.

    Attributes
    ----------
    RHO : "rho"
        The covariance scale ρ of every group (a fixed value).
    BIAS : "bias"
        The bias norm ‖μ‖ of every group (a fixed value).
    N : "n"
        Epochs per trial.
    DIM : "dim"
        Dimension.
    B : "B"
        Number of sign flips of the ELT (``n_flips``).
    TAU : "tau"
        The relevance floor τ_NCI in dB.
    AR : "ar"
        AR(1) coefficient of the whitened errors.
    """

    RHO = "rho"
    BIAS = "bias"
    N = "n"
    DIM = "dim"
    B = "B"
    TAU = "tau"
    AR = "ar"


@dataclass(frozen=True)
class Sweep:
    """One parameter and the values a sweep gives it.

    Attributes
    ----------
    parameter : SweepParameter
        The parameter varied.
    values : tuple of float
        Its values, in order.
    """

    parameter: SweepParameter
    values: tuple[float, ...]

    @classmethod
    def parse(cls, text: str) -> Sweep:
        """A sweep from ``name=start:stop:count`` (evenly spaced) or ``name=v1,v2,...``.

        Parameters
        ----------
        text : str
            The ``--sweep`` text; the name is case-insensitive.

        Returns
        -------
        Sweep
            The parameter and its values (a grid's rounded to 12 significant digits).

        Raises
        ------
        CredcliError
            If the text is malformed, the name unknown, there are no or more than
            ``MAX_SWEEP_VALUES`` values, or a value is out of the parameter's range
            (n, dim and B positive integers, rho and tau > 0, bias >= 0, ar in (−1, 1)).

        Examples
        --------
        >>> Sweep.parse("RHO=0.5:2:4")
        Sweep(parameter=<SweepParameter.RHO: 'rho'>, values=(0.5, 1.0, 1.5, 2.0))
        """
        if "=" not in text:
            raise CredcliError(f"`sweep` '{text}': expected NAME=start:stop:count or NAME=v1,v2,…")
        name, spec = (t.strip() for t in text.split("=", 1))
        by_name = {p.value.lower(): p for p in SweepParameter}
        param = by_name.get(name.lower())
        if param is None:
            raise CredcliError(
                f"`sweep`: unknown parameter '{name}'; choose "
                f"{', '.join(p.value for p in SweepParameter)}",
                "sweep",
            )
        try:
            if ":" in spec:
                start, stop, count = spec.split(":")
                count = int(count)
                if not 1 <= count <= MAX_SWEEP_VALUES:
                    raise CredcliError(
                        f"`sweep` '{text}': the count must be 1 … {MAX_SWEEP_VALUES}; got {count}"
                    )
                grid = np.linspace(float(start), float(stop), count)
                # 12 significant digits: no float noise such as 19.950000000000003
                values = tuple(float(f"{v:.12g}") for v in grid)
            else:
                values = tuple(float(v) for v in spec.split(",") if v.strip())
        except ValueError as exc:
            raise CredcliError(
                f"`sweep` '{text}': expected NAME=start:stop:count or NAME=v1,v2,… with numbers"
            ) from exc
        if not values:
            raise CredcliError(f"`sweep` '{text}': no values")
        if len(values) > MAX_SWEEP_VALUES:
            raise CredcliError(f"`sweep` '{text}': at most {MAX_SWEEP_VALUES} values")
        if not all(math.isfinite(v) for v in values):
            raise CredcliError(f"`sweep` '{text}': every value must be a finite number")
        if param in (SweepParameter.N, SweepParameter.DIM, SweepParameter.B):
            if any(v != int(v) or v < 1 for v in values):
                raise CredcliError(f"`sweep` {param.value}: values must be positive integers")
        if param in (SweepParameter.RHO, SweepParameter.TAU) and any(v <= 0 for v in values):
            raise CredcliError(f"`sweep` {param.value}: values must be > 0")
        if param is SweepParameter.BIAS and any(v < 0 for v in values):
            raise CredcliError("`sweep` bias: values must be >= 0")
        if param is SweepParameter.AR and any(not -1 < v < 1 for v in values):
            raise CredcliError("`sweep` ar: values must be in (-1, 1)")
        return cls(param, values)


@dataclass(frozen=True)
class SweepPoint:
    """The accuracy of every method at one sweep value, for one true label.

    Attributes
    ----------
    value : float
        The sweep value.
    truth : Label
        The true label of the group, from its actual parameters (ρ < 1 optimism, ρ > 1
        pessimism, bias > 0 SMM).
    accuracy : dict of Method to float
        The fraction of the group's trials each method labelled ``truth``.
    trials : int
        Trials in the group.
    """

    value: float
    truth: Label
    accuracy: dict[Method, float]
    trials: int


def sweep_specs(sweep: Sweep, value: float, config: SimulationConfig, scenarios: list[Label]):
    """The groups and configuration of one sweep value (deduplicated by their parameters).

    Parameters
    ----------
    sweep : Sweep
        The sweep.
    value : float
        One of its values.
    config : SimulationConfig
        The study's settings.
    scenarios : list of Label
        The scenarios whose groups the value changes.

    Returns
    -------
    specs : list of ScenarioSpec
        The scenarios' groups with ρ or the bias set to ``value`` (rho, bias), without
        repeats (e.g. a fixed ρ makes the unbiased scenarios one group).
    config : SimulationConfig
        ``config`` with n, dim, B, ar or τ_NCI set to ``value`` (the others unchanged).

    Raises
    ------
    CredcliError
        If the changed configuration is invalid (e.g. n below the smallest diagnosed
        segment).
    """
    cfg = config
    specs = [config.spec(s) for s in scenarios]
    if sweep.parameter is SweepParameter.RHO:
        specs = [replace(s, rho=(value, value)) for s in specs]
    elif sweep.parameter is SweepParameter.BIAS:
        specs = [replace(s, bias=(value, value)) for s in specs]
    elif sweep.parameter is SweepParameter.N:
        cfg = replace(config, n=int(value))
    elif sweep.parameter is SweepParameter.DIM:
        cfg = replace(config, dim=int(value))
    elif sweep.parameter is SweepParameter.B:
        cfg = replace(config, diagnosis=replace(config.diagnosis, n_flips=int(value)))
    elif sweep.parameter is SweepParameter.AR:
        cfg = replace(config, ar=value)
    else:
        cfg = replace(config, diagnosis=replace(config.diagnosis, tau_nci=value))
    unique = list(dict.fromkeys(specs))
    return unique, cfg


def _checked_specs(sweep: Sweep, value: float, config: SimulationConfig, scenarios):
    """:func:`sweep_specs`, with a refused value named as the sweep's (not as the setting
    it changes, whose own flag the user did not give)."""
    try:
        return sweep_specs(sweep, value, config, scenarios)
    except CredcliError as exc:
        raise CredcliError(
            f"`sweep` {sweep.parameter.value}={value:g}: {plain(exc.message)}", "sweep"
        ) from exc


def run_sweep(
    sweep: Sweep,
    config: SimulationConfig,
    scenarios: list[Label],
    jobs: int = 1,
    progress=None,
    runner=None,
) -> list[SweepPoint]:
    """Accuracy of every method per sweep value and true label (every point's trials are
    one set of tasks).

    Parameters
    ----------
    sweep : Sweep
        The parameter and its values.
    config : SimulationConfig
        The study's settings, which the sweep changes one value at a time.
    scenarios : list of Label
        The scenarios whose groups are run at each value.
    jobs : int
        Worker processes (default 1: in this process); the results do not depend on it.
    progress : callable, optional
        Called as ``progress(done, total)`` with counts of trials as tasks finish.
    runner : DaskRunner, optional
        A :class:`credcli.schedule.cluster.DaskRunner` that runs the tasks on its cluster instead
        of local processes (``jobs`` then only sets the trials per task).

    Returns
    -------
    list of SweepPoint
        Per value in order, one point per distinct group, labelled by its true label.

    Raises
    ------
    CredcliError
        If a value makes an invalid configuration (named as the sweep's value).
    """
    plans = [(v, *_checked_specs(sweep, v, config, scenarios)) for v in sweep.values]
    groups = run_group_sets([(specs, cfg) for _, specs, cfg in plans], jobs, progress, runner)
    points: list[SweepPoint] = []
    for (value, specs, _), per_spec in zip(plans, groups):
        truths = [spec.truth for spec in specs]
        study = summarise(truths, per_spec, config.diagnosis.variant)
        points.extend(
            SweepPoint(value, t, {m: study.accuracy[m][t] for m in Method}, study.trials)
            for t in truths
        )
    return points


@dataclass(frozen=True)
class CurvePoint:
    """Fig. 1: scores of N(x̂, ρΣ) with x = 0, Σ = I_d, x̂ ~ N(μ, Σ), μ = γ·1.

    Attributes
    ----------
    rho : float
        The covariance scale ρ.
    gamma : float
        The bias per component γ.
    mean_es, expected_es : float
        The energy score (Eq. (10)): sample mean over the runs, and exact expectation.
    mean_nll, expected_nll : float
        The negative log-likelihood (Eq. (6)): sample mean over the runs, and exact
        expectation (Eq. (7)).
    """

    rho: float
    gamma: float
    mean_es: float  # sample mean over the runs
    expected_es: float  # exact expectation
    mean_nll: float
    expected_nll: float


def fig1_curves(
    rhos, gammas, runs: int = CURVE_RUNS, dim: int = 2, seed: int = 0
) -> tuple[list[CurvePoint], list[CurvePoint]]:
    """Fig. 1a (ES against ρ, γ = 0) and Fig. 1b (ES against γ, ρ = 1), with NLL beside.

    The sample means follow the paper (``runs`` Monte Carlo runs per point); the exact
    expectations use Y − x ~ N(μ, (1 + ρ)Σ) and Y − Y′ ~ N(0, 2ρΣ):
    E[ES] = E‖N(μ, (1+ρ)I)‖ − ½√ρ·E‖N(0, 2I)‖ and E[NLL] from Eq. (7).

    Parameters
    ----------
    rhos : iterable of float
        The values of ρ of Fig. 1a.
    gammas : iterable of float
        The values of γ of Fig. 1b.
    runs : int
        Monte Carlo runs per point (default ``CURVE_RUNS``, the paper's 5,000); every
        point uses the same draws.
    dim : int
        Dimension d (default 2, the paper's).
    seed : int
        Seed of the draws (default 0).

    Returns
    -------
    by_rho : list of CurvePoint
        Fig. 1a: one point per ρ, at γ = 0.
    by_gamma : list of CurvePoint
        Fig. 1b: one point per γ, at ρ = 1.

    References
    ----------
    The paper, Section II-D (the energy score, Eq. (10)) and Fig. 1.
    """
    gen = np.random.default_rng(seed)
    z = gen.standard_normal((runs, dim))
    eye = np.broadcast_to(np.eye(dim), (runs, dim, dim))
    spread = 0.5 * metrics.expected_norm(np.zeros((1, dim)), 2 * np.eye(dim)[None])[0]

    def point(rho: float, gamma: float) -> CurvePoint:
        mu = np.full(dim, gamma)
        errors = -(mu + z)  # e = x − x̂ with x = 0, x̂ = μ + z
        es = metrics.energy_score(errors, eye, rho)
        nll = metrics.gaussian_nll(errors, eye, rho)
        expected_first = metrics.expected_norm(mu[None], ((1 + rho) * np.eye(dim))[None])[0]
        expected_nll = 0.5 * (
            (dim + mu @ mu) / rho + dim * math.log(rho) + dim * math.log(2 * math.pi)
        )
        return CurvePoint(
            rho,
            gamma,
            float(es.mean()),
            float(expected_first - math.sqrt(rho) * spread),
            float(nll.mean()),
            float(expected_nll),
        )

    return [point(r, 0.0) for r in rhos], [point(1.0, g) for g in gammas]
