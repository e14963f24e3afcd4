"""CI gate: `--fail-on` conditions, baselines, and segment-by-segment regression checks."""

from __future__ import annotations

import enum
import itertools
import math
from dataclasses import dataclass

from credcli.ci.thresholds import Thresholds  # noqa: F401 (re-exported)
from credcli.engine.config import LOCATION_CONDITIONS, SMM_CONDITION
from credcli.engine.diagnosis import LABEL_ALIASES, Label, parse_label
from credcli.engine.short import SegmentResults
from credcli.errors import CredcliError, shortened
from credcli.report.formats import format_pvalue
from credcli.report.records import Baseline, Snapshot, json_value, shown_label

_CONDITIONS = ("optimism", "pessimism") + LOCATION_CONDITIONS
NONCREDIBLE = "noncredible"
UNTESTED = "untested"


@dataclass(frozen=True)
class FailOn:
    """What `--fail-on` fails on: any of its comma-separated items.

    - a condition (``optimism``, ``pessimism``, ``bias``, ``asymmetric``, ``smm``): every
      label that contains it (``bias`` fails ``bias``, ``optimism+bias`` and
      ``pessimism+bias``); ``smm``, the paper's system-model mismatch, fails every label
      with a location condition (bias, asymmetric or smm);
    - a combined label (``optimism+bias``): that label only (``optimism+smm``: every label
      whose paper label it is, :attr:`Label.paper`);
    - ``insufficient-data``: segments without a verdict;
    - ``untested``: partial verdicts, whose label answers one question and leaves the other
      (scale or location) untested;
    - ``noncredible``: every segment but a complete ``credible`` one (a partial
      ``credible`` has a question open, so it fails too).

    ``str(fail_on)`` lists the items again, comma-separated. Made by :func:`parse_fail_on`.

    Attributes
    ----------
    conditions : frozenset of str
        The single conditions that fail every label containing them (``optimism``,
        ``pessimism``, ``bias``, ``asymmetric``, ``smm``).
    labels : frozenset of Label
        The combined labels that fail as themselves (or as their paper label), and
        ``insufficient-data``.
    noncredible : bool
        Whether every segment but a complete ``credible`` one fails.
    untested : bool
        Whether a partial verdict (a question left untested) fails.
    """

    conditions: frozenset[str] = frozenset()
    labels: frozenset[Label] = frozenset()
    noncredible: bool = False
    untested: bool = False

    def __str__(self) -> str:
        items = sorted(self.conditions) + sorted(lab.value for lab in self.labels)
        flags = [NONCREDIBLE] * self.noncredible + [UNTESTED] * self.untested
        return ",".join(flags + items)

    def fails(self, label: Label, untested=()) -> bool:
        """Whether a segment with ``label`` (and ``untested`` questions) fails.

        Parameters
        ----------
        label : Label
            The segment's answered label.
        untested : sequence of Question or str, default ()
            The questions its verdict leaves open (scale, location); empty for a
            complete verdict.

        Returns
        -------
        bool
            True when any item of ``--fail-on`` matches the segment.
        """
        if self.noncredible:
            return label is not Label.CREDIBLE or bool(untested)
        if self.untested and untested and label is not Label.INSUFFICIENT:
            return True
        if label in self.labels or label.paper in self.labels:
            return True
        if SMM_CONDITION in self.conditions and label.location is not None:
            return True
        return bool(label.conditions & self.conditions)


