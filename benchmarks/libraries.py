"""`make bench`, part 4 (issue 24, point 5): credcli's labels on filters from public
estimator libraries, run as their users run them (credcli/studies/libraries.py).

For each library: the four cases (right tuning; Q, R and P0 4x too small; 4x too large;
an unmodelled 1-sigma offset on the x measurements), RUNS runs of 300 steps each, a 2-D
nearly-constant-velocity target measured in position; the labels of the calibrated rule
on the whole state (x, vx, y, vy), read through credcli's adapter. And Stone Soup's
single-target tracker on its own simulator, right tuning, through log_from_tracks.
"""

from __future__ import annotations

import sys
import time
from collections import Counter

import credcli
from credcli.studies.libraries import (
    EXPECTED,
    LIBRARY_TUNINGS,
    filterpy_run,
    stonesoup_run,
    stonesoup_tracker_run,
)

RUNS = 20


def _label(diagnosis) -> str:
    untested = " and ".join(q.value for q in diagnosis.untested)
    return diagnosis.label.value + (f" ({untested} untested)" if untested else "")


def _table(name: str, run) -> None:
    print(f"\n{name}: {RUNS} runs of 300 steps per case")
    print(f"{'case':<11}{'right':>7}  labels")
    for case, tuning in LIBRARY_TUNINGS.items():
        started = time.perf_counter()
        labels = Counter(
            _label(credcli.diagnose_log(run(tuning, seed=s))[0].diagnosis) for s in range(RUNS)
        )
        want = EXPECTED[case]
        right = sum(n for lab, n in labels.items() if lab == want)
        shown = ", ".join(f"{lab} {n}" for lab, n in labels.most_common())
        print(f"{case:<11}{right:>4}/{RUNS}  {shown}  ({time.perf_counter() - started:.1f} s)")


def main() -> int:
    _table("filterpy KalmanFilter + Saver (credcli.adapters.filterpy.log_from_saver)", filterpy_run)
    _table(
        "Stone Soup KalmanPredictor/Updater, Track + GroundTruthPath (log_from_track)",
        stonesoup_run,
    )
    labels = Counter(
        _label(r.diagnosis)
        for s in range(RUNS)
        for r in credcli.diagnose_log(stonesoup_tracker_run(seed=s))
    )
    print(
        f"\nStone Soup SingleTargetTracker on its simulator, right tuning, {RUNS} runs "
        f"(log_from_tracks): " + ", ".join(f"{lab} {n}" for lab, n in labels.most_common())
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
