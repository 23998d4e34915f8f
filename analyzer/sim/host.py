"""A scripted host program: the robot controller side of a pick-and-place cell.

``run_host_cycle`` drives one or more grippers through pick-and-place cycles on any of the three
protocols, the way real controllers do it (reference sections 1.4 and 4): set speed and force,
close on the object, poll state and opening every ``poll_s`` until the catch completes (state 6,
or 2 when there was nothing to catch), "move the arm" for a moment, open, poll until fully open.
It keeps at least ``min_gap_s`` (5 ms) between commands, waits ``timeout_s`` (30 ms) for each
answer and resends a few times (also after a failure status 0x55 or a bad checksum), and waits
more than a second after a save.

Quirks of third-party clients (section 4) are options of ``HostQuirks``; the wire forms of
each action are in ``dialects``, the transactions in ``hostlink``.

Usable from a thread: pass a ``threading.Event`` and set it to stop; the function returns
within about one time-out.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterable

import can
import serial

from .dialects import FORCE, SPEED, Driver, HostQuirks, connect
from .hostlink import MIN_GAP_S, RETRIES, TIMEOUT_S, GripperReading, HostResult, Stopped

__all__ = ["GripperReading", "HostQuirks", "HostResult", "run_host_cycle"]


def run_host_cycle(
    protocol: str,
    port_or_bus: str | serial.Serial | can.BusABC,
    ids: Iterable[int] = (1,),
    cycles: int | None = 1,
    stop_event: threading.Event | None = None,
    quirks: HostQuirks | None = None,
    *,
    speed: int = SPEED,
    force: int = FORCE,
    poll_s: float = 0.025,
    timeout_s: float = TIMEOUT_S,
    min_gap_s: float = MIN_GAP_S,
    retries: int = RETRIES,
    dwell_s: float = 0.1,
    motion_timeout_s: float = 3.0,
    result: HostResult | None = None,
) -> HostResult:
    """Run ``cycles`` pick-and-place cycles (None: until stop_event) on every gripper in ids.

    protocol: "serial", "modbus" or "can". port_or_bus: a serial port path (or an open
    pyserial port) for serial and Modbus; a python-can bus, or a virtual channel name, for CAN.
    Pass ``result`` to watch progress from another thread. Returns the HostResult.
    """
    stop = stop_event if stop_event is not None else threading.Event()
    quirks = quirks if quirks is not None else HostQuirks()
    result = result if result is not None else HostResult()
    driver = connect(
        protocol,
        port_or_bus,
        stop,
        result,
        quirks,
        speed=speed,
        force=force,
        timeout_s=timeout_s,
        min_gap_s=min_gap_s,
        retries=retries,
    )
    try:
        _program(driver, list(ids), cycles, stop, quirks, result, poll_s, dwell_s, motion_timeout_s)
    except Stopped:
        pass
    finally:
        driver.shutdown()
    return result


def _program(
    driver: Driver,
    devices: list[int],
    cycles: int | None,
    stop: threading.Event,
    quirks: HostQuirks,
    result: HostResult,
    poll_s: float,
    dwell_s: float,
    motion_timeout_s: float,
) -> None:
    if quirks.id_scan:
        for device in range(1, quirks.id_scan + 1):
            if driver.probe(device):
                result.found.append(device)
    for device in devices:
        result.grips.setdefault(device, 0)
        result.states_seen.setdefault(device, set())
        driver.setup(device)
    if quirks.save_first:
        for device in devices:
            driver.save(device)
        if stop.wait(1.05):  # the manual: allow more than 1 s after a save
            raise Stopped
    done = 0
    while cycles is None or done < cycles:
        # pick: close every gripper on its object, wait for the catch
        for device in devices:
            driver.close(device)
        final = _wait_for(driver, devices, {2, 3, 6}, stop, result, poll_s, motion_timeout_s)
        for device, state in final.items():
            if state == 6:
                result.grips[device] += 1
        _dwell(driver, devices, stop, result, poll_s, dwell_s)  # the arm carries the object
        # place: open, wait until fully open
        for device in devices:
            driver.open(device)
        _wait_for(driver, devices, {1, 3}, stop, result, poll_s, motion_timeout_s)
        _dwell(driver, devices, stop, result, poll_s, dwell_s)  # the arm goes back
        done += 1
        result.cycles = done


def _poll_all(driver: Driver, devices: list[int], result: HostResult) -> dict[int, int | None]:
    states: dict[int, int | None] = {}
    for device in devices:
        reading = driver.poll(device)
        states[device] = None if reading is None else reading.state
        if reading is not None:
            result.last[device] = reading
            if reading.state is not None:
                result.states_seen.setdefault(device, set()).add(reading.state)
            if reading.fault:
                driver.clear_faults(device)
    return states


def _wait_for(
    driver: Driver,
    devices: list[int],
    done_states: set[int],
    stop: threading.Event,
    result: HostResult,
    poll_s: float,
    limit_s: float,
) -> dict[int, int | None]:
    """Poll until every gripper is in one of done_states (or limit_s passes)."""
    deadline = time.monotonic() + limit_s
    waiting = list(devices)
    final: dict[int, int | None] = {}
    while waiting and time.monotonic() < deadline:
        started = time.monotonic()
        states = _poll_all(driver, waiting, result)
        for device, state in states.items():
            if state in done_states:
                final[device] = state
                waiting.remove(device)
        if not waiting:
            break
        if stop.wait(max(0.0, poll_s - (time.monotonic() - started))):
            raise Stopped
    for device in waiting:
        final[device] = None
    return final


def _dwell(
    driver: Driver,
    devices: list[int],
    stop: threading.Event,
    result: HostResult,
    poll_s: float,
    dwell_s: float,
) -> None:
    """Keep polling (as controllers do) while the arm moves."""
    end = time.monotonic() + dwell_s
    while time.monotonic() < end:
        started = time.monotonic()
        _poll_all(driver, devices, result)
        if stop.wait(max(0.0, min(poll_s - (time.monotonic() - started), end - time.monotonic()))):
            raise Stopped
