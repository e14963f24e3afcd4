"""Dask distributed (issue 13): the real engine on a LocalCluster of worker processes on
the loopback interface. Outputs must equal the local run byte for byte."""

from __future__ import annotations

import json
import os
import signal
import threading
import time

import pytest

distributed = pytest.importorskip("distributed")

from helpers import ROOT, error_line, run  # noqa: E402

from credcli.io.schema import LogReading  # noqa: E402
from credcli.report.render import OutputFormat, to_text  # noqa: E402
from credcli.requests import DiagnoseRequest, SimulateRequest  # noqa: E402
from credcli.schedule.cluster import DaskRunner  # noqa: E402
from credcli.studies.samples import GOOD_SEGMENTS, estimator_log  # noqa: E402
from credcli.workflows import run_diagnose, run_simulate  # noqa: E402


def _logs(tmp_path, count: int, per_segment: int = 300):
    paths = []
    for k in range(count):
        path = tmp_path / f"log{k}.csv"
        estimator_log(GOOD_SEGMENTS * 2, epochs_per_segment=per_segment, seed=k).to_csv(
            path, index=False
        )
        paths.append(path)
    return paths


def _document(run) -> str:
    """The report's JSON document as the renderer writes it (its segments are Records, made
    as they are written), keys sorted."""
    return json.dumps(json.loads(to_text(run.report, OutputFormat.JSON)), sort_keys=True)


@pytest.fixture(scope="module")
def runner():
    with DaskRunner("local:2") as r:
        yield r


def test_diagnose_on_the_cluster_equals_the_local_run(tmp_path, runner):
    paths = _logs(tmp_path, 3)
    request = DiagnoseRequest(tuple(paths), LogReading(window="10s"))
    local = run_diagnose(request)
    remote = run_diagnose(request, runner=runner)
    assert _document(remote) == _document(local)
    assert len(remote.results) == 3 * 37  # 36 windows of 10 s and the run, per log


