"""Ensembles: local processes and a real Dask cluster on loopback, resume, failure rows."""

from __future__ import annotations

import csv
import json

import pytest

from calippso import ensemble
from calippso.cli import main

SPEC = {"protocol": "ls", "n": 24, "d": 2, "distribution": "bidisperse"}


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

    finished = ensemble.packing_file(tmp_path, 1).stat().st_mtime_ns
    ensemble.packing_file(tmp_path, 2).rmdir()
    rows = ensemble.run(SPEC, 4, seeds=1, out_dir=tmp_path, workers=2)
    assert [row["state"] for row in rows] == ["done"] * 4
    assert ensemble.packing_file(tmp_path, 1).stat().st_mtime_ns == finished  # skipped
    assert not (tmp_path / "packing_000002.error.txt").exists()
    assert not list(tmp_path.glob("state_*"))
    assert len(_table(tmp_path)) == 4


def test_dask_local_cluster(tmp_path):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(
        n_workers=1,
        threads_per_worker=2,
        processes=False,
        protocol="tcp://",
        host="127.0.0.1",
        dashboard_address=None,
    ) as cluster:
        with distributed.Client(cluster) as client:
            rows = ensemble.run(SPEC, 2, seeds=5, out_dir=tmp_path, executor=client)
        assert [row["state"] for row in rows] == ["done", "done"]
        # The CLI's --scheduler path, on the same cluster: one new packing, two resumed.
        code = main(
            [
                "ensemble",
                "--n",
                "24",
                "--d",
                "2",
                "--distribution",
                "bidisperse",
                "--seed",
                "5",
                "--packings",
                "3",
                "-o",
                str(tmp_path),
                "--scheduler",
                cluster.scheduler_address,
                "--quiet",
            ]
        )
    assert code == 0
    assert [row["state"] for row in _table(tmp_path)] == ["done"] * 3


def test_unreachable_scheduler_is_named(tmp_path):
    pytest.importorskip("distributed")
    with pytest.raises(ValueError, match="cannot reach the Dask scheduler at tcp://127.0.0.1:1"):
        ensemble.run_on_scheduler(SPEC, 1, address="tcp://127.0.0.1:1", out_dir=tmp_path, timeout=1)


def test_cli_json_summary_and_spec_checks(tmp_path, capfd):
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


def test_ls_starts_with_a_slow_end_jam_in_a_few_lps(tmp_path):
    spec = {"protocol": "ls", "n": 128, "d": 3, "pressure": 1e6, "final_growth_rate": 1e-3}
    rows = ensemble.run(spec, 1, seeds=[2], out_dir=tmp_path, workers=1)
    assert rows[0]["state"] == "done"
    row = _table(tmp_path)[0]
    assert row["isostatic"] == "True" and int(row["iterations"]) <= 5
