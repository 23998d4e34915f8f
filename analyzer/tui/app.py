"""The TUI application: the panes, the keys, and one session on a worker thread.

The session (live taps or a capture) is made with the app and runs in a Textual thread worker;
the ``TuiFeed`` listener fills the store on that thread and posts a ``FeedUpdate`` 10-20 times
a second; beside it the grip cycles (``CyclesListener`` writing to a ``CycleFeed``) and the bus
health (``HealthFeed``) post theirs in batches too. Pausing the view never pauses capture or
recording; quitting stops the session and waits for it to close every listener, so a recording
is complete when the app has gone. The app ending any other way (a crash) stops the session
too. A session thread that raises is shown at once (a notification, the status line, the events
tab) and kept in ``failure``: ``eg2scope tui`` prints it and exits 1.
"""

from __future__ import annotations

import re
import time
import traceback
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

from textual import events, on, work
from textual.app import App, ComposeResult, SystemCommand
from textual.binding import BindingType
from textual.containers import Horizontal, Vertical
from textual.css.query import NoMatches
from textual.screen import Screen
from textual.timer import Timer
from textual.widgets import Footer, Input, Static, TabbedContent, TabPane
from textual.worker import Worker, WorkerState

from ..cycles.model import Cycle
from ..health.rates import BusRates
from ..model import ERROR, LEVEL_NAMES, SourceEvent
from ..session.listener import Listener
from ..session.session import Session
from . import keys
from .aggregates import Snapshot
from .cycle_feed import cycle_frames, cycles_listener, find_frame
from .export import export, export_format
from .feed import TRIGGERS, TuiFeed
from .filter import FilterError, parse
from .health_feed import HealthFeed
from .layout import HEIGHT_BREAKPOINTS, WIDTH_BREAKPOINTS
from .messages import (
    ByteSelected,
    CycleChosen,
    CyclesUpdate,
    FeedUpdate,
    FieldSelected,
    FilterCancelled,
    HealthUpdate,
    JumpTo,
    RowSelected,
)
from .notes import Notes
from .replay import ReplaySource, next_speed, speed_text
from .rows import MARKER_EVIDENCE, TimeMode
from .screens import HelpScreen, PromptScreen
from .store import RecordStore
from .widgets.cycles import CyclesPanel
from .widgets.detail import DetailTree, HexPane
from .widgets.devices import DevicePanel
from .widgets.event_log import EventLog
from .widgets.filter_box import FilterBox
from .widgets.frame_list import FrameList
from .widgets.health import HealthLines
from .widgets.latency import LatencyPanel
from .widgets.problems import ProblemsPanel
from .widgets.registers import RegisterWatch

DETAIL_S = 0.08  # the detail pane follows the cursor at most this often
DETAIL_FOLLOW_S = 0.5  # ... and the newest record, while following, at most this often
PANELS_S = 0.5  # the visible panel is redrawn this often (ages, fading highlights)


@dataclass
class SessionPlan:
    """How the app gets its session: ``build(listeners)`` makes it with the TUI's listeners
    (the feed, the grip cycles, the bus health) among its own. ``live``: taps (ages by the wall
    clock) or a capture; ``replay``: the capture source, for pause and speed; ``recorder``:
    where marks go; ``freeze_on``: the armed trigger; ``title``: what is watched; ``notes``:
    what outputs say while the app runs; ``rates``: each bus's bit rate or baud (the bus load's
    measure); ``keep``: how many of the newest records the store keeps (None: every one)."""

    build: Callable[[list[Listener]], Session]
    live: bool = True
    replay: ReplaySource | None = None
    recorder: Any = None
    recording_path: str | None = None
    freeze_on: str | None = None
    title: str = "eg2scope"
    notes: Notes | None = None
    rates: BusRates = field(default_factory=BusRates)
    keep: int | None = None


