"""How `cncctl run` ends, embedded or through cncd: exit codes, and the signals that stop it."""

from __future__ import annotations

import signal

from controller.motion.types import Outcome

EXIT_CODES = {Outcome.DONE: 0, Outcome.FAULT: 3, Outcome.ABORTED: 4}
EXIT_REJECTED = 2  # nothing moved: a bad program, a drive that cannot be opened, a refused job
# SIGTERM is what systemd and kill send, SIGHUP a closed terminal: both stop like Ctrl-C.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
