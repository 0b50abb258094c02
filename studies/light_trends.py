"""How far each frame's sun and sky depart from the day's, on seen renders with the light told.

Stop 71's lead for a day-level light ("Stop 71: a design for the next
candidate on few-facet objects", ``studies/README.md``). For every sun-lit
sequence of the seen mixed sets whose gamma more than 3 facets measured
(their frames' light is told by the facets, not by its prior), the score
keeps each frame's inferred sun a_t and sky b_t (posterior medians,
relative to the most-weighted sky family's prediction). Per sequence:

- the sd over the day of log a_t over its clear frames (a_t > 0.2), and
  the residual sd after a straight line in the frame's relative air mass
  (Kasten and Young 1989, :func:`bayesgloss.sun.relative_airmass_kasten_young`;
  Beer-Lambert: a beam dimmed by extra optical depth tau falls as exp(-tau m));
- the sd over the day of log b_t, and the residual sd after a straight line
  in the cosine of the sun's zenith angle.

The default's per-frame priors are sd 0.35 (clear sun) and 0.7 (sky); a
day-level light with these trends needs the residual spreads to be much
smaller on clear days. Fits nothing: reads the committed scores.

Usage: python studies/light_trends.py [--json FILE]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from bayesgloss import sun

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
#: Seen sets scored with the default of stop 63 (scores file, drawn configs).
SETS = {
    "validation_holdout26": "validation_holdout26_configs.json",
    "validation_holdout28": "validation_holdout28_configs.json",
    "validation_mitsuba_holdout13": "mitsuba_holdout13.json",
    "validation_mitsuba_holdout14": "mitsuba_holdout14.json",
}
#: A frame's sun counts as clear above this fraction of the model's.
CLEAR_SUN = 0.2
#: Objects whose gamma more than this many facets measured.
MIN_FACETS = 3


def residual_sd(y: np.ndarray, x: np.ndarray) -> float:
    """sd of y about its least-squares line in x (2 degrees of freedom
    used); NaN with fewer than 4 points."""
    if y.size < 4:
        return float("nan")
    design = np.column_stack([np.ones_like(x), x])
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    return float(np.std(y - design @ coef, ddof=2))


def day_spreads(entry: dict, config: dict) -> dict:
    """The spreads of one score's frames (module docstring)."""
    zenith = np.asarray(
        sun.solar_position(config["times"], config["latitude"], config["longitude"])[
            "solar_zenith"
        ],
        dtype=float,
    )[np.asarray(entry["frame"])]
    a, b = np.asarray(entry["sun"], dtype=float), np.asarray(entry["sky"], dtype=float)
    clear = a > CLEAR_SUN
    log_a, log_b = np.log(a[clear]), np.log(b)
    airmass = np.asarray(sun.relative_airmass_kasten_young(zenith), dtype=float)
    return {
        "clear_frames": int(clear.sum()),
        "frames": int(a.size),
        "sun_sd": float(np.std(log_a)) if clear.sum() > 1 else float("nan"),
        "sun_residual_sd": residual_sd(log_a, airmass[clear]),
        "sky_sd": float(np.std(log_b)),
        "sky_residual_sd": residual_sd(log_b, np.cos(np.radians(zenith))),
    }


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", type=Path, default=RESULTS / "light_trends_stop71.json")
    args = ap.parse_args(argv)
    rows = []
    for scores_name, configs_name in SETS.items():
        scores = json.loads((RESULTS / f"{scores_name}.json").read_text())["sequences"]
        configs = {
            s["name"]: s["config"]
            for s in json.loads((RESULTS / configs_name).read_text())["sequences"]
        }
        for s in scores:
            entry = s.get("perez")
            if not s.get("direct_sun") or not isinstance(entry, dict):
                continue
            if entry["model_error"]["facets"] <= MIN_FACETS:
                continue
            name = s["bundle"].rsplit("/", 1)[-1].rsplit("-", 1)[0]
            rows.append(
                {
                    "set": scores_name,
                    "sequence": name,
                    "category": s["category"],
                    **day_spreads(entry, configs[name]),
                }
            )
    by_category = {}
    for cat in sorted({r["category"] for r in rows}):
        rs = [r for r in rows if r["category"] == cat]
        by_category[cat] = {"sequences": len(rs)} | {
            key: float(np.nanmedian([r[key] for r in rs]))
            for key in ("sun_sd", "sun_residual_sd", "sky_sd", "sky_residual_sd")
        }
    out = {"sequences": rows, "median_by_category": by_category}
    args.json.write_text(json.dumps(out, indent=1) + "\n")
    for cat, v in by_category.items():
        print(
            f"{cat:20s} {v['sequences']:2d}  sun sd {v['sun_sd']:.3f} -> {v['sun_residual_sd']:.3f}"
            f"  sky sd {v['sky_sd']:.3f} -> {v['sky_residual_sd']:.3f}"
        )
    return out


if __name__ == "__main__":
    main()