def test_logs_with_one_stem_get_the_local_ids_on_the_cluster(tmp_path, runner):
    """The client makes the logs' ids unique (issue 34) and the workers tie their results
    to those ids: the cluster groups and names the logs as the local run does."""
    paths = _logs(tmp_path, 2, per_segment=40)
    for path, part in zip(paths, "ab"):
        (tmp_path / part).mkdir()
        path.rename(tmp_path / part / "run.csv")
    request = DiagnoseRequest(tuple(str(tmp_path / part / "run.csv") for part in "ab"))
    local = run_diagnose(request)
    remote = run_diagnose(request, runner=runner)
    assert [r.log for r in remote.results] == [r.log for r in local.results]
    assert [r.log.stem for r in local.results[:: len(local.results) // 2]] == ["a_run", "b_run"]
    assert _document(remote) == _document(local)


def test_a_sweep_on_the_cluster_equals_the_local_run(runner):
    from credcli.studies.settings import SimulationConfig

    config = SimulationConfig(trials=12)
    request = SimulateRequest(config, sweep="ar=0,0.5")
    local, _ = run_simulate(request)
    remote, _ = run_simulate(request, runner=runner)
    assert _document(remote) == _document(local)


def test_the_command_line_with_local_workers(tmp_path):
    log = ROOT / "sample_data" / "estimator_log.csv"
    here = run("diagnose", log, "-f", "json")
    there = run("diagnose", log, "-f", "json", "--scheduler", "local:1")
    assert there[0] == 0 and there[1] == here[1]


def test_bad_input_on_the_cluster_is_the_local_error(tmp_path, runner):
    bad = tmp_path / "bad.csv"
    bad.write_text("time,truth_0,est_0,var_0\n0,1,x,1\n")
    local = error_line(*run("diagnose", bad)[::2])
    remote = error_line(*run("diagnose", bad, "--scheduler", "local:1")[::2])
    assert remote == local


def test_unreachable_scheduler_and_bad_address(monkeypatch):
    import credcli.schedule.cluster

    monkeypatch.setattr(credcli.schedule.cluster, "CONNECT_TIMEOUT", "0.5s")
    line = error_line(
        *run(
            "diagnose",
            ROOT / "sample_data" / "estimator_log.csv",
            "--scheduler",
            "tcp://127.0.0.1:9",
        )[::2]
    )
    assert "cannot connect" in line and "dask scheduler" in line
    line = error_line(*run("simulate", "--scheduler", "local:two")[::2])
    assert "expected local:N" in line
    # localhost:PORT is an address to connect to, not a malformed local:N
    line = error_line(*run("simulate", "--scheduler", "localhost:9")[::2])
    assert "cannot connect" in line


def test_a_worker_killed_mid_run_leaves_the_result_complete_and_identical(tmp_path):
    paths = _logs(tmp_path, 3, per_segment=600)
    local = run_diagnose(DiagnoseRequest(tuple(paths), LogReading(window="10s")))
    with DaskRunner("local:2") as r:
        pids = r.client.run(os.getpid)
        out = {}
        worker = threading.Thread(
            target=lambda: out.setdefault(
                "run",
                run_diagnose(DiagnoseRequest(tuple(paths), LogReading(window="10s")), runner=r),
            )
        )
        worker.start()
        deadline = time.time() + 20
        while time.time() < deadline and not any(r.client.processing().values()):
            time.sleep(0.01)
        busy = [w for w, tasks in r.client.processing().items() if tasks]
        assert busy, "no task was running: nothing to kill"
        os.kill(pids[busy[0]], signal.SIGKILL)
        worker.join(60)
    assert _document(out["run"]) == _document(local)


def test_without_a_scheduler_nothing_of_dask_is_imported():
    import subprocess
    import sys

    code = (
        "import sys; from credcli.cli import main; "
        f"main(['diagnose', {str(ROOT / 'sample_data' / 'estimator_log.csv')!r}, '-f', 'json', '-o', '/dev/null']); "
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('dask', 'distributed')))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip().endswith("[]")


def test_missing_dask_is_a_clear_error(monkeypatch):
    import builtins

    real = builtins.__import__

    def no_dask(name, *a, **k):
        if name.split(".")[0] in ("dask", "distributed"):
            raise ImportError(name)
        return real(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", no_dask)
    line = error_line(*run("simulate", "--scheduler", "local:1")[::2])
    assert "credcli[dask]" in line


def test_workers_read_fsspec_urls(tmp_path, runner):
    from credcli.io.logs import as_url

    assert as_url("s3:/bucket/a.parquet") == "s3://bucket/a.parquet"  # after pathlib
    assert as_url("file:/tmp/a.csv") == "file:///tmp/a.csv"
    assert as_url("/tmp/a.csv") is None and as_url("C:/logs/a.csv") is None
    path = _logs(tmp_path, 1)[0]
    url = f"memory://credcli-test/{path.name}"
    import fsspec

    with fsspec.open(url, "wb") as fh:  # the client's memory filesystem: local run only
        fh.write(path.read_bytes())
    local = run_diagnose(DiagnoseRequest((url,)))
    assert str(local.results[0].log) == url
    file_url = f"file://{path}"
    here = run_diagnose(DiagnoseRequest((file_url,)))
    there = run_diagnose(DiagnoseRequest((file_url,)), runner=runner)
    assert _document(there) == _document(here)
    assert _document(here).replace(file_url, url) == _document(local)


def _certificates(directory) -> dict[str, str]:
    """A certificate authority and one certificate it signed for 127.0.0.1 (openssl)."""
    import shutil
    import subprocess

    if shutil.which("openssl") is None:
        pytest.skip("openssl is not installed")

    def openssl(*args):
        subprocess.run(["openssl", *args], cwd=directory, check=True, capture_output=True)

    key = ("-newkey", "rsa:2048", "-nodes")
    openssl("req", "-x509", *key, "-keyout", "ca.key", "-out", "ca.pem", "-subj", "/CN=test-ca")
    openssl("req", *key, "-keyout", "node.key", "-out", "node.csr", "-subj", "/CN=127.0.0.1")
    (directory / "san.cnf").write_text("subjectAltName=IP:127.0.0.1\n")
    sign = ("-CA", "ca.pem", "-CAkey", "ca.key", "-CAcreateserial", "-extfile", "san.cnf")
    openssl("x509", "-req", "-in", "node.csr", *sign, "-out", "node.pem", "-days", "1")
    return {name: str(directory / name) for name in ("ca.pem", "node.pem", "node.key")}


def test_a_tls_cluster_end_to_end(tmp_path):
    """Issue 32 item 1: a tls:// scheduler on loopback with generated certificates gives the
    local run's document; without this client's certificates it is one line, exit 2."""
    import dask
    from distributed import LocalCluster
    from distributed.security import Security

    from credcli.errors import CredcliError

    certs = _certificates(tmp_path)
    node = {"cert": certs["node.pem"], "key": certs["node.key"]}
    security = Security(
        tls_ca_file=certs["ca.pem"],
        require_encryption=True,
        **{
            f"tls_{role}_{part}": path
            for role in ("client", "scheduler", "worker")
            for part, path in node.items()
        },
    )
    request = DiagnoseRequest((ROOT / "sample_data" / "estimator_log.csv",), LogReading())
    with LocalCluster(
        n_workers=1,
        threads_per_worker=1,
        processes=False,  # the comms are TLS sockets all the same; a worker starts at once
        protocol="tls",
        host="127.0.0.1",
        security=security,
        dashboard_address=None,
    ) as cluster:
        address = cluster.scheduler_address
        assert address.startswith("tls://127.0.0.1:")
        tls = "distributed.comm.tls."
        client = {f"{tls}client.{part}": path for part, path in node.items()}
        with dask.config.set({f"{tls}ca-file": certs["ca.pem"], **client}):
            runner = DaskRunner(address)
        with runner:
            remote = run_diagnose(request, runner=runner)
        assert _document(remote) == _document(run_diagnose(request))
        with dask.config.set({f"{tls}ca-file": None, f"{tls}client.cert": None}):
            with pytest.raises(CredcliError, match="tls:// needs this client's certificates"):
                DaskRunner(address)
