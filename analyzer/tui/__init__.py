"""``eg2scope tui``: the live bus-debugging terminal UI (a Textual app, a listener of one session).

One module per job: ``store`` (compact record storage), ``timeorder`` (records in capture time
across buses), ``filter`` (the display-filter language), ``feed`` (the session listener that
fills the store and posts batches), ``aggregates`` (what the side panels fold from records),
``rows`` (one record as one line), ``spans`` (which bytes carry which field), ``replay`` (paced
capture replay with pause and speed), ``export``, ``messages``, ``notes`` (outputs' stderr
while the TUI holds the terminal), ``keys`` (every key, one table), ``layout`` (the screen at
each terminal size), ``widgets/`` and ``screens``, ``app`` that joins them, and ``launch``
(``eg2scope tui``'s run: the session plan, the app, what is said after). Textual is imported
only here.
"""
