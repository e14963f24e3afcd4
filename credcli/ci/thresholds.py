"""The gate's regression thresholds (plain Python: the command line reads the defaults)."""

from __future__ import annotations

from dataclasses import dataclass

from credcli.errors import CredcliError


@dataclass(frozen=True)
class Thresholds:
    max_nci_increase: float = 1.0  # dB of |NCI|
    max_anees_ratio: float = 1.25  # factor on max(ANEES, 1/ANEES)
    allow_new_segments: bool = False

    def describe(self) -> str:
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
