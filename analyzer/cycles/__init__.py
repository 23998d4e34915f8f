"""Grip cycles: every motion command to a gripper, with what came of it (docs/contracts.md,
"Grip cycles"). ``commands`` finds the motion commands in the records of each protocol,
``rules`` decides a cycle's outcome from what the readings showed, ``segmenter`` cuts each
gripper's timeline into cycles, ``listener`` feeds it from a session (both engines' sequences,
through their bulk methods), ``outputs`` and ``summary`` write and count the cycles, ``run``
is ``eg2scope cycles``'s run."""
