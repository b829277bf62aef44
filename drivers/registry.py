"""Drive backends by name (python-can style): config `drive.backend` picks one, imported on use.

A backend from another package registers through the entry-point group `phcnc.drives`
(`name = "module:factory"`, see controller/backends.py); factory(config, **drive.options)
returns a drivers.base.Drive, not yet opened."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any

from controller.backends import allow_backend, installed_backends
from controller.backends import backend_names as backend_names
from controller.config import MachineConfig
from controller.errors import DriveError
from drivers.base import Drive

# name -> "module:class"; imported only when chosen, so an unused backend's libraries
# (python-can, pyserial) cost nothing.
BUILTIN_BACKENDS: dict[str, str] = {
    "sim": "drivers.sim.card:SimCard",
    "canopen": "drivers.canopen.backend:CanopenDrive",
    "serial": "drivers.serial.backend:SerialCard",
}
# name -> "module:function" of a simulated peer that speaks the backend's wire protocol in its
# own process (`cncctl simdrive NAME`): serve(config, options, announce, stop) prints the
# device path through announce(path) once it can be opened, then serves until stop is set.
SIMULATED_PEERS: dict[str, str] = {
    "canopen": "drivers.canopen.sim_peer:serve",
    "serial": "drivers.serial.sim_peer:serve",
}
_registered: dict[str, Callable[..., Drive]] = {}


def register_backend(name: str, factory: Callable[..., Drive]) -> None:
    """Make a backend available under `name` (config drive.backend) in this process; an
    installed package uses the `phcnc.drives` entry point instead."""
    _registered[name] = factory
    allow_backend(name)


def _factory(name: str) -> Callable[..., Drive]:
    if name in _registered:
        return _registered[name]
    if name in BUILTIN_BACKENDS:
        module_name, class_name = BUILTIN_BACKENDS[name].split(":")
        return getattr(importlib.import_module(module_name), class_name)
    ep = installed_backends().get(name)
    if ep is None:
        raise DriveError(f"drive backend {name!r} is not available "
                         f"(have: {', '.join(backend_names())})")
    try:
        factory = ep.load()
    except Exception as exc:  # a broken plug-in is a drive error, not a traceback
        raise DriveError(f"drive backend {name!r} ({ep.value}, entry point "
                         f"{ep.group}) cannot be loaded: {type(exc).__name__}: {exc}") from exc
    if not callable(factory):
        raise DriveError(f"drive backend {name!r}: {ep.value} is not callable")
    return factory


def simulated_peer(name: str) -> Callable[..., None]:
    """The serve function of a backend's simulated peer."""
    if name not in SIMULATED_PEERS:
        raise DriveError(f"no simulated peer for {name!r} (have: {', '.join(SIMULATED_PEERS)})")
    module_name, func_name = SIMULATED_PEERS[name].split(":")
    return getattr(importlib.import_module(module_name), func_name)


def make_drive(config: MachineConfig, **overrides: Any) -> Drive:
    """Construct (not open) the configured backend; overrides beat config drive.options."""
    options = dict(config.drive.options) | overrides
    return _factory(config.drive.backend)(config, **options)
