"""Machine configs are read strictly: a mistake is a ConfigError naming the key, never a guess."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from controller.config import ConfigError, load_config, parse_config

REPO = Path(__file__).resolve().parents[2]
SHIPPED = sorted((REPO / "config").glob("*.yaml"))
BASE = (REPO / "config/xy_table.yaml").read_text()


def _load(tmp_path: Path, text: str) -> None:
    path = tmp_path / "machine.yaml"
    path.write_text(text)
    load_config(str(path))


@pytest.mark.parametrize("path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_every_shipped_config_loads(path: Path) -> None:
    assert load_config(str(path)).name


def test_a_mistyped_required_key_is_named_as_written(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"interpolator\.max_acel_mm_s2: unknown key "
                                          r"\(did you mean max_accel_mm_s2\?\)"):
        _load(tmp_path, BASE.replace("max_accel_mm_s2", "max_acel_mm_s2"))


def test_a_mistyped_optional_key_suggests_the_known_one(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"max_dynamic_rounds: unknown key \(did you mean "
                                          r"max_dynamics_rounds\?\)"):
        _load(tmp_path, BASE.replace("max_dynamics_rounds", "max_dynamic_rounds"))


def test_a_key_given_twice_is_refused_with_both_places(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"(?s)line 2.*'name' is given twice.*line \d+"):
        _load(tmp_path, BASE + "name: dup\n")


def test_yaml_exponent_text_gets_a_hint(tmp_path: Path) -> None:
    text = BASE.replace("max_accel_mm_s2: 2450.0", "max_accel_mm_s2: 1e3")
    assert text != BASE
    with pytest.raises(ConfigError, match=r"got '1e3' \(YAML reads 1e3 as text: write "
                                          r"1\.0e\+3\)"):
        _load(tmp_path, text)


DATA = yaml.safe_load(BASE)
PATHS = [(k,) for k in DATA] + [(k, j) for k, v in DATA.items() if isinstance(v, dict)
                                for j in v]


@settings(max_examples=300, deadline=None)
@given(st.sampled_from(PATHS), st.sampled_from(["drop", "rename", "value"]),
       st.none() | st.booleans() | st.integers() | st.floats(allow_nan=True)
       | st.text(max_size=5) | st.lists(st.integers(), max_size=3))
def test_any_one_mistake_is_a_config_error_or_a_valid_config(path: tuple, action: str,
                                                             value: object) -> None:
    import copy
    data = copy.deepcopy(DATA)
    parent = data if len(path) == 1 else data[path[0]]
    key = path[-1]
    if action == "drop":
        del parent[key]
    elif action == "rename":
        parent[key + "x"] = parent.pop(key)
    else:
        parent[key] = value
    try:
        parse_config(data, "machine.yaml")
    except ConfigError:
        pass


def test_a_folder_is_not_a_config(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="a folder, not a configuration file"):
        load_config(str(tmp_path))
    with pytest.raises(ConfigError, match="no such configuration file"):
        load_config(str(tmp_path / "nope.yaml"))


# -- hostile and nonsensical configs: a ConfigError naming the key, never a crash ----------
LAUGHS = "".join(f"l{i}: &l{i} [{', '.join([f'*l{i - 1}'] * 9) if i else 'x'}]\n"
                 for i in range(9))


@pytest.mark.parametrize("text, match", [
    ("extra: " + "[" * 5000 + "]" * 5000 + "\n" + BASE, "nested"),  # was RecursionError
    ("? [a, b]\n: 1\n" + BASE, "a key must be a name or a number"),  # was TypeError
    (LAUGHS + BASE, "once its aliases are expanded"),  # was 1.8 GB and on
    ("x: " + "[" * 40 + "]" * 40 + "\n" + BASE, "nested more than 32 levels"),
])
def test_documents_no_config_can_be_are_refused_before_they_are_built(
        tmp_path: Path, text: str, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        _load(tmp_path, text)


def test_an_alias_a_config_may_use_still_loads(tmp_path: Path) -> None:
    text = BASE.replace("servo: {a0", "servo: &s {a0", 1)
    assert text != BASE
    _load(tmp_path, text)


@pytest.mark.parametrize("old, new, match", [
    ("sample_period_s: 0.001", "sample_period_s: 1.0e-9", "sample_period_s: must be >= "),
    ("a0: 1.938e+9", "a0: 1.0e+300", r"axes\.x\.servo\.a0: must be <= 1e\+30"),
    ("max_accel_mm_s2: 2450.0", "max_accel_mm_s2: 1.0e-9",
     r"interpolator\.max_accel_mm_s2: reaching max_feed_mm_min takes"),
    ("a3: 698.4", "a3: 1.0", r"axes\.x\.servo: unstable: poles .*79\.2[+-]473\.3j"),
    ("a3: 698.4", "a3: 250.0", r"axes\.x\.servo: damping 0\.078 below 0\.1"),
    ("b0: 1.938e+9", "b0: 1.938e+6", r"axes\.x\.servo\.b0: b0 / a0 = 0\.001"),
])
def test_a_machine_no_plan_can_serve_is_refused_naming_the_key(
        tmp_path: Path, old: str, new: str, match: str) -> None:
    text = BASE.replace(old, new, 1)
    assert text != BASE
    with pytest.raises(ConfigError, match=match):
        _load(tmp_path, text)
def test_reference_buffer_and_in_position_keys_default_and_are_checked(tmp_path: Path) -> None:
    cfg = load_config(str(REPO / "config/xy_table.yaml"))
    assert cfg.runtime.reference_buffer_s == 5.0
    assert cfg.runtime.in_position_tolerance_mm == 0.002
    runtime = "runtime:\n  nc_fifo_blocks: 64\n"
    path = tmp_path / "machine.yaml"
    path.write_text(BASE.replace(runtime, runtime + "  reference_buffer_s: 12.5\n"
                                 "  in_position_tolerance_mm: 0.005\n"))
    cfg = load_config(str(path))
    assert (cfg.runtime.reference_buffer_s, cfg.runtime.in_position_tolerance_mm) == (12.5,
                                                                                      0.005)
    for bad, key in (("reference_buffer_s: 0.1", "runtime.reference_buffer_s"),
                     ("reference_buffer_s: '5'", "runtime.reference_buffer_s"),
                     ("in_position_tolerance_mm: 0.0", "runtime.in_position_tolerance_mm"),
                     ("reference_buffer: 5.0", "runtime.reference_buffer")):
        with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
            _load(tmp_path, BASE.replace(runtime, runtime + f"  {bad}\n"))


def test_model_watch_share_defaults_to_half_and_is_checked(tmp_path: Path) -> None:
    assert load_config(str(REPO / "config/xy_table.yaml")).runtime.model_watch_share == 0.5
    runtime = "runtime:\n  nc_fifo_blocks: 64\n"
    path = tmp_path / "machine.yaml"
    path.write_text(BASE.replace(runtime, runtime + "  model_watch_share: 0.8\n"))
    assert load_config(str(path)).runtime.model_watch_share == 0.8
    for bad in ("model_watch_share: 0.0", "model_watch_share: -1.0", "model_watch_share: 101.0",
                "model_watch_share: 'half'"):
        with pytest.raises(ConfigError, match=r"runtime\.model_watch_share"):
            _load(tmp_path, BASE.replace(runtime, runtime + f"  {bad}\n"))
    with pytest.raises(ConfigError, match=r"runtime\.model_watch"):
        _load(tmp_path, BASE.replace(runtime, runtime + "  model_watch: 0.5\n"))
