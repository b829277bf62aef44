"""Commissioning figures: plants the controller does not know, before and after `cncctl identify`.

For each plant (the sim card's X and Y loops off the config's model, passed as the drive options
`plant_x` and `plant_y`), on the airfoil, the loop and the butterfly:

1. `cncctl run --virtual-time --json` with the config's (nominal) model: the measured contour
   error (encoder positions against the path) and the motion time;
2. `cncctl identify x y --yes --virtual-time --output FILE` on that plant: the fit, the
   identification's wall time and the travel it used;
3. `cncctl run --virtual-time --json --config FILE` on the same plant: the same figures with
   the identified model.

The motion time is compared with the plan of the nominal model on the nominal plant. Plants:
- gain: the loop's feed-forward short of the ideal by more or less (c1, c2 scaled:
  `controller/servo/model.py: mismatched(gain_pct)`);
- poles: the denominator's roots scaled (s -> s / k), the numerator's roots kept;
- zeros: the numerator's roots scaled, the denominator kept;
- all: poles and zeros scaled together (the sim card's `plant_pole_pct`);
- opposite: X's poles +20 %, Y's -20 %.
Every plant keeps a0 = b0 (no steady-state error at rest).

    python bench/identify.py [--quick] [--markdown]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from controller.config import ServoParams, load_config  # noqa: E402
from controller.servo.model import mismatched  # noqa: E402
from controller.servo.plant_option import plant_text  # noqa: E402

CNCCTL = [sys.executable, "-m", "controller.operator.cli"]
PROGRAMS = ("naca2415.nc", "naca2415_loop.nc", "butterfly.nc")
CONFIG = "xy_table"


def poles_scaled(p: ServoParams, pct: float) -> ServoParams:
    k = 1.0 + pct / 100.0
    a = [p.a0 * k**4, p.a1 * k**3, p.a2 * k**2, p.a3 * k, p.a4]
    dc = a[0] / p.b0  # the numerator keeps its roots and the DC gain stays 1
    return ServoParams(a0=a[0], a1=a[1], a2=a[2], a3=a[3], a4=a[4], b0=a[0], b1=p.b1 * dc,
                       b2=p.b2 * dc)


def zeros_scaled(p: ServoParams, pct: float) -> ServoParams:
    k = 1.0 + pct / 100.0
    return replace(p, b1=p.b1 / k, b2=p.b2 / k**2)


def plants(quick: bool) -> list[tuple[str, dict[str, ServoParams]]]:
    cfg = load_config(CONFIG)
    x, y = (a.servo for a in cfg.axes[:2])
    steps = (-20.0, 20.0) if quick else (-20.0, -10.0, 10.0, 20.0)
    out: list[tuple[str, dict[str, ServoParams]]] = []
    for name, make in (("gain", lambda p, s: mismatched(p, gain_pct=s)),
                       ("poles", poles_scaled), ("zeros", zeros_scaled),
                       ("all", lambda p, s: mismatched(p, pole_pct=s))):
        for step in steps:
            out.append((f"{name} {step:+.0f} %", {"x": make(x, step), "y": make(y, step)}))
    out.append(("opposite: X poles +20 %, Y -20 %",
                {"x": poles_scaled(x, 20.0), "y": poles_scaled(y, -20.0)}))
    return out


def drive_options(plant: dict[str, ServoParams]) -> list[str]:
    words: list[str] = []
    for axis, params in plant.items():
        words += ["--drive-option", f"plant_{axis}={plant_text(params)}"]
    return words


def run_job(program: str, config: str, options: list[str]) -> dict[str, Any]:
    done = subprocess.run([*CNCCTL, "run", str(REPO / "nc_programs" / program), "--config",
                           config, "--virtual-time", "--json", *options], capture_output=True,
                          text=True, timeout=600, stdin=subprocess.DEVNULL)
    lines = done.stdout.splitlines()
    final = json.loads(lines[-1]) if lines else {}
    if final.get("event") != "done":
        return {"outcome": final.get("event") or done.stderr.strip()[-120:]}
    return {"outcome": "done", "contour_um": final["contour_error_um"]["max"],
            "motion_s": final["motion_time_s"]}


def identify(options: list[str], output: Path) -> dict[str, Any]:
    t0 = time.monotonic()
    done = subprocess.run([*CNCCTL, "identify", "x", "y", "--config", CONFIG, "--yes",
                           "--virtual-time", "--output", str(output), "--force", *options],
                          capture_output=True, text=True, timeout=600,
                          stdin=subprocess.DEVNULL)
    wall_s = time.monotonic() - t0
    text = done.stdout + done.stderr
    fits = [float(line.split("data: ")[1].split(" %")[0]) for line in text.splitlines()
            if "fit on held-out data" in line]
    travel = [line.split("within ")[1].split(" mm")[0] for line in text.splitlines()
              if "will move within" in line]
    return {"exit": done.returncode, "wall_s": wall_s, "fit_pct": fits, "travel_mm": travel,
            "message": "" if done.returncode == 0 else text.strip().splitlines()[-1][:160]}


def case(name: str, plant: dict[str, ServoParams], reference_s: dict[str, float],
         folder: Path) -> dict[str, Any]:
    options = drive_options(plant)
    identified = folder / "identified.yaml"
    ident = identify(options, identified)
    row: dict[str, Any] = {"plant": name, "identify": ident, "programs": {}}
    for program in PROGRAMS:
        before = run_job(program, CONFIG, options)
        after = (run_job(program, str(identified), options) if ident["exit"] == 0
                 else {"outcome": "no identified model"})
        if "motion_s" in after:
            after["time_ratio"] = after["motion_s"] / reference_s[program]
        row["programs"][program] = {"nominal_model": before, "identified_model": after}
    return row


def markdown(rows: list[dict[str, Any]], eps_um: float) -> str:
    out = ["| plant | identify: fit X / Y (%), wall (s), travel (mm) | program | contour error "
           "nominal model (um) | after identify (um) | motion time after / nominal plan |",
           "|---|---|---|---|---|---|"]
    for row in rows:
        ident = row["identify"]
        first = (f"{' / '.join(f'{f:.1f}' for f in ident['fit_pct'])}, {ident['wall_s']:.1f}, "
                 f"{ident['travel_mm'][0] if ident['travel_mm'] else '-'}"
                 if ident["exit"] == 0 else f"refused (exit {ident['exit']}): "
                                            f"{ident['message']}")
        for k, (program, result) in enumerate(row["programs"].items()):
            before, after = result["nominal_model"], result["identified_model"]
            b = f"{before['contour_um']:.1f}" if "contour_um" in before else before["outcome"]
            a = (f"{after['contour_um']:.1f}" + (" **over**" if after["contour_um"] > eps_um
                                                  else "")
                 if "contour_um" in after else after["outcome"])
            r = f"{after['time_ratio']:.3f}" if "time_ratio" in after else "-"
            out.append(f"| {row['plant'] if k == 0 else ''} | {first if k == 0 else ''} | "
                       f"{program} | {b} | {a} | {r} |")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="+-20 % only")
    ap.add_argument("--markdown", action="store_true")
    args = ap.parse_args()
    eps_um = load_config(CONFIG).interpolator.contour_error_limit_mm * 1e3
    reference_s = {p: run_job(p, CONFIG, [])["motion_s"] for p in PROGRAMS}
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, plant in plants(args.quick):
            rows.append(case(name, plant, reference_s, Path(tmp)))
            print(f"{name}: done", file=sys.stderr)
    print(markdown(rows, eps_um) if args.markdown else json.dumps(
        {"reference_motion_s": reference_s, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