def parse_fail_on(text: str) -> FailOn:
    """The conditions of ``--fail-on``, parsed.

    Parameters
    ----------
    text : str
        Comma-separated items, case and spaces ignored: ``optimism,bias`` (any of),
        ``optimism+bias`` (that label), ``noncredible``, ``untested``,
        ``insufficient-data`` or label aliases (``pess+smm``); see ``FailOn``. A label
        with one condition (``bias``) counts as that condition.

    Returns
    -------
    FailOn
        What the gate fails on.

    Raises
    ------
    CredcliError
        If an item is not a condition, a label or an alias (``credible`` is none), or if
        ``text`` has no item at all.

    Examples
    --------
    >>> fail_on = parse_fail_on("pessimism, optimism+bias")
    >>> str(fail_on)
    'pessimism,optimism+bias'
    >>> fail_on.fails(Label.PESSIMISM_BIAS), fail_on.fails(Label.OPTIMISM)
    (True, False)
    """
    conditions: set[str] = set()
    labels: set[Label] = set()
    noncredible = untested = False
    for item in (t.strip().lower() for t in text.split(",")):
        if not item:
            continue
        if item == NONCREDIBLE:
            noncredible = True
            continue
        if item == UNTESTED:
            untested = True
            continue
        if item in _CONDITIONS:
            conditions.add(item)
            continue
        label = parse_label(item)
        if label is None or label is Label.CREDIBLE:
            raise CredcliError(
                f"`fail_on`: unknown condition '{item}'; use {', '.join(_CONDITIONS)}, "
                f"{Label.INSUFFICIENT.value}, {UNTESTED}, {NONCREDIBLE}, a label such as "
                "optimism+bias, or "
                f"an alias ({', '.join(a for a in LABEL_ALIASES if a != 'cred')})"
            )
        if len(label.conditions) == 1:
            conditions |= label.conditions
        else:
            labels.add(label)
    if not (conditions or labels or noncredible or untested):
        raise CredcliError("`fail_on`: give at least one condition, e.g. noncredible", "fail_on")
    return FailOn(frozenset(conditions), frozenset(labels), noncredible, untested)


def fails(label: Label, fail_on: FailOn, untested=()) -> bool:
    """Whether a segment's label fails ``fail_on`` (``FailOn.fails``).

    Parameters
    ----------
    label : Label
        The segment's answered label.
    fail_on : FailOn
        The conditions of ``--fail-on``.
    untested : sequence of Question or str, default ()
        The questions the segment's verdict leaves open.

    Returns
    -------
    bool
        True when the segment fails.
    """
    return fail_on.fails(label, untested)


class Status(str, enum.Enum):
    """What became of a baseline's segment in the current run.

    Attributes
    ----------
    UNCHANGED : str
        No rule fired either way.
    IMPROVED : str
        Something got better and nothing worse.
    REGRESSED : str
        At least one regression rule fired (it fails the gate).
    NEW : str
        The segment is not in the baseline.
    MISSING : str
        The baseline's segment is not in the log.
    """

    UNCHANGED = "unchanged"
    IMPROVED = "improved"
    REGRESSED = "regressed"
    NEW = "new"
    MISSING = "missing"


@dataclass(frozen=True)
class SegmentComparison:
    """One segment of the baseline against the same segment now.

    Attributes
    ----------
    segment : str
        The segment's name.
    status : Status
        Unchanged, improved, regressed, new or missing.
    old : Snapshot or None
        The baseline's segment (None for a new one).
    new : Snapshot or None
        The segment now (None for a missing one).
    reasons : tuple of str
        Why it regressed (or is new / missing); empty otherwise.
    improvements : tuple of str
        What got better.
    """

    segment: str
    status: Status
    old: Snapshot | None  # the baseline's segment
    new: Snapshot | None  # the segment now
    reasons: tuple[str, ...]  # why it regressed (or is new / missing)
    improvements: tuple[str, ...]

    @property
    def failed(self) -> bool:
        return self.status is Status.REGRESSED

    def failed_with(self, thresholds: Thresholds) -> bool:
        """Whether the segment fails the gate under ``thresholds``.

        Parameters
        ----------
        thresholds : Thresholds
            The gate's thresholds; only ``allow_new_segments`` matters here.

        Returns
        -------
        bool
            A regressed segment fails; a new or missing one fails unless
            ``thresholds.allow_new_segments``.
        """
        if self.status in (Status.NEW, Status.MISSING):
            return not thresholds.allow_new_segments
        return self.failed


def _anees_ratio(old: float, new: float) -> float:
    """How many times further from 1 the new ANEES is than the old, on a log scale
    (max(a, 1/a)); an ANEES of 0 (every error exactly 0) is infinitely far, and two of
    them are no change."""
    far = [math.inf if a <= 0 else max(a, 1.0 / a) for a in (old, new)]
    if math.isinf(far[0]) and math.isinf(far[1]):
        return 1.0
    return far[1] / far[0]


def _beyond(label: Label, other: Label) -> set[str]:
    """The conditions of ``label`` that ``other`` lacks. A location condition is not new
    where ``other`` has one too: a bias or an asymmetry where a baseline said smm is the
    same finding (the paper's SMM), named more precisely."""
    conditions = set(label.conditions - other.conditions)
    if other.location is not None:
        conditions -= set(LOCATION_CONDITIONS)
    return conditions


