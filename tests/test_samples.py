"""The bundled sample data is what its generator makes."""

from __future__ import annotations

import numpy as np
import pandas as pd
from conftest import SAMPLE

from credcli.studies.samples import write_samples


def test_sample_data_is_reproducible(tmp_path):
    written = write_samples(tmp_path)
    for path in written:
        committed = SAMPLE / path.relative_to(tmp_path)
        if path.suffix == ".parquet":
            pd.testing.assert_frame_equal(pd.read_parquet(path), pd.read_parquet(committed))
        elif path.is_dir():  # a ROS2 bag: SQLite pages may differ, the messages may not
            from credcli.io.rosbag import read_bag

            for topic in ("/odom", "/ground_truth"):
                role = "estimate" if topic == "/odom" else "truth"
                new, old = (
                    read_bag(path, topic, role, "auto"),
                    read_bag(committed, topic, role, "auto"),
                )
                np.testing.assert_array_equal(new.position, old.position)
                np.testing.assert_array_equal(new.time, old.time)
        else:
            assert path.read_bytes() == committed.read_bytes(), "run `make sample-data`"
