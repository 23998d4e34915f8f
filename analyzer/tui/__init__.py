"""``eg2scope tui``: the live bus-debugging terminal UI (a Textual app, a listener of one session).

One module per job: ``store`` (compact record storage), ``filter`` (the display-filter
language), ``feed`` (the session listener that fills the store and posts batches), ``rows``
(one record as one line), ``spans`` (which bytes carry which field), ``replay`` (paced capture
replay with pause and speed), ``export``, ``messages``, ``keys`` (every key, one table),
``widgets/`` and ``screens``, and ``app`` that joins them. Textual is imported only here.
"""
