"""The blocks a check keeps for `cncctl simulate` to plan: runs of G0/G1 lines as numbers."""

from __future__ import annotations

from array import array
from collections.abc import Iterator

from controller.blocks import LineBlock, NcBlock, Source


class _LineRun:
    """Lines that follow each other with the same feed, kind, path control and file, each from
    one program line: the first one's start, then per line its end (x, y, z) and line number
    (32 bytes a line, against some 350 for the blocks themselves)."""

    def __init__(self, first: LineBlock) -> None:
        self.start = first.start
        self.feed_mm_s, self.rapid, self.path = first.feed_mm_s, first.rapid, first.path
        self.file = first.source.path
        self.ends = array("d")
        self.lines = array("q")
        self.last_end = first.start

    def takes(self, b: LineBlock) -> bool:
        """Whether b (a line of one program line) is the run's next line."""
        # Identity first: the interpreter hands the same objects on from line to line.
        return (
            (b.start is self.last_end or b.start == self.last_end)
            and b.feed_mm_s == self.feed_mm_s
            and b.rapid == self.rapid
            and (b.path is self.path or b.path == self.path)
            and b.source.path == self.file
        )

    def add(self, b: LineBlock) -> None:
        self.ends.extend(b.end)
        self.lines.append(b.source.first_line)
        self.last_end = b.end

    def blocks(self) -> Iterator[LineBlock]:
        """The lines again: blocks equal to those added (each start the one before's end)."""
        start, e = self.start, self.ends
        feed, rapid, path, file = self.feed_mm_s, self.rapid, self.path, self.file
        for i, line in enumerate(self.lines):
            end = (e[3 * i], e[3 * i + 1], e[3 * i + 2])
            yield LineBlock(start, end, feed, rapid, path, Source(file, line, line))
            start = end


class KeptBlocks:
    """A program's blocks in order, kept while there are at most max_blocks blocks other than
    plain lines and max_lines plain lines (then full: the caller reads the program again). A
    plain line (a G0/G1 of one program line) past the first lines_as_blocks is kept as numbers
    in a run of such lines (a shorter program keeps its blocks as they are: nothing to make
    again)."""

    def __init__(self, max_blocks: int, max_lines: int, lines_as_blocks: int) -> None:
        self.max_blocks, self.max_lines = max_blocks, max_lines
        self.lines_as_blocks = lines_as_blocks
        self.n_blocks = self.n_lines = 0
        self._parts: list[NcBlock | _LineRun] = []
        self._run: _LineRun | None = None

    @property
    def full(self) -> bool:
        """More blocks came than are kept: the blocks kept are not the whole program."""
        return self.n_blocks > self.max_blocks or self.n_lines > self.max_lines

    def append(self, block: NcBlock) -> None:
        """Keep block (past either limit: count it only; the caller asks full)."""
        if type(block) is not LineBlock or block.source.first_line != block.source.last_line:
            self.n_blocks += 1
            if self.n_blocks <= self.max_blocks:
                self._run = None
                self._parts.append(block)
            return
        self.n_lines += 1
        if self.n_lines <= self.lines_as_blocks:  # the first lines: before any run
            self._parts.append(block)
        elif self.n_lines <= self.max_lines:
            run = self._run
            if run is None or not run.takes(block):
                run = self._run = _LineRun(block)
                self._parts.append(run)
            run.add(block)

    def __len__(self) -> int:
        return self.n_blocks + self.n_lines

    def __iter__(self) -> Iterator[NcBlock]:
        for part in self._parts:
            if isinstance(part, _LineRun):
                yield from part.blocks()
            else:
                yield part
