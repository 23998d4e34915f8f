"""A Line-API list with a cursor (the frame list, the cycles panel): the keys that move the
cursor, its colours, and the growing of the list without a layout of the screen. A panel
says how many rows it has (``row_count``), how many header rows stand above them
(``HEADER_ROWS``) and how the cursor is put on a row and into view (``move_to``)."""

from __future__ import annotations

from typing import ClassVar

from textual import events
from textual.binding import Binding, BindingType
from textual.geometry import Size
from textual.scroll_view import ScrollView

CURSOR_CLASS = "cursor-list--cursor"


class CursorList(ScrollView, can_focus=True):
    """See the module doc."""

    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("up,k", "cursor(-1)", "up", show=False),
        Binding("down,j", "cursor(1)", "down", show=False),
        Binding("pageup", "page(-1)", "page up", show=False),
        Binding("pagedown", "page(1)", "page down", show=False),
        Binding("home", "first", "first", show=False),
        Binding("end,G", "follow", "follow", show=False),
    ]
    COMPONENT_CLASSES: ClassVar[set[str]] = {CURSOR_CLASS}
    DEFAULT_CSS = f"""
    CursorList {{ background: $surface; overflow-x: hidden; }}
    CursorList > .{CURSOR_CLASS} {{ background: $accent 40%; }}
    CursorList:focus > .{CURSOR_CLASS} {{ background: $accent 70%; }}
    """
    HEADER_ROWS: ClassVar[int] = 0  # lines above the rows that do not scroll with them

    cursor: int  # position in the rows; -1: none

    @property
    def row_count(self) -> int:
        raise NotImplementedError

    def move_to(self, position: int, follow: bool = False) -> None:
        """Put the cursor on row ``position`` and scroll it into view."""
        raise NotImplementedError

    def action_cursor(self, step: int) -> None:
        self.move_to(self.cursor + step)

    def action_page(self, step: int) -> None:
        rows = self.scrollable_content_region.height - self.HEADER_ROWS
        self.move_to(self.cursor + step * max(1, rows - 1))

    def action_first(self) -> None:
        self.move_to(0)

    def action_follow(self) -> None:
        self.move_to(self.row_count - 1, follow=True)

    def on_click(self, event: events.Click) -> None:
        offset = event.get_content_offset(self)
        if offset is not None and offset.y >= self.HEADER_ROWS:
            self.move_to(self.scroll_offset.y + offset.y - self.HEADER_ROWS)

    def _grow_to(self, size: Size) -> None:
        height = self.scrollable_content_region.height
        if height and min(size.height, self.virtual_size.height) > height:
            # longer, with the scroll bar already shown: only the scroll bar changes. Setting
            # virtual_size asks for a layout of the whole screen, 10 times a second on a live
            # bus, which cost more than drawing the rows
            self.set_reactive(CursorList.virtual_size, size)
            self._scroll_update(size)
        else:
            self.virtual_size = size
