"""The plant_<axis> drive options: the eq. 27 text read and written back, pole checks, refusals."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from controller.config import ServoParams, load_config
from controller.servo.model import mismatched
from controller.servo.plant_option import (
    PlantOptionError,
    parse_plant,
    plant_config,
    plant_text,
)

T_S = 0.001
XY = load_config("xy_table")
NOMINAL_X = XY.axis("x").servo


@st.composite
def stable_plants(draw: st.DrawFn) -> ServoParams:
    """A damped eq. 27 loop under the Nyquist rate at 1 ms: two pole pairs, any scale."""
    poles = []
    for _ in range(2):
        magnitude = draw(st.floats(1.0, 2500.0))
        angle = draw(st.floats(0.0, 1.4))  # from the negative real axis: damping cos >= 0.17
        poles += [magnitude * -np.exp(1j * angle), magnitude * -np.exp(-1j * angle)]
    a4 = draw(st.floats(1e-6, 1e3))
    a4, a3, a2, a1, a0 = (a4 * np.real(np.poly(poles))).tolist()
    b0 = a0 * draw(st.floats(0.5, 2.0))
    b1, b2 = a1 * draw(st.floats(0.0, 1.0)), a2 * draw(st.floats(0.0, 1.0))
    return ServoParams(a0=a0, a1=a1, a2=a2, a3=a3, a4=a4, b0=b0, b1=b1, b2=b2)


@settings(max_examples=60, deadline=None)
@given(stable_plants())
def test_text_reads_back_as_the_same_plant(plant: ServoParams) -> None:
    assert parse_plant(plant_text(plant), T_S) == plant


@settings(max_examples=200, deadline=None)
@given(st.one_of(st.text(max_size=80),
                 st.lists(st.one_of(st.floats(), st.integers(), st.text(max_size=5),
                                    st.booleans(), st.none()), max_size=10),
                 st.floats(), st.none()))
def test_any_value_is_a_plant_or_an_error_naming_the_option(value: object) -> None:
    try:
        parse_plant(value, T_S, "plant_y")
    except PlantOptionError as exc:
        assert str(exc).startswith("plant_y: ")


def test_the_tables_model_reads_as_written_and_a_yaml_list_too() -> None:
    assert parse_plant(plant_text(NOMINAL_X), T_S) == NOMINAL_X
    assert parse_plant("1.938e+9, 3.538e+7, 2.135e+5, 698.4, 1, 1.938e9, 3.476e7, 1.471e5",
                       T_S) == NOMINAL_X
    assert parse_plant([1.938e9, 3.538e7, 2.135e5, "698.4", 1, 1.938e9, 3.476e7, 1.471e5],
                       T_S) == NOMINAL_X


@pytest.mark.parametrize("text, why", [
    ("1,2,3", "expected eight numbers"),
    ("1,2,3,4,5,6,7,x", "b2 = 'x' is not a number"),
    ("1,2,3,4,5,6,7,nan", "b2 = 'nan' is not a finite number"),
    ("1e31,2,3,4,5,6,7,8", "a0 = '1e31' is not a finite number"),
    ([10**400] * 8, "a0 = 1000"),
    ("1,2,3,4,-1,1,1,1", "a4 and a0 must be positive"),
    # s^4 + s^3 + s^2 + s + 1: two poles on the right half plane
    ("1,1,1,1,1,1,0,0", "unstable"),
    ("2e9,3.5e7,2.1e5,698,1,5e9,3.4e7,1.4e5", "b0 / a0 = 2.5"),
    # (s + 1)^2 (s^2 + 0.02 s + 1e4): a pair with damping 1e-4
    ("10000,20000.02,10001.04,2.02,1,10000,0,0", "damping"),
    # (s + 4000)^4: faster than pi / T at 1 ms
    ("2.56e14,2.56e11,9.6e7,16000,1,2.56e14,0,0", "Nyquist"),
])
def test_a_plant_no_drive_can_run_is_refused_naming_the_option(text: object, why: str) -> None:
    with pytest.raises(PlantOptionError, match="^plant_x: ") as info:
        parse_plant(text, T_S, "plant_x")
    assert why in str(info.value)


def test_the_percentages_apply_on_top_of_the_given_plant() -> None:
    slow = mismatched(NOMINAL_X, -30.0, 0.0)
    machine = plant_config(XY, {"plant_x": plant_text(slow), "plant_pole_pct": 10,
                                "plant_gain_pct": 20})
    assert machine.axis("x").servo == mismatched(slow, 10.0, 20.0)
    assert machine.axis("y").servo == mismatched(XY.axis("y").servo, 10.0, 20.0)
    nominal = plant_config(XY, {})
    assert [a.servo for a in nominal.axes] == [mismatched(a.servo) for a in XY.axes]


def test_faster_poles_past_nyquist_are_refused_with_the_percentage_named() -> None:
    # (s + 2000)^4 passes at 1 ms (Nyquist 3142 rad/s); twice as fast does not.
    fast = "1.6e13,3.2e10,2.4e7,8000,1,1.6e13,0,0"
    plant_config(XY, {"plant_x": fast})
    with pytest.raises(PlantOptionError, match="^plant_x: with plant_pole_pct = 100: .*Nyquist"):
        plant_config(XY, {"plant_x": fast, "plant_pole_pct": 100})


def test_plant_z_needs_a_z_axis() -> None:
    z = plant_text(mismatched(NOMINAL_X, -20.0))
    with pytest.raises(PlantOptionError, match=r"^plant_z: the machine has no Z axis \(axes x, y"):
        plant_config(XY, {"plant_z": z})
    mill = load_config("xyz_mill")
    assert plant_config(mill, {"plant_z": z}).axis("z").servo == mismatched(parse_plant(z, T_S))


@pytest.mark.parametrize("key, value", [("plant_pole_pct", "x"), ("plant_gain_pct", 101),
                                        ("plant_pole_pct", float("nan")),
                                        ("plant_gain_pct", True),
                                        ("plant_pole_pct", 10**400)])
def test_a_bad_percentage_names_itself(key: str, value: object) -> None:
    with pytest.raises(PlantOptionError, match=f"^{key}: "):
        plant_config(XY, {key: value})
