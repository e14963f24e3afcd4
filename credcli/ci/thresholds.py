"""The gate's regression thresholds (plain Python: the command line reads the defaults)."""

from __future__ import annotations

from dataclasses import dataclass

from credcli.errors import CredcliError


@dataclass(frozen=True)
class Thresholds:
    """The regression thresholds of ``credcli gate``: how much worse a segment may get
    before the gate fails it (beside the rules without a threshold: a label gaining a
    condition, the ELT newly rejecting).

    Attributes
    ----------
    max_nci_increase : float
        The largest increase of |NCI|, in dB, that is not a regression (default 1.0;
        a larger decrease counts as an improvement).
    max_anees_ratio : float
        The largest factor by which ANEES may move further from 1, measured as
        max(ANEES, 1/ANEES), before it is a regression (default 1.25).
    allow_new_segments : bool
        Whether a segment new since the baseline, or missing from the log, passes
        (default False: it fails the gate).

    Raises
    ------
    CredcliError
        If ``max_nci_increase`` < 0 or ``max_anees_ratio`` < 1 (or either is NaN).
    """

    max_nci_increase: float = 1.0  # dB of |NCI|
    max_anees_ratio: float = 1.25  # factor on max(ANEES, 1/ANEES)
    allow_new_segments: bool = False

    def describe(self) -> str:
        """The thresholds in one line, as the gate's Markdown summary states them.

        Returns
        -------
        str
            ``"thresholds: |NCI| +1 dB, ANEES x1.25 further from 1, …"`` for the defaults.
        """
        return (
            f"thresholds: |NCI| +{self.max_nci_increase:g} dB, ANEES x{self.max_anees_ratio:g} "
            "further from 1, a label gaining a condition, the ELT newly rejecting"
            + ("; new/missing segments allowed" if self.allow_new_segments else "")
        )

    def __post_init__(self) -> None:
        if not self.max_nci_increase >= 0:
            raise CredcliError(
                f"`max_nci_increase` must be >= 0; got {self.max_nci_increase}", "max_nci_increase"
            )
        if not self.max_anees_ratio >= 1:
            raise CredcliError(
                f"`max_anees_ratio` must be >= 1; got {self.max_anees_ratio}", "max_anees_ratio"
            )
