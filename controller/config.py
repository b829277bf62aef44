"""Machine configuration: strict YAML reading into typed, frozen objects (klippy style)."""

from __future__ import annotations

import importlib
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import yaml

from controller.backends import BUILTIN_BACKENDS, backend_names
from controller.errors import ConfigError
from controller.gcode_config import GcodeConfig, read_gcode_section
from controller.io_config import IoConfig, read_io
from controller.service_config import ServiceConfig, read_service
from controller.servo_poles import pole_problem
from controller.tools import ToolsConfig, read_tools_section
from controller.yaml_strict import Section, StrictLoader

DEFAULT_CONFIG_NAME = "xy_table"
CONFIG_ENV_VAR = "CNC_CONFIG"
# The installed machine's config (systemd/install.py writes it): `cncctl` and `cncd` read it
# when neither --config nor $CNC_CONFIG names one, so both see the same machine.
SYSTEM_CONFIG_PATH = Path("/etc/cncd/cncd.yaml")
CONFIG_HELP = (f"machine configuration, a YAML file or a built-in name (default: "
               f"${CONFIG_ENV_VAR}, else {SYSTEM_CONFIG_PATH} if it exists, "
               f"else {DEFAULT_CONFIG_NAME})")


@dataclass(frozen=True, slots=True)
class ServoParams:
    """Closed-loop position model of one axis (paper eq. 27, Table II)."""

    a0: float
    a1: float
    a2: float
    a3: float
    a4: float
    b0: float
    b1: float
    b2: float


@dataclass(frozen=True, slots=True)
class ServoBand:
    """How far the real loop may be from its model (`axes.<a>.servo_band`): its poles anywhere
    within +-pole_pct of the model's and its velocity and acceleration lags within +-gain_pct
    (controller/servo/model.mismatched); the generator then plans for every plant in it."""

    pole_pct: float = 0.0
    gain_pct: float = 0.0


@dataclass(frozen=True, slots=True)
class HomingConfig:
    """One axis's homing sequence (LinuxCNC HOME_* style), run by the drive (CiA 402 mode 6).

    Search toward the switch at search speed, back off, approach again at latch speed; the
    point found (switch edge, or the encoder index after it) becomes home_mm in machine
    coordinates, then the axis moves to final_mm."""

    direction: int  # -1: search toward negative travel, +1 toward positive
    search_mm_s: float
    latch_mm_s: float
    home_mm: float  # machine coordinate of the point found
    final_mm: float  # where the axis stands once homed
    use_index: bool  # latch on the encoder index after the switch (not the switch edge)
    sequence: int  # axes home in increasing sequence; equal sequences home together
    accel_mm_s2: float  # search and latch moves (0x609A)


@dataclass(frozen=True, slots=True)
class AxisConfig:
    name: str
    servo: ServoParams
    travel_mm: tuple[float, float]
    pulse_mm: float
    max_velocity_mm_s: float
    ferror_mm: float  # following-error limit at full speed (LinuxCNC FERROR)
    min_ferror_mm: float  # following-error floor (LinuxCNC MIN_FERROR)
    homing: HomingConfig | None = None  # None: no homing sequence (the position is absolute)
    servo_band: ServoBand | None = None  # None: the plant is taken to be its model

    def ferror_limit_mm(self, v_mm_s: float) -> float:
        """LinuxCNC rule: max(MIN_FERROR, FERROR * |v| / Vmax)."""
        return max(self.min_ferror_mm, self.ferror_mm * abs(v_mm_s) / self.max_velocity_mm_s)


@dataclass(frozen=True, slots=True)
class InterpolatorConfig:
    """The interpolator parameters of Table III plus the rapid feed."""

    max_feed_mm_s: float
    max_accel_mm_s2: float
    chord_tolerance_mm: float
    reference_curvature_per_mm: float
    contour_error_limit_mm: float
    ph_error_limit_mm: float
    rapid_feed_mm_s: float
    max_dynamics_rounds: int
    # Send X and Y a reference that leads the path by the servo model's lag, so the model's
    # actual position follows the path itself (controller/servo/precompensation.py).
    # Off is the paper's method (Table IV); on, the contour limit rarely binds.
    servo_precompensation: bool = False
    # The share of a feed transition whose acceleration is not constant: 1 is the paper's
    # quintic (peak 15/8 of the mean); lower is shorter at the same Amax but with more jerk,
    # which the pre-compensation and the dynamics module's contour check have to absorb
    # (controller/generator/feed/shape.py).
    ramp_share: float = 1.0

    @property
    def kappa_threshold_per_mm(self) -> float:
        """Sharp-corner curvature threshold (eq. 15): Amax / Vmax**2."""
        return self.max_accel_mm_s2 / self.max_feed_mm_s**2


