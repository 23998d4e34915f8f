"""Every key of the TUI, in one table: the app's bindings, the footer, the help screen, the
command palette and ``eg2scope tui --help`` are all made from it. Each binding has an ``id``
(``eg2scope.<action>``), so it can be remapped through Textual's keymap."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

if TYPE_CHECKING:
    from textual.binding import BindingType


@dataclass(frozen=True)
class Key:
    keys: str  # Textual key names, comma separated
    action: str
    description: str
    footer: str = ""  # its word in the footer ("": not in the footer); short: 80 columns hold all
    shown: str = ""  # how the help writes the key, when not the key names
    # taken as the app reads the key, before any widget (the m/' of marks: the letter that
    # follows must find the app waiting for it); not while a text box takes the key
    priority: bool = False


KEYS: Final[tuple[Key, ...]] = (
    Key("question_mark,f1", "help", "help: every key", "help", "? F1"),
    Key("q", "quit", "quit (ends the capture and finishes the recording)", "quit"),
    Key("space", "pause", "pause/resume the view (live) or the replay (captures)", "pause"),
    Key("end,G", "follow", "follow the newest frame again", "", "End G"),
    Key("slash,f", "filter", "display filter (e.g. dev == 1 and bus == can0)", "filter", "/ f"),
    Key("ctrl+f", "search", "search: highlight matches; n/N move between them"),
    Key("n", "next_problem", "next search match, or next problem frame"),
    Key("N", "previous_problem", "previous search match, or previous problem frame"),
    Key("p", "pair", "jump to the paired request/response", "pair"),
    Key("t", "time_reference", "set/clear the time reference on this frame"),
    Key("T", "time_mode", "time column: relative, absolute, delta, reference", "time"),
    Key("m", "set_mark", "mark this frame: m then a letter", priority=True),
    Key("apostrophe", "goto_mark", "jump to a mark: ' then a letter", "", "'", priority=True),
    Key("ctrl+g", "goto", "go to a frame number or a time (t=12.5)"),
    Key("x", "arm_trigger", "arm/disarm the trigger (freeze on the first match)"),
    Key("plus,equals_sign", "faster", "replay faster (1x 2x 5x 10x max)", "", "+"),
    Key("minus", "slower", "replay slower", "", "-"),
    Key("e", "export", "export the shown (or marked a..b) records: JSONL, CSV, MCAP", "export"),
    Key("1", "tab('devices')", "device panel"),
    Key("2", "tab('problems')", "problems panel (Enter jumps)"),
    Key("3", "tab('registers')", "register watch of the selected gripper"),
    Key("4", "tab('latency')", "latency per command"),
    Key("5", "tab('events')", "source events"),
    Key("6", "tab('cycles')", "grip cycles panel: each cycle as it ends, outcome and figures"),
    Key("c", "cycles", "grip cycles: to the panel's list (Enter shows a cycle's frames)", "cycles"),
    Key("right_square_bracket", "next_evidence", "next frame of the chosen grip cycle", "", "]"),
    Key("left_square_bracket", "previous_evidence", "previous frame of the chosen cycle", "", "["),
    Key("d", "toggle_detail", "detail pane: hide/show (narrow: swap with the list)"),
    Key("tab", "focus_next", "next pane (frames, detail, hex, panels)"),
    Key("ctrl+t", "toggle_dark", "light/dark theme"),
    # its footer word is this description's first word: short, so 80 columns hold every key
    Key("ctrl+p", "command_palette", "commands: the command palette, every action by name"),
)

LIST_KEYS: Final[tuple[tuple[str, str], ...]] = (
    ("up/down, k/j", "move the cursor (stops following)"),
    ("PgUp/PgDn, Home", "page, first frame"),
    ("Enter (problems)", "jump to the first frame of that problem"),
    ("Enter (cycles)", "jump to the cycle's command; the frames that decided it are marked ◆"),
    ("left/right (hex)", "move the byte cursor: the field that holds it is selected"),
)


def bindings() -> list[BindingType]:
    from textual.binding import Binding  # here: `eg2scope --help` must not load Textual

    return [
        Binding(
            k.keys,
            k.action,
            k.footer or k.description.split(":")[0].split(" (")[0],
            show=bool(k.footer),
            priority=k.priority,
            id=f"eg2scope.{k.action.split('(')[0]}.{k.keys.split(',')[0]}",
        )
        for k in KEYS
    ]


def literal(text: str) -> str:
    """``text`` as Textual markup that shows it as it is: the command palette reads its help as
    markup, where "[/ f]" is a closing tag and "[End G]" a style (textual.markup.escape
    passes both)."""
    return text.replace("[", "\\[")


def shown_keys(k: Key) -> str:
    return k.shown or k.keys.replace(",", " ")


def help_lines() -> list[tuple[str, str]]:
    """(keys, what they do) for the help screen and ``--help``."""
    return [(shown_keys(k), k.description) for k in KEYS] + list(LIST_KEYS)


def help_text() -> str:
    width = max(len(keys) for keys, _ in help_lines())
    return "\n".join(f"  {keys:{width}}  {what}" for keys, what in help_lines())
