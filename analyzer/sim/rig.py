"""The demo rig: simulated grippers on all three buses, a host program on each running a
pick-and-place cycle, and a passive tap on each bus exactly as on real hardware.

serial (RS232): PtyBus[gripper, host, tap]   grippers 1 and 2, regular serial protocol
rs485  (Modbus): PtyBus[gripper, host, tap]  grippers 1 and 2, the host uses short registers
can0   (CAN):    python-can virtual channel  grippers 1 and 2

Each tap opens the bus's ``tap`` pty (or the virtual channel) and knows nothing of the
simulator: it sees the same bytes and frames it would see on a real line.

With a scenario (``scenarios``) gripper 1 alone is on each bus, and the host of each bus plays
the scenario on it (``play``) instead of the pick-and-place cycle; every step played goes to
``truth`` (and, as JSON lines, to the truth file).
"""

from __future__ import annotations

import contextlib
import os
import threading
import time
from typing import Any

from decoders.model import EG2_SERIAL, MODBUS_RTU

from ..lifecycle import Running
from ..outfile import output_stream
from ..sources.can_tap import CanTap
from ..sources.live import Tap, wait_open
from ..sources.serial_tap import SerialTap
from .demo_options import BUSES, DemoOptions
from .endpoints import CanGripperServer, ModbusGripperServer, SerialGripperServer
from .gripper import GripperModel
from .host import HostQuirks, HostResult, run_host_cycle
from .play import TruthLog, play_scenario
from .ptybus import PtyBus
from .scenarios import Scenario

BUS_NAMES = {"serial": "rs232", "modbus": "rs485", "can": "can0"}


class DemoRig(Running):
    """Context manager: start() everything, ``taps`` to watch it, stop() in the right order."""

    def __init__(
        self,
        buses: tuple[str, ...] = BUSES,
        noise: float = 0.0,
        seed: int = 1,
        *,
        scenario: Scenario | None = None,
        pace: float = 1.0,
        truth_file: str | None = None,
    ) -> None:
        unknown = set(buses) - set(BUSES)
        if unknown:
            raise ValueError(
                f"unknown demo bus {', '.join(sorted(unknown))}; choose from {', '.join(BUSES)}"
            )
        self.buses = buses
        self.noise = noise
        self.seed = seed
        self.scenario = scenario
        self.pace = pace
        self.truth_file = truth_file
        self.truth = TruthLog()
        self._files = contextlib.ExitStack()
        self.stop_event = threading.Event()
        self.taps: list[Tap] = []
        self.protocols: dict[str, str] = {}  # bus name -> protocol, for the decoder
        self.results: dict[str, HostResult] = {}
        self._servers: list[Any] = []
        self._ptybuses: list[PtyBus] = []
        self._threads: list[threading.Thread] = []
        self.can_channel = f"eg2scope-demo-{os.getpid()}-{time.monotonic_ns()}"

    @classmethod
    def of(cls, options: DemoOptions) -> DemoRig:
        """The rig a command's demo options ask for."""
        return cls(
            options.buses,
            noise=options.noise,
            scenario=options.scenario,
            pace=options.pace,
            truth_file=options.truth,
        )

    @property
    def devices(self) -> tuple[int, ...]:
        return (1,) if self.scenario is not None else (1, 2)

    def _models(self) -> dict[int, GripperModel]:
        now = time.monotonic()
        if self.scenario is not None:  # the scenario places its parts
            return {1: GripperModel(1, now=now, pace=self.pace)}
        return {
            1: GripperModel(1, now=now, object_width=420.0, pace=self.pace),
            2: GripperModel(2, now=now, object_width=250.0, pace=self.pace),
        }

    def start(self) -> DemoRig:
        if self.truth_file is not None:
            self.truth.out = self._files.enter_context(output_stream(self.truth_file, False))
        corrupt, garbage, drop = self.noise, self.noise / 2, self.noise / 2
        for bus in self.buses:
            name = BUS_NAMES[bus]
            result = self.results[name] = HostResult()
            quirks = HostQuirks(short_registers=bus == "modbus", continuous=bus == "can")
            if bus == "can":
                server: Any = CanGripperServer(
                    self._models(),
                    channel=self.can_channel,
                    seed=self.seed,
                    corrupt=corrupt,
                    garbage=garbage,
                    drop=drop,
                )
                target: Any = self.can_channel
                self.taps.append(CanTap(name, "virtual", self.can_channel))
            else:
                line = PtyBus(["gripper", "host", "tap"])
                self._ptybuses.append(line)
                cls = SerialGripperServer if bus == "serial" else ModbusGripperServer
                server = cls(
                    line.path("gripper"),
                    self._models(),
                    seed=self.seed,
                    corrupt=corrupt,
                    garbage=garbage,
                    drop=drop,
                )
                target = line.path("host")
                self.taps.append(SerialTap(name, line.path("tap")))
                self.protocols[name] = EG2_SERIAL if bus == "serial" else MODBUS_RTU
            server.start()
            self._servers.append(server)
            self._threads.append(self._host(bus, name, target, server, quirks, result))
        return self

    def _host(
        self, bus: str, name: str, target: Any, server: Any, quirks: HostQuirks, result: HostResult
    ) -> threading.Thread:
        """The host program's thread: the scenario's player, or the pick-and-place cycles."""
        thread_name = f"demo-host-{bus}"
        if self.scenario is not None:
            quirks.continuous = False  # each step says how it catches
            return threading.Thread(
                target=play_scenario,
                args=(self.scenario, bus, name, target, server, 1, self.stop_event, self.truth),
                kwargs={"quirks": quirks, "pace": self.pace},
                name=thread_name,
                daemon=True,
            )
        return threading.Thread(
            target=run_host_cycle,
            args=(bus, target, (1, 2), None, self.stop_event, quirks),
            kwargs={"result": result},
            name=thread_name,
            daemon=True,
        )

    def run_hosts(self) -> None:
        """Start the host programs once the taps are listening, so nothing is missed."""
        wait_open(self.taps)
        for thread in self._threads:
            thread.start()

    def stop(self) -> None:
        self.stop_event.set()
        for thread in self._threads:
            if thread.is_alive():
                thread.join(2.0)
        for server in self._servers:
            server.stop()
        for line in self._ptybuses:
            line.close()
        self._files.close()  # the truth file, complete