@dataclass(frozen=True, slots=True)
class DriveConfig:
    backend: str
    options: tuple[tuple[str, Any], ...] = ()


@dataclass(frozen=True, slots=True)
class RuntimeConfig:
    nc_fifo_blocks: int
    card_fifo_low_water_ms: float
    card_fifo_high_water_ms: float
    in_position_tolerance_mm: float = 0.002  # a run's motion time ends this close to the end
    reference_buffer_s: float = 5.0  # reference points planned ahead of the motion loop
    # A job warns (model_warning) where the measured contour leaves the servo model's
    # prediction by more than this share of the contour limit (controller/motion/model_watch.py).
    model_watch_share: float = 0.5


@dataclass(frozen=True, slots=True)
class MachineConfig:
    name: str
    path: str
    sample_period_s: float
    axes: tuple[AxisConfig, ...]
    interpolator: InterpolatorConfig
    drive: DriveConfig
    runtime: RuntimeConfig = field(default_factory=lambda: RuntimeConfig(64, 20.0, 100.0))
    service: ServiceConfig = field(default_factory=ServiceConfig)
    allow_unhomed: bool = False  # run programs before the axes with a homing sequence are homed
    tools: ToolsConfig = field(default_factory=ToolsConfig)  # tool table, M6 position
    io: IoConfig = field(default_factory=IoConfig)  # machine outputs -> backend outputs
    gcode: GcodeConfig = field(default_factory=GcodeConfig)  # subroutine folders

    @property
    def axis_names(self) -> tuple[str, ...]:
        return tuple(a.name for a in self.axes)

    def axis(self, name: str) -> AxisConfig:
        for a in self.axes:
            if a.name == name:
                return a
        raise KeyError(name)

    def has_axis(self, name: str) -> bool:
        return name in self.axis_names

    def with_drive_options(self, overrides: dict[str, Any]) -> MachineConfig:
        """The same machine with drive.options overridden (`--drive-option KEY=VALUE`)."""
        if not overrides:
            return self
        options = dict(self.drive.options) | overrides
        return replace(self, drive=replace(self.drive, options=tuple(sorted(options.items()))))


def _read_servo(sec: Section) -> ServoParams:
    values = {k: sec.float(k, above=0.0, maxval=1e30)
              for k in ("a0", "a1", "a2", "a3", "a4", "b0", "b1", "b2")}
    if not 0.5 <= values["b0"] / values["a0"] <= 2.0:  # a position loop tracks: b0 = a0
        raise ConfigError(sec.path, sec._key("b0"), f"b0 / a0 = {values['b0'] / values['a0']:.3g}: "
                          "a position loop's static gain must be near 1 (b0 = a0)")
    sec.finish()
    return ServoParams(**values)


def _read_axis(sec: Section, name: str) -> AxisConfig:
    axis = AxisConfig(
        name=name,
        servo=_read_servo(sec.section("servo")),
        travel_mm=sec.range("travel_mm"),
        pulse_mm=sec.float("pulse_mm", above=0.0, maxval=1.0),
        max_velocity_mm_s=sec.float("max_velocity_mm_s", above=0.0, maxval=10000.0),
        ferror_mm=sec.float("ferror_mm", above=0.0, maxval=100.0),
        min_ferror_mm=sec.float("min_ferror_mm", above=0.0, maxval=100.0),
        homing=None,
    )
    if "homing" in sec.data:
        axis = replace(axis, homing=_read_homing(sec.section("homing"), axis))
    if "servo_band" in sec.data:
        axis = replace(axis, servo_band=_read_band(sec.section("servo_band")))
    sec.finish()
    return axis


# A band this wide is no longer a model of the loop (and a pole 50 % slower halves the bandwidth).
MAX_BAND_PCT = 50.0


def _read_band(sec: Section) -> ServoBand:
    band = ServoBand(pole_pct=sec.float("pole_pct", 0.0, minval=0.0, maxval=MAX_BAND_PCT),
                     gain_pct=sec.float("gain_pct", 0.0, minval=0.0, maxval=MAX_BAND_PCT))
    sec.finish()
    return band


