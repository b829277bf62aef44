"""The servo side of `cncctl simulate` alone: instructions and CPU of the servo stream.

Usage: python bench/simulate_servo.py PROGRAM [PROGRAM ...] [--tree DIR ...] [--runs N]
       [--no-callgrind]

The program is planned once (ph-lookahead, the default config) and its reference chunks kept;
each tree given (default: this one) then runs `ServoStream` over them, as `cncctl simulate`
does: the axis filters, the tangents and eq. 28, the true distance of every sample. Per tree:
- instructions of the stream alone, counted by valgrind (callgrind, OPENBLAS_NUM_THREADS=1):
  the stream runs inside itertools.starmap and only starmap_next is collected, so the start-up,
  the planning and the reading of the chunks are not counted;
- CPU (process_time) of the stream, the least of --runs, the trees in turn;
- a hash of every finished sample, which must be the same for every tree.
Under valgrind numpy takes its AVX2 loops (valgrind has no AVX-512), so the hash there may
differ from that of a plain run; it is the same for every tree.
"""

from __future__ import annotations

import argparse
import os
import pickle
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

_PLAN = """
import pickle, sys
from controller.config import load_config
from controller.generator.plan import plan_program
from controller.interpreter.program import read_program
config = load_config()
chunks = []
for step in plan_program(read_program(sys.argv[1], config), config, "ph-lookahead"):
    c = step.chunk
    if len(c):
        chunks.append((c.pos_mm, c.feed_mm_s, c.line, step.rapid, step.phi_rad))
pickle.dump(chunks, open(sys.argv[2], "wb"))
"""

_STREAM = """
import hashlib, itertools, pickle, sys, time
from controller.config import load_config
from controller.runtime.simulate_stream import ServoStream
config = load_config()
chunks = pickle.load(open(sys.argv[1], "rb"))
FIELDS = ("ex_mm", "ey_mm", "contour_mm", "true_mm")

def stream(chunks):
    s = ServoStream(config)
    blocks = [b for c in chunks for b in s.push(*c)] + list(s.finish())
    return blocks

def digest(blocks):
    h = hashlib.sha1()
    for b in blocks:
        for f in FIELDS:
            h.update(getattr(b, f).tobytes())
    return h.hexdigest()[:12]

if sys.argv[2] == "count":
    blocks = list(itertools.starmap(stream, [(chunks,)]))[0]
    print(digest(blocks))
else:
    best = float("inf")
    for _ in range(int(sys.argv[3])):
        t0 = time.process_time()
        blocks = stream(chunks)
        best = min(best, time.process_time() - t0)
    print(digest(blocks), best)
"""


def _run(
    tree: Path,
    args: list[str],
    env_extra: dict[str, str] | None = None,
    prefix: list[str] | None = None,
) -> str:
    env = {**os.environ, "PYTHONPATH": str(tree), "OPENBLAS_NUM_THREADS": "1", **(env_extra or {})}
    done = subprocess.run(
        [*(prefix or []), sys.executable, *args],
        env=env,
        check=True,
        capture_output=True,
        text=True,
    )
    return done.stdout.strip()


def instructions(tree: Path, script: Path, chunks: Path, out_dir: Path) -> tuple[int, str]:
    out = out_dir / f"cg.{abs(hash(str(tree)))}"
    digest = _run(
        tree,
        [str(script), str(chunks), "count"],
        prefix=[
            "valgrind",
            "--tool=callgrind",
            "--toggle-collect=starmap_next",
            f"--callgrind-out-file={out}",
        ],
    )
    for line in out.read_text().splitlines():
        if line.startswith("summary:") or line.startswith("totals:"):
            return int(line.split()[1]), digest
    raise RuntimeError("no callgrind summary")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("programs", nargs="+")
    ap.add_argument("--tree", action="append", type=Path, help="a checkout to measure")
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--no-callgrind", action="store_true")
    args = ap.parse_args(argv)
    trees = args.tree or [REPO]
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        plan, stream = work / "plan.py", work / "stream.py"
        plan.write_text(_PLAN)
        stream.write_text(_STREAM)
        for program in args.programs:
            chunks = work / "chunks.pkl"
            _run(trees[0], [str(plan), program, str(chunks)])
            n = sum(len(c[0]) for c in pickle.loads(chunks.read_bytes()))
            for tree in trees:
                digest, cpu = _run(tree, [str(stream), str(chunks), "cpu", str(args.runs)]).split()
                row = f"{Path(program).name} ({n} samples) {tree}: CPU {float(cpu):.3f} s"
                if not args.no_callgrind:
                    count, cg_digest = instructions(tree, stream, chunks, work)
                    row += f", {count / 1e6:,.0f} M instructions (hash {cg_digest})"
                print(f"{row}, hash {digest}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
