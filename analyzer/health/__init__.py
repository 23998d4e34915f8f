"""Bus health: how loaded each bus is and how well it behaves, computed by a listener
(``HealthListener``) from the raw input of a session and, for byte streams, the frames found in
it. One module per job:

- ``rates``: the bit rate or baud each bus runs at, and where that figure came from;
- ``figures``: load per whole second of capture time, percentiles, spreads of times;
- ``can_load``: CAN frames and their exact bits per bus and second (natively where the core is
  built: ``_native.can_seconds``);
- ``error_frames``: CAN error frames by class, the error counters, error-passive and bus-off
  periods;
- ``line_clock``: when a byte stream's frames began and ended, from the times of the reads;
- ``serial_line``: a serial line's use, the gaps between its frames, Modbus frames closer than
  3.5 characters, each gripper's turnaround;
- ``latency_timer``: the hint a USB adapter's latency timer leaves in read times;
- ``seconds``: each bus second by second (``HealthSecond``: frames, bits, load, errors, the
  controller's worst state, the worst event in words), for the TUI, Rerun and ``batch``;
- ``bus``: the figures of one bus together, as ``stats`` reports them (docs/contracts.md);
- ``listener``: the listener that feeds them.
"""
