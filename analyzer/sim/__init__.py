"""Simulated EG2-4XX grippers for demos, tests and benchmarks.

``gripper.GripperModel`` is the device (pure, time passed in); ``ptybus.PtyBus`` a virtual
multi-drop serial line of real ptys; ``endpoints`` serves models over the regular serial
protocol, Modbus RTU and CAN; ``host`` is a scripted host program (a pick-and-place cycle) on
``hostlink`` (one transaction at a time) and ``dialects`` (each protocol's wire forms);
``scenarios`` are scripts of grip cycles with their true outcomes, which ``play`` plays and
records (``can_trouble``: a CAN bus-off's error frames); ``rig`` joins them into the demo rig
(grippers and a passive tap on each of the three buses); ``serve`` is ``eg2scope sim``'s run.
"""
