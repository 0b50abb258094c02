"""The README's main job: `bayesgloss demo` end to end."""

import json

import pytest

from bayesgloss import cli


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


def test_report_of_a_saved_estimate(tmp_path, capsys):
    # estimate --out writes what report reads; the report names its PNG
    from conftest import make_synthetic_bundle

    b = make_synthetic_bundle(tmp_path / "b", specularity=0.5)
    out = tmp_path / "est"
    assert cli.main(["estimate", str(b), "--out", str(out), "--quiet", "--max-steps", "1500"]) == 0
    capsys.readouterr()
    assert cli.main(["report", str(out)]) == 0
    assert capsys.readouterr().out.strip().endswith("report.png")
    assert (out / "report.png").stat().st_size > 50_000
    assert cli.main(["report", str(tmp_path / "nothing")]) == 2
    assert "no summary.json" in capsys.readouterr().err
