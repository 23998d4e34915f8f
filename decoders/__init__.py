"""EG2-4XX protocol decoders: pure functions of bytes and frames, no I/O.

Modules: ``model`` (Chunk, CanFrame, Record), ``registers`` (the one register table),
``framing`` (byte-stream framer base), ``eg2_serial``, ``modbus_rtu``, ``eg2_can`` (one per
protocol), ``pairing`` and ``lint`` (stages after decoding), ``build`` (frame builders),
``registry`` (names to decoders, protocol detection).
"""
