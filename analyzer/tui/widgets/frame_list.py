"""The frame list: one line per record, as a Line-API virtual view (Toolong's way).

Only the visible lines are rendered, each into a cached ``Strip``; the list holds no per-row
widgets or objects, only the store and, when a filter is on, an ``array`` of the shown
records' store indices. A million rows scroll as fast as a hundred. Rows are laid out for the
list's width (``layout.row_layout``): nothing to scroll sideways, and what is cut ends in ``…``.

Follow: while following, the cursor sits on the newest shown record; moving the cursor or
scrolling up stops following (the capture goes on), ``End``/``G`` resumes.

A store that keeps only the newest records (a live session) drops the oldest as the list
takes new ones in: the rows left keep their place under the cursor and on the screen.
"""

from __future__ import annotations

import re
from array import array
from bisect import bisect_left
from typing import Any

from rich.style import Style
from textual import events
from textual.cache import LRUCache
from textual.geometry import Size
from textual.reactive import reactive
from textual.strip import Strip

from ..filter import CompiledFilter
from ..layout import RowLayout, row_layout
from ..messages import RowSelected
from ..rows import MARKER_EVIDENCE, STYLE_MATCH, TimeMode, render_row
from ..store import OK, RecordStore
from .cursor_list import CURSOR_CLASS, CursorList

NO_STYLE = Style()  # padding: as no style, but one a filter can read


