"""The detail pane: the selected record as a tree (fields with the manual's names and units, the
frame's envelope, errors and warnings in words with their flag codes, the pair and latency),
and the hex pane below it, linked both ways through ``spans``."""

from __future__ import annotations

from typing import Any, ClassVar

from rich.style import Style
from rich.text import Text
from textual import events
from textual.binding import Binding, BindingType
from textual.reactive import reactive
from textual.widget import Widget
from textual.widgets import Tree
from textual.widgets.tree import TreeNode

from decoders.flags import DESCRIPTIONS
from decoders.model import Record

from ..messages import ByteSelected, FieldSelected
from ..rows import cut_at
from ..spans import FRAME_PART, Span, span_at, span_of, spans

NodeData = Span | None
UNITS = {"force_g": "g", "force_setting_g": "g", "temperature_c": "°C", "position_mm": "mm"}


def _value_text(key: str, value: Any) -> str:
    unit = UNITS.get(key, "")
    if isinstance(value, list):
        return ", ".join(map(str, value)) or "-"
    return f"{value} {unit}".rstrip()


class DetailTree(Tree[NodeData]):
    """The selected record's tree; a node's data is the span of its bytes (if known)."""

    DEFAULT_CSS = "DetailTree { background: $surface; overflow-x: hidden; }"

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("no frame selected", **kwargs)
        self.show_root = True
        self.record: Record | None = None
        self.spans: list[Span] = []
        self._field_nodes: dict[tuple[str, ...], TreeNode[NodeData]] = {}

    def show(self, rec: Record | None, pair_text: str = "") -> None:
        self.clear()
        self._field_nodes = {}
        self.record = rec
        if rec is None:
            self.root.set_label("no frame selected")
            self.spans = []
            return
        self.spans = spans(rec)
        title = Text(f"#{rec.seq} ", style="dim")
        title.append(rec.name or rec.kind, style="bold")
        title.append(f"  {rec.summary}")
        self.root.set_label(title)
        where = self.root.add("frame", expand=False)
        for key, value in (
            ("time", rec.t),
            ("bus", rec.bus),
            ("protocol", rec.protocol),
            ("kind", rec.kind),
            ("direction", rec.direction),
            ("device", rec.device),
            ("code", rec.code),
            ("offset" if rec.offset is not None else "index", rec.offset or rec.index),
            ("length", rec.length),
        ):
            where.add_leaf(f"{key}: {value}")
        fields = self.root.add("fields", expand=True)
        self._add_fields(fields, rec.fields, ())
        envelope = [s for s in self.spans if s.path[0] == FRAME_PART]
        if envelope:
            parts = self.root.add("bytes", expand=True)
            for s in sorted(envelope, key=lambda s: s.start):
                raw = rec.raw[s.start : s.end].hex(" ").upper()
                self._field_nodes[s.path] = parts.add_leaf(f"{s.label}: {raw}", data=s)
        self._problems(rec)
        if rec.pair is not None or rec.latency_ms is not None:
            pair = self.root.add("pair", expand=True)
            if rec.pair is not None:
                pair.add_leaf(f"paired with #{rec.pair} {pair_text}  (p jumps to it)")
            if rec.latency_ms is not None:
                pair.add_leaf(f"latency: {rec.latency_ms:.3f} ms")
        self.root.expand()

    def _add_fields(
        self, node: TreeNode[NodeData], fields: dict[str, Any], path: tuple[str, ...]
    ) -> None:
        for key, value in fields.items():
            here = (*path, key)
            span = span_of(self.spans, here)
            if isinstance(value, dict):
                child = node.add(key, data=span, expand=True)
                self._add_fields(child, value, here)
                continue
            label = Text(f"{key}: ", style="bold")
            label.append(_value_text(key, value))
            if span is not None:
                label.append(f"  [{span.start}:{span.end}]", style="dim")
            self._field_nodes[here] = node.add_leaf(label, data=span)

    def _problems(self, rec: Record) -> None:
        if not rec.errors and not rec.warnings:
            return
        problems = self.root.add("problems", expand=True)
        for words, style in ((rec.errors, "red bold"), (rec.warnings, "yellow")):
            for text in words:
                problems.add_leaf(Text(text, style=style))
        for code in rec.flags:
            problems.add_leaf(Text(f"{code}: {DESCRIPTIONS.get(code, '')}", style="dim"))

    def render_label(self, node: TreeNode[NodeData], base_style: Style, style: Style) -> Text:
        """The label cut to the pane's width with an ellipsis (the tree would otherwise run
        past the pane's edge, cut there without a mark)."""
        label = super().render_label(node, base_style, style)
        depth = 0
        while node.parent is not None:
            depth, node = depth + 1, node.parent
        room = self.size.width - depth * self.guide_depth
        if self.last_line >= self.size.height:  # the scroll bar (not laid out yet) takes a share
            room -= self.styles.scrollbar_size_vertical
        if room > 0 and label.cell_len > room:
            if label.cell_len == len(label.plain):  # one cell a character: cut between words
                room = cut_at(label.plain, room) + 1
            label.truncate(room, overflow="ellipsis")
        return label

    def select_offset(self, offset: int) -> None:
        """Select the field holding byte ``offset`` (from the hex pane)."""
        span = span_at(self.spans, offset)
        node = self._field_nodes.get(span.path) if span is not None else None
        if node is not None:
            self.move_cursor(node)

    def on_tree_node_highlighted(self, event: Tree.NodeHighlighted[NodeData]) -> None:
        event.stop()
        self.post_message(FieldSelected(event.node.data))


