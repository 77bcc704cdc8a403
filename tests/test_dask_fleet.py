"""--scheduler: the logs of analyze, evaluate and train on a Dask cluster give the same outputs as
--jobs 1, a worker that dies mid-run never loses a log, and bad uses are one line and exit 2."""

from __future__ import annotations

import json
import os
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

distributed = pytest.importorskip("distributed")

from logscan.errors import UsageError  # noqa: E402
from logscan.fleet import LogFailure, run_many  # noqa: E402

SAMPLES = Path(__file__).resolve().parents[1] / "sample_logs"
ANALYZED = [str(SAMPLES / n) for n in ("quad_healthy.mcap", "quad_imu_bias.mcap", "sbw_healthy.mcap")]


@pytest.fixture(scope="module")
def scheduler():
    """The module's one LocalCluster (2 worker processes). allowed-failures 0: the first death of a
    worker running a task is a KilledWorker for the client, so run_many's resubmission is what the
    killed-worker tests exercise (not the scheduler's own rescheduling)."""
    import cloudpickle
    import dask

    cloudpickle.register_pickle_by_value(sys.modules[__name__])  # the workers cannot import tests/
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
        cluster = distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None, silence_logs=50
        )
    try:
        yield cluster.scheduler_address
    finally:
        cluster.close()


def test_analyze_on_a_local_cluster_writes_the_same_json_as_one_job(cli, tmp_path):
    outputs = {}
    for name, how in (("jobs", ["--jobs", "1"]), ("dask", ["--scheduler", "local:2"])):
        path = tmp_path / f"{name}.json"
        result = cli("analyze", *ANALYZED, "--no-report", "--json", path, *how, "--exit-zero")
        assert result.exit_code == 0, result.output
        outputs[name] = (path.read_bytes(), result.stdout)
    # nothing in the summary depends on how the logs were run (no timing field): byte for byte
    assert outputs["jobs"] == outputs["dask"]
    assert [log["file"] for log in json.loads(outputs["dask"][0])["logs"]] == ANALYZED


def test_evaluate_on_a_cluster_writes_the_same_json_as_one_job(cli, tmp_path, scheduler):
    logs = [*ANALYZED, str(tmp_path / "broken.mcap")]
    Path(logs[-1]).write_bytes(b"not an mcap at all")
    outputs = {}
    for name, how in (("jobs", ["--jobs", "1"]), ("dask", ["--scheduler", scheduler])):
        path = tmp_path / f"{name}.json"
        result = cli("evaluate", *logs, "--json", path, *how)
        assert result.exit_code == 2, result.output  # the file that is no log is an error in either
        outputs[name] = (path.read_bytes(), result.stdout)
    assert outputs["jobs"] == outputs["dask"]
    document = json.loads(outputs["dask"][0])
    assert document["n_logs"] == 3 and document["skipped_no_truth"] == []
    assert [error["file"] for error in document["errors"]] == [logs[-1]], document["errors"]
    assert "named .mcap but not an MCAP file" in document["errors"][0]["error"]


def test_train_prepares_the_logs_on_the_cluster_and_fits_the_same_tables(cli, tmp_path, scheduler):
    logs = [SAMPLES / "jackal_train_1.mcap", SAMPLES / "jackal_train_2.mcap"]
    tables = {}
    modes = (("jobs", ["--jobs", "1"]), ("processes", ["--jobs", "2"]), ("dask", ["--scheduler", scheduler]))
    for name, how in modes:
        path = tmp_path / f"{name}.tables.json"
        result = cli("train", *logs, "-o", path, "--no-report", "-q", *how)
        assert result.exit_code == 0, result.output
        tables[name] = path.read_bytes()
    assert tables["jobs"] == tables["processes"] == tables["dask"]


