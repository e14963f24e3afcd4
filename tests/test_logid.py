"""Issue 34: a log's typed identity, and the rule that gives the logs of one command
stems (figure names) no two share."""

from __future__ import annotations

import pickle

import pytest
from hypothesis import given
from hypothesis import strategies as st

from credcli.logid import LogId, unique_ids


def _stems(*paths: str) -> list[tuple[str, str]]:
    return [(i.stem, i.label) for i in unique_ids([LogId.of(p, p) for p in paths])]


def test_a_log_id_is_its_name_in_messages_and_hashable():
    log_id = LogId.of("data/a/run.csv", "data/a/run.csv")
    assert (log_id.path, log_id.name, log_id.stem, log_id.label) == (
        "data/a/run.csv",
        "data/a/run.csv",
        "run",
        "run.csv",
    )
    assert f"{log_id}: row 3" == "data/a/run.csv: row 3"
    assert pickle.loads(pickle.dumps(log_id)) == log_id  # worker processes carry it
    assert len({log_id, LogId.of("data/a/run.csv", "data/a/run.csv")}) == 1
    assert LogId.of("<arrays>").path is None
    # one name, two logs: an id is not its name (a file given twice is two logs)
    assert unique_ids([log_id, log_id])[0] != unique_ids([log_id, log_id])[1]


@pytest.mark.parametrize(
    ("paths", "expected"),
    [
        # a stem one log alone has stays as it was
        (("a/run.csv", "b/other.csv"), [("run", "run.csv"), ("other", "other.csv")]),
        # shared: the fewest parents that tell them apart, for all of them
        (("a/run.csv", "b/run.csv"), [("a_run", "a/run.csv"), ("b_run", "b/run.csv")]),
        (("x/a/run.csv", "y/a/run.csv"), [("x_a_run", "x/a/run.csv"), ("y_a_run", "y/a/run.csv")]),
        (("run.csv", "a/run.csv"), [("run", "run.csv"), ("a_run", "a/run.csv")]),
        (("/run.csv", "/tmp/run.csv"), [("run", "run.csv"), ("tmp_run", "tmp/run.csv")]),
        # one file twice: numbered in command order, the first keeps its stem
        (("a/run.csv", "a/run.csv"), [("run", "run.csv"), ("run-2", "run.csv (2)")]),
        # parents that tell some apart, then numbers for the rest
        (
            ("a/run.csv", "a/run.csv", "b/run.csv"),
            [("a_run", "a/run.csv"), ("a_run-2", "a/run.csv (2)"), ("b_run", "b/run.csv")],
        ),
        # one stem, two suffixes, one directory: a number; the labels differ already
        (("s/log.csv", "s/log.parquet"), [("log", "log.csv"), ("log-2", "log.parquet")]),
        # a stem made from parents that meets the stem another log has alone: numbered
        (
            ("a/run.csv", "b/run.csv", "a_run.csv"),
            [("a_run-2", "a/run.csv"), ("b_run", "b/run.csv"), ("a_run", "a_run.csv")],
        ),
        # a number never takes a stem another log has
        (("x.csv", "x.csv", "x-2.csv"), [("x", "x.csv"), ("x-3", "x.csv (3)"), ("x-2", "x-2.csv")]),
    ],
)
def test_the_stems_of_one_command_are_unique(paths, expected):
    assert _stems(*paths) == expected


def test_logs_made_in_memory_are_numbered_and_a_run_is_named_after_its_log():
    memory = unique_ids([LogId.of("<memory>"), LogId.of("<memory>")])
    assert [(i.stem, i.label, i.name) for i in memory] == [
        ("<memory>", "<memory>", "<memory>"),
        ("<memory>-2", "<memory> (2)", "<memory>"),  # the name in messages stays
    ]
    run = LogId.of("a/mc.csv", "a/mc.csv").run("3")
    assert (run.path, run.name, run.label) == ("a/mc.csv", "a/mc.csv (run 3)", "mc.csv (run 3)")


PARTS = st.sampled_from(["a", "b", "run", "a_run", ".."])


@given(st.lists(st.lists(PARTS, min_size=1, max_size=4), min_size=1, max_size=8))
def test_unique_ids_gives_distinct_stems_keeps_names_and_order(paths):
    ids = [LogId.of("/".join(p) + ".csv", "/".join(p) + ".csv") for p in paths]
    out = unique_ids(ids)
    assert len({i.stem for i in out}) == len(out)
    assert [(i.path, i.name) for i in out] == [(i.path, i.name) for i in ids]
    assert unique_ids(ids) == out  # the same logs, the same names
    alone = {i.stem for i in ids if sum(j.stem == i.stem for j in ids) == 1}
    assert all(o.stem == i.stem for i, o in zip(ids, out) if i.stem in alone)
