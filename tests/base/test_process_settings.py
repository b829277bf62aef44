"""Every process of the controller: numpy's BLAS on one thread, freed memory kept (glibc)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

PROBE = ("import controller.operator.cli, os, numpy; "
         "print(os.environ['OPENBLAS_NUM_THREADS'], os.environ['OMP_NUM_THREADS'])")


@pytest.mark.parametrize(("given", "expected"), [(None, "1 1"), ("2", "2 1")])
def test_one_blas_thread_unless_set(given: str | None, expected: str) -> None:
    """Spinning BLAS threads doubled the CPU of planning a G1 program on 2 cores (and would
    take the motion process's core under `cncctl run`); a fresh process importing the CLI,
    as `cncctl` does, gets one thread, and the processes it starts inherit it."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    if given is not None:
        env["OPENBLAS_NUM_THREADS"] = given
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True,
                         check=True, timeout=60).stdout.split()
    assert " ".join(out) == expected


FAULTS = """
import resource, sys
if sys.argv[1] == "controller":
    import controller  # noqa: F401
import numpy as np
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(50):
    a = np.ones(1_000_000)
    b = a * 2.0
    c = b + a
    del a, b, c
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def _faults(*args: str) -> int:
    env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")}
    out = subprocess.run([sys.executable, "-c", FAULTS, *args], env=env, capture_output=True,
                         text=True, check=True, timeout=60)
    return int(out.stdout.split()[-1])


def test_freed_arrays_are_not_faulted_in_again() -> None:
    """Planning allocates and frees arrays of a few MB all the time: glibc gave each back to
    the kernel and faulted it in again page by page (3 s of kernel time in 16 s on a
    100k-line walk). With the controller imported, 50 rounds of three 8 MB arrays fault a
    few pages, not every page of every round."""
    plain, kept = _faults("plain"), _faults("controller")
    assert plain > 20_000  # glibc's default: every round faults its 6000 pages in again
    assert kept < plain / 10
