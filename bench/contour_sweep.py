"""True contour error of ph-lookahead over many programs: the limit kept everywhere, or where not.

Usage: python bench/contour_sweep.py [--config xy_table_paper] [--corpus DIR ...] [--markdown]

Programs: the repository's nc_programs, generated sections and lobed NURBS (tests/gen_programs.py,
as bench/table4_generated.py makes them), stop programs written here (a G61 square, an M0 in a
contour, a dwell between moves) and, with --corpus, every .nc/.ngc file under the folders given
(e.g. the LinuxCNC programs of a corpus of CAM programs, when present beside the clone). Each is
planned by `simulate` with the config given; reported:
true contour error max (the modelled tool's distance from the path, settling included), whether
`contour_limit_met`, motion time and dynamics rounds. A program the interpreter refuses is counted
as refused (not planned), one that raises anything else as a crash.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

from gen_programs import generated_program  # noqa: E402

from controller.config import load_config  # noqa: E402
from controller.errors import NcError  # noqa: E402
from controller.interpreter.program import read_program  # noqa: E402
from controller.runtime.simulation import report, simulate  # noqa: E402

GENERATED = ("naca0012_20", "naca2412_30", "naca4415_40", "naca6409_30", "lobed_1", "lobed_2",
             "lobed_3", "lobed_4", "lobed_5")
STOP_PROGRAMS = {
    "g61_square.nc": "G21 G90 G61 F3500\nG1 X20\nG1 Y20\nG1 X0\nG1 Y0\nM2\n",
    "m0_in_contour.nc": ("G21 G90 G64 F3500\nG1 X10 Y0\nG1 X20 Y5\nM0\nG1 X30 Y0\nG1 X20 Y-10\n"
                         "G1 X0 Y0\nM2\n"),
    "dwell.nc": "G21 G90 G64 F3000\nG1 X15 Y5\nG4 P0.2\nG1 X0 Y10\nG1 X0 Y0\nM2\n",
}


def programs(folder: Path, corpora: list[str]) -> list[Path]:
    out = sorted((REPO / "nc_programs").glob("*.nc"))
    out += [generated_program(folder, name) for name in GENERATED]
    for name, text in STOP_PROGRAMS.items():
        (folder / name).write_text(text)
        out.append(folder / name)
    for corpus in corpora:
        out += sorted(p for p in Path(corpus).rglob("*") if p.suffix.lower() in (".nc", ".ngc"))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", help="machine configuration (default: the built-in one)")
    ap.add_argument("--corpus", nargs="*", default=[])
    ap.add_argument("--markdown", action="store_true")
    args = ap.parse_args(argv)
    config = load_config(args.config)
    limit_um = config.interpolator.contour_error_limit_mm * 1e3
    rows, refused, crashed = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for path in programs(Path(tmp), args.corpus):
            try:
                r = report(simulate(read_program(str(path), config), config, "ph-lookahead"),
                           str(path), "ph-lookahead", config)
            except NcError as exc:
                refused.append((path.name, str(exc).splitlines()[0]))
                continue
            except Exception as exc:  # noqa: BLE001 (a bench counts crashes, it does not stop)
                crashed.append((path.name, repr(exc)))
                continue
            rows.append((path.name, r["contour_error_true_um"]["max"], r["contour_limit_met"],
                         r["motion_time_s"], r["dynamics_rounds"]))
    print(f"config {config.name}: servo_precompensation "
          f"{config.interpolator.servo_precompensation}, limit {limit_um:g} um\n")
    print("| program | true max (um) | limit met | motion (s) | rounds |")
    print("|---|---|---|---|---|")
    for name, true_um, met, t_s, rounds in rows:
        print(f"| {name} | {true_um:.2f} | {'yes' if met else 'NO'} | {t_s:.3f} | {rounds} |")
    met = sum(r[2] for r in rows)
    print(f"\n{met} of {len(rows)} planned programs keep the limit; worst "
          f"{max(r[1] for r in rows):.2f} um; {len(refused)} refused by the interpreter, "
          f"{len(crashed)} crashed")
    for name, why in refused + crashed:
        print(f"- {name}: {why}")
    return 0 if met == len(rows) and not crashed else 1


if __name__ == "__main__":
    sys.exit(main())