def _read_homing(sec: Section, axis: AxisConfig) -> HomingConfig:
    lo, hi = axis.travel_mm
    direction = sec.int("direction", minval=-1, maxval=1)
    if direction == 0:
        raise ConfigError(sec.path, sec._key("direction"), "must be -1 or 1")
    home_mm = sec.float("home_mm", minval=lo, maxval=hi)
    cfg = HomingConfig(
        direction=direction,
        search_mm_s=sec.float("search_mm_s", above=0.0, maxval=axis.max_velocity_mm_s),
        latch_mm_s=sec.float("latch_mm_s", above=0.0, maxval=axis.max_velocity_mm_s),
        home_mm=home_mm,
        final_mm=sec.float("final_mm", home_mm, minval=lo, maxval=hi),
        use_index=sec.bool("use_index", False),
        sequence=sec.int("sequence", 0, minval=0, maxval=9),
        accel_mm_s2=sec.float("accel_mm_s2", 500.0, above=0.0, maxval=1e6),
    )
    if cfg.latch_mm_s > cfg.search_mm_s:
        raise ConfigError(sec.path, sec._key("latch_mm_s"), "must not exceed search_mm_s")
    sec.finish()
    return cfg


def _read_interpolator(sec: Section) -> InterpolatorConfig:
    cfg = InterpolatorConfig(
        max_feed_mm_s=sec.float("max_feed_mm_min", above=0.0, maxval=600000.0) / 60.0,
        max_accel_mm_s2=sec.float("max_accel_mm_s2", above=0.0, maxval=1e6),
        chord_tolerance_mm=sec.float("chord_tolerance_mm", above=0.0, maxval=1.0),
        reference_curvature_per_mm=sec.float("reference_curvature_per_mm", above=0.0),
        contour_error_limit_mm=sec.float("contour_error_limit_mm", above=0.0, maxval=10.0),
        ph_error_limit_mm=sec.float("ph_error_limit_mm", above=0.0, maxval=1.0),
        rapid_feed_mm_s=sec.float("rapid_feed_mm_min", above=0.0, maxval=600000.0) / 60.0,
        max_dynamics_rounds=sec.int("max_dynamics_rounds", 20, minval=1, maxval=1000),
        servo_precompensation=sec.bool("servo_precompensation", False),
        ramp_share=sec.float("ramp_share", 1.0, minval=0.01, maxval=1.0),
    )
    sec.finish()
    return cfg


def _read_drive(sec: Section) -> DriveConfig:
    backend = sec.str("backend")
    if backend not in BUILTIN_BACKENDS:  # only then are the installed packages looked through
        backend = sec.str("backend", choices=backend_names())
    options = sec.mapping("options", {})
    sec.finish()
    return DriveConfig(backend=backend, options=tuple(sorted(options.items())))


def _read_runtime(sec: Section) -> RuntimeConfig:
    cfg = RuntimeConfig(
        nc_fifo_blocks=sec.int("nc_fifo_blocks", 64, minval=2, maxval=100000),
        card_fifo_low_water_ms=sec.float("card_fifo_low_water_ms", 20.0, above=0.0),
        card_fifo_high_water_ms=sec.float("card_fifo_high_water_ms", 100.0, above=0.0),
        in_position_tolerance_mm=sec.float("in_position_tolerance_mm", 0.002, above=0.0,
                                           maxval=1.0),
        reference_buffer_s=sec.float("reference_buffer_s", 5.0, minval=1.0, maxval=600.0),
        model_watch_share=sec.float("model_watch_share", 0.5, above=0.0, maxval=100.0),
    )
    if cfg.card_fifo_low_water_ms >= cfg.card_fifo_high_water_ms:
        raise ConfigError(sec.path, "runtime.card_fifo_low_water_ms", "must be below high water")
    sec.finish()
    return cfg


def parse_config(data: Any, path: str) -> MachineConfig:
    """Build a MachineConfig from parsed YAML; any mistake is a ConfigError naming the key."""
    top = Section(data, path, "")
    name = top.str("name")
    period = top.float("sample_period_s", minval=1e-4, maxval=0.1)
    axes_sec = top.mapping("axes")
    for axis_name in axes_sec:
        if axis_name not in ("x", "y", "z"):
            raise ConfigError(path, f"axes.{axis_name}", "unknown axis (x, y, z)")
    for needed in ("x", "y"):
        if needed not in axes_sec:
            raise ConfigError(path, f"axes.{needed}", "is required")
    axes = tuple(_read_axis(Section(axes_sec[a], path, f"axes.{a}"), a)
                 for a in ("x", "y", "z") if a in axes_sec)
    cfg = MachineConfig(
        name=name,
        path=path,
        sample_period_s=period,
        axes=axes,
        interpolator=_read_interpolator(top.section("interpolator")),
        drive=_read_drive(top.section("drive")),
        runtime=_read_runtime(top.section("runtime", {})),
        service=read_service(top.section("service", {}), name),
        allow_unhomed=top.bool("allow_unhomed", False),
        tools=read_tools_section(top.section("tools", {}), tuple(a.name for a in axes),
                                 tuple(a.travel_mm for a in axes)),
        io=read_io(top.section("io", {})),
        gcode=read_gcode_section(top.section("gcode", {})),
    )
    top.finish()
    _check_plan_sizes(cfg, path)
    for axis in axes:
        sv = axis.servo
        problem = pole_problem((sv.a4, sv.a3, sv.a2, sv.a1, sv.a0), period)
        if problem is not None:
            raise ConfigError(path, f"axes.{axis.name}.servo", problem)
        if axis.servo_band is not None:
            # Its fastest plant: every pole moved out by pole_pct (servo.model.mismatched).
            k = 1.0 + axis.servo_band.pole_pct / 100.0
            problem = pole_problem((sv.a4 / k**4, sv.a3 / k**3, sv.a2 / k**2, sv.a1 / k, sv.a0),
                                   period)
            if problem is not None:
                raise ConfigError(path, f"axes.{axis.name}.servo_band.pole_pct",
                                  f"the band's fastest plant: {problem}")
    if cfg.interpolator.servo_precompensation:
        for axis in axes[:2]:
            if abs(axis.servo.a0 - axis.servo.b0) > 1e-9 * axis.servo.a0:
                raise ConfigError(path, "interpolator.servo_precompensation",
                                  f"needs a0 = b0 on axes.{axis.name}.servo (a loop without "
                                  "steady position error)")
    return cfg


