"""Files the commands write (`--trajectory`, `--plot`): checked before any work is done."""

from __future__ import annotations

import os
import stat

from controller.errors import CncError


class OutputError(CncError):
    """An output path that cannot or must not be written."""


def output_path(path: str, option: str) -> str:
    """The regular file to write for `option` (a symlink's target), or OutputError naming the
    option: its folder must exist and be writable, and whatever stands at the path must be a
    regular file. Replacing it by rename would otherwise swap out a device (`/dev/full`, as
    root), a pipe or a folder, and a missing folder would show up only after the planning."""
    if not path:
        raise OutputError(f"{option}: empty path")
    real = os.path.realpath(path)
    try:
        mode = os.stat(real).st_mode
    except FileNotFoundError:
        mode = None
    except OSError as exc:
        raise OutputError(f"{option} {path}: {exc.strerror}") from None
    if mode is not None and not stat.S_ISREG(mode):
        kind = "a folder" if stat.S_ISDIR(mode) else "not a regular file"
        raise OutputError(f"{option} {path}: {kind}; give a file name")
    folder = os.path.dirname(real) or "."
    if not os.path.isdir(folder):
        raise OutputError(f"{option} {path}: no such folder {folder}")
    if not os.access(folder, os.W_OK | os.X_OK) or mode is not None and \
            not os.access(real, os.W_OK):
        raise OutputError(f"{option} {path}: permission denied")
    return real


PLOT_INSTALL = "pip install 'phcnc[plot]'"  # the `plot` extra of pyproject.toml
DEFAULT_PLOT_FORMAT = "png"


def plot_format(path: str) -> str:
    """The file format of a plot: its extension, or png for a name without one (matplotlib
    would otherwise write `name.png` beside the path that was checked)."""
    return os.path.splitext(path)[1][1:].lower() or DEFAULT_PLOT_FORMAT


def plot_path(path: str, option: str = "--plot") -> str:
    """output_path, and matplotlib there and able to write the format: all known before the
    program is planned, instead of a traceback after it."""
    real = output_path(path, option)
    try:
        from matplotlib.backend_bases import FigureCanvasBase
    except ImportError:
        raise OutputError(f"{option} needs matplotlib: {PLOT_INSTALL}") from None
    formats = FigureCanvasBase.get_supported_filetypes()
    fmt = plot_format(real)
    if fmt not in formats:
        raise OutputError(f"{option} {path}: cannot write .{fmt} (give a file name ending in "
                          f"{', '.join('.' + f for f in sorted(formats))})")
    return real
