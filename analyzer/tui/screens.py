"""The TUI's modal screens: help (every key, the list's gutter markers) and a one-line prompt
(go-to, export, search)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar

from rich.table import Table
from textual.app import ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Vertical, VerticalScroll
from textual.screen import ModalScreen
from textual.widgets import Input, Label, Static

from .keys import help_lines
from .rows import MARKERS


class HelpScreen(ModalScreen[None]):
    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("escape,q,question_mark,f1", "dismiss", "close")
    ]
    DEFAULT_CSS = """
    HelpScreen { align: center middle; }
    HelpScreen > VerticalScroll {
        width: 90; max-width: 100%; height: 80%; border: thick $accent; background: $panel;
        padding: 0 1;
    }
    """

    def compose(self) -> ComposeResult:
        table = Table(title="eg2scope tui: keys", box=None, expand=True)
        table.add_column("key", style="bold cyan", no_wrap=True)
        table.add_column("what it does")
        for keys, what in help_lines():
            table.add_row(keys, what)
        markers = Table(title="the frame list's gutter", box=None, expand=True)
        markers.add_column("mark", style="bold", no_wrap=True)
        markers.add_column("what it means")
        for mark, what in MARKERS:
            markers.add_row(mark, what)
        with VerticalScroll():
            yield Static(table)
            yield Static(markers)
            yield Static(
                "Filter: dev == 1 and bus == can0 · name ~ CATCH · flag == unanswered · "
                "latency > 5 · errors · not foreign.  Esc closes.",
                classes="hint",
            )

    def action_dismiss(self) -> None:  # type: ignore[override]
        self.dismiss(None)


class PromptScreen(ModalScreen[str | None]):
    """Ask for one line; ``check`` returns an error to show (None: acceptable)."""

    BINDINGS: ClassVar[list[BindingType]] = [Binding("escape", "cancel", "cancel")]
    DEFAULT_CSS = """
    PromptScreen { align: center middle; }
    PromptScreen > Vertical {
        width: 70; max-width: 100%; height: auto; border: thick $accent; background: $panel;
        padding: 0 1;
    }
    PromptScreen #error { color: $error; }
    """

    def __init__(
        self,
        title: str,
        value: str = "",
        placeholder: str = "",
        check: Callable[[str], str | None] | None = None,
        **kwargs: Any,
    ) -> None:
        super().__init__(**kwargs)
        self.title_text = title
        self.value = value
        self.placeholder = placeholder
        self.check = check

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(self.title_text)
            yield Input(self.value, placeholder=self.placeholder, id="answer")
            yield Label("", id="error")

    def on_input_changed(self, event: Input.Changed) -> None:
        error = self.check(event.value) if self.check and event.value else None
        self.query_one("#error", Label).update(error or "")

    def on_input_submitted(self, event: Input.Submitted) -> None:
        error = self.check(event.value) if self.check else None
        if error:
            self.query_one("#error", Label).update(error)
            return
        self.dismiss(event.value)

    def action_cancel(self) -> None:
        self.dismiss(None)
