"""A stamped trajectory read from one file or bag topic: what every navigation-format
reader returns (:mod:`credcli.io.formats`, :mod:`credcli.io.rosbag`) and pairing takes."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from credcli.io.schema import InputFormat


@dataclass(frozen=True)
class Trajectory:
    """Stamped states read from one file (or bag topic), sorted by time.

    ``position`` is (N, 3) for pose formats and the (N, d) vector of a credcli log;
    ``quaternion`` (N, 4) is x, y, z, w, or None; ``cov`` is (N, 6, 6) in ROS order for
    pose formats, (N, d, d) for a credcli log, or None; ``rows`` are the 1-based data rows
    (message numbers for a bag) of the epochs. ``cross_covariance`` is False for a pose
    covariance read as two 3×3 blocks (OpenVINS): the cross terms are then 0, not read.
    """

    time: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray | None
    cov: np.ndarray | None
    rows: np.ndarray
    source: str
    format: InputFormat
    pose: bool = True
    notes: tuple[str, ...] = field(default=())
    cross_covariance: bool = True  # False: the file has no position-orientation block
