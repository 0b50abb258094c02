"""The README's main job: `bayesgloss demo` end to end."""

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from bayesgloss import cli


@pytest.mark.long
@pytest.mark.radiance
def test_demo_runs_the_main_job(tmp_path, capsys):
    # renders the built-in default sequence with Radiance, runs the baseline and
    # the posterior and writes the report: the README's first command
    assert cli.main(["demo", "--out", str(tmp_path), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "object gloss: posterior" in out and "baseline" in out
    summary = json.loads((tmp_path / "summary.json").read_text())
    g = summary["object"]["gamma"]
    # plastic of specularity 0.5 and grey 0.5: gamma 2/3 at normal view, more with
    # Radiance's Fresnel raise at oblique views; the baseline reads far lower
    assert 0.6 < g["median"] < 0.75
    assert summary["baseline"]["object"]["gamma"] < g["median"]
    assert (tmp_path / "report.png").stat().st_size > 50_000
    assert (tmp_path / "posterior.nc").exists()


def test_unknown_command_and_bad_bundle(tmp_path, capsys):
    with pytest.raises(SystemExit):
        cli.main(["frobnicate"])
    assert cli.main(["baseline", str(tmp_path / "missing")]) == 2
    err = capsys.readouterr().err
    assert "bayesgloss baseline: error:" in err and "Traceback" not in err


def test_report_of_a_saved_estimate(saved_result, tmp_path, capsys):
    # estimate --out writes what report reads; the report names its PNG
    out = tmp_path / "est"
    shutil.copytree(saved_result, out)
    assert cli.main(["report", str(out)]) == 0
    assert capsys.readouterr().out.strip().endswith("report.png")
    assert (out / "report.png").stat().st_size > 50_000
    assert cli.main(["report", str(tmp_path / "nothing")]) == 2
    assert "no summary.json" in capsys.readouterr().err


# -- what a newcomer trips on ---------------------------------------------------

ROOT = Path(__file__).resolve().parents[1]


def _edited_bundle(src: Path, dst: Path, edit) -> Path:
    """A copy of bundle ``src`` with its manifest changed by ``edit(manifest)``."""
    shutil.copytree(src, dst)
    manifest = json.loads((dst / "sequence.json").read_text())
    edit(manifest)
    (dst / "sequence.json").write_text(json.dumps(manifest))
    return dst


@pytest.fixture(scope="module")
def odd_bundles(tmp_path_factory):
    """A synthetic bundle, the same at night (every frame between 00:00 and
    03:00 UTC at longitude 0 in June), and the same with one frame."""
    from conftest import make_synthetic_bundle

    root = tmp_path_factory.mktemp("odd")
    day = make_synthetic_bundle(root / "day", specularity=0.5)

    def night(m):
        for i, f in enumerate(m["frames"]):
            f["time"] = f"1996-06-21T{i // 7:02d}:{(i % 7) * 8:02d}:00+00:00"

    def one_frame(m):
        m["frames"] = m["frames"][9:10]

    return {
        "day": day,
        "night": _edited_bundle(day, root / "night", night),
        "one": _edited_bundle(day, root / "one", one_frame),
    }


@pytest.mark.parametrize("kind", ["night", "one"])
@pytest.mark.parametrize("command", ["estimate", "compare", "baseline"])
def test_no_usable_data_is_one_clear_error(odd_bundles, kind, command, capsys):
    # today's numpy words ("need at least one array to concatenate", "cannot
    # reshape array of size 0") become what is wrong, with exit 2
    assert cli.main([command, str(odd_bundles[kind])]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err, err
    assert err.startswith(f"bayesgloss {command}: error: bundle '{odd_bundles[kind]}'"), err
    assert "no facet has enough usable frames" in err, err
    up = "0 of 19 frames have the sun up" if kind == "night" else "1 of 1 frames have the sun up"
    assert up in err, err


def test_report_of_a_result_without_facets(odd_bundles, tmp_path, capsys):
    # a summary with no facet posterior (hand-made, or from an older run) is
    # refused in one line rather than failing inside the figure code
    res = tmp_path / "empty"
    res.mkdir()
    (res / "summary.json").write_text(json.dumps({"facets": [], "bundle": "x"}))
    (res / "posterior.nc").write_bytes(b"")
    assert cli.main(["report", str(res)]) == 2
    err = capsys.readouterr().err
    assert "holds no facet posterior" in err and "Traceback" not in err


def test_max_steps_bounds_every_facet(odd_bundles, capsys):
    # --max-steps reaches the sampler: no facet runs more production steps (the
    # first convergence check alone comes at 250 steps, so a run that ignored
    # the option would report a median of at least 250)
    day = str(odd_bundles["day"])
    assert (
        cli.main(
            [
                "estimate",
                day,
                "--quiet",
                "--json",
                "--max-steps",
                "100",
                "--jobs",
                "1",
                "--fixed-brightness",
            ]
        )
        == 0
    )
    summary = json.loads(capsys.readouterr().out)
    assert summary["sampler"]["median_steps"] == 100


@pytest.mark.long
def test_commands_print_no_third_party_warning(odd_bundles, tmp_path):
    # run as a user does, in a fresh interpreter with Python's default warning
    # filters and an empty cache folder (so ArviZ's once-a-day refactor notice
    # would fire): stderr holds progress and our own lines only
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path / "cache")}
    env.pop("PYTHONWARNINGS", None)
    out = tmp_path / "est"
    runs = [
        ["estimate", str(odd_bundles["day"]), "--out", str(out), "--max-steps", "200"],
        ["report", str(out)],
    ]
    for args in runs:
        proc = subprocess.run(
            [sys.executable, "-m", "bayesgloss.cli", *args], capture_output=True, text=True, env=env
        )
        assert proc.returncode == 0, proc.stderr
        assert "Warning" not in proc.stderr and "warn" not in proc.stderr.lower(), proc.stderr
    # the notice is really there to be hidden: a bare import shows it (in another
    # cache folder: ArviZ stamps the day even when its notice is filtered)
    env["XDG_CACHE_HOME"] = str(tmp_path / "other-cache")
    proc = subprocess.run(
        [sys.executable, "-c", "import arviz"], capture_output=True, text=True, env=env
    )
    assert "FutureWarning" in proc.stderr


def _readme_commands() -> list[str]:
    """The commands of the README's command table."""
    text = (ROOT / "README.md").read_text()
    return sorted(set(re.findall(r"^\| `bayesgloss (\w+)", text, flags=re.M)))


def test_readme_command_table_is_the_command_line(capsys):
    # every command in the README's table exists and its --help runs; every
    # command of the parser is in the table
    listed = _readme_commands()
    parser_commands = set(cli._parser()._subparsers._group_actions[0].choices)
    assert set(listed) == parser_commands, (listed, parser_commands)
    for command in listed:
        with pytest.raises(SystemExit) as stop:
            cli.main([command, "--help"])
        assert stop.value.code == 0
        assert f"usage: bayesgloss {command}" in capsys.readouterr().out


def test_readme_documents_every_estimate_option():
    # a newcomer reads estimate's options in one table: each option of the
    # parser is named in the README's section on them
    text = (ROOT / "README.md").read_text()
    section = text.split("### What `estimate` fits, and its options", 1)[1].split("\n## ", 1)[0]
    estimate = cli._parser()._subparsers._group_actions[0].choices["estimate"]
    options = [a.option_strings[0] for a in estimate._actions if a.option_strings]
    missing = [o for o in options if o != "-h" and f"`{o}" not in section]
    assert not missing, missing


# -- result folders: checked first, written as one set, read back checked ---------


@pytest.mark.parametrize("where", ["a file", "under a file", "read-only"])
def test_bad_out_is_said_before_any_work(odd_bundles, tmp_path, monkeypatch, capsys, where):
    # an --out that cannot be a folder is refused before the sampler runs (it
    # used to fail after the whole computation)
    from bayesgloss import estimate

    def never(*args, **kwargs):
        raise AssertionError("the estimate ran before --out was checked")

    monkeypatch.setattr(estimate, "estimate_bundle", never)
    blocker = tmp_path / "taken"
    if where == "read-only":
        if os.geteuid() == 0:
            pytest.skip("root may write into a read-only folder")
        blocker.mkdir(mode=0o555)
        out, problem = blocker / "result", f"'{blocker}' is not writable"
    else:
        blocker.write_text("a user's file")
        out = blocker if where == "a file" else blocker / "result"
        problem = "not a folder"
    assert cli.main(["estimate", str(odd_bundles["day"]), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and problem in err and str(blocker) in err, err
    assert where == "read-only" or blocker.read_text() == "a user's file"


@pytest.mark.long
def test_estimate_out_is_written_as_one_set(odd_bundles, tmp_path, capsys):
    # an older run's files do not survive beside the new ones (report once drew
    # an old comparison into a new figure); other files of the folder stay; the
    # summary names the bundle by its resolved path and the netCDF it goes with
    import hashlib

    out = tmp_path / "res"
    out.mkdir()
    for name in ("summary.json", "posterior.nc", "report.png", "comparison.txt"):
        (out / name).write_text("from an older run")
    (out / "notes.txt").write_text("mine")
    day = odd_bundles["day"]
    args = ["estimate", str(day), "--out", str(out), "--quiet", "--max-steps", "100", "--jobs", "1"]
    assert cli.main(args) == 0
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt", "posterior.nc", "summary.json"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["bundle"] == str(Path(day).resolve())
    digest = hashlib.sha256((out / "posterior.nc").read_bytes()).hexdigest()
    assert summary["posterior_sha256"] == digest


@pytest.fixture(scope="module")
def saved_result(odd_bundles, tmp_path_factory):
    # one named sky, not the default's four families: these tests are about the
    # result's files, and the sky average would cost 40 s more of every run
    out = tmp_path_factory.mktemp("saved") / "res"
    args = ["estimate", str(odd_bundles["day"]), "--out", str(out), "--quiet", "--max-steps", "100"]
    args += ["--sky", "gensky-clear"]
    assert cli.main([*args, "--jobs", "1"]) == 0
    return out


@pytest.mark.parametrize(
    "damage, message",
    [
        (
            lambda d: (d / "posterior.nc").write_bytes((d / "posterior.nc").read_bytes()[:96]),
            "not the one",
        ),
        (lambda d: (d / "posterior.nc").unlink(), "no posterior.nc: an incomplete result"),
        (lambda d: (d / "summary.json").unlink(), "no summary.json: an incomplete result"),
        (lambda d: (d / "summary.json").write_text("[]"), "summary.json holds no estimate"),
        (lambda d: (d / "summary.json").write_text("{tru"), "summary.json is not JSON"),
    ],
    ids=["truncated-netcdf", "no-netcdf", "no-summary", "summary-list", "summary-garbage"],
)
def test_report_of_a_damaged_result_is_one_line(saved_result, tmp_path, capsys, damage, message):
    # what a killed or tampered run leaves: report says so in one line, exit 2
    res = tmp_path / "res"
    shutil.copytree(saved_result, res)
    damage(res)
    assert cli.main(["report", str(res)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and "Traceback" not in err, err


# -- stale or silently wrong (issue 17) -------------------------------------------


@pytest.mark.parametrize("command", ["estimate", "compare"])
def test_every_pixel_saturated_is_one_clear_error(tmp_path, command, capsys):
    # every entry a lower bound: the estimate once reported a "converged"
    # 0.29 [0.13, 0.77] with no saturation flag
    from conftest import make_synthetic_bundle

    b = make_synthetic_bundle(tmp_path / "sat", encoding="srgb", bits=8, exposure=1e-6)
    assert cli.main([command, str(b), "--quiet"] if command == "estimate" else [command, str(b)])
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err, err
    assert "no facet has enough measured frames: 120 of 120 usable entries are saturated" in err
    assert "lower the exposure" in err


def test_report_refuses_a_bundle_changed_since_the_estimate(saved_result, tmp_path, capsys):
    # summary.json records the bundle's resolved path and its content digest;
    # a bundle rewritten since (or another of the same name) is not drawn silently
    from bayesgloss import bundle

    summary = json.loads((saved_result / "summary.json").read_text())
    b = tmp_path / "b"
    shutil.copytree(summary["bundle"], b)  # keeps the files' times: the same content
    res = tmp_path / "res"
    shutil.copytree(saved_result, res)
    (res / "summary.json").write_text(json.dumps({**summary, "bundle": str(b)}))
    assert cli.main(["report", str(res), "--out", str(tmp_path / "a.png")]) == 0
    capsys.readouterr()
    frame = bundle.read_bundle(b).frame_files[3]
    pixels, _ = bundle.read_image(frame)
    bundle.write_tiff(frame, pixels * 1.5)  # a frame replaced
    assert cli.main(["report", str(res), "--out", str(tmp_path / "b.png")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "has changed since the estimate" in err, err
    assert not (tmp_path / "b.png").exists()
    # named explicitly, the user's choice stands
    assert cli.main(["report", str(res), "--bundle", str(b), "--out", str(tmp_path / "c.png")]) == 0


def test_several_bundles_reuse_results_by_content(odd_bundles, tmp_path, monkeypatch, capsys):
    # a finished unit is found again by the bundle's content, not its folder
    # name: replacing a bundle's frames once returned the old answer
    import concurrent.futures
    import contextlib

    from bayesgloss import bundle, estimate, runner

    calls = []

    def fake_unit(bundle, **options):  # the estimate's files, cheaply
        calls.append(Path(bundle).name)
        g = {"median": 0.5, "q05": 0.4, "q95": 0.6}
        return {"summary.json": json.dumps({"object": {"gamma": g}}).encode()}

    @contextlib.contextmanager
    def in_process(jobs, scheduler=None):
        with concurrent.futures.ThreadPoolExecutor(1) as ex:
            yield ex

    monkeypatch.setattr(estimate, "estimate_unit", fake_unit)
    monkeypatch.setattr(runner, "executor", in_process)
    a, c = tmp_path / "a", tmp_path / "c"
    shutil.copytree(odd_bundles["day"], a)
    shutil.copytree(odd_bundles["day"], c)
    args = ["estimate", str(a), str(c), "--out", str(tmp_path / "out"), "--quiet"]
    assert cli.main(args) == 0 and sorted(calls) == ["a", "c"]
    assert cli.main(args) == 0 and sorted(calls) == ["a", "c"]  # both finished: reused
    frame = bundle.read_bundle(a).frame_files[3]
    pixels, _ = bundle.read_image(frame)
    bundle.write_tiff(frame, pixels * 1.5)  # a's frames replaced, same folder name
    assert cli.main(args) == 0 and sorted(calls) == ["a", "a", "c"]
    assert len(list((tmp_path / "out").iterdir())) == 3
    capsys.readouterr()


# a `bayesgloss estimate --out` whose computation is replaced by a saved result
# (with a new netCDF: an attribute changed) and which SIGKILLs itself at one point
# of the write; the CLI's own path from --out check to the files is the real one
_KILLED_ESTIMATE = """
import os, signal, sys
from bayesgloss import cli, estimate, results

saved, bundle, out, point = sys.argv[1:5]
res = results.read_result(saved)
res.idata.posterior.attrs["run"] = "newer"
estimate.estimate_bundle = lambda *a, **k: res
die = lambda: os.kill(os.getpid(), signal.SIGKILL)
real_replace, real_fdopen, real_unlink = os.replace, os.fdopen, results.Path.unlink
if point == "after removing the old files":
    def unlink(self, *a, **k):
        real_unlink(self, *a, **k)
        if self.name == results.RESULT_FILES[-1]:
            die()
    results.Path.unlink = unlink

class HalfWritten:  # writes half of what it is given, then dies
    def __init__(self, f): self.f = f
    def __enter__(self): return self
    def __exit__(self, *a): return self.f.__exit__(*a)
    def write(self, data):
        self.f.write(data[: len(data) // 2]); self.f.flush(); os.fsync(self.f.fileno()); die()

def fdopen(fd, *a, **k):
    f = real_fdopen(fd, *a, **k)
    name = os.readlink(f"/proc/self/fd/{fd}")
    want = {"during the netCDF write": ".posterior.nc.",
            "during the summary write": ".summary.json."}.get(point, "//")
    return HalfWritten(f) if want in name else f

def replace(src, dst):
    real_replace(src, dst)
    if point == "after the netCDF write" and str(dst).endswith("posterior.nc"):
        die()

os.fdopen, os.replace = fdopen, replace
sys.exit(cli.main(["estimate", bundle, "--out", out, "--quiet"]))
"""

KILL_POINTS = [
    "after removing the old files",
    "during the netCDF write",
    "after the netCDF write",
    "during the summary write",
    "never",
]


@pytest.mark.parametrize("point", KILL_POINTS)
def test_kill_9_during_estimate_out_leaves_a_result_or_says_it_is_incomplete(
    saved_result, odd_bundles, tmp_path, capsys, point
):
    # the folder holds an older complete result; `kill -9` at each point of the
    # write leaves either a complete result (report works) or one that report
    # refuses in one line as incomplete, never an older summary beside a newer
    # netCDF (a 96-byte posterior.nc beside an older summary.json crashed report)
    out = tmp_path / "res"
    shutil.copytree(saved_result, out)

    def estimate_out(point):
        args = [str(saved_result), str(odd_bundles["day"]), str(out), point]
        proc = subprocess.run(
            [sys.executable, "-c", _KILLED_ESTIMATE, *args], capture_output=True, text=True
        )
        assert proc.returncode == (0 if point == "never" else -9), proc.stderr

    estimate_out(point)
    leftovers = sorted(p.name for p in out.iterdir())
    code = cli.main(["report", str(out), "--out", str(tmp_path / "report.png")])
    err = capsys.readouterr().err
    if point != "never":
        assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
        assert "no summary.json: an incomplete result" in err, err
        assert "summary.json" not in leftovers  # the older one went first
        estimate_out("never")  # the next run completes, with nothing of the killed one left
        code = cli.main(["report", str(out), "--out", str(tmp_path / "report.png")])
        err = capsys.readouterr().err
    assert code == 0, err
    assert sorted(p.name for p in out.iterdir()) == ["posterior.nc", "summary.json"]
    assert b"newer" in (out / "posterior.nc").read_bytes()


def test_baseline_without_sun_says_so_not_nan(monkeypatch, capsys):
    # an overcast or hazy day where no facet has the sun at its peak frame
    # (holdout 8's vs09 printed "object gloss ...: nan"): the line says there
    # is no answer and why, and the JSON has null
    import numpy as np

    from bayesgloss import baseline

    res = baseline.BaselineResult(
        ids=np.array([2, 3]),
        gloss=np.full(2, np.nan),
        interval=np.full((2, 2), np.nan),
        flags=[["no-direct-sun"], ["no-direct-sun"]],
        object_gloss=float("nan"),
        observed_peak=np.array([4, 4]),
        predicted_peak=np.full((3, 2), -1),
        gloss_grid=np.linspace(0, 1, 3),
        exponent=2.0,
        direct_sun=np.zeros(2, bool),
    )
    monkeypatch.setattr(baseline, "bundle_peak_frame_gloss", lambda *a, **k: res)
    assert cli.main(["baseline", "any-bundle"]) == 0
    out = capsys.readouterr().out
    assert "object gloss: none" in out and "nan" not in out
    assert res.to_json()["object"]["gamma"] is None
