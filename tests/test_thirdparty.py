"""Tests of bayesgloss._thirdparty: ArviZ imports quietly whatever the cache."""

import os
import subprocess
import sys

_IMPORT = "from bayesgloss._thirdparty import arviz; az = arviz(); print(az.__version__)"


def _run_with_cache(code, cache):
    env = {**os.environ, "XDG_CACHE_HOME": str(cache)}
    env.pop("PYTHONWARNINGS", None)
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)


def test_arviz_imports_when_its_daily_stamp_cannot_be_written(tmp_path):
    # a cache "folder" that is a file: ArviZ's own import fails making its stamp
    # folder there (the same OSError path as two workers racing on the stamp's
    # temporary file, which stopped stop 43's CI); ours must still import it,
    # print no notice, and leave the user's environment as it was
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("")
    plain = _run_with_cache(_IMPORT, blocker)
    direct = _run_with_cache("import arviz", blocker)
    assert direct.returncode != 0  # the failure is real without the retry
    assert plain.returncode == 0, plain.stderr
    assert plain.stdout.strip().startswith("0.")
    # (matplotlib, imported by ArviZ, says on stderr that it cannot use this
    # cache either; that line is matplotlib's and is left alone)
    assert "Traceback" not in plain.stderr
    assert "refactor" not in plain.stderr


def test_arviz_import_prints_no_refactor_notice_on_a_fresh_cache(tmp_path):
    proc = _run_with_cache(_IMPORT, tmp_path / "cache")
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""
    assert (tmp_path / "cache" / "arviz" / "daily_warning").exists()