class HexPane(Widget, can_focus=True):
    """The selected record's bytes, 16 a line (8 in a narrow pane); the selected field's bytes
    highlighted; a byte cursor (left/right, or a click) selects the field that holds the
    byte."""

    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("left", "move(-1)", "byte left", show=False),
        Binding("right", "move(1)", "byte right", show=False),
        Binding("up", "line(-1)", "byte up", show=False),
        Binding("down", "line(1)", "byte down", show=False),
    ]
    DEFAULT_CSS = "HexPane { height: auto; min-height: 3; background: $surface; padding: 0 1; }"
    WIDE_LINE = 16  # bytes a line where "0000  " + 3 cells and 1 character a byte fit
    HIGHLIGHT = Style(color="black", bgcolor="yellow", bold=True)
    CURSOR = Style(reverse=True)

    raw: reactive[bytes] = reactive(b"", layout=True)
    span: reactive[Span | None] = reactive(None)
    cursor: reactive[int] = reactive(-1)

    @property
    def per_line(self) -> int:
        width = self.content_region.width
        return self.WIDE_LINE if width == 0 or width >= 7 + 4 * self.WIDE_LINE else 8

    def render(self) -> Text:
        if not self.raw:
            return Text("no bytes", style="dim")
        text = Text(no_wrap=True)
        per_line = self.per_line
        for line_start in range(0, len(self.raw), per_line):
            text.append(f"{line_start:04X}  ", style="dim")
            chunk = self.raw[line_start : line_start + per_line]
            for k, b in enumerate(chunk):
                offset = line_start + k
                style = None
                if self.span is not None and offset in self.span:
                    style = self.HIGHLIGHT
                if offset == self.cursor:
                    style = self.CURSOR
                text.append(f"{b:02X}", style)
                text.append(" ")
            text.append("   " * (per_line - len(chunk)))
            text.append(" ")
            for k, b in enumerate(chunk):
                ch = chr(b) if 32 <= b < 127 else "."
                in_span = self.span is not None and line_start + k in self.span
                text.append(ch, self.HIGHLIGHT if in_span else "dim")
            text.append("\n")
        text.rstrip()
        return text

    def show(self, raw: bytes) -> None:
        self.raw = raw
        self.span = None
        self.cursor = -1

    def action_move(self, step: int) -> None:
        if not self.raw:
            return
        start = 0 if self.cursor < 0 else self.cursor + step
        self.select_byte(min(max(start, 0), len(self.raw) - 1))

    def action_line(self, step: int) -> None:
        self.action_move(step * self.per_line)

    def select_byte(self, offset: int) -> None:
        self.cursor = offset
        self.post_message(ByteSelected(offset))

    def on_click(self, event: events.Click) -> None:
        offset = event.get_content_offset(self)
        if offset is None or not self.raw:
            return
        column = offset.x - 6  # after "0000  "
        per_line = self.per_line
        if 0 <= column < per_line * 3:
            byte = offset.y * per_line + column // 3
            if byte < len(self.raw):
                self.select_byte(byte)
