"""The bundled sample data is what its generator makes."""

from __future__ import annotations

import pandas as pd
from conftest import SAMPLE

from credcli.studies.samples import write_samples


def test_sample_data_is_reproducible(tmp_path):
    written = write_samples(tmp_path)
    for path in written:
        committed = SAMPLE / path.name
        if path.suffix == ".csv":
            assert path.read_bytes() == committed.read_bytes(), "run `make sample-data`"
        else:
            pd.testing.assert_frame_equal(pd.read_parquet(path), pd.read_parquet(committed))
