"""Drive backend names a config may give: built in, registered in-process, or installed."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from importlib.metadata import EntryPoint

# drivers/registry.py maps each built-in name to its class; the names live here so that the
# config check (this base layer) knows them without importing any driver.
BUILTIN_BACKENDS: tuple[str, ...] = ("sim", "canopen", "serial")
# Another package's backend: in its pyproject.toml,
#   [project.entry-points."phcnc.drives"]
#   mydrive = "mypackage.drive:MyDrive"
# where MyDrive(config, **drive.options) -> a drivers.base.Drive.
ENTRY_POINT_GROUP = "phcnc.drives"
_registered: set[str] = set()


def allow_backend(name: str) -> None:
    """A name registered in this process (drivers.registry.register_backend) passes the check."""
    _registered.add(name)


def installed_backends() -> dict[str, EntryPoint]:
    """name -> entry point of every backend an installed package provides (first one wins)."""
    # Imported here: importlib.metadata (email, zipfile, csv) costs every command ~30 ms of
    # start-up, and only a backend that is not built in asks for it.
    from importlib.metadata import entry_points

    found: dict[str, EntryPoint] = {}
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        found.setdefault(ep.name, ep)
    return found


def backend_names() -> tuple[str, ...]:
    """Every name drive.backend may take here. The installed packages are searched only for a
    name that is not built in (it reads every package's metadata on sys.path)."""
    return tuple(sorted(set(BUILTIN_BACKENDS) | _registered | installed_backends().keys()))
