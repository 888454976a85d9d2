"""Ensembles: local processes and a real Dask cluster on loopback, resume, failure rows."""

from __future__ import annotations

import concurrent.futures
import csv
import dataclasses
import json
import multiprocessing
import os
import re

import pytest
from click.testing import CliRunner

from calippso import ensemble
from calippso.cli import cli, main

SPEC = {"protocol": "ls", "n": 24, "d": 2, "distribution": "bidisperse"}


@pytest.fixture
def local_threads(monkeypatch):
    """Local workers run as threads instead of spawned processes (a spawned worker starts a
    fresh interpreter, ~2 s), for the tests whose point is not the processes."""
    def threads(max_workers, mp_context=None, initializer=None, initargs=()):
        return concurrent.futures.ThreadPoolExecutor(max_workers)  # no thread limits here

    monkeypatch.setattr(concurrent.futures, "ProcessPoolExecutor", threads)


def _table(out_dir):
    with open(out_dir / ensemble.SUMMARY, newline="") as stream:
        return list(csv.DictReader(stream))


def test_local_processes_write_resume_and_record_failures(tmp_path):
    # A folder where packing 2 should go makes its atomic write fail: that packing is
    # recorded as failed, the others finish.
    ensemble.packing_file(tmp_path, 2).mkdir(parents=True)
    rows = ensemble.run(SPEC, 3, seeds=[1, 2, 3], out_dir=tmp_path, workers=2)
    assert [row["state"] for row in rows] == ["done", "failed", "done"]
    assert "IsADirectoryError" in rows[1]["error"]
    assert (tmp_path / "packing_000002.error.txt").read_text().startswith("Traceback")
    table = _table(tmp_path)
    assert [row["seed"] for row in table] == ["1", "2", "3"]
    assert table[0]["isostatic"] == "True" and float(table[0]["phi"]) > 0.8
    assert not list(tmp_path.glob(".*.tmp"))  # no temporary file left behind
    assert not (tmp_path / "state_000001_jam.npz").exists()  # removed once written
    assert (tmp_path / "state_000002_jam.npz").exists()  # kept: packing 2 was not written

    # Resuming is the client's work (which packings to skip, which to compute): threads
    # compute here, where fresh worker processes would only add their imports.
    finished = ensemble.packing_file(tmp_path, 1).stat().st_mtime_ns
    ensemble.packing_file(tmp_path, 2).rmdir()
    with concurrent.futures.ThreadPoolExecutor(2) as threads:
        rows = ensemble.run(SPEC, 4, seeds=1, out_dir=tmp_path, executor=threads)
    assert [row["state"] for row in rows] == ["done"] * 4
    assert ensemble.packing_file(tmp_path, 1).stat().st_mtime_ns == finished  # skipped
    assert not (tmp_path / "packing_000002.error.txt").exists()
    assert not list(tmp_path.glob("state_*"))
    assert len(_table(tmp_path)) == 4


def test_dask_workers_only_compute_and_the_client_writes(tmp_path, monkeypatch):
    # Workers in another working directory, as on a cluster without a shared disk: with a
    # relative out_dir, every file must land in the client's folder, none in the worker's.
    distributed = pytest.importorskip("distributed")
    client_dir, worker_dir = tmp_path / "client", tmp_path / "worker"
    client_dir.mkdir()
    worker_dir.mkdir()
    monkeypatch.chdir(client_dir)
    with distributed.LocalCluster(
        n_workers=1,
        threads_per_worker=1,
        processes=True,
        protocol="tcp://",
        host="127.0.0.1",
        dashboard_address=None,
        local_directory=str(tmp_path / "scratch"),
    ) as cluster:
        with distributed.Client(cluster) as client:
            client.run(os.chdir, str(worker_dir))
            assert list(client.run(os.getcwd).values()) == [str(worker_dir)]
            rows = ensemble.run(SPEC, 2, seeds=5, out_dir="ens", executor=client)
            assert [row["state"] for row in rows] == ["done", "done"]
            # The CLI's --scheduler path, on the same cluster: one new packing, two resumed.
            result = CliRunner().invoke(
                cli,
                [
                    "ensemble", "--n", "24", "--d", "2", "--distribution", "bidisperse",
                    "--seed", "5", "--packings", "3", "-o", "ens",
                    "--scheduler", cluster.scheduler_address, "--quiet",
                ],
            )
    assert result.exit_code == 0, result.output
    assert "3 of 3 packings done" in result.output
    assert [row["state"] for row in _table(client_dir / "ens")] == ["done"] * 3
    assert sorted(p.name for p in (client_dir / "ens").glob("packing_*")) == [
        "packing_000005.npz", "packing_000006.npz", "packing_000007.npz"
    ]
    assert list(worker_dir.iterdir()) == []


def test_unreachable_scheduler_is_named(tmp_path):
    pytest.importorskip("distributed")
    with pytest.raises(ValueError, match="cannot reach the Dask scheduler at tcp://127.0.0.1:1"):
        ensemble.run_on_scheduler(SPEC, 1, address="tcp://127.0.0.1:1", out_dir=tmp_path, timeout=1)


