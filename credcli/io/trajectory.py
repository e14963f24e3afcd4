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

    Attributes
    ----------
    time : numpy.ndarray, shape (N,)
        The stamps in seconds.
    position : numpy.ndarray, shape (N, 3) or (N, d)
        The positions of a pose format, or the state vector of a credcli log.
    quaternion : numpy.ndarray, shape (N, 4), or None
        The orientations as quaternions (x, y, z, w), normalised by the readers' checks;
        None where the format has none.
    cov : numpy.ndarray, shape (N, 6, 6) or (N, d, d), or None
        The claimed covariance: ROS order (x, y, z, rotations about x, y, z) for pose
        formats; None where the file has none (a truth).
    rows : numpy.ndarray of int, shape (N,)
        The 1-based data rows of the epochs (message numbers for a bag).
    source : str
        The file as given (``<path>:<topic>`` for a bag topic).
    format : InputFormat
        The format it was read as.
    pose : bool
        True for pose formats (position and orientation); False for a credcli log's vector.
    notes : tuple of str
        The decisions taken while reading (format, unit, topic, order).
    cross_covariance : bool
        False when the pose covariance was read as two 3×3 blocks: its
        position-orientation terms are 0 because the file has none.
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
