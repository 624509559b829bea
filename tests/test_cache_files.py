"""Content-checked cache files (meshes.cachefiles): every way of spoiling a file is caught before it is parsed."""
import hashlib
import logging

import numpy as np
import pytest

from cache_spoils import NPZ_SPOILS, assert_refused, spoil

from meshes import cachefiles
from meshes.cachefiles import checked, content_problem, find_cached, sidecar, write_checked


def _arrays(path):
    np.savez(path, data=np.linspace(0.0, 1.0, 1000), names=np.array(["X", "Y", "Z"]))


@pytest.fixture
def user_cache(tmp_path, monkeypatch):
    folder = tmp_path / "user"
    folder.mkdir()
    monkeypatch.setenv("THERMAL_TWIN_CACHE", str(folder))
    monkeypatch.setattr(cachefiles, "SHIPPED_CACHE", tmp_path / "shipped")
    (tmp_path / "shipped").mkdir()
    return folder


def test_written_file_has_a_sha256sum_sidecar_and_no_leftovers(tmp_path):
    path = write_checked(tmp_path / "op.npz", _arrays)
    line = sidecar(path).read_text()
    assert line == f"{hashlib.sha256(path.read_bytes()).hexdigest()}  op.npz\n"   # `sha256sum -c` format
    assert sorted(p.name for p in tmp_path.iterdir()) == ["op.npz", "op.npz.sha256"]
    assert content_problem(path) is None and checked(path) == path


@pytest.mark.parametrize("how", NPZ_SPOILS)
def test_spoiled_user_cache_file_is_named_removed_and_not_used(user_cache, caplog, how):
    path = write_checked(user_cache / "op.npz", _arrays)
    spoil(path, how)
    with caplog.at_level(logging.WARNING, logger="thermal_twin"):
        assert find_cached("op.npz") is None                 # the caller builds it again
    assert not path.exists() and not sidecar(path).exists()
    assert str(path) in caplog.text and "corrupt" in caplog.text


@pytest.mark.parametrize("how", NPZ_SPOILS)
def test_spoiled_shipped_file_stops_with_one_line_naming_it(user_cache, how):
    path = write_checked(cachefiles.SHIPPED_CACHE / "op.npz", _arrays)
    (user_cache / "op.npz").write_bytes(b"never looked at")   # the shipped copy is not replaced silently
    spoil(path, how)
    assert_refused(path, lambda: find_cached("op.npz"))
    assert path.exists()                                         # a shipped file is never deleted


def test_a_good_file_is_found_and_a_missing_one_is_none(user_cache):
    (user_cache / "sub").mkdir(parents=True)
    write_checked(user_cache / "sub" / "rec.npz", _arrays)
    assert find_cached("sub/rec.npz") == user_cache / "sub" / "rec.npz"
    assert find_cached("absent.npz") is None


def test_a_failing_writer_leaves_nothing_behind(tmp_path):
    def broken(tmp):
        tmp.write_bytes(b"half")
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        write_checked(tmp_path / "op.npz", broken)
    assert list(tmp_path.iterdir()) == []
