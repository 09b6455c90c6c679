"""Keys as family objects: each family builds its keys; the builders are the families'."""

import pytest

from common import keys


def test_each_family_builds_its_own_keys_and_the_builders_are_the_families():
    """Keys as family objects (issue 24): the shape of a key is written once, in FAMILIES."""
    assert keys.BATTERY_STATE.key("mapp-1") == keys.battery_state("mapp-1") == "lunaris/mapp-1/battery/state"
    assert keys.LOAD_POWER.key("mapp-1", "imu") == keys.load_power("mapp-1", "imu") \
        == "lunaris/mapp-1/load/imu/power"
    assert keys.INPUT_PANEL_SUN_ANGLE.key("*", "left") == "lunaris/*/input/solar/left/sun_angle"
    for family in keys.FAMILIES:
        name = "x" if family.placeholder else None
        built = family.key("r", name)
        assert family.matches(keys.split(built)[1]), family.name
    with pytest.raises(TypeError, match="takes a load name"):
        keys.LOAD_POWER.key("mapp-1")
    with pytest.raises(TypeError, match="takes no name"):
        keys.CLOCK.key("mapp-1", "x")