class Eg2ScopeApp(App[int]):
    """See the module doc."""

    CSS_PATH = "eg2scope.tcss"
    TITLE = "eg2scope"
    BINDINGS: ClassVar[list[BindingType]] = list(keys.bindings())
    # Textual declares these without ClassVar (mypy would refuse one)
    HORIZONTAL_BREAKPOINTS = list(WIDTH_BREAKPOINTS)  # noqa: RUF012
    VERTICAL_BREAKPOINTS = list(HEIGHT_BREAKPOINTS)  # noqa: RUF012

    def __init__(self, plan: SessionPlan, store: RecordStore | None = None) -> None:
        """Makes the session (ValueError: it cannot be made, e.g. an engine that does not
        apply); it starts when the app does."""
        super().__init__()
        self.plan = plan
        self.store = store if store is not None else RecordStore(plan.keep)
        self.feed = TuiFeed(self.store, live=plan.live)
        self.feed.recorder = plan.recorder
        self.cycles, self.cycle_feed = cycles_listener()
        self.health = HealthFeed(plan.rates)
        # the feed last: its final update (the session is over) comes after the others'
        session = self.session = plan.build([self.health, self.cycles, self.feed])
        self.feed.states = lambda: session.tracker.states
        self.feed.counts = lambda: (session.counts.items, session.source.dropped)
        self.failure: BaseException | None = None  # what the session's thread raised
        self.awaiting_letter: tuple[str, Callable[[str], None]] | None = None  # m, '
        self.done = False
        self.damage: list[str] = []  # what the source found wrong with its input, at its end
        self.captured = 0
        self.dropped = 0
        self.trigger: str | None = plan.freeze_on
        self.frozen_on: int | None = None
        self.export_note = ""
        self.snapshot: Snapshot | None = None
        self.evidence: list[int] = []  # store indices of the chosen cycle's frames
        self.panels_stale = False
        self._detail_due: int | None = None
        self._detail_timer: Timer | None = None
        self._status = ""
        self.sub_title = plan.title

    # -- layout ----------------------------------------------------------------------------

    def compose(self) -> ComposeResult:
        with Horizontal(id="main"):
            with Vertical(id="left"):
                yield FrameList(self.store, id="frames")
                yield HealthLines(self.clock, self.plan.live, id="health")
                yield FilterBox(placeholder="filter: dev == 1 and bus == can0", id="filter")
                yield Static("", id="filter-error")
                yield Static("", id="status")
            with Vertical(id="right"):
                yield DetailTree(id="detail")
                yield HexPane(id="hex")
        with TabbedContent(id="panels", initial="devices"):
            with TabPane("Devices", id="devices"):
                yield DevicePanel(self.clock, id="device-panel")
            with TabPane("Problems", id="problems"):
                yield ProblemsPanel(id="problem-panel")
            with TabPane("Registers", id="registers"):
                yield RegisterWatch(id="register-panel")
            with TabPane("Latency", id="latency"):
                yield LatencyPanel(id="latency-panel")
            with TabPane("Events", id="events"):
                yield EventLog(id="event-log")
            with TabPane("Cycles", id="cycles"):
                yield CyclesPanel(self.store, id="cycle-panel")
        yield Static("", id="letter-prompt")
        yield Footer(compact=True)  # compact: 80 columns hold every key

    @property
    def main_screen(self) -> Screen[Any]:
        """The screen of the panes (a prompt or the help may be on top of it)."""
        return self.screen_stack[0]

    @property
    def frames(self) -> FrameList:
        return self.main_screen.query_one(FrameList)

    def on_mount(self) -> None:
        self.main_screen.query_one("#filter", Input).display = False
        self.main_screen.query_one("#filter-error", Static).display = False
        self.main_screen.query_one("#letter-prompt", Static).display = False
        if self.plan.notes is not None:
            notes = self.plan.notes
            for line in notes.lines:
                self.notify(line, timeout=10)
            notes.show = lambda line: self.call_from_thread(self.notify, line, timeout=10)
        self.frames.focus()
        self.feed.target = self
        self.cycle_feed.target = self
        self.health.target = self
        if self.trigger:
            self.feed.arm(self.trigger)
        self.set_interval(0.25, self.show_status)
        self.set_interval(PANELS_S, self.show_panels)
        self.show_status()
        self.run_session()

    # -- the session -----------------------------------------------------------------------

    @work(thread=True, exclusive=True, name="session", exit_on_error=False)
    def run_session(self) -> None:
        self.session.run()

    def on_worker_state_changed(self, event: Worker.StateChanged) -> None:
        if event.worker.name != "session" or event.state != WorkerState.ERROR:
            return
        self.failure = event.worker.error
        if self.closing:
            return  # printed on exit all the same
        text = self.failure_text()
        self.notify(text, title="session failed", severity="error", timeout=3600)
        self.main_screen.query_one(EventLog).add(
            self._event_line(SourceEvent(time.time(), "session", ERROR, text, "failed"))
        )
        self.done = True
        self.show_status()

    def failure_text(self) -> str:
        """The session thread's failure in words, with where it happened."""
        exc = self.failure
        if exc is None:
            return ""
        where = traceback.extract_tb(exc.__traceback__)[-1:] if exc.__traceback__ else []
        at = f" (at {Path(where[0].filename).name}:{where[0].lineno})" if where else ""
        return f"the session failed: {type(exc).__name__}: {exc}{at}"

    def stop_session(self) -> None:
        """Ask the session to end (from any thread; it closes every listener as it ends)."""
        self.session.stop()
        if self.plan.replay is not None:
            self.plan.replay.resume()  # a paused replay must see the stop

    def on_unmount(self) -> None:
        # however the app ends (a crash too): the session's thread must end, or leaving the
        # event loop would wait for it forever
        self.stop_session()

    def clock(self) -> float | None:
        """Ages are measured on the wall clock live, on the capture's own clock otherwise."""
        return time.time() if self.plan.live else self.store.t_last

    @property
    def closing(self) -> bool:
        """The app is being taken down: its widgets may be gone already (timers and the
        feed's last updates must not look for them)."""
        if self._exit or not self.screen_stack:
            return True
        screen = self.main_screen
        return not screen.is_attached or not screen.children

    def on_feed_update(self, update: FeedUpdate) -> None:
        if self.closing:
            return
        self.captured, self.dropped = update.captured, update.dropped
        self.frames.take_new(update.count)
        self.main_screen.query_one(DevicePanel).take(update.devices, update.changed)
        if update.snapshot is not None:
            self.snapshot = update.snapshot
            self.panels_stale = True
        log = self.main_screen.query_one(EventLog)
        for event in update.events:
            log.add(self._event_line(event))
        if update.trigger is not None:
            self._freeze(update.trigger)
        if update.done:
            self.done = True
            self._ended()
            self.show_panels()

    def on_cycles_update(self, update: CyclesUpdate) -> None:
        if not self.closing:
            self.main_screen.query_one(CyclesPanel).take(update.cycles)

    def on_health_update(self, update: HealthUpdate) -> None:
        if not self.closing:
            lines = self.main_screen.query_one(HealthLines)
            lines.take(update.seconds, update.untimed, update.whole)

    def _ended(self) -> None:
        """The session is over: the damage its source found is said at once (a notification,
        the Events tab, the status line; ``eg2scope tui`` prints it again on exit), and the
        panels that stayed empty say so for good."""
        screen = self.main_screen
        log = screen.query_one(EventLog)
        self.damage = list(getattr(self.session.source, "errors", []))
        for text in self.damage:
            self.notify(text, title="damaged input", severity="error", timeout=30)
            log.add(self._event_line(SourceEvent(time.time(), "capture", ERROR, text, "damaged")))
        what = "session" if self.plan.live else "capture"
        log.ended(what)
        screen.query_one(DevicePanel).ended(what)
        screen.query_one(LatencyPanel).ended(what)
        screen.query_one(CyclesPanel).ended(what)
        self.show_status()

    def show_panels(self) -> None:
        """Redraw the visible panel (``PANELS_S``; hidden ones are drawn when shown)."""
        if self.closing:
            return
        try:
            self.main_screen.query_one(HealthLines).redraw()  # ages
            active = self.main_screen.query_one(TabbedContent).active
        except NoMatches:  # the timer fired while the app tears its panes down
            return
        snap = self.snapshot
        if active == "devices":
            panel = self.main_screen.query_one(DevicePanel)
            if snap is not None and snap.latency_by_device:
                panel.latency = snap.latency_by_device
            panel.redraw()
        if snap is None or (not self.panels_stale and active != "devices"):
            return
        if active == "problems":
            self.main_screen.query_one(ProblemsPanel).take(snap.problems)
        elif active == "registers":
            self.main_screen.query_one(RegisterWatch).take(snap.registers)
        elif active == "latency":
            self.main_screen.query_one(LatencyPanel).take(snap.latency_by_command)
        self.panels_stale = active == "devices"

    @on(TabbedContent.TabActivated)
    def tab_activated(self) -> None:
        if self.closing:  # a message that comes in while the app is taken down
            return
        self.panels_stale = True
        self.show_panels()

    @staticmethod
    def _event_line(event: SourceEvent) -> str:
        stamp = time.strftime("%H:%M:%S", time.localtime(event.t)) if event.t > 1e8 else ""
        count = f" (x{event.count})" if event.count > 1 else ""
        level = LEVEL_NAMES.get(event.level, "info")
        return f"{stamp} {level:7} {event.bus}: {event.message}{count}"

    def _freeze(self, index: int) -> None:
        self.trigger = None
        self.frozen_on = index
        frames = self.frames
        if not frames.jump_to_index(index):
            frames.set_filter(None)
            self.main_screen.query_one("#filter", Input).value = ""
            frames.jump_to_index(index)
        self.bell()
        self.notify(
            f"trigger: frozen on #{self.store.seq[index]} (capture goes on; End follows)",
            severity="warning",
        )

    # -- status ----------------------------------------------------------------------------

    def status_text(self) -> str:
        frames = self.frames
        parts = []
        if self.failure is not None:
            parts.append("SESSION FAILED (see Events; q quits)")
        elif self.plan.replay is not None:
            replay = self.plan.replay
            filled = int(replay.position * 10)
            bar = "█" * filled + "░" * (10 - filled)
            state = "paused" if replay.paused else "done" if self.done else "playing"
            parts.append(f"replay {state} {speed_text(replay.speed)} {bar} {replay.position:.0%}")
        elif self.done:
            parts.append("capture ended")
        else:
            parts.append("live")
        if self.damage:
            parts.append("INPUT DAMAGED (see Events)")
        if frames.follow:
            parts.append("following")
        else:
            parts.append(f"paused, {frames.new_while_paused:,} new")
        # what the list has taken in: the store may hold a batch more until the next update
        if frames.filter is None:
            parts.append(f"{frames.known:,} records")
        else:
            shown = f"{frames.row_count:,} of {frames.known - frames.first:,} shown"
            parts.append(f"{shown} (filter: {frames.filter.text})")
        if frames.first:
            parts.append(f"keeping the last {self.store.keep:,}")
        if self.dropped:
            parts.append(f"{self.dropped:,} DROPPED")
        if frames.marks:
            parts.append("marks " + "".join(sorted(frames.marks)))
        if self.trigger:
            parts.append(f"trigger armed: {self.trigger}")
        parts.append(f"time: {frames.time_mode.value}")
        if self.plan.recording_path:
            parts.append(f"recording {Path(self.plan.recording_path).name}")
        return " | ".join(parts)

    def show_status(self) -> None:
        if self.closing:
            return
        try:
            text = self.status_text()
            if text != self._status:  # one line of fixed height: no layout needed
                self.main_screen.query_one("#status", Static).update(text, layout=False)
                self._status = text
        except NoMatches:  # the 0.25 s timer fired while the app tears its panes down
            return

    # -- selection, detail, hex --------------------------------------------------------------

    @on(RowSelected)
    def row_selected(self, event: RowSelected) -> None:
        if self.closing:  # a message that comes in while the app is taken down
            return
        # following a fast bus must not rebuild the tree per batch: it costs the session's
        # thread the GIL while a capture decodes
        self._detail_due = event.index
        if self._detail_timer is None:
            delay = DETAIL_FOLLOW_S if self.frames.follow else DETAIL_S
            self._detail_timer = self.set_timer(delay, self._apply_detail)

    def _apply_detail(self) -> None:
        self._detail_timer = None
        if not self.closing:  # the timer can outlive the screens when the app quits
            self._show_detail(self._detail_due)

    def _show_detail(self, index: int | None) -> None:
        tree = self.main_screen.query_one(DetailTree)
        hexpane = self.main_screen.query_one(HexPane)
        if index is None or index < self.store.first:  # (dropped since: the next one comes)
            tree.show(None)
            hexpane.show(b"")
            return
        rec = self.store.record(index)
        pair_text = ""
        if rec.pair is not None:
            pair_index = self.store.index_of_seq(rec.pair)
            if pair_index is not None:
                pair_text = f"({self.store.name_of(pair_index)}: {self.store.summary[pair_index]})"
        tree.show(rec, pair_text)
        hexpane.show(rec.raw)
        device = self.store.device_of(index)
        if device is not None:
            self.main_screen.query_one(RegisterWatch).follow((self.store.bus_of(index), device))

    @on(FieldSelected)
    def field_selected(self, event: FieldSelected) -> None:
        if self.closing:  # a message that comes in while the app is taken down
            return
        self.main_screen.query_one(HexPane).span = event.span

    @on(ByteSelected)
    def byte_selected(self, event: ByteSelected) -> None:
        if self.closing:  # a message that comes in while the app is taken down
            return
        self.main_screen.query_one(DetailTree).select_offset(event.offset)

    @on(JumpTo)
    def jump_to(self, event: JumpTo) -> None:
        if self.closing:  # a message that comes in while the app is taken down
            return
        self.go_to_index(event.index)

    def go_to_index(self, index: int) -> None:
        frames = self.frames
        if index < frames.first:
            self.notify(f"that frame is no longer kept (the last {self.store.keep:,} are)")
            return
        if not frames.jump_to_index(index):
            self.notify("that frame is hidden by the filter: filter cleared")
            self.main_screen.query_one("#filter", Input).value = ""
            frames.set_filter(None)
            frames.jump_to_index(index)
        frames.focus()

    # -- grip cycles -------------------------------------------------------------------------

    @on(CycleChosen)
    def cycle_chosen(self, event: CycleChosen) -> None:
        if not self.closing:  # a message that comes in while the app is taken down
            self.show_cycle(event.cycle)

    def show_cycle(self, cycle: Cycle) -> None:
        """Select the cycle's command in the frame list and mark every frame that decided it
        (] and [ step through them); a filter that hides the command is cleared, and said."""
        frames, store = self.frames, self.store
        frames.take_new(store.count)  # the store may be a batch ahead of the list
        self.evidence = cycle_frames(store, cycle)
        frames.evidence = frozenset(self.evidence)
        frames.restyle()
        start = find_frame(store, cycle.bus, cycle.start_seq)
        if start is None:
            self.notify(f"the cycle's command (#{cycle.start_seq} on {cycle.bus}) is not held")
            return
        self.go_to_index(start)
        self.notify(
            f"{len(self.evidence)} frames decided it: {MARKER_EVIDENCE} (] [ step)", timeout=4
        )

    def action_cycles(self) -> None:
        self.action_tab("cycles")
        self.main_screen.query_one(CyclesPanel).focus()

    def action_next_evidence(self) -> None:
        self._step_evidence(1)

    def action_previous_evidence(self) -> None:
        self._step_evidence(-1)

    def _step_evidence(self, step: int) -> None:
        if not self.evidence:
            self.notify("no grip cycle chosen: Enter on one in the cycles panel (c)")
            return
        here = self.frames.selected
        if here is None:
            later = self.evidence
        else:
            later = [i for i in self.evidence if (i - here) * step > 0]
        if not later:
            self.notify(f"no {'next' if step > 0 else 'previous'} frame of this cycle")
            return
        self.go_to_index(later[0] if step > 0 else later[-1])

    # -- actions -----------------------------------------------------------------------------

    async def action_quit(self) -> None:
        """Stop the session and wait until every listener (the recording) is closed."""
        self.notify("closing the session ...")
        self.stop_session()
        for worker in self.workers:
            if worker.name == "session":
                try:
                    await worker.wait()
                except Exception:
                    pass  # what the session raised is in self.failure already
        self.exit(0)  # a session failure is in self.failure (exit status 1)

    def action_help(self) -> None:
        self.push_screen(HelpScreen())

    def action_pause(self) -> None:
        replay = self.plan.replay
        if replay is not None and not self.done:
            paused = replay.toggle()
            self.notify("replay paused" if paused else "replay resumed")
        elif self.frames.follow:
            self.frames.follow = False
        else:
            self.frames.action_follow()
        self.show_status()

    def action_follow(self) -> None:
        self.frames.action_follow()
        self.frames.focus()

    def action_filter(self) -> None:
        box = self.main_screen.query_one("#filter", Input)
        box.display = True
        box.focus()

    def applied_filter_text(self) -> str:
        applied = self.frames.filter
        return "everything is shown" if applied is None else f"still applied: {applied.text}"

    @on(Input.Changed, "#filter")
    def filter_changed(self, event: Input.Changed) -> None:
        error = self.main_screen.query_one("#filter-error", Static)
        try:
            parse(event.value)
        except FilterError as exc:
            error.update(
                f"{' ' * exc.position}^ {exc.message} (not applied; {self.applied_filter_text()})"
            )
            error.display = True
            event.input.add_class("-invalid")
            return
        error.display = False
        event.input.remove_class("-invalid")

    @on(FilterCancelled)
    def filter_cancelled(self) -> None:
        """Esc: the box shows the filter that is applied again (hidden if none) and the list
        takes the keys back."""
        applied = self.frames.filter
        box = self.main_screen.query_one("#filter", Input)
        with box.prevent(Input.Changed):
            box.value = "" if applied is None else applied.text
        box.remove_class("-invalid")
        box.display = applied is not None
        self.main_screen.query_one("#filter-error", Static).display = False
        self.frames.focus()
        self.notify(f"filter edit cancelled; {self.applied_filter_text()}")

    @on(Input.Submitted, "#filter")
    def filter_submitted(self, event: Input.Submitted) -> None:
        try:
            compiled = parse(event.value)
        except FilterError as exc:
            self.notify(
                f"the filter is not applied: {exc.message}; {self.applied_filter_text()}",
                severity="warning",
            )
            return  # the error stays under the line
        self.frames.set_filter(compiled)
        if compiled is None:
            event.input.display = False
        self.frames.focus()
        self.show_status()

    def action_search(self) -> None:
        def done(text: str | None) -> None:
            frames = self.frames
            frames.search = re.compile(re.escape(text), re.IGNORECASE) if text else None
            frames.restyle()
            if frames.search is not None and not frames.find(1, frames.search_matches):
                frames.find(-1, frames.search_matches)

        current = self.frames.search.pattern if self.frames.search else ""
        self.push_screen(
            PromptScreen("search (n/N: next/previous)", re.sub(r"\\(.)", r"\1", current)), done
        )

    def action_next_problem(self) -> None:
        self._step(1)

    def action_previous_problem(self) -> None:
        self._step(-1)

    def _step(self, step: int) -> None:
        frames = self.frames
        match = frames.search_matches if frames.search is not None else frames.is_problem
        if not frames.find(step, match):
            what = "match" if frames.search is not None else "problem"
            self.notify(f"no {'next' if step > 0 else 'previous'} {what}")

    def action_pair(self) -> None:
        frames = self.frames
        index = frames.selected
        pair = None if index is None else self.store.pair_of(index)
        target = None if pair is None else self.store.index_of_seq(pair)
        if target is None:
            self.notify("this frame has no pair")
            return
        self.go_to_index(target)

    def action_time_reference(self) -> None:
        frames = self.frames
        index = frames.selected
        frames.reference = None if index is None or index == frames.reference else index
        if frames.reference is not None:
            frames.time_mode = TimeMode.REFERENCE
        frames.restyle()
        self.show_status()

    def action_time_mode(self) -> None:
        frames = self.frames
        frames.time_mode = frames.time_mode.next()
        frames.restyle()
        self.show_status()

    # -- marks: m or ' and then a letter -------------------------------------------------------
    # The letter is taken in ``on_event``, before any widget sees it: the m/' bindings are
    # priority bindings, run as the app takes the key from the terminal, so the next key (typed
    # 50 ms later, or in the same read) is always the letter, however busy the screen is.

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        if action in ("set_mark", "goto_mark"):
            return self.screen is self.main_screen  # not over the help or a prompt
        return True

    def action_set_mark(self) -> None:
        self._await_letter("mark this frame: press a letter (Esc cancels)", self._set_mark)

    def action_goto_mark(self) -> None:
        self._await_letter("go to mark: press a letter (Esc cancels)", self._goto_mark)

    def _await_letter(self, prompt: str, then: Callable[[str], None]) -> None:
        self.awaiting_letter = (prompt, then)
        label = self.main_screen.query_one("#letter-prompt", Static)
        label.update(prompt)
        label.display = True

    async def on_event(self, event: events.Event) -> None:
        if isinstance(event, events.Key) and self.awaiting_letter is not None:
            _, then = self.awaiting_letter
            self.awaiting_letter = None
            self.main_screen.query_one("#letter-prompt", Static).display = False
            letter = event.character or ""
            if len(letter) == 1 and letter.isalpha():
                then(letter)
            elif event.key == "escape":
                self.notify("cancelled")
            else:
                self.notify(f"{event.key} is not a letter: cancelled")
            return
        await super().on_event(event)

    def _set_mark(self, letter: str) -> None:
        frames = self.frames
        index = frames.selected
        if index is None:
            self.notify("no frame to mark")
            return
        frames.marks[letter] = index
        frames.restyle()
        seq = self.store.seq[index]
        saved = self.feed.add_mark(self.store.time(index), letter, seq)
        self.notify(f"mark {letter} on #{seq}" + (" (saved in the recording)" if saved else ""))
        self.show_status()

    def _goto_mark(self, letter: str) -> None:
        if letter in self.frames.marks:
            self.go_to_index(self.frames.marks[letter])
        else:
            self.notify(f"no mark {letter}")

    def action_goto(self) -> None:
        def check(text: str) -> str | None:
            return None if self._goto_target(text) is not None else "a frame number, or t=SECONDS"

        def done(text: str | None) -> None:
            target = self._goto_target(text or "")
            if target is not None:
                self.go_to_index(target)

        self.push_screen(
            PromptScreen("go to frame number (1234) or time (t=12.5)", check=check), done
        )

    def _goto_target(self, text: str) -> int | None:
        text = text.strip().lower()
        try:
            if text.startswith("t=") or text.endswith("s"):
                seconds = float(text.removeprefix("t=").removesuffix("s"))
                return self.store.first_index_at_or_after((self.store.t0 or 0.0) + seconds)
            return self.store.index_of_seq(int(text.lstrip("#")))
        except ValueError:
            return None

    def action_arm_trigger(self) -> None:
        if self.trigger:
            self.trigger = None
            self.feed.arm(None)
            self.notify("trigger disarmed")
        else:
            self.trigger = self.plan.freeze_on or "error"
            self.feed.arm(self.trigger)
            self.notify(f"trigger armed: freeze on the next {self.trigger}")
        self.show_status()

    def action_faster(self) -> None:
        self._speed(1)

    def action_slower(self) -> None:
        self._speed(-1)

    def _speed(self, step: int) -> None:
        replay = self.plan.replay
        if replay is None:
            self.notify("speed applies to replays of captures")
            return
        replay.set_speed(next_speed(replay.speed, step))
        self.show_status()

    def export_indices(self) -> Iterable[int]:
        frames = self.frames
        shown = range(frames.row_count)
        positions: Iterable[int] = shown
        if "a" in frames.marks and "b" in frames.marks:
            lo, hi = sorted((frames.marks["a"], frames.marks["b"]))
            positions = (p for p in shown if lo <= frames.index_at(p) <= hi)
        return [frames.index_at(p) for p in positions]

    def action_export(self) -> None:
        def check(text: str) -> str | None:
            try:
                export_format(text)
            except ValueError as exc:
                return str(exc)
            return None

        def done(path: str | None) -> None:
            if path:
                self.run_export(path, list(self.export_indices()))

        marks = self.frames.marks
        what = "marked range a..b" if "a" in marks and "b" in marks else "shown records"
        self.push_screen(
            PromptScreen(
                f"export the {what} to (.jsonl, .csv, .mcap):", "eg2scope-export.jsonl", check=check
            ),
            done,
        )

    @work(thread=True, name="export")
    def run_export(self, path: str, indices: list[int]) -> None:
        try:
            n = export(self.store, indices, path)
        except (OSError, ValueError) as exc:
            self.call_from_thread(self.notify, f"export failed: {exc}", severity="error")
            return
        self.export_note = f"exported {n:,} records to {Path(path).name}"
        self.call_from_thread(self.notify, self.export_note)

    def action_toggle_detail(self) -> None:
        screen = self.main_screen
        screen.toggle_class("-show-detail" if screen.has_class("-narrow") else "-hide-detail")

    def action_tab(self, name: str) -> None:
        self.main_screen.query_one(TabbedContent).active = name

    def get_system_commands(self, screen: Screen) -> Iterable[SystemCommand]:
        yield from super().get_system_commands(screen)
        for key in keys.KEYS:
            if key.action in ("command_palette", "help"):
                continue
            title = key.description.split(":")[0].split(" (")[0]
            yield SystemCommand(
                keys.literal(title.capitalize()),
                keys.literal(f"{key.description} [{keys.shown_keys(key)}]"),
                lambda action=key.action: self.run_action(action),
            )


__all__ = ["TRIGGERS", "Eg2ScopeApp", "SessionPlan"]