def test_train_stops_at_a_faulty_log_on_the_cluster_as_in_one_process(cli, tmp_path, scheduler):
    logs = [SAMPLES / "jackal_train_1.mcap", SAMPLES / "jackal_gps_bias.mcap"]
    result = cli("train", *logs, "-o", tmp_path / "t.json", "--no-report", "-q", "--scheduler", scheduler)
    assert result.exit_code == 2 and not (tmp_path / "t.json").exists()
    assert result.stderr.strip().count("\n") == 0 and "jackal_gps_bias.mcap: its ground truth lists" in result.stderr


@dataclass(frozen=True)
class DyingTask:
    """Upper-cases its item; "dies" kills its worker process on its first attempt (a marker file
    says it was tried), "always" on every attempt, "bad" raises."""

    marker_dir: str

    def __call__(self, item: str) -> str:
        marker = Path(self.marker_dir) / f"{item}.tried"
        if item == "always" or (item == "dies" and not marker.exists()):
            marker.write_text("")
            os._exit(1)
        if item == "bad":
            from logscan.errors import InputError

            raise InputError("cannot read", path=item)
        return item.upper()


def test_a_log_whose_worker_dies_is_resubmitted_and_every_result_comes_back(tmp_path, scheduler):
    items = ["a", "dies", "bad", "b"]
    outcomes = run_many(items, DyingTask(str(tmp_path)), scheduler=scheduler)
    assert outcomes[:2] == ["A", "DIES"] and outcomes[3] == "B"
    assert outcomes[2] == LogFailure("bad", "bad: cannot read", 2)  # as the local path makes it
    assert (tmp_path / "dies.tried").exists()


def test_a_log_that_kills_every_worker_becomes_a_failure_saying_so(tmp_path, scheduler):
    # alone: with allowed-failures 0 a task queued on the same worker would die with it (and be resubmitted)
    (failure,) = run_many(["always"], DyingTask(str(tmp_path)), scheduler=scheduler)
    assert isinstance(failure, LogFailure) and failure.exit_code == 3
    assert failure.message.startswith("always: the Dask worker processing it died (3 attempt(s)")
    assert run_many(["a", "b"], DyingTask(str(tmp_path)), scheduler=scheduler) == ["A", "B"]  # workers restarted


def test_without_isolation_the_first_error_in_input_order_propagates(tmp_path, scheduler):
    from logscan.errors import InputError

    with pytest.raises(InputError, match="cannot read"):
        run_many(["a", "bad", "b"], DyingTask(str(tmp_path)), scheduler=scheduler, isolate=False)


def test_scheduler_with_several_jobs_is_exit_2(cli):
    result = cli("analyze", ANALYZED[0], "--no-report", "--scheduler", "local:2", "--jobs", "2")
    assert result.exit_code == 2
    assert result.stderr.strip().count("\n") == 0 and "--scheduler and --jobs 2" in result.stderr


@pytest.mark.parametrize("address", ["local:0", "somewhere"])
def test_a_malformed_address_is_exit_2(cli, address):
    result = cli("evaluate", ANALYZED[0], "--scheduler", address)
    assert result.exit_code == 2 and result.stderr.strip().count("\n") == 0, result.stderr


def test_an_unreachable_scheduler_is_one_line_and_exit_2(cli):
    import dask

    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        result = cli("analyze", ANALYZED[0], "--no-report", "--scheduler", "tcp://127.0.0.1:1")
    assert result.exit_code == 2
    assert result.stderr.strip().count("\n") == 0
    assert "cannot connect to the scheduler" in result.stderr


def test_without_dask_the_option_says_which_extra(cli, monkeypatch):
    import importlib.util

    find_spec = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "distributed" else find_spec(name, *a)
    )
    result = cli("train", ANALYZED[0], "-o", "x.json", "--scheduler", "local:2")
    assert result.exit_code == 2
    assert result.stderr.strip() == "logscan: error: --scheduler needs the dask extra: pip install 'logscan[dask]'"
    with pytest.raises(UsageError):
        run_many(["a"], str.upper, scheduler="local:1")