MAX_RAMP_S = 60.0  # Vmax / Amax: a ramp of minutes is a typo (1e-9 planned 1.4 TiB of ramp)


def _check_plan_sizes(cfg: MachineConfig, path: str) -> None:
    """Limits whose ratio sets how long a plan's ramps are, and so its memory."""
    ip = cfg.interpolator
    for name, value_mm_s in (("max_feed_mm_min", ip.max_feed_mm_s),
                             ("rapid_feed_mm_min", ip.rapid_feed_mm_s)):
        ramp_s = value_mm_s / ip.max_accel_mm_s2
        if ramp_s > MAX_RAMP_S:
            raise ConfigError(path, "interpolator.max_accel_mm_s2", f"reaching {name} takes "
                              f"{ramp_s:.3g} s at {ip.max_accel_mm_s2:g} mm/s^2 (at most "
                              f"{MAX_RAMP_S:g} s)")


def builtin_config_path(name: str) -> Path | None:
    """The installed copy of a built-in config (`xy_table`, `xyz_mill`), if there is one."""
    # The package's folder, not importlib.resources: that one imports tempfile, shutil and
    # the compressors (~20 ms of every command's start-up) for the zip installs phcnc has not.
    package = importlib.import_module("controller.machine_configs")
    candidate = Path(package.__file__).parent / f"{name}.yaml"  # type: ignore[arg-type]
    return candidate if candidate.is_file() else None


def resolve_config_path(explicit: str | None = None) -> Path:
    """--config FILE, else $CNC_CONFIG, else /etc/cncd/cncd.yaml if there is one, else the
    built-in xy_table; a bare name is a built-in. `cncctl` and `cncd` both resolve here."""
    chosen = explicit or os.environ.get(CONFIG_ENV_VAR)
    if not chosen:
        if SYSTEM_CONFIG_PATH.is_file():
            return SYSTEM_CONFIG_PATH
        chosen = DEFAULT_CONFIG_NAME
    path = Path(chosen)
    if path.is_file():
        return path
    builtin = builtin_config_path(chosen.removesuffix(".yaml"))
    if builtin is not None and os.sep not in chosen:
        return builtin
    if path.is_dir():
        raise ConfigError(chosen, "<file>", "a folder, not a configuration file")
    raise ConfigError(chosen, "<file>", "no such configuration file (nor a built-in one)")


MAX_CONFIG_BYTES = 1 << 20  # a machine config is a few kB; a larger file is refused unread


def load_config(explicit: str | None = None) -> MachineConfig:
    """Load and check a machine configuration (see resolve_config_path for which one)."""
    path = resolve_config_path(explicit)
    try:
        with path.open("rb") as fh:
            raw = fh.read(MAX_CONFIG_BYTES + 1)
        if len(raw) > MAX_CONFIG_BYTES:
            raise ConfigError(str(path), "<file>", f"larger than {MAX_CONFIG_BYTES} bytes: "
                              "not a machine configuration")
        text = raw.decode("utf-8")
        data = yaml.load(text, Loader=StrictLoader)  # noqa: S506  (a SafeLoader)
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(str(path), "<file>", f"cannot read: {exc}") from exc
    except yaml.YAMLError as exc:
        raise ConfigError(str(path), "<file>", f"not valid YAML: {exc}") from exc
    except RecursionError:  # PyYAML's parser recurses per level, before any limit of ours
        raise ConfigError(str(path), "<file>", "nested too deeply: not a machine "
                          "configuration") from None
    return parse_config(data, str(path))
