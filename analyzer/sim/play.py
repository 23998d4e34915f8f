"""Playing a scenario (``scenarios``) on one gripper: the host's side and the world's.

The ``Player`` is the host program of a scripted cell. For each step it sets up the world
through the gripper server's knobs (the part between the jaws, an obstruction, a gripper that
hears nothing, a bus-off), sends the step's motion command in the bus's dialect, and polls
state, opening and force every ``poll_s`` until the motion is over, acting as the step says
on the way (a stop at an opening, a part that slips once the grip is seen). Faults it polls it
clears, as controllers do. When the script ends it starts again (``repeat``) or keeps polling
until it is stopped.

Every step played is written to the ``TruthLog``: the step, the bus and gripper, when its
command went out and when it was over (on the taps' clock, ``time.time()``), whether the
command was answered and the states the host polled. That is the truth a capture of the
scenario is held against.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import IO, Any, Final, Protocol

import can
import serial

from .dialects import Driver, HostQuirks, connect
from .gripper import FULLY_CLOSED, FULLY_OPEN, GRIPPING, STOPPED
from .hostlink import GripperReading, HostResult, Stopped
from .scenarios import CLOSING, Scenario, Step

BUS_OFF_S: Final = 0.3  # how long the gripper's node stays bus-off
# the answer awaited longer than a pick-and-place host does (30 ms): a busy machine must not
# turn a scripted cycle into an unanswered one
TIMEOUT_S: Final = 0.1
UNANSWERED_WATCH_S: Final = 0.3  # polling after a command that got no answer
HOLD_POLLS: Final = 2  # polls of state 6 before a part slips (the grip is seen first)
# the states that end a command's motion
DONE_STATES: Final = {
    "catch": {FULLY_CLOSED, STOPPED, GRIPPING},
    "continuous catch": {FULLY_CLOSED, STOPPED, GRIPPING},
    "release": {FULLY_OPEN, STOPPED},
    "seek": {FULLY_OPEN, FULLY_CLOSED, STOPPED, GRIPPING},
}


class World(Protocol):
    """The knobs of a gripper server (``endpoints``) a scenario turns."""

    def place_object(self, device: int, width: float | None) -> None: ...

    def place_jam(self, device: int, at: float | None) -> None: ...

    def mute(self, device: int, muted: bool) -> None: ...

    def bus_off(self, off_s: float) -> None: ...


@dataclass(slots=True)
class Played:
    """One step as it played: a grip cycle's truth."""

    scenario: str
    protocol: str
    bus: str  # the bus's name in a recording (the demo's rs232, rs485, can0)
    device: int
    index: int  # the step's place in the script, counting on when the script repeats
    step: Step
    start_t: float  # the command went out (time.time(), the taps' clock)
    end_t: float  # the motion was over and the host moved on
    answered: bool
    states: list[int] = field(default_factory=list)  # polled, repeats dropped
    faults_seen: int = 0  # the fault bits polled

    def to_json(self) -> dict[str, Any]:
        return {
            "scenario": self.scenario,
            "protocol": self.protocol,
            "bus": self.bus,
            "device": self.device,
            "index": self.index,
            **self.step.to_json(),
            "start_t": round(self.start_t, 6),
            "end_t": round(self.end_t, 6),
            "answered": self.answered,
            "states": self.states,
            "faults_seen": self.faults_seen,
        }


class TruthLog:
    """Every step played, from any number of players; each also as a JSON line to ``out``."""

    def __init__(self, out: IO[str] | None = None) -> None:
        self.out = out
        self.played: list[Played] = []
        self._lock = threading.Lock()

    def add(self, played: Played) -> None:
        with self._lock:
            self.played.append(played)
            if self.out is not None:
                self.out.write(json.dumps(played.to_json(), separators=(",", ":")) + "\n")
                self.out.flush()


@dataclass(slots=True)
class _Watch:
    """What the host has seen of the current step."""

    states: list[int] = field(default_factory=list)
    faults: int = 0
    gripped_polls: int = 0  # polls of state 6 in a row
    slipped: bool = False
    stopped: bool = False

    def saw(self, state: int) -> None:
        if not self.states or self.states[-1] != state:
            self.states.append(state)
        self.gripped_polls = self.gripped_polls + 1 if state == GRIPPING else 0


