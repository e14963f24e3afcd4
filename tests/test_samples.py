"""The bundled sample data is what its generator makes.

The generators call numpy's transcendental functions (cos, sin, the quaternion conversions of
scipy's ``Rotation``), whose last bits differ between releases and CPUs. So a regenerated file is
compared with the committed one by its decoded content, not its bytes:

- a text file token by token: the same words, and numbers equal to within one unit of the last
  digit either file printed (a value 1e-16 from a rounding boundary may print either way);
- a Parquet file column by column, to a relative 1e-12;
- a ROS bag by its decoded messages (times, positions, quaternions, covariances), to 1e-12.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from helpers import SAMPLE

from credcli.io.rosbag import read_bag
from credcli.studies.samples import write_samples

_NUMBER = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")
_TOKENS = re.compile(r"[^,\s]+")
RELATIVE = 1e-12  # of binary values, which are not printed and rounded


def last_digit_unit(token: str) -> float:
    """One unit in the last printed digit of a number token (1e-6 for ``1.234567``,
    1e-11 for ``2.5e-9``, 1 for ``42``)."""
    match = _NUMBER.fullmatch(token)
    mantissa, exponent = match.group(1), match.group(2)
    decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
    return 10.0 ** (int(exponent[1:]) if exponent else 0) * 10.0**-decimals


def assert_text_equivalent(new: Path, old: Path) -> None:
    new_lines = new.read_text().splitlines()
    old_lines = old.read_text().splitlines()
    assert len(new_lines) == len(old_lines), f"{new.name}: line count differs"
    for row, (a_line, b_line) in enumerate(zip(new_lines, old_lines, strict=True), start=1):
        if a_line == b_line:  # most lines: nothing to weigh token by token
            continue
        a_tokens, b_tokens = _TOKENS.findall(a_line), _TOKENS.findall(b_line)
        assert len(a_tokens) == len(b_tokens), f"{new.name} line {row}: token count differs"
        for a, b in zip(a_tokens, b_tokens, strict=True):
            if _NUMBER.fullmatch(a) and _NUMBER.fullmatch(b):
                unit = max(last_digit_unit(a), last_digit_unit(b))
                assert abs(float(a) - float(b)) <= unit * (1 + 1e-9), (
                    f"{new.name} line {row}: {a} != {b} (beyond one unit in the last digit)"
                )
            else:
                assert a == b, f"{new.name} line {row}: {a!r} != {b!r}"


def assert_bag_equivalent(new: Path, old: Path) -> None:
    for topic, role in (("/odom", "estimate"), ("/ground_truth", "truth")):
        a, b = read_bag(new, topic, role, "auto"), read_bag(old, topic, role, "auto")
        np.testing.assert_array_equal(a.rows, b.rows)
        for name in ("time", "position", "quaternion", "cov"):
            x, y = getattr(a, name), getattr(b, name)
            assert (x is None) == (y is None), f"{new.name} {topic}: {name} present in one only"
            if x is not None:
                np.testing.assert_allclose(x, y, rtol=RELATIVE, atol=RELATIVE, err_msg=name)


@pytest.fixture(scope="module")
def regenerated(tmp_path_factory):
    root = tmp_path_factory.mktemp("samples")
    return root, write_samples(root)


def test_sample_data_is_reproducible(regenerated):
    root, written = regenerated
    for path in written:
        committed = SAMPLE / path.relative_to(root)
        assert committed.exists(), f"{committed} missing: run `make sample-data`"
        if path.suffix == ".parquet":
            pd.testing.assert_frame_equal(
                pd.read_parquet(path), pd.read_parquet(committed), rtol=RELATIVE
            )
        elif path.is_dir() or path.suffix == ".bag":
            assert_bag_equivalent(path, committed)
        else:
            assert_text_equivalent(path, committed)


def test_text_comparison_tolerates_only_the_last_digit(tmp_path):
    old, new = tmp_path / "old.csv", tmp_path / "new.csv"
    old.write_text("time,x,y\n0.100,1.234567,2.5e-09\n")
    new.write_text("time,x,y\n0.100,1.234568,2.6e-09\n")
    assert_text_equivalent(new, old)  # one unit in the last digit of each
    new.write_text("time,x,y\n0.100,1.234569,2.5e-09\n")
    with pytest.raises(AssertionError, match="beyond one unit"):
        assert_text_equivalent(new, old)
    new.write_text("time,x,z\n0.100,1.234567,2.5e-09\n")
    with pytest.raises(AssertionError, match="'z' != 'y'"):
        assert_text_equivalent(new, old)


def test_bag_comparison_sees_a_moved_quaternion(regenerated, tmp_path, monkeypatch):
    """The tolerance of the bag comparison is far below what a real change moves."""
    import credcli.studies.pose_samples as pose_samples

    root, _ = regenerated
    truth, estimate = pose_samples.bag_messages()
    moved = estimate[0], estimate[1] * (1 + 1e-9), *estimate[2:]  # positions moved by 1e-9
    changed = pose_samples.write_bag(tmp_path / "moved.bag", 1, moved, truth)
    with pytest.raises(AssertionError):
        assert_bag_equivalent(changed, root / "formats" / "odom.bag")


def test_errors_only_sample_is_read_as_errors_and_gets_its_planted_labels():
    """sample_data/errors_only.csv: err_i and cov_i_j only; an honest segment, then one
    whose covariance is 0.35 times the errors' (the README's errors-only example)."""
    import credcli

    log = credcli.read_log(SAMPLE / "errors_only.csv", errors_only=True)
    assert log.truth is None and log.estimate is None and log.n == 200
    results = credcli.diagnose_log(log)
    assert [(r.segment, r.diagnosis.label.value) for r in results] == [
        ("cruise", "credible"),
        ("turn", "optimism"),
    ]
