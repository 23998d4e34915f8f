"""The simulated gripper model: motion, grip, continuous catch, limits, temperature, faults,
save pause and the register interface. Pure: time is passed in, nothing waits."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from analyzer.sim.gripper import (
    CLOSING,
    FAULT_OVER_TEMPERATURE,
    FAULT_STALL,
    FULL_STROKE_S,
    FULLY_CLOSED,
    FULLY_OPEN,
    GRIPPING,
    ILLEGAL_ADDRESS,
    ILLEGAL_VALUE,
    OPENING,
    SAVE_PAUSE_S,
    STOPPED,
    GripperModel,
)


def test_factory_state_matches_the_run_state_vector() -> None:
    m = GripperModel()
    assert (m.state, m.fault, m.temperature_c, m.position, m.force) == (1, 0, 35, 1000, 100)
    assert m.current < 0  # small negative at rest, as the manual's -2
    assert m.read_register(1062, 0.0) == 0xFFFE


def test_motion_toward_target_at_speed() -> None:
    m = GripperModel(speed=1000)
    assert m.move_to(0, 0.0)
    m.step(FULL_STROKE_S / 2)
    assert m.state == CLOSING
    assert m.position == pytest.approx(500, abs=10)
    assert m.current > 0
    m.step(FULL_STROKE_S + 0.01)
    assert (m.position, m.state) == (0, FULLY_CLOSED)
    # half the speed, half the distance in the same time
    assert m.set_speed(500, 1.0)
    assert m.move_to(1000, 1.0)
    m.step(1.0 + FULL_STROKE_S / 2)
    assert m.state == OPENING
    assert m.position == pytest.approx(250, abs=10)
    assert m.current < 0
    m.step(3.0)
    assert (m.position, m.state) == (1000, FULLY_OPEN)


def test_seek_to_the_middle_stops_idle() -> None:
    m = GripperModel()
    assert m.seek(500, 0.0)
    m.step(2.0)
    assert (m.position, m.state) == (500, STOPPED)
    assert not m.seek(0, 2.0)  # the 0x54 section: 1-1000
    assert not m.seek(1001, 2.0)


def test_object_stops_closing_with_state_6_and_force_at_the_limit() -> None:
    m = GripperModel(object_width=400)
    assert m.catch(1000, 300, 0.0)
    m.step(0.45)  # 1000 -> 400 takes 0.42 s at speed 1000
    assert m.position == 400
    assert m.state == CLOSING  # the force is still building up
    assert 0 < m.measured_force < 300
    m.step(1.0)
    assert (m.position, m.state, m.measured_force) == (400, GRIPPING, 300)
    assert m.read_register(1060, 1.0) == 300
    assert m.current > 200  # holding current
    # stop keeps the grip, release lets go
    assert m.stop(1.1) and m.state == GRIPPING
    assert m.release(1000, 1.2)
    assert m.state == OPENING and m.measured_force == 0
    m.step(2.0)
    assert m.state == FULLY_OPEN


def test_no_object_closes_fully() -> None:
    m = GripperModel()
    assert m.catch(1000, 100, 0.0)
    m.step(1.0)
    assert (m.position, m.state, m.measured_force) == (0, FULLY_CLOSED, 0)


def test_continuous_catch_retightens_when_the_grip_is_lost() -> None:
    m = GripperModel(object_width=400)
    assert m.catch(1000, 200, 0.0, continuous=True)
    m.step(1.0)
    assert m.state == GRIPPING
    m.place_object(350, 1.0)  # the object gives way
    assert m.state == CLOSING and m.measured_force == 0
    m.step(2.0)
    assert (m.position, m.state, m.measured_force) == (350, GRIPPING, 200)


def test_single_catch_just_stops_when_the_grip_is_lost() -> None:
    m = GripperModel(object_width=400)
    assert m.catch(1000, 200, 0.0)
    m.step(1.0)
    m.place_object(350, 1.0)
    m.step(2.0)
    assert (m.position, m.state, m.measured_force) == (400, STOPPED, 0)


def test_catch_mode_register_makes_a_1010_move_continuous() -> None:
    m = GripperModel(object_width=600)
    assert m.write_registers(1005, [1], 0.0) == 0
    assert m.write_register(1010, 0, 0.0) == 0
    m.step(1.0)
    assert m.state == GRIPPING
    m.place_object(None, 1.0)  # the object is pulled out: the jaw closes fully
    m.step(3.0)
    assert (m.position, m.state) == (0, FULLY_CLOSED)


def test_raising_the_force_setting_while_holding_squeezes_harder() -> None:
    m = GripperModel(object_width=500)
    m.catch(1000, 100, 0.0)
    m.step(1.0)
    assert m.write_register(1012, 600, 1.0) == 0
    m.step(1.5)
    assert (m.state, m.measured_force) == (GRIPPING, 600)


def test_opening_limits() -> None:
    m = GripperModel()
    assert not m.set_limits(1200, 0, 0.0)
    assert not m.set_limits(100, 200, 0.0)  # max < min
    assert not m.set_limits(500, -1, 0.0)
    assert (m.max_opening, m.min_opening) == (1000, 0)
    assert m.set_limits(800, 100, 0.0)
    assert m.catch(1000, 100, 0.0)
    m.step(2.0)
    assert (m.position, m.state) == (100, FULLY_CLOSED)
    assert m.release(1000, 2.0)
    m.step(4.0)
    assert (m.position, m.state) == (800, FULLY_OPEN)
    assert m.move_to(1000, 4.0)  # clamped to the upper limit
    m.step(5.0)
    assert m.position == 800


def test_register_interface_exceptions() -> None:
    m = GripperModel()
    assert m.write_register(1016, 1001, 0.0) == ILLEGAL_VALUE
    assert m.write_register(1011, 5, 0.0) == ILLEGAL_VALUE  # speed 10-1000 on Modbus
    assert m.write_register(1012, 50, 0.0) == ILLEGAL_VALUE  # force 100-1000 on Modbus
    assert m.write_register(1003, 0, 0.0) == ILLEGAL_VALUE  # 0 is the broadcast address
    assert m.write_registers(1016, [100, 200], 0.0) == ILLEGAL_VALUE  # max < min
    assert m.write_register(1013, 1, 0.0) == ILLEGAL_ADDRESS  # undocumented
    assert m.write_register(1061, 1, 0.0) == ILLEGAL_ADDRESS  # read-only
    assert m.read_register(1013, 0.0) is None
    assert m.read_register(1066, 0.0) is None
    # all or nothing: a bad value in a multiple write changes nothing
    assert m.write_registers(1010, [0, 1000, 5000], 0.0) == ILLEGAL_VALUE
    assert m.state == FULLY_OPEN and m.speed == 500
    assert m.write_registers(1010, [0, 1000, 1000], 0.0) == 0
    assert (m.speed, m.force, m.state) == (1000, 1000, CLOSING)


def test_over_temperature_trips_above_80_and_clears_below_60() -> None:
    m = GripperModel()
    m.inject_fault("over_temperature", now=0.0)
    assert m.fault & FAULT_OVER_TEMPERATURE
    assert m.temperature_c > 80
    assert not m.catch(500, 100, 0.0)  # a faulted gripper does not move
    assert m.clear_faults(0.0)
    assert m.fault & FAULT_OVER_TEMPERATURE  # cannot be cleared by command
    # cooling toward 35 °C (tau 120 s): 70 °C after about 40 s, still faulted
    m.step(40.0)
    assert 60 < m.temperature < 80
    assert m.fault & FAULT_OVER_TEMPERATURE
    m.step(120.0)
    assert m.temperature < 60
    assert m.fault == 0
    assert m.catch(500, 100, 120.0)


def test_working_hard_heats_the_driver_until_it_trips() -> None:
    m = GripperModel(thermal_tau_s=2.0, heat_moving_c=60.0, speed=1000)
    t = 0.0
    while not m.fault and t < 20:
        target = 0 if m.position > 500 else 1000
        m.move_to(target, t)
        t += 0.1
        m.step(t)
    assert m.fault == FAULT_OVER_TEMPERATURE
    assert 75 < m.temperature < 82  # tripped just above 80, cooling since
    assert m.state == STOPPED and not m.moving  # the fault stopped the jaw


def test_clearable_and_permanent_faults() -> None:
    m = GripperModel()
    m.catch(100, 100, 0.0)
    m.inject_fault("stall", now=0.1)
    assert m.fault == FAULT_STALL
    assert m.state == STOPPED and not m.moving
    assert not m.release(500, 0.2)
    assert m.clear_faults(0.3) and m.fault == 0
    assert m.release(500, 0.3)
    m.inject_fault("driver", now=0.4, permanent=True)
    m.clear_faults(0.5)
    assert m.fault  # came straight back
    with pytest.raises(ValueError):
        m.inject_fault("gremlins")


def test_save_pause_and_power_cycle() -> None:
    m = GripperModel()
    assert m.set_id(5, 0.0)
    assert not m.set_id(0, 0.0) and not m.set_id(255, 0.0)
    assert m.save(1.0)
    assert m.busy(1.0) and m.busy(1.0 + SAVE_PAUSE_S - 0.01)
    assert not m.busy(1.0 + SAVE_PAUSE_S + 0.01)
    m.set_speed(900, 3.0)
    m.set_id(6, 3.0)
    m.power_cycle(4.0)
    assert (m.device_id, m.speed) == (5, 500)  # what was saved
    assert m.write_register(1001, 1, 5.0) == 0  # a save through the register
    assert m.busy(5.5)
    assert m.write_register(1002, 1, 7.0) == 0  # factory reset: ID 1 again, and a pause
    assert m.device_id == 1 and m.busy(7.5)


def test_can_ids_go_beyond_254() -> None:
    m = GripperModel()
    m.id_max = 16382
    assert m.write_register(1003, 1000, 0.0) == 0
    assert m.device_id == 1000


actions = st.lists(
    st.tuples(
        st.sampled_from(["catch", "catch2", "release", "seek", "move", "stop", "object", "wait"]),
        st.integers(-100, 1200),
        st.floats(0.0, 0.5),
    ),
    max_size=40,
)


@settings(max_examples=60, deadline=None)
@given(actions)
def test_any_command_sequence_keeps_the_gripper_sane(seq: list[tuple[str, int, float]]) -> None:
    m = GripperModel(object_width=300)
    t = 0.0
    for name, value, dt in seq:
        t += dt
        if name == "catch":
            m.catch(max(1, value), 100, t)
        elif name == "catch2":
            m.catch(500, max(50, min(1000, value)), t, continuous=True)
        elif name == "release":
            m.release(value, t)
        elif name == "seek":
            m.seek(value, t)
        elif name == "move":
            m.move_to(value, t)
        elif name == "stop":
            m.stop(t)
        elif name == "object":
            m.place_object(None if value < 0 else min(1000, value), t)
        m.step(t)
        assert 0 <= m.position <= 1000
        assert 1 <= m.state <= 6
        assert 0 <= m.measured_force <= m.force
        assert -2000 <= m.current <= 2000
        if m.state == GRIPPING:
            assert m.measured_force == m.force
        for reg in (1060, 1061, 1062, 1063, 1064, 1065):
            v = m.read_register(reg, t)
            assert v is not None and 0 <= v <= 0xFFFF