def compare_segment(
    name: str, old: Snapshot, new: Snapshot, alpha: float, th: Thresholds
) -> SegmentComparison:
    """The regression rules of the gate, for one matched segment.

    A segment regresses when any of these holds (each a reason):

    - its label was ``credible`` and is not, or it gained a condition (a location condition
      where the baseline had one is the same finding, named more precisely);
    - a question it answered is now untested (while it still has a verdict);
    - |NCI| grew by more than ``th.max_nci_increase`` dB;
    - ANEES moved further from 1 by more than the factor ``th.max_anees_ratio`` (measured
      as max(ANEES, 1/ANEES));
    - the ELT rejects at ``alpha`` where it did not.

    The opposite changes are recorded as improvements (a better label only when nothing
    regressed). A rule whose numbers are missing on either side is skipped.

    Parameters
    ----------
    name : str
        The segment's name.
    old, new : Snapshot
        The segment in the baseline and now.
    alpha : float
        The ELT's level (α_L in the calibrated variant).
    th : Thresholds
        The gate's thresholds.

    Returns
    -------
    SegmentComparison
        REGRESSED with its reasons, else IMPROVED when something got better, else
        UNCHANGED.
    """
    reasons, better = [], []
    old_label, new_label = old.label, new.label
    if old_label is Label.CREDIBLE and new_label is not Label.CREDIBLE:
        reasons.append(f"label credible -> {new_label.value}")
    else:
        gained = sorted(_beyond(new_label, old_label))
        if gained:
            reasons.append(
                f"label {old_label.value} -> {new_label.value} (gained {'+'.join(gained)})"
            )
    if new_label is not Label.INSUFFICIENT:
        opened = sorted(set(new.untested) - set(old.untested))
        if opened:
            reasons.append(f"{' and '.join(opened)} no longer tested")
        closed = sorted(set(old.untested) - set(new.untested))
        if closed and old_label is not Label.INSUFFICIENT:
            better.append(f"{' and '.join(closed)} tested again")
    if new_label is not old_label and not reasons:
        lost = sorted(_beyond(old_label, new_label))
        if lost or new_label is Label.CREDIBLE:
            better.append(f"label {old_label.value} -> {new_label.value}")
    if old.nci is not None and new.nci is not None:
        change = abs(new.nci) - abs(old.nci)
        if change > th.max_nci_increase:
            reasons.append(
                f"|NCI| {abs(old.nci):.2f} -> {abs(new.nci):.2f} dB (+{change:.2f} > {th.max_nci_increase:g})"
            )
        elif change < -th.max_nci_increase:
            better.append(f"|NCI| {abs(old.nci):.2f} -> {abs(new.nci):.2f} dB")
    if old.anees is not None and new.anees is not None:
        ratio = _anees_ratio(old.anees, new.anees)
        if ratio > th.max_anees_ratio:
            reasons.append(
                f"ANEES {old.anees:.3g} -> {new.anees:.3g} (further from 1 by x{ratio:.2f} > {th.max_anees_ratio:g})"
            )
        elif ratio < 1 / th.max_anees_ratio:
            better.append(f"ANEES {old.anees:.3g} -> {new.anees:.3g} (closer to 1)")
    if old.elt_pvalue is not None and new.elt_pvalue is not None:
        if old.elt_pvalue >= alpha > new.elt_pvalue:
            reasons.append(
                f"ELT newly rejects (p {format_pvalue(old.elt_pvalue)} -> "
                f"{format_pvalue(new.elt_pvalue)} < {alpha:.3g})"
            )
        elif new.elt_pvalue >= alpha > old.elt_pvalue:
            better.append(
                f"ELT no longer rejects (p {format_pvalue(old.elt_pvalue)} -> "
                f"{format_pvalue(new.elt_pvalue)})"
            )
    status = Status.REGRESSED if reasons else Status.IMPROVED if better else Status.UNCHANGED
    return SegmentComparison(name, status, old, new, tuple(reasons), tuple(better))


