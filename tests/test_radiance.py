"""Driving Radiance: scratch folders of killed renders are cleaned up."""

import os
import subprocess
import sys

from bayesgloss import radiance


def _dead_pid() -> int:
    """The id of a process that has ended (a child run and reaped)."""
    proc = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True
    )
    return int(proc.stdout)


def test_orphan_scratch_folders_of_dead_processes_are_removed(tmp_path):
    # a render killed with SIGKILL leaves its octree folder behind (issue 17);
    # the next one removes it, and only it
    dead = tmp_path / f"bayesgloss-frame-{_dead_pid()}-abc123"
    alive = tmp_path / f"bayesgloss-frame-{os.getpid()}-def456"
    other = tmp_path / "bayesgloss-cie-general-0123abcd.cal"
    mine = tmp_path / "someone-elses-folder-1-x"
    for folder in (dead, alive, mine):
        folder.mkdir()
        (folder / "frame.oct").write_bytes(b"octree")
    other.write_text("a cached file")
    assert radiance.remove_orphan_scratch(tmp_path) == [dead]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        p.name for p in (alive, other, mine)
    )


def test_scratch_folder_names_its_process_and_goes_away(tmp_path, monkeypatch):
    monkeypatch.setattr(radiance.tempfile, "tempdir", str(tmp_path))
    with radiance.scratch_folder("frame") as tmp:
        assert os.path.basename(tmp).startswith(f"bayesgloss-frame-{os.getpid()}-")
        assert os.path.isdir(tmp)
    assert not os.path.exists(tmp)


def test_a_killed_render_leaves_nothing_for_long(tmp_path):
    # kill -9 a process inside scratch_folder: its folder survives it, and the
    # next scratch_folder removes it
    env = {**os.environ, "TMPDIR": str(tmp_path)}
    code = (
        "import os, signal\n"
        "from bayesgloss import radiance\n"
        "with radiance.scratch_folder('frame') as tmp:\n"
        "    open(os.path.join(tmp, 'frame.oct'), 'wb').write(b'x' * 1000)\n"
        "    os.kill(os.getpid(), signal.SIGKILL)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], env=env)
    assert proc.returncode == -9
    assert [p.name.split("-")[1] for p in tmp_path.iterdir()] == ["frame"]
    code = "from bayesgloss import radiance\nwith radiance.scratch_folder('rad'): pass\n"
    subprocess.run([sys.executable, "-c", code], env=env, check=True)
    assert list(tmp_path.iterdir()) == []
