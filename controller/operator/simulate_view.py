"""What `cncctl simulate` shows on a terminal while it plans: a progress bar by program line."""

from __future__ import annotations

from typing import TextIO

from controller.operator.run.view import ProgramLines, lines_text
from controller.runtime.simulate_stream import SampleBlock


class SimulateView:
    """A transient bar on stderr, one task per algorithm: the program line the simulation has
    reached (of the program's lines), its text, and the motion time simulated so far. A
    million-line program takes a minute or more; without it `simulate` looks hung. Shown only
    on a terminal (stdout's table and JSON stay as they are); gone once the run is done."""

    def __init__(self, path: str, sample_period_s: float, stream: TextIO) -> None:
        from rich.console import Console
        from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

        self.lines = ProgramLines(path)
        self.T = sample_period_s  # noqa: N815
        self.bar = Progress(TextColumn("{task.description}"), BarColumn(bar_width=30),
                            TextColumn("line {task.completed:.0f}/{task.total:.0f}"),
                            TextColumn("motion {task.fields[motion_s]:.1f} s"),
                            TimeElapsedColumn(), TextColumn("{task.fields[text]}"),
                            console=Console(file=stream), transient=True)
        self.bar.start()
        self.task = -1

    def start(self, algorithm: str) -> None:
        """A new task for the next algorithm (`--compare` runs four, one after another)."""
        self.task = self.bar.add_task(algorithm, total=max(len(self.lines), 1), motion_s=0.0,
                                      text="")

    def add(self, b: SampleBlock) -> None:
        """A sample sink: where the finished samples have got to."""
        if b.n_ref == 0:
            return
        line = int(b.line[b.n_ref - 1])
        self.bar.update(self.task, completed=line, motion_s=(b.i0 + b.n_ref) * self.T,
                        text=lines_text(self.lines, line))

    def close(self) -> None:
        self.bar.stop()
        self.lines.close()