def compare(
    baseline: list[Snapshot], current: list[Snapshot], th: Thresholds, alpha: float
) -> list[SegmentComparison]:
    """Every segment of the baseline and of the current run, matched by name.

    Parameters
    ----------
    baseline : list of Snapshot
        The baseline's segments.
    current : list of Snapshot
        The segments of the current run.
    th : Thresholds
        The gate's thresholds (:func:`compare_segment`).
    alpha : float
        The ELT's level (α_L in the calibrated variant).

    Returns
    -------
    list of SegmentComparison
        One per segment, in the baseline's order followed by new segments; a baseline
        segment absent now is MISSING, a segment absent from the baseline NEW.
    """
    old = {s.segment: s for s in baseline}
    new = {s.segment: s for s in current}
    out = []
    for name, rec in old.items():
        if name in new:
            out.append(compare_segment(name, rec, new[name], alpha, th))
        else:
            out.append(
                SegmentComparison(
                    name, Status.MISSING, rec, None, ("segment missing from the log",), ()
                )
            )
    for name, rec in new.items():
        if name not in old:
            out.append(
                SegmentComparison(name, Status.NEW, None, rec, ("segment not in the baseline",), ())
            )
    return out


def check_same_dimension(baseline: Baseline, current: list[Snapshot]) -> None:
    """Check that the new log's errors have the baseline's state dimension.

    Parameters
    ----------
    baseline : Baseline
        The baseline as read.
    current : list of Snapshot
        The segments of the current run.

    Raises
    ------
    CredcliError
        If a segment of the new log has another dimension d than the baseline's segments:
        its labels describe other states, and no segment of one is a regression of the
        other's.
    """
    before = {s.dim for s in baseline.segments if s.dim is not None}
    now = {s.dim for s in current if s.dim is not None}
    if before and now and before != now:
        was, is_now = (", ".join(map(str, sorted(dims))) for dims in (before, now))
        raise CredcliError(
            f"{baseline.source}: the baseline's segments have d = {was} states, the new log's "
            f"d = {is_now}; gate compares one estimator's states: gate a log of the same "
            "states, or record a new baseline"
        )


def check_same_parameters(baseline: Baseline, requested: dict) -> None:
    """Check that the settings given to the gate (command line or config file) equal the
    baseline's.

    Parameters
    ----------
    baseline : Baseline
        The baseline as read, with the settings it was made with.
    requested : dict
        A setting's name (a DiagnosisConfig field, ``seed``, ``window``, ``whole``) to
        the value given; a value of None (not given) is not compared.

    Raises
    ------
    CredcliError
        If any given setting differs from the baseline's (compared as JSON values); the
        message lists every difference.
    """
    diff = []
    for name, value in requested.items():
        recorded, now = json_value(baseline.setting(name)), json_value(value)
        if value is not None and recorded != now:
            diff.append(f"{name}: baseline {recorded!r}, now {now!r}")
    if diff:
        raise CredcliError(
            f"{baseline.source}: the baseline was made with different parameters "
            f"({'; '.join(diff)}); gate with the baseline's settings or record a new baseline"
        )


def check_same_reading(baseline: Baseline, given: dict[str, tuple[object, list[str]]]) -> None:
    """Check that the gate reads the new log as the baseline's log was read.

    Every reading setting the gate is given (a config's [columns] and [input]) must equal
    the recorded one.

    Parameters
    ----------
    baseline : Baseline
        The baseline as read, with how its log was read.
    given : dict of str to (object, list of str)
        A table name (``"columns"``, ``"input"``) to the typed settings built from it and
        the names the user set there; file names (``truth``) are not settings and are
        skipped.

    Raises
    ------
    CredcliError
        If any named setting differs from the recorded one (compared as JSON values);
        the message lists every difference.
    """
    recorded = {"columns": baseline.reading.schema, "input": baseline.reading.options}
    diff = []
    for table, (now, names) in given.items():
        for name in names:
            if name == "truth":
                continue
            before, after = getattr(recorded[table], name), getattr(now, name)
            if json_value(before) != json_value(after):
                diff.append(
                    f"[{table}] {name}: baseline {json_value(before)!r}, now {json_value(after)!r}"
                )
    if diff:
        raise CredcliError(
            f"{baseline.source}: the baseline's log was read differently ({'; '.join(diff)}); "
            "gate reads the new log as the baseline's was: drop these settings or record a "
            "new baseline"
        )


