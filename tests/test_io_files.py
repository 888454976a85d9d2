"""Files on disk: permissions of written files, and one-line errors for files that are not ours."""

from __future__ import annotations

import os
import stat

import numpy as np
import pytest

import calippso
from calippso import Packing
from calippso.atomic import current_umask, save_npz_atomic
from calippso.result import JammingResult, empty_history


def _packing() -> Packing:
    rng = np.random.default_rng(0)
    return Packing(rng.random((20, 3)) * 6, np.full(20, 0.5), 6.0)


def _result() -> JammingResult:
    packing = _packing()
    return JammingResult(packing=packing, contacts=np.array([[0, 1]]), forces=np.array([1.0]),
                         rattlers=np.zeros(packing.n, dtype=bool), converged=True,
                         status="Converged after 1 LP.", iterations=1, history=empty_history(),
                         wall_time=0.1, force_balance=0.0, dual_normalization=1.0,
                         solver="highs")


@pytest.fixture(params=[0o022, 0o077], ids=["umask022", "umask077"])
def umask(request):
    """Run the test under this umask; the previous one is restored afterwards."""
    previous = os.umask(request.param)
    yield request.param
    os.umask(previous)


def _mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


@pytest.mark.parametrize("suffix", [".npz", ".xyz", ".gsd", ".h5", ".dat"])
def test_written_files_honour_the_umask(tmp_path, umask, suffix):
    if suffix == ".gsd":
        pytest.importorskip("gsd")
    if suffix == ".h5":
        pytest.importorskip("h5py")
    for name, obj in (("packing", _packing()), ("result", _result())):
        path = calippso.write(obj, tmp_path / f"{name}{suffix}")
        assert _mode(path) == 0o666 & ~umask, (name, oct(_mode(path)))


def test_saved_results_and_checkpoints_honour_the_umask(tmp_path, umask):
    result_path = _result().save(tmp_path / "result.npz")
    save_npz_atomic(tmp_path / "state.npz", {"x": np.arange(3)})
    assert _mode(result_path) == _mode(tmp_path / "state.npz") == 0o666 & ~umask


def test_a_rewritten_file_keeps_its_permissions(tmp_path, umask):
    path = tmp_path / "packing.npz"
    calippso.write(_packing(), path)
    os.chmod(path, 0o640)
    calippso.write(_packing(), path)
    assert _mode(path) == 0o640


def test_umask_is_read_without_proc_too(monkeypatch, umask):
    assert current_umask() == umask
    monkeypatch.setattr("calippso.atomic._PROC_STATUS", "/nonexistent/status")
    assert current_umask() == umask
    assert os.umask(umask) == umask  # and left as it was


def _not_npz_files(folder) -> dict[str, str]:
    """Files named .npz that calippso cannot read, with what the error must say about each."""
    (folder / "text.npz").write_text("positions 1 2 3\n")
    (folder / "empty.npz").write_bytes(b"")
    np.save(folder / "array.npy", np.arange(3))
    (folder / "array.npy").rename(folder / "array.npz")
    (folder / "broken.npz").write_bytes(b"PK\x03\x04 truncated")
    np.savez(folder / "objects.npz", positions=np.array([{"a": 1}], dtype=object))
    archive = "not a calippso/numpy .npz archive"
    return {"text.npz": f"{archive} (it is not a zip file)",
            "empty.npz": f"{archive} (it is empty)",
            "array.npz": f"{archive} (it is a single numpy array, a .npy file)",
            "broken.npz": "unreadable .npz file (damaged zip:",
            "objects.npz": "not a calippso .npz file (it holds pickled Python objects"}


@pytest.mark.parametrize("loader", [calippso.read, calippso.load_result,
                                    calippso.io.read_result],
                         ids=["read", "load_result", "read_result"])
def test_a_file_that_is_not_an_npz_archive_is_named_on_one_line(tmp_path, loader):
    for name, why in _not_npz_files(tmp_path).items():
        with pytest.raises(ValueError) as error:
            loader(tmp_path / name)
        message = str(error.value)
        assert message.startswith(f"{tmp_path / name}: {why}")
        assert "\n" not in message and "pickle=" not in message and "unsafely" not in message


def test_cli_names_a_text_file_given_as_npz(tmp_path, capfd):
    from calippso.cli import main

    path = tmp_path / "x.npz"
    path.write_text("not an archive\n")
    for argv in (["jam", path, "-o", tmp_path / "out.npz"], ["report", path, "-o", tmp_path],
                 ["convert", path, tmp_path / "x.xyz"]):
        assert main(list(map(str, argv))) == 1
        err = capfd.readouterr().err
        assert err == (f"error: {path}: not a calippso/numpy .npz archive (it is not a zip "
                       "file)\n")
