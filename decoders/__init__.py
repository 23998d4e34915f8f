"""EG2-4XX protocol decoders: pure functions of bytes and frames, no I/O.

Modules: ``model`` (Chunk, CanFrame, Record), ``registers`` (the one register table),
``flags`` (the codes of what is wrong or notable) and ``notes`` (a frame's errors and warnings
with their codes), ``framing`` (byte-stream framer base), ``eg2_serial``, ``modbus_rtu``,
``eg2_can`` (one per protocol; Modbus RTU in parts: ``modbus_framing``, ``modbus_pdu``,
``modbus_registers``), ``pairing`` and ``lint`` (stages after decoding), ``build`` (frame
builders), ``registry`` (names to decoders, protocol detection), ``can_bits`` (a CAN frame's
bits on the wire, for bus load).
"""