def verdict_line(comparisons: list[SegmentComparison], th: Thresholds) -> tuple[bool, str]:
    """The gate's verdict in one line: PASS, or FAIL with the first failing segment.

    Parameters
    ----------
    comparisons : list of SegmentComparison
        Every segment, as :func:`compare` returns them.
    th : Thresholds
        The gate's thresholds (whether new or missing segments fail).

    Returns
    -------
    passed : bool
        Whether no segment fails and at least one was compared (new and missing segments
        alone, allowed or not, compare nothing and fail).
    line : str
        ``"PASS: no regression in …"`` or ``"FAIL: k of n segment(s) regressed (…);
        first: …"``, with the count of each status.
    """
    failed = [c for c in comparisons if c.failed_with(th)]
    counts = {s: sum(c.status is s for c in comparisons) for s in Status}
    tally = ", ".join(f"{n} {s.value}" for s, n in counts.items() if n)
    if not failed and counts[Status.NEW] + counts[Status.MISSING] == len(comparisons):
        # new and missing segments allowed, but none compared: no evidence of no regression
        return False, (
            f"FAIL: no segment of the log is in the baseline ({tally}), so nothing was "
            "compared; give the log the baseline was recorded from (its segment names)"
        )
    if failed:
        first = failed[0]
        return False, (
            f"FAIL: {len(failed)} of {len(comparisons)} segment(s) regressed ({tally}); "
            f"first: {shortened(first.segment)}: {first.reasons[0]}"
        )
    return True, f"PASS: no regression in {len(comparisons)} segment(s) ({tally})"


def gate_fail_on(
    comparisons: list[SegmentComparison], fail_on: FailOn, passed: bool, verdict: str
) -> tuple[bool, str]:
    """`gate --fail-on`: the gate's verdict, failed also by a segment whose label now
    fails ``fail_on`` (whatever the baseline said).

    Parameters
    ----------
    comparisons : list of SegmentComparison
        Every segment, as :func:`compare` returns them.
    fail_on : FailOn
        The conditions of ``--fail-on``.
    passed : bool
        The gate's own verdict (:func:`verdict_line`).
    verdict : str
        The gate's verdict line.

    Returns
    -------
    passed : bool
        False when the gate failed or a current segment matches ``fail_on``.
    line : str
        The verdict line, with the matching segments appended (the first five named).
    """
    bad = [
        c for c in comparisons if c.new is not None and fail_on.fails(c.new.label, c.new.untested)
    ]
    if not bad:
        return passed, verdict
    shown = ", ".join(
        f"{shortened(c.segment)} ({shown_label(c.new.label, c.new.untested)})" for c in bad[:5]
    )
    more = f" and {len(bad) - 5} more" if len(bad) > 5 else ""
    line = f"{len(bad)} segment(s) match `fail_on` {fail_on}: {shown}{more}"
    return False, (f"{verdict}; {line}" if not passed else f"FAIL: {line}")


def fail_on_verdict(results, fail_on: FailOn) -> tuple[bool, str, list[int]]:
    """The verdict of `diagnose --fail-on`, decided on the typed results.

    Parameters
    ----------
    results : sequence of SegmentDiagnosis or SegmentVerdict, or SegmentResults
        The diagnosed segments, or what was kept of them (their ``verdict()``); a run of
        short segments is decided on its labels without making its items
        (``credcli.engine.short.SegmentResults.verdicts``).
    fail_on : FailOn
        The conditions of ``--fail-on``.

    Returns
    -------
    passed : bool
        Whether no segment matches ``fail_on``.
    line : str
        The one-line verdict, ``"PASS: …"`` or ``"FAIL: …"`` naming the first five
        failing segments.
    failing : list of int
        The indices of the failing segments in ``results``.
    """
    if isinstance(results, SegmentResults):  # a run of short segments without its items
        verdicts = results.verdicts()
    else:
        verdicts = ((v.label, v.untested) for v in (r.verdict() for r in results))
    decided: dict = {}  # each (label, untested) decided once

    def fails(verdict) -> bool:
        if verdict not in decided:
            decided[verdict] = fail_on.fails(*verdict)
        return decided[verdict]

    bad = list(itertools.compress(itertools.count(), map(fails, verdicts)))
    listed = str(fail_on)
    if bad:
        shown = ", ".join(
            f"{shortened(v.segment)} ({shown_label(v.label, v.untested)})"
            for v in (results[k].verdict() for k in bad[:5])
        )
        more = f" and {len(bad) - 5} more" if len(bad) > 5 else ""
        return (
            False,
            f"FAIL: {len(bad)} of {len(results)} segment(s) match `fail_on` {listed}: {shown}{more}",
            bad,
        )
    return True, f"PASS: none of {len(results)} segment(s) match `fail_on` {listed}", []
