"""The `service.opcua` section of a machine config: the OPC UA server cncd starts beside itself
(off unless the section is there), its endpoint, the machine's identification and who may call
its methods."""

from __future__ import annotations

from dataclasses import dataclass
from urllib.parse import urlsplit

from controller.errors import ConfigError
from controller.yaml_strict import Section

DEFAULT_PUBLISH_MS = 50.0


@dataclass(frozen=True, slots=True)
class OpcuaConfig:
    endpoint: str  # opc.tcp://HOST:PORT[/PATH]
    machine_name: str  # the machine's browse name under Objects/Machines
    manufacturer: str
    model: str
    serial_number: str
    methods: bool = False  # Hold, Resume, Abort for authenticated users; read-only without
    users_file: str | None = None  # user:pbkdf2 lines, readable by cncd's user only
    min_publish_ms: float = DEFAULT_PUBLISH_MS  # the fastest publishing interval granted
    certificate: str | None = None  # the server's certificate (DER or PEM) and key (PEM): a
    private_key: str | None = None  # Basic256Sha256 endpoint, and passwords sent encrypted

    @property
    def host_port(self) -> tuple[str, int]:
        parts = urlsplit(self.endpoint)
        return parts.hostname or "", parts.port or 4840


def read_opcua(sec: Section, machine_name: str) -> OpcuaConfig | None:
    """The section, or None when it is absent (no OPC UA server)."""
    if "opcua" not in sec.data:
        sec.used.add("opcua")
        return None
    s = sec.section("opcua")
    endpoint = s.str("endpoint")
    _check_endpoint(s, endpoint)
    cfg = OpcuaConfig(
        endpoint=endpoint,
        machine_name=_text(s, "machine_name", machine_name),
        manufacturer=_text(s, "manufacturer", "not set"),
        model=_text(s, "model", machine_name),
        serial_number=_text(s, "serial_number", "not set"),
        methods=s.bool("methods", False),
        users_file=s.str("users_file", "") or None,
        min_publish_ms=s.float("min_publish_ms", DEFAULT_PUBLISH_MS, minval=10.0,
                               maxval=10000.0),
        certificate=s.str("certificate", "") or None,
        private_key=s.str("private_key", "") or None,
    )
    if (cfg.certificate is None) != (cfg.private_key is None):
        raise ConfigError(s.path, s._key("certificate" if cfg.certificate is None
                                         else "private_key"),
                          "is required with the other (certificate and private_key)")
    if cfg.methods and cfg.users_file is None:
        raise ConfigError(s.path, s._key("users_file"), "is required with methods: true (the "
                          "users who may call Hold, Resume and Abort)")
    for key in ("users_file", "certificate", "private_key"):
        value = getattr(cfg, key)
        if value is not None and not value.startswith("/"):
            raise ConfigError(s.path, s._key(key), "must be an absolute path")
    s.finish()
    return cfg


def _text(s: Section, key: str, default: str) -> str:
    value = s.str(key, default)
    if not value or len(value) > 200 or any(ord(c) < 32 for c in value):
        raise ConfigError(s.path, s._key(key), "must be a one-line text of 1-200 characters")
    return value


def _check_endpoint(s: Section, endpoint: str) -> None:
    parts = urlsplit(endpoint)
    try:
        port = parts.port
    except ValueError:
        port = -1
    if parts.scheme != "opc.tcp" or not parts.hostname or port is None or not 0 < port < 65536:
        raise ConfigError(s.path, s._key("endpoint"), "must be opc.tcp://HOST:PORT[/PATH], "
                          "e.g. opc.tcp://0.0.0.0:4840/phcnc")
