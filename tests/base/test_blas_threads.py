"""Every process of the controller runs numpy's BLAS on one thread unless the user says more."""

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
