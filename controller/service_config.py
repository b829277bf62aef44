"""The `service` section of a machine config: who may use cncd's sockets, and its listeners."""

from __future__ import annotations

from dataclasses import dataclass

from controller.errors import ConfigError
from controller.http_listen import ListenError, parse_listen
from controller.opcua_config import OpcuaConfig, read_opcua
from controller.yaml_strict import Section


@dataclass(frozen=True, slots=True)
class ServiceConfig:
    """Who may use cncd's control socket, and its limits (the `service` section, optional)."""

    socket_group: str | None = None  # group of the socket file (default: the daemon's own)
    allowed_groups: tuple[str, ...] = ()  # besides root, the daemon's user and socket group
    allowed_users: tuple[str, ...] = ()
    max_connections: int = 64
    log_events: int = 1000  # kept in memory for `cncctl log`
    http: str | None = None  # the web panel's HOST:PORT (controller/http_listen.py), or none
    http_token_file: str | None = None  # the API token; required beyond the loopback
    opcua: OpcuaConfig | None = None  # the OPC UA server beside cncd (controller/opcua_config)


def read_service(sec: Section, name: str) -> ServiceConfig:
    """The section; name: the machine's, the OPC UA server's default machine name."""
    group = sec._raw("socket_group", None)
    if group is not None and not (isinstance(group, str) and group):
        raise ConfigError(sec.path, sec._key("socket_group"), "must be a group name")
    cfg = ServiceConfig(
        socket_group=group,
        allowed_groups=sec.names("allowed_groups"),
        allowed_users=sec.names("allowed_users"),
        max_connections=sec.int("max_connections", 64, minval=4, maxval=4096),
        log_events=sec.int("log_events", 1000, minval=10, maxval=1_000_000),
        http=_http_listen(sec), http_token_file=sec._raw("http_token_file", None),
        opcua=read_opcua(sec, name),
    )
    if cfg.http_token_file is not None and not (isinstance(cfg.http_token_file, str)
                                                and cfg.http_token_file.startswith("/")):
        raise ConfigError(sec.path, sec._key("http_token_file"), "must be an absolute path")
    sec.finish()
    return cfg


def _http_listen(sec: Section) -> str | None:
    text = sec._raw("http", None)
    try:
        return None if text is None else (parse_listen(text) and text)
    except ListenError as exc:
        raise ConfigError(sec.path, sec._key("http"), str(exc)) from None
