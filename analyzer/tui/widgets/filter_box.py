"""The display filter's one-line box. Esc cancels the edit (an ``Input`` takes every other
key, so without its own binding Esc would do nothing and ``q`` would be typed into the box)."""

from __future__ import annotations

from typing import ClassVar

from textual.binding import Binding, BindingType
from textual.widgets import Input

from ..messages import FilterCancelled


class FilterBox(Input):
    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("escape", "cancel", "cancel the edit", show=False)
    ]

    def action_cancel(self) -> None:
        self.post_message(FilterCancelled())
