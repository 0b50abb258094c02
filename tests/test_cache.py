"""The user's cache of tables (bayesgloss._cache)."""

import numpy as np

from bayesgloss import _cache


def test_cached_array_computes_once_then_reads(tmp_path, monkeypatch):
    monkeypatch.setenv("BAYESGLOSS_CACHE_DIR", str(tmp_path / "c"))
    calls = []

    def compute():
        calls.append(1)
        return np.arange(6, dtype=np.float32).reshape(2, 3)

    a = _cache.cached_array("t-v1", (2, 3), np.float32, compute)
    b = _cache.cached_array("t-v1", (2, 3), np.float32, compute)
    np.testing.assert_array_equal(a, b)
    assert len(calls) == 1
    assert [p.name for p in (tmp_path / "c").iterdir()] == ["t-v1.npy"]  # no temporary left


def test_cached_array_survives_a_bad_file_and_an_unwritable_folder(tmp_path, monkeypatch):
    folder = tmp_path / "c"
    folder.mkdir()
    (folder / "t-v1.npy").write_bytes(b"not a numpy file")
    monkeypatch.setenv("BAYESGLOSS_CACHE_DIR", str(folder))
    out = _cache.cached_array("t-v1", (2,), np.float64, lambda: np.ones(2))
    np.testing.assert_array_equal(out, [1.0, 1.0])
    assert np.load(folder / "t-v1.npy").tolist() == [1.0, 1.0]  # rewritten
    blocker = tmp_path / "file"
    blocker.write_text("")
    monkeypatch.setenv("BAYESGLOSS_CACHE_DIR", str(blocker / "sub"))  # cannot be made
    np.testing.assert_array_equal(_cache.cached_array("t", (1,), float, lambda: np.zeros(1)), [0.0])


def test_cache_turned_off_by_an_empty_setting(monkeypatch):
    monkeypatch.setenv("BAYESGLOSS_CACHE_DIR", "")
    assert _cache.cache_dir() is None
    monkeypatch.delenv("BAYESGLOSS_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", "/x")
    assert str(_cache.cache_dir()) == "/x/bayesgloss"
