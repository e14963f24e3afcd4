"""Pose topics of ROS1 ``.bag`` files and ROS2 bag directories, read with ``rosbags``
(pure Python, no ROS install; the ``credcli[ros]`` extra).

Estimates come from nav_msgs/Odometry or geometry_msgs/PoseWithCovarianceStamped (with
their 6×6 covariance); truth also from geometry_msgs/PoseStamped or TransformStamped.
Stamps are the messages' ``header.stamp`` (the bag's receive times, said in a note, when
every header stamp is zero).

Messages of one topic usually have one serialized length. Per length, the byte offsets of
the stamp, the pose and the covariance are found in one deserialized message and the rest
are decoded with numpy; two more messages of each length are deserialized and must agree,
or that length is decoded message by message.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from credcli.errors import CredcliError
from credcli.io.schema import InputFormat, TimeUnit
from credcli.io.trajectory import Trajectory

ESTIMATE_TYPES = ("nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseWithCovarianceStamped")
TRUTH_TYPES = ESTIMATE_TYPES + (
    "geometry_msgs/msg/PoseStamped",
    "geometry_msgs/msg/TransformStamped",
)


def _require_rosbags():
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError as exc:
        raise CredcliError(
            "reading ROS bags needs the rosbags package: pip install 'credcli[ros]'"
        ) from exc
    return AnyReader, Stores, get_typestore


def _fields(msg):
    """(sec, nanosec, position (3), quaternion (4), covariance (36) or None) of a message."""
    stamp = msg.header.stamp
    if hasattr(msg, "transform"):
        p, q, cov = msg.transform.translation, msg.transform.rotation, None
    else:
        pose = msg.pose
        if hasattr(pose, "covariance"):  # PoseWithCovariance
            cov = np.asarray(pose.covariance, dtype=float)
            pose = pose.pose
        else:
            cov = None
        p, q = pose.position, pose.orientation
    return (
        int(stamp.sec),
        int(stamp.nanosec),
        np.array([p.x, p.y, p.z], float),
        np.array([q.x, q.y, q.z, q.w], float),
        cov,
    )


MAX_METADATA_BYTES = 16 << 20
"""Largest ROS2 ``metadata.yaml`` read (16 MiB; a bag's is a few kB)."""


def check_bag_path(path: Path) -> None:
    """Refuse a directory that is not a ROS2 bag: a directory is one only with a
    metadata.yaml in it, of at most :data:`MAX_METADATA_BYTES`, and holds files (a FIFO
    among them would block the reader).

    Parameters
    ----------
    path : pathlib.Path
        A bag file or directory.

    Raises
    ------
    CredcliError
        If ``path`` is a directory without a ``metadata.yaml`` file, with one too large,
        or with an entry that is neither a file nor a directory.
    """
    if not path.is_dir():
        return
    metadata = path / "metadata.yaml"
    if not metadata.is_file():
        raise CredcliError(
            f"{path}: not a ROS2 bag directory (no metadata.yaml); name a log file or a bag"
        )
    if metadata.stat().st_size > MAX_METADATA_BYTES:
        raise CredcliError(
            f"{metadata}: larger than {MAX_METADATA_BYTES // 2**20} MiB, too large for a bag's "
            "metadata; check the bag"
        )
    for entry in path.iterdir():  # a FIFO or device among the bag's files would block
        if not (entry.is_file() or entry.is_dir()):
            raise CredcliError(
                f"{entry}: not a regular file (a FIFO, device or socket) in the bag directory; "
                "a bag holds files"
            )


def read_bag(path: Path, topic: str | None, role: str, time_unit: TimeUnit) -> Trajectory:
    """The poses (and covariances) of ``topic`` in the bag at ``path``.

    Parameters
    ----------
    path : pathlib.Path
        A ROS1 ``.bag`` file or a ROS2 bag directory.
    topic : str or None
        The topic; None: the only one of a type the ``role`` can use.
    role : str
        ``"estimate"`` (nav_msgs/Odometry, geometry_msgs/PoseWithCovarianceStamped) or
        ``"truth"`` (also PoseStamped and TransformStamped).
    time_unit : TimeUnit
        The ``time_unit`` given: bag stamps are seconds and nanoseconds, so a unit other
        than ``auto``, ``s`` or ``ns`` only adds a note.

    Returns
    -------
    Trajectory
        As :func:`read_bag_topics` gives it.
    """
    return read_bag_topics(path, [(topic, role)], time_unit)[0]


def read_bag_topics(
    path: Path, requests: list[tuple[str | None, str]], time_unit: TimeUnit
) -> list[Trajectory]:
    """The trajectories of several (topic, role) requests, in their order, from one pass
    over the bag: its chunks and index are read once, not once per topic.

    Parameters
    ----------
    path : pathlib.Path
        A ROS1 ``.bag`` file or a ROS2 bag directory (one with a ``metadata.yaml``).
    requests : list of (str or None, str)
        The topics and their roles (``"estimate"`` or ``"truth"``); a topic None is the
        only one of a type its role can use, and a note says which was picked.
    time_unit : TimeUnit
        The ``time_unit`` given (a unit other than ``auto``, ``s`` or ``ns`` only adds a
        note).

    Returns
    -------
    list of Trajectory
        One per request, its epochs in bag order: stamps from ``header.stamp`` (the
        bag's receive times, with a note, when every header stamp is zero), positions,
        quaternions (x, y, z, w), and the 6×6 covariance where the message type has one;
        the source is ``"<path>:<topic>"``.

    Raises
    ------
    CredcliError
        If the ``rosbags`` package is missing, the bag cannot be opened, a topic is missing,
        ambiguous, of the wrong type or without messages, or a message cannot be decoded.
    """
    AnyReader, Stores, get_typestore = _require_rosbags()

    check_bag_path(Path(path))
    try:
        reader = AnyReader([Path(path)], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except Exception as exc:  # rosbags and its decompressors raise their own error types
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        if "YAML" in first:
            first = "its metadata.yaml is not valid YAML"
        raise CredcliError(f"{path}: cannot be read as a ROS bag: {first}") from exc
    names: set[str] = set()
    try:
        topics = {c.topic: c.msgtype for c in reader.connections}
        resolved = [_resolve_topic(path, topics, topic, role) for topic, role in requests]
        names = {topic for topic, _ in resolved}
        records: dict[str, list] = {topic: [] for topic in names}
        connections = [c for c in reader.connections if c.topic in names]
        for connection, ts, raw in reader.messages(connections=connections):
            records[connection.topic].append((ts, bytes(raw)))
        out = [
            _trajectory(path, reader, topic, topics[topic], records[topic], note, time_unit)
            for topic, note in resolved
        ]
    except CredcliError:
        raise
    except Exception as exc:  # a corrupt bag: rosbags raises its own error types
        what = f"topic{'s' if len(names) > 1 else ''} {', '.join(sorted(names))}"
        raise CredcliError(f"{path}: cannot read {what}: {exc}") from exc
    finally:
        reader.close()
    return out


def _resolve_topic(path: Path, topics: dict, topic: str | None, role: str) -> tuple[str, str]:
    """The topic of a request (the only one of a usable type when not named), checked, and
    the note that says it was picked ("" when named)."""
    wanted = ESTIMATE_TYPES if role == "estimate" else TRUTH_TYPES
    flag = "`topic`" if role == "estimate" else "`truth_topic`"
    note = ""
    if topic is None:
        usable = sorted(t for t, m in topics.items() if m in wanted)
        if len(usable) != 1:
            raise CredcliError(
                f"{path}: name the {role} topic with {flag}; "
                f"{'topics' if usable else 'no topic of type ' + ' or '.join(wanted)}"
                f"{': ' + ', '.join(usable) if usable else ''} in the bag"
            )
        topic = usable[0]
        note = f"{path}: {role} from topic {topic} (the only one of its type)"
    if topic not in topics:
        listed = ", ".join(f"{t} ({m})" for t, m in sorted(topics.items())) or "none"
        raise CredcliError(f"{path}: no topic {topic} in the bag; its topics: {listed}")
    if topics[topic] not in wanted:
        raise CredcliError(
            f"{path}: topic {topic} has type {topics[topic]}; the {role} needs "
            f"{' or '.join(wanted)}"
        )
    return topic, note


def _trajectory(path, reader, topic, msgtype, records, note, time_unit) -> Trajectory:
    """One topic's messages, (receive time, raw bytes) in bag order, as a Trajectory."""
    notes = [note] if note else []
    if not records:
        raise CredcliError(f"{path}: topic {topic} has no messages")
    try:
        sec, nsec, position, quaternion, cov = _decode(reader, [r for _, r in records], msgtype)
    except Exception as exc:  # a corrupt message: rosbags raises its own error types
        raise CredcliError(f"{path}: cannot read topic {topic}: {exc}") from exc
    if not (sec.any() or nsec.any()):  # drivers that leave header.stamp unset
        received = np.array([ts for ts, _ in records], dtype=np.int64)
        sec, nsec = received // 10**9, received % 10**9
        notes.append(
            f"{path}: {topic} has no header stamps (all zero); using the bag's "
            "receive times instead"
        )
    if TimeUnit(time_unit) not in (TimeUnit.AUTO, TimeUnit.NS, TimeUnit.S):
        notes.append(f"{path}: `time_unit` does not apply to bag stamps (sec, nanosec)")
    time = sec.astype(float) + 1e-9 * nsec.astype(float)
    return Trajectory(
        time=time,
        position=position,
        quaternion=quaternion,
        cov=None if cov is None else cov.reshape(-1, 6, 6),
        rows=np.arange(1, len(time) + 1),
        source=f"{path}:{topic}",
        format=InputFormat.ROSBAG,
        notes=tuple(notes),
    )


def _decode(reader, raws: list[bytes], msgtype: str):
    """Stamps, positions, quaternions and covariances of every message, in bag order."""
    n = len(raws)
    sec, nsec = np.empty(n, np.int64), np.empty(n, np.int64)
    position, quaternion = np.empty((n, 3)), np.empty((n, 4))
    cov = None
    lengths = np.fromiter((len(r) for r in raws), np.int64, n)
    for length in np.unique(lengths):
        idx = np.flatnonzero(lengths == length)
        decoded = _fast(reader, [raws[i] for i in idx], msgtype)
        if decoded is None:
            decoded = _slow(reader, [raws[i] for i in idx], msgtype)
        s, ns, p, q, c = decoded
        sec[idx], nsec[idx], position[idx], quaternion[idx] = s, ns, p, q
        if c is not None:
            if cov is None:
                cov = np.empty((n, 36))
            cov[idx] = c
    return sec, nsec, position, quaternion, cov


def _slow(reader, raws, msgtype):
    parts = [_fields(reader.deserialize(r, msgtype)) for r in raws]
    cov = None if parts[0][4] is None else np.array([p[4] for p in parts])
    return (
        np.array([p[0] for p in parts]),
        np.array([p[1] for p in parts]),
        np.array([p[2] for p in parts]),
        np.array([p[3] for p in parts]),
        cov,
    )


def _fast(reader, raws, msgtype):
    """numpy decoding at the offsets found in the first message, or None when they cannot
    be found unambiguously or a check message disagrees."""
    first = _fields(reader.deserialize(raws[0], msgtype))
    sec, nsec, p, q, c = first
    head = raws[0]
    pose_bytes = np.r_[p, q].astype("<f8").tobytes()
    stamp_bytes = np.array([sec, nsec], "<u4").tobytes()
    offsets = [head.find(stamp_bytes), head.find(pose_bytes)]
    if c is not None:
        offsets.append(head.find(c.astype("<f8").tobytes(), offsets[1] + 56))
    if min(offsets) < 0:
        return None
    table = np.frombuffer(b"".join(raws), np.uint8).reshape(len(raws), len(head))

    def column(offset, count, dtype):
        width = np.dtype(dtype).itemsize * count
        return table[:, offset : offset + width].copy().view(dtype).reshape(len(raws), count)

    stamp = column(offsets[0], 2, "<u4").astype(np.int64)
    pose = column(offsets[1], 7, "<f8")
    cov = column(offsets[2], 36, "<f8") if c is not None else None
    out = (stamp[:, 0], stamp[:, 1], pose[:, :3], pose[:, 3:], cov)
    for k in {len(raws) // 2, len(raws) - 1}:  # two checks against the deserializer
        s, ns, pk, qk, ck = _fields(reader.deserialize(raws[k], msgtype))
        same = s == out[0][k] and ns == out[1][k]
        same = same and np.array_equal(pk, out[2][k]) and np.array_equal(qk, out[3][k])
        if ck is not None:
            same = same and np.array_equal(ck, out[4][k])
        if not same:
            return None
    return out