class Player:
    """Plays ``scenario`` on gripper ``device`` through ``driver`` (the host's side) and
    ``world`` (the server's knobs) until ``stop`` is set. ``pace``: the simulated jaw's speed-up;
    the host's pauses shrink with it. ``repeat``: play the script over and over even if the
    scenario does not."""

    def __init__(
        self,
        scenario: Scenario,
        protocol: str,
        bus: str,
        driver: Driver,
        world: World,
        device: int,
        stop: threading.Event,
        log: TruthLog,
        *,
        pace: float = 1.0,
        repeat: bool = False,
        poll_s: float = 0.025,
        dwell_s: float = 0.1,
        motion_timeout_s: float = 3.0,
    ) -> None:
        self.scenario = scenario
        self.protocol = protocol
        self.bus = bus
        self.driver = driver
        self.world = world
        self.device = device
        self.stop = stop
        self.log = log
        self.pace = pace
        self.repeat = repeat or scenario.repeat
        self.poll_s = poll_s
        self.dwell_s = dwell_s / pace
        self.motion_timeout_s = motion_timeout_s

    def run(self) -> None:
        """Play until stopped (the link is let go at the end)."""
        try:
            self.driver.setup(self.device)
            self._play_all()
            while True:  # the script is over: a controller keeps watching
                self._poll_for(_Watch(), 1.0, self._never)
        except Stopped:
            pass
        finally:
            self.driver.shutdown()

    def _play_all(self) -> None:
        steps = self.scenario.script(self.protocol)
        index = 0
        while True:
            for step in steps:
                self._play(index, step)
                index += 1
            if not self.repeat:
                return

    def _play(self, index: int, step: Step) -> None:
        world, device = self.world, self.device
        if step.command in CLOSING:
            world.place_object(device, step.part)
            world.place_jam(device, step.jam_at)
        start = time.time()
        answered = self._send(step)
        if answered and step.bus_off:
            world.bus_off(BUS_OFF_S)
        watch = _Watch()
        if answered:
            self._poll_for(watch, self.motion_timeout_s, lambda r: self._advance(step, r, watch))
        else:
            self._poll_for(watch, UNANSWERED_WATCH_S / self.pace, self._never)
        try:
            self._poll_for(watch, self.dwell_s, self._never)  # the arm moves meanwhile
        finally:  # the motion is over: its truth is known, even if the simulator stops now
            world.place_jam(device, None)
            self.log.add(self._played(index, step, start, answered, watch))

    def _played(
        self, index: int, step: Step, start: float, answered: bool, watch: _Watch
    ) -> Played:
        where = (self.scenario.name, self.protocol, self.bus, self.device)
        return Played(*where, index, step, start, time.time(), answered, watch.states, watch.faults)

    def _send(self, step: Step) -> bool:
        """The step's motion command; True if it was answered (a muted gripper hears none)."""
        driver, device = self.driver, self.device
        if step.drop:
            self.world.mute(device, True)
        try:
            if step.command == "release":
                return driver.open(device)
            if step.command == "seek":
                return driver.seek(device, step.position or 0)
            return driver.catch(device, continuous=step.command == "continuous catch")
        finally:
            if step.drop:
                self.world.mute(device, False)

    def _advance(self, step: Step, reading: GripperReading, watch: _Watch) -> bool:
        """Act on one poll as the step says; True once its motion is over."""
        if step.stop_at is not None and not watch.stopped:
            position = reading.position
            if position is not None and position <= step.stop_at:
                watch.stopped = self.driver.stop(self.device)
            return False
        if step.slip_to is not None and not watch.slipped:
            if watch.gripped_polls >= HOLD_POLLS:  # the host has seen the grip: now it slips
                self.world.place_object(self.device, step.slip_to)
                watch.slipped = True
            return False
        return reading.state in DONE_STATES[step.command]

    @staticmethod
    def _never(reading: GripperReading) -> bool:
        return False

    def _poll_for(
        self, watch: _Watch, limit_s: float, done: Callable[[GripperReading], bool]
    ) -> None:
        """Poll every poll_s until ``done(reading)`` or limit_s passes (faults are cleared)."""
        deadline = time.monotonic() + limit_s
        while time.monotonic() < deadline:
            started = time.monotonic()
            reading = self.driver.poll(self.device)
            if reading is not None and reading.state is not None:
                watch.saw(reading.state)
                if reading.fault:
                    watch.faults |= reading.fault
                    self.driver.clear_faults(self.device)
                if done(reading):
                    return
            wait = min(self.poll_s - (time.monotonic() - started), deadline - time.monotonic())
            if self.stop.wait(max(0.0, wait)):
                raise Stopped


def play_scenario(
    scenario: Scenario,
    protocol: str,
    bus: str,
    port_or_bus: str | serial.Serial | can.BusABC,
    world: World,
    device: int,
    stop: threading.Event,
    log: TruthLog,
    *,
    quirks: HostQuirks | None = None,
    pace: float = 1.0,
    repeat: bool = False,
) -> None:
    """Connect the host's side (as ``host.run_host_cycle`` takes its port or bus) and play the
    scenario (over and over if ``repeat``) until ``stop`` is set; for a thread."""
    quirks = quirks if quirks is not None else HostQuirks()
    driver = connect(protocol, port_or_bus, stop, HostResult(), quirks, timeout_s=TIMEOUT_S)
    player = Player(
        scenario, protocol, bus, driver, world, device, stop, log, pace=pace, repeat=repeat
    )
    player.run()