def test_cli_json_summary_and_spec_checks(tmp_path, capfd, local_threads):
    code = main(
        [
            "ensemble",
            "--protocol",
            "poisson",
            "--n",
            "16",
            "--d",
            "2",
            "--packings",
            "1",
            "--workers",
            "1",
            "-o",
            str(tmp_path),
            "--json",
            "--quiet",
        ]
    )
    record = json.loads(capfd.readouterr().out)
    assert code == 0 and record["failed"] == 0 and record["rows"][0]["converged"]
    with pytest.raises(ValueError, match="protocol"):
        ensemble.EnsembleSpec(protocol="magic")
    with pytest.raises(ValueError, match="final_growth_rate must be > 0"):
        ensemble.EnsembleSpec(final_growth_rate=0.0)
    with pytest.raises(ValueError, match="unknown ensemble spec keys"):
        ensemble.run({"nn": 3}, 1, out_dir=tmp_path)
    with pytest.raises(ValueError, match="2 seeds for 3 packings"):
        ensemble.run(SPEC, 3, seeds=[1, 2], out_dir=tmp_path)


def test_folder_remembers_its_spec_and_refuses_another(tmp_path):
    threads = concurrent.futures.ThreadPoolExecutor(1)
    previous = os.umask(0o027)
    try:
        ensemble.run(SPEC, 1, seeds=1, out_dir=tmp_path, executor=threads)
    finally:
        os.umask(previous)
    manifest = tmp_path / ensemble.MANIFEST
    assert json.loads(manifest.read_text()) == dataclasses.asdict(ensemble.EnsembleSpec(**SPEC))
    assert manifest.stat().st_mode & 0o777 == 0o640  # the umask, not mkstemp's 0o600
    refusal = (
        f"{tmp_path} holds an ensemble with other parameters "
        "(n 24 → 32, distribution 'bidisperse' → 'monodisperse'): "
        "rerun with those or choose another folder"
    )
    with pytest.raises(ValueError, match=f"^{re.escape(refusal)}$"):
        ensemble.run({"n": 32, "d": 2}, 2, seeds=1, out_dir=tmp_path, executor=threads)
    assert len(_table(tmp_path)) == 1  # nothing was run or rewritten

    rows = ensemble.run(SPEC, 2, seeds=1, out_dir=tmp_path, executor=threads)  # extend
    assert [row["state"] for row in rows] == ["done", "done"]

    manifest.unlink()  # a folder written before manifests: n and d come from its packings
    with pytest.raises(ValueError, match=r"\(n 24 → 32\)"):
        ensemble.run({**SPEC, "n": 32}, 2, seeds=1, out_dir=tmp_path, executor=threads)
    threads.shutdown()


@pytest.mark.slow
def test_cli_refuses_a_rerun_with_other_parameters(tmp_path, capfd, local_threads):
    folder = tmp_path / "ens"
    args = ["ensemble", "--protocol", "poisson", "--n", "16", "--d", "2", "--workers", "1",
            "-o", str(folder), "--quiet"]
    runner = CliRunner()
    first = runner.invoke(cli, [*args, "--packings", "1"])
    assert first.exit_code == 0 and "1 of 1 packings done" in first.output
    more = runner.invoke(cli, [*args, "--packings", "2"])  # same spec: resume and extend
    assert more.exit_code == 0 and "2 of 2 packings done" in more.output

    changed = runner.invoke(cli, [*args, "--packings", "2", "--n", "20"])
    assert changed.exit_code != 0
    assert str(changed.exception) == (
        f"{folder} holds an ensemble with other parameters (n 16 → 20): "
        "rerun with those or choose another folder"
    )
    capfd.readouterr()
    assert main([*args, "--packings", "2", "--n", "20"]) == 1  # the command's own error line
    assert capfd.readouterr().err == f"error: {changed.exception}\n"
    assert len(_table(folder)) == 2


def _worker_threads() -> tuple[int, list[int]]:
    """Numba's threads and the BLAS / OpenMP pools' threads of this process."""
    import numba
    from threadpoolctl import threadpool_info

    return numba.get_num_threads(), [pool["num_threads"] for pool in threadpool_info()]


def test_pool_workers_share_out_the_cores():
    """Each worker of the local pool computes on its share of the cores (oversubscribed
    threads spin-wait on each other's parallel regions)."""
    assert ensemble.threads_per_worker(1) == (os.cpu_count() or 1)
    assert ensemble.threads_per_worker(4 * (os.cpu_count() or 1)) == 1
    with concurrent.futures.ProcessPoolExecutor(
            1, mp_context=multiprocessing.get_context("spawn"),
            initializer=ensemble.limit_threads, initargs=(1,)) as pool:
        numba_threads, pools = pool.submit(_worker_threads).result()
    assert numba_threads == 1
    assert pools and set(pools) == {1}