class FrameList(CursorList):
    """See the module doc."""

    follow: reactive[bool] = reactive(True)

    def __init__(self, store: RecordStore, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.store = store
        self.known = 0  # store records the list has taken in
        self.first = 0  # the oldest of them the store still keeps
        self.view: array[int] | None = None  # shown store indices; None: all
        self.filter: CompiledFilter | None = None
        self.cursor = -1  # position in the shown rows
        self.time_mode = TimeMode.RELATIVE
        self.reference: int | None = None  # store index of the time reference
        self.search: re.Pattern[str] | None = None
        self.marks: dict[str, int] = {}  # letter -> store index
        self.evidence: frozenset[int] = frozenset()  # store indices of the chosen cycle's frames
        self.new_while_paused = 0
        self._cache: LRUCache[tuple[Any, ...], Strip] = LRUCache(2048)
        self._styles: tuple[Style, Style] | None = None  # (base, cursor): looked up per theme
        self._selected: int | None = None
        self._layout: RowLayout = row_layout(0)

    # -- what is shown --------------------------------------------------------------------

    @property
    def row_count(self) -> int:
        return len(self.view) if self.view is not None else self.known - self.first

    def index_at(self, position: int) -> int:
        """The store index of shown row ``position``."""
        return self.view[position] if self.view is not None else self.first + position

    def position_of(self, index: int) -> int | None:
        """The shown row of store index ``index`` (None: filtered out, or no longer kept)."""
        if self.view is None:
            return index - self.first if self.first <= index < self.known else None
        pos = bisect_left(self.view, index)
        return pos if pos < len(self.view) and self.view[pos] == index else None

    def nearest_position(self, index: int) -> int:
        if self.view is None:
            return min(max(index - self.first, 0), self.row_count - 1)
        return min(bisect_left(self.view, index), len(self.view) - 1)

    @property
    def selected(self) -> int | None:
        """The store index under the cursor."""
        if 0 <= self.cursor < self.row_count:
            return self.index_at(self.cursor)
        return None

    # -- new records, filters ---------------------------------------------------------------

    def take_new(self, count: int) -> None:
        """The store now holds ``count`` records: show the new ones (and forget the oldest,
        if the store drops them)."""
        self._forget(self.store.trim(below=self.known))  # every record is shown once
        old = self.known
        if count <= old:
            return
        self.known = count
        before = self.row_count
        if self.view is not None and self.filter is not None:
            self.view.extend(self.filter.indices(self.store, old, count))
        added = self.row_count - (before if self.view is not None else old)
        self._resize()
        if self.follow:
            self.move_to(self.row_count - 1, follow=True)
        else:
            self.new_while_paused += added
        if self.time_mode is TimeMode.DELTA:
            self.refresh()

    def _forget(self, dropped: int) -> None:
        """The store dropped its ``dropped`` oldest records."""
        if not dropped:
            return
        first = self.first = self.store.first
        gone = dropped  # rows the list showed
        if self.view is not None:
            gone = bisect_left(self.view, first)
            del self.view[:gone]
        if self.reference is not None and self.reference < first:
            self.reference = None
        self._cache.clear()
        self.cursor = max(self.cursor - gone, 0 if self.row_count else -1)
        self._resize()
        y = max(self.scroll_offset.y - gone, 0)
        self.scroll_to(y=y, animate=False, immediate=True, force=True)
        self._announce()

    def set_filter(self, compiled: CompiledFilter | None) -> None:
        keep = self.selected
        self.filter = compiled
        self.view = (
            None
            if compiled is None
            else array("q", compiled.indices(self.store, self.first, self.known))
        )
        self._cache.clear()
        self._resize()
        if self.follow or keep is None:
            self.move_to(self.row_count - 1, follow=self.follow)
        else:
            self.move_to(self.nearest_position(keep))
        self.refresh()

    def _resize(self) -> None:
        size = Size(self.scrollable_content_region.width, self.row_count)
        if size == self.virtual_size:
            return
        self._grow_to(size)

    def restyle(self) -> None:
        """Forget the rendered lines (time mode, reference, search, marks or theme changed)."""
        self._cache.clear()
        self.refresh()

    def notify_style_update(self) -> None:
        super().notify_style_update()
        self._cache.clear()
        self._styles = None

    def _base_and_cursor(self) -> tuple[Style, Style]:
        # resolving a widget's style walks the DOM: once per theme, not once per row
        if self._styles is None:
            cursor = self.get_component_rich_style(CURSOR_CLASS)
            self._styles = (self.rich_style, Style(bgcolor=cursor.bgcolor))
        return self._styles

    # -- the cursor -------------------------------------------------------------------------

    def move_to(self, position: int, follow: bool = False) -> None:
        """Put the cursor on shown row ``position`` and scroll it into view."""
        n = self.row_count
        position = min(max(position, 0), n - 1) if n else -1
        self.follow = follow
        if follow:
            self.new_while_paused = 0
        self.cursor = position
        height = self.scrollable_content_region.height or 1
        y = self.scroll_offset.y
        if position >= 0 and not y <= position < y + height:
            target = position - height + 1 if position >= y + height else position
            if not follow:
                target = max(0, position - height // 2)
            # force: right after the list grew, its scroll bar is not shown until the next
            # layout, and Textual would not scroll it (a small capture decoded in one update
            # stayed on its first page while "following")
            self.scroll_to(y=target, animate=False, immediate=True, force=True)
            if not self.show_vertical_scrollbar:  # ... nor move the bar it is about to show
                self.vertical_scrollbar.position = self.scroll_y
        self.refresh()
        self._announce()

    def jump_to_index(self, index: int) -> bool:
        """Select store index ``index`` (stops following); False if the filter hides it."""
        pos = self.position_of(index)
        if pos is None:
            return False
        self.move_to(pos)
        return True

    def _announce(self) -> None:
        selected = self.selected
        if selected != self._selected:
            self._selected = selected
            self.post_message(RowSelected(selected))

    def _fit_width(self) -> None:
        """Lay rows out for the list's width (it changes with the terminal, the panes and the
        vertical scroll bar)."""
        width = self.scrollable_content_region.width
        if width != self._layout.width:
            self._layout = row_layout(width)
            self._cache.clear()
            self._resize()

    def on_resize(self, event: events.Resize) -> None:
        self._fit_width()
        # a scroll asked for before the list had its size (a capture decoded before the first
        # layout) was clamped to the top: following, the newest row goes back into view
        if self.follow and self.row_count:
            self.move_to(self.row_count - 1, follow=True)

    def on_mouse_scroll_up(self, event: events.MouseScrollUp) -> None:
        self.follow = False

    # -- searching and problems -------------------------------------------------------------

    def find(self, step: int, match: Any) -> bool:
        """Move to the next (step 1) or previous (-1) shown row whose store index satisfies
        ``match``; False if there is none."""
        pos = self.cursor + step
        n = self.row_count
        index_at = self.index_at
        while 0 <= pos < n:
            if match(index_at(pos)):
                self.move_to(pos)
                return True
            pos += step
        return False

    def search_matches(self, i: int) -> bool:
        pattern = self.search
        if pattern is None:
            return False
        store = self.store
        return bool(pattern.search(store.summary[i]) or pattern.search(store.name_of(i)))

    def is_problem(self, i: int) -> bool:
        return self.store.severity[i] != OK or bool(
            self.store.flags[i] & self.store.flag_bits.get("unanswered")
        )

    # -- rendering ----------------------------------------------------------------------------

    def render_line(self, y: int) -> Strip:
        self._fit_width()
        scroll_x, scroll_y = self.scroll_offset
        position = scroll_y + y
        width = self.size.width
        if not 0 <= position < self.row_count:
            return Strip.blank(width, self.rich_style)
        index = self.index_at(position)
        previous = self.index_at(position - 1) if position > 0 else None
        is_cursor = position == self.cursor
        key = (index, previous if self.time_mode.value == "delta" else None, is_cursor)
        strip = self._cache.get(key)
        if strip is None:
            strip = self._render_row(index, previous, is_cursor)
            self._cache[key] = strip
        # padded with an empty style, not None: a segment without one fails Textual's
        # monochrome filter (NO_COLOR=1), which crashed the app at its first short row
        return strip.crop_extend(scroll_x, scroll_x + width, NO_STYLE)

    def _render_row(self, index: int, previous: int | None, is_cursor: bool) -> Strip:
        store = self.store
        reference = None if self.reference is None else store.time(self.reference)
        mark = next((letter for letter, i in self.marks.items() if i == index), "")
        if not mark and index in self.evidence:
            mark = MARKER_EVIDENCE
        text = render_row(
            store,
            index,
            self.time_mode,
            previous,
            reference,
            is_reference=index == self.reference,
            mark=mark,
            layout=self._layout,
        )
        if self.search is not None:
            text.highlight_regex(self.search, STYLE_MATCH)
        base, cursor = self._base_and_cursor()
        text.stylize_before(base)
        if is_cursor:
            text.stylize(cursor)
        line = text.render(self.app.console)
        return Strip(list(line), text.cell_len).extend_cell_length(
            self._layout.width, cursor if is_cursor else NO_STYLE
        )
