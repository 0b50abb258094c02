"""Resumable fan-out: a run killed part-way resumes without redoing finished
units, and a Dask cluster gives the numbers local processes give."""

import functools
import json
import os
import signal
import subprocess
import sys
import time

import pytest
from conftest import make_synthetic_bundle

from bayesgloss import bundle, estimate, runner


@pytest.fixture(scope="module")
def bundles(tmp_path_factory):
    root = tmp_path_factory.mktemp("synthetic")
    return [
        make_synthetic_bundle(root / f"b{i}", specularity=s, seed=i)
        for i, s in enumerate([0.0, 0.5, 1.0, 0.5])
    ]


def _units(bundles):
    return [
        (
            b.name,
            {
                "bundle": str(b.resolve()),
                "illumination": "gensky-clear",
                "noise": "relative",
                "camera": "auto",
                "seed": 3,
                "max_steps": 8000,  # the command line's default with --fixed-brightness
                "bundle_content": bundle.bundle_digest(bundle.read_bundle(b)),
            },
        )
        for b in bundles
    ]


def _object_gamma(folder):
    return json.loads((folder / "summary.json").read_text())["object"]["gamma"]


def test_killed_run_resumes_without_redoing_finished_units(bundles, tmp_path):
    out = tmp_path / "run"
    cmd = [
        sys.executable,
        "-m",
        "bayesgloss.cli",
        "estimate",
        *map(str, bundles),
        "--out",
        str(out),
        "--jobs",
        "1",
        "--quiet",
        "--seed",
        "3",
        "--fixed-brightness",  # the units of _units (the joint model's are minutes each)
    ]
    proc = subprocess.Popen(
        cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True
    )
    deadline = time.time() + 120
    # wait until the first unit is complete, then kill the whole run for real
    while time.time() < deadline:
        done = [p for p in out.glob("*") if not p.name.startswith(".")] if out.exists() else []
        if done:
            break
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)  # the run and its worker processes, as a user's kill
    proc.wait()
    assert proc.returncode == -signal.SIGKILL
    finished = {p.name: p.stat().st_mtime_ns for p in out.glob("*") if not p.name.startswith(".")}
    assert 1 <= len(finished) < len(bundles)
    # the rerun completes, keeping the finished units as they were
    assert subprocess.run(cmd, capture_output=True).returncode == 0
    now = {p.name: p for p in out.glob("*") if not p.name.startswith(".")}
    assert len(now) == len(bundles)
    for name, stamp in finished.items():
        assert now[name].stat().st_mtime_ns == stamp  # not recomputed
    # and the numbers equal an uninterrupted run's
    clean = runner.run_units(estimate.estimate_unit, _units(bundles), tmp_path / "clean", jobs=2)
    for folder in clean:
        assert _object_gamma(now[folder.name]) == _object_gamma(folder)


def test_dask_cluster_gives_the_local_numbers(bundles, tmp_path):
    distributed = pytest.importorskip("distributed")
    units = _units(bundles[:2])
    local = runner.run_units(estimate.estimate_unit, units, tmp_path / "local", jobs=2)
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        remote = runner.run_units(
            estimate.estimate_unit, units, tmp_path / "dask", scheduler=cluster.scheduler_address
        )
    for a, b in zip(local, remote, strict=True):
        assert a.name == b.name
        assert _object_gamma(a) == _object_gamma(b)
        sa = json.loads((a / "summary.json").read_text())
        sb = json.loads((b / "summary.json").read_text())
        assert [f["gamma"] for f in sa["facets"]] == [f["gamma"] for f in sb["facets"]]


def _unit_script(folder):
    """A script that imports a sibling module, as the studies import _common."""
    folder.mkdir()
    (folder / "unit_helper.py").write_text("def double(x):\n    return 2 * x\n")
    (folder / "unit_script.py").write_text(
        "import json\n"
        "import os\n\n"
        "import unit_helper\n\n\n"
        "def unit(x):\n"
        "    return {'out.json': json.dumps([unit_helper.double(x), os.getpid()]).encode()}\n"
    )
    return folder / "unit_script.py"


def test_script_unit_runs_a_script_function_in_worker_processes(tmp_path):
    script = _unit_script(tmp_path / "scripts")
    func = functools.partial(runner.script_unit, str(script), "unit")
    units = [(f"u{x}", {"x": x}) for x in (1, 2, 3)]
    folders = runner.run_units(func, units, tmp_path / "out", jobs=2)
    got = [json.loads((f / "out.json").read_text()) for f in folders]
    assert [v for v, _ in got] == [2, 4, 6]
    assert os.getpid() not in {pid for _, pid in got}  # ran in the workers
    assert "unit_script" not in sys.modules and "unit_helper" not in sys.modules
    # a failing unit raises in the caller and leaves no folder behind
    bad = functools.partial(runner.script_unit, str(script), "no_such_function")
    with pytest.raises(AttributeError, match="no_such_function"):
        runner.run_units(bad, [("bad", {"x": 1})], tmp_path / "bad", jobs=1)
    assert list((tmp_path / "bad").iterdir()) == []


def test_script_unit_on_a_dask_cluster(tmp_path):
    distributed = pytest.importorskip("distributed")
    script = _unit_script(tmp_path / "scripts")
    func = functools.partial(runner.script_unit, str(script), "unit")
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        (folder,) = runner.run_units(
            func, [("u5", {"x": 5})], tmp_path / "out", scheduler=cluster.scheduler_address
        )
    value, pid = json.loads((folder / "out.json").read_text())
    assert value == 10 and pid != os.getpid()


def _alive(pid: int) -> bool:
    """Whether a process exists and is not a zombie (Linux /proc)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(")")[-1].split()[0] != "Z"
    except FileNotFoundError:
        return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_workers_end_when_their_parent_is_killed():
    # a parent with two busy workers is SIGKILLed alone (not its process group):
    # the workers must end within seconds instead of computing on as orphans
    script = (
        "import os, sys, time\n"
        "from bayesgloss.pool import process_pool\n"
        "pool = process_pool(2)\n"
        "pids = set()\n"
        "while len(pids) < 2:\n"
        "    pids |= {f.result() for f in [pool.submit(os.getpid) for _ in range(8)]}\n"
        "for _ in range(2): pool.submit(time.sleep, 120)\n"
        "print(*pids, flush=True)\n"
        "time.sleep(120)\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    with proc.stdout:
        pids = [int(p) for p in proc.stdout.readline().split()]
    assert len(pids) == 2 and all(_alive(p) for p in pids)
    proc.kill()  # the parent only
    proc.wait()
    deadline = time.time() + 20
    while time.time() < deadline and any(_alive(p) for p in pids):
        time.sleep(0.1)
    assert not any(_alive(p) for p in pids)
