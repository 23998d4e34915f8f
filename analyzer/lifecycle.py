"""The two context-manager shapes used across eg2scope, written once.

- ``Closing``: ``with reader:`` gives the object and closes it at the end (capture readers,
  the MCAP recorder, the virtual serial line).
- ``Running``: ``with server:`` starts the object and stops it at the end (simulated
  grippers, the demo rig); a start that fails part-way (Ctrl-C or SIGTERM while the demo rig
  starts its buses) stops what it had started.
"""

from __future__ import annotations

from types import TracebackType
from typing import Any, Self


class Closing:
    def close(self) -> None:
        raise NotImplementedError

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


class Running:
    def start(self) -> Any:
        raise NotImplementedError

    def stop(self) -> None:
        raise NotImplementedError

    def __enter__(self) -> Self:
        try:
            self.start()
        except BaseException:
            self.stop()
            raise
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()
