"""Where a Rerun view of a session goes: a viewer spawned here, an .rrd file, a running viewer,
or Rerun's web viewer served on this machine; and the ``--rerun [TARGET]`` option of the live
commands.

Default (no target named): spawn the viewer that ships with rerun-sdk when a display can be
opened, otherwise write ``<name>.rrd`` in the current directory and say how to open it. The web
viewer is served by Rerun's own command-line server, bound to 127.0.0.1 only (the SDK's
``serve_web_viewer`` listens on every interface), and ends with eg2scope however eg2scope ends
(Ctrl-C, SIGTERM, or killed outright: on Linux the kernel ends it). Its address asks for the
WebGL renderer: Rerun's default, WebGPU, fails on machines without a GPU (its buffers are too
large for a software renderer), and WebGL works everywhere.

rerun is imported only when an output is opened, so the command line starts fast.
"""

from __future__ import annotations

import atexit
import os
import signal
import socket
import subprocess
import sys
import threading
import time
import webbrowser
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import IO, Any, Final
from urllib.parse import quote

from ..errors import UsageError

APPLICATION_ID: Final = "eg2scope"
SAVE: Final = "save"
SPAWN: Final = "spawn"
CONNECT: Final = "connect"
SERVE_WEB: Final = "serve-web"
DEFAULT: Final = "default"  # --rerun given without a target
DEFAULT_URL: Final = "rerun+http://127.0.0.1:9876/proxy"
LOCALHOST: Final = "127.0.0.1"
WEB_PORT: Final = 9090  # Rerun's own default, when it is free
# the web viewer's renderer: WebGPU (Rerun's default) fails without a GPU, WebGL works anywhere
WEB_RENDERER: Final = "webgl"
URL_SCHEMES: Final = ("rerun://", "rerun+http://", "rerun+https://")


@dataclass(frozen=True)
class RerunTarget:
    """``kind``: save, spawn, connect or serve-web; ``where``: the .rrd path or the viewer URL."""

    kind: str
    where: str | None = None

    def describe(self) -> str:
        return f"{self.kind} {self.where}" if self.where else self.kind


def can_display() -> bool:
    """Whether a native viewer window can be opened here (X11/Wayland on Linux; always on
    macOS and Windows)."""
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def rrd_name(source: str | None) -> str:
    """``<capture name>.rrd`` in the current directory (``run.log.gz`` -> ``run.rrd``), or a
    dated name for a live session."""
    if not source:
        return datetime.now().strftime("eg2scope-%Y%m%d-%H%M%S.rrd")
    name = Path(source).name
    for _ in range(2):  # x.log.gz -> x
        stem, dot, suffix = name.rpartition(".")
        if not dot or not stem:
            break
        name = stem
        if suffix.lower() != "gz":
            break
    return f"{name}.rrd"


def default_target(source: str | None) -> RerunTarget:
    """Spawn a viewer when a display can be opened, else write ``<name>.rrd`` here."""
    return RerunTarget(SPAWN) if can_display() else RerunTarget(SAVE, rrd_name(source))


def save_target(path: str) -> RerunTarget:
    if not path.lower().endswith(".rrd"):
        raise UsageError(f"Rerun recordings are .rrd files: name the file *.rrd, not {path}")
    return RerunTarget(SAVE, path)


def connect_target(url: str | None) -> RerunTarget:
    url = url or DEFAULT_URL
    if not url.startswith(URL_SCHEMES):
        raise UsageError(
            f"a Rerun viewer URL starts with {', '.join(URL_SCHEMES)} and ends in /proxy "
            f"(default {DEFAULT_URL}), not {url!r}"
        )
    return RerunTarget(CONNECT, url)


def parse_target(text: str | None, source: str | None = None) -> RerunTarget:
    """``--rerun [TARGET]``: nothing (the default rule), ``spawn``, ``web`` / ``serve-web``,
    a viewer URL (``rerun+http://...``) or a file ``NAME.rrd``."""
    if text in (None, "", DEFAULT):
        return default_target(source)
    assert text is not None
    if text == SPAWN:
        return RerunTarget(SPAWN)
    if text in ("web", SERVE_WEB):
        return RerunTarget(SERVE_WEB)
    if "://" in text:
        return connect_target(text)
    if text.lower().endswith(".rrd"):
        return save_target(text)
    raise UsageError(
        f"--rerun takes spawn, web, a viewer URL (rerun+http://HOST:PORT/proxy) or a file "
        f"NAME.rrd, not {text!r}"
    )


@dataclass(frozen=True)
class TargetChoice:
    """Where ``eg2scope plot``'s options send the plot: ``save`` an .rrd file, ``spawn`` a
    viewer, ``connect`` to a running one ("": the default URL), or ``serve_web``; none of
    them: the default for the source (``default_target``)."""

    save: str | None = None
    spawn: bool = False
    connect: str | None = None
    serve_web: bool = False


def chosen_target(choice: TargetChoice, source: str | None) -> RerunTarget:
    """The target the choice names, or the default for ``source`` (None: a live session)."""
    if choice.save:
        if source is not None and choice.save == source:
            raise UsageError(f"--save {choice.save} would overwrite the capture being plotted")
        return save_target(choice.save)
    if choice.spawn:
        return RerunTarget(SPAWN)
    if choice.connect is not None:
        return connect_target(choice.connect or None)
    if choice.serve_web:
        return RerunTarget(SERVE_WEB)
    return default_target(source)


# -- opening an output -------------------------------------------------------------------------


class RerunOutput:
    """A recording stream and where it goes. Data logged before ``attach`` waits in the
    stream's buffer, so a capture is attached once its grippers are known and its file holds
    one blueprint; ``show`` attaches, or sends the new blueprint to what is attached.
    ``finish()`` completes it (an .rrd file gets its footer); ``hold()`` keeps a served web
    viewer up until Ctrl-C."""

    def __init__(self, target: RerunTarget, out: IO[str] | None = None) -> None:
        import rerun as rr

        self.target = target
        self.out = out or sys.stderr
        if target.kind == SAVE:
            assert target.where is not None
            _check_writable(target.where)  # fail before the session starts
        self.stream = rr.RecordingStream(APPLICATION_ID)
        # only send_columns and static data are logged: no log_time or log_tick timelines
        self.stream.set_log_time_enabled(False)
        self.stream.set_log_tick_enabled(False)
        self.server: subprocess.Popen[bytes] | None = None
        self.web_url: str | None = None
        self.attached = False
        self._finished = False
        self._discarded = False

    def show(self, blueprint: Any) -> None:
        """Attach to the target with ``blueprint`` as the default, or send it as the new one."""
        if self._discarded:
            return
        if self.attached:
            self.stream.send_blueprint(blueprint, make_active=True, make_default=True)
        else:
            self.attach(blueprint)

    @property
    def is_file(self) -> bool:
        return self.target.kind == SAVE

    def attach(self, blueprint: Any) -> None:
        """Send the recording (what is buffered, then everything) to the target, with
        ``blueprint`` as its default (None: one is sent later, with ``show``). OSError when it
        cannot be reached."""
        self.attached = True
        kind, where, stream = self.target.kind, self.target.where, self.stream
        if kind == SAVE:
            assert where is not None
            stream.save(where, default_blueprint=blueprint)
        elif kind == SPAWN:
            stream.spawn(default_blueprint=blueprint, hide_welcome_screen=True)
        elif kind == CONNECT:
            stream.connect_grpc(where, default_blueprint=blueprint)
        elif kind == SERVE_WEB:
            self.server, grpc_url, self.web_url = _serve_web()
            atexit.register(self.stop_server)  # whoever ran the session, the server ends with it
            stream.connect_grpc(grpc_url, default_blueprint=blueprint)
            print(
                f"eg2scope: serving the Rerun web viewer at {self.web_url} (the WebGL renderer: "
                "it needs no GPU); Ctrl-C to stop",
                file=self.out,
            )
            if can_display():
                webbrowser.open(self.web_url)
        else:
            raise ValueError(f"unknown Rerun target {kind!r}")

    def finish(self, blueprint: Any) -> None:
        """Send everything (attaching first, with ``blueprint``, if nothing was sent yet);
        close a file and say how to open it. Idempotent."""
        if self._finished:
            return
        self._finished = True
        if not self.attached:
            self.attach(blueprint)
        self.stream.flush()
        if self.target.kind == SAVE:
            self.stream.disconnect()  # writes the footer: the file is complete
            print(
                f"eg2scope: Rerun recording written to {self.target.where}; open it with: "
                f"rerun {self.target.where}",
                file=self.out,
            )

    def discard(self) -> None:
        """Nothing could be read: no file (the empty one the check made, or one begun, is
        removed), and nothing more sent anywhere."""
        self._finished = self._discarded = True
        if self.attached:
            self.stream.disconnect()
        if self.target.kind == SAVE and self.target.where:
            Path(self.target.where).unlink(missing_ok=True)

    def hold(self) -> None:
        """Serve the web viewer until Ctrl-C, SIGTERM or SIGHUP (a capture is sent at once;
        the browser reads it from the server), then stop the server."""
        if self.server is None:
            return
        from ..session.session import signals_as_interrupt  # SIGTERM and SIGHUP as Ctrl-C

        try:
            with signals_as_interrupt():
                # the address came before the data: say when the viewer has all of it, once
                # the handlers are in place (a Ctrl-C it prompts is a clean stop)
                print(
                    "eg2scope: everything is sent to the web viewer; Ctrl-C to stop it",
                    file=self.out,
                )
                while self.server.poll() is None:
                    time.sleep(0.2)
        except KeyboardInterrupt:
            pass
        self.stop_server()

    def stop_server(self) -> None:
        """Stop a served web viewer. The stream lets go of it first: everything sent is
        flushed, and nothing is left to send to a server that is gone (Rerun would report a
        failed flush at exit)."""
        if self.server is not None and self.server.poll() is None:
            self.stream.disconnect()
            self.server.terminate()
            try:
                self.server.wait(5)
            except subprocess.TimeoutExpired:
                self.server.kill()
                self.server.wait()


def _check_writable(path: str) -> None:
    """Fail before the session starts, with the OS's own words, if the file cannot be made."""
    with open(path, "ab"):
        pass


def _free_port(preferred: int | None = None) -> int:
    """A port free on 127.0.0.1: ``preferred`` if it is, else one the OS picks."""
    for port in (preferred, 0):
        if port is None:
            continue
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            try:
                s.bind((LOCALHOST, port))
            except OSError:
                continue
            return int(s.getsockname()[1])
    raise OSError("no free TCP port on 127.0.0.1")


def rerun_executable() -> list[str]:
    """The Rerun program that ships with rerun-sdk, run directly: the ``rerun`` script is a
    wrapper that starts it as a child and would leave it running when stopped."""
    override = os.environ.get("RERUN_CLI_PATH")  # rerun_cli's own override
    if override:
        return [override]
    import rerun_cli

    base = Path(rerun_cli.__file__).parent
    suffix = ".exe" if sys.platform == "win32" else ""
    for candidate in (base / "Rerun.app" / "Contents" / "MacOS" / "Rerun", base / f"rerun{suffix}"):
        if candidate.is_file():
            return [str(candidate)]
    return [sys.executable, "-m", "rerun_cli"]


def _serve_web() -> tuple[subprocess.Popen[bytes], str, str]:
    """Rerun's web viewer and its gRPC proxy, both bound to 127.0.0.1; (process, gRPC URL for
    the SDK, http URL for the browser)."""
    grpc_port = _free_port()
    web_port = _free_port(WEB_PORT)
    cmd = [
        *rerun_executable(),
        "--serve-web",
        "--bind",
        LOCALHOST,
        "--port",
        str(grpc_port),
        "--web-viewer-port",
        str(web_port),
    ]
    quiet = subprocess.DEVNULL  # its banner and log lines are not ours to show
    # its own session: Ctrl-C in the terminal reaches eg2scope, which stops it after the last
    # data is sent; on Linux the kernel also ends it if eg2scope dies without stopping it
    server = subprocess.Popen(
        cmd,
        stdin=quiet,
        stdout=quiet,
        stderr=quiet,
        start_new_session=sys.platform != "win32",
        preexec_fn=_end_with_parent(),
    )
    deadline = time.monotonic() + 20.0
    while not _listening(grpc_port) or not _listening(web_port):
        if server.poll() is not None:
            raise OSError(f"the Rerun web viewer did not start (exit {server.returncode})")
        if time.monotonic() > deadline:
            server.terminate()
            raise OSError("the Rerun web viewer did not start within 20 s")
        time.sleep(0.05)
    grpc_url = f"rerun+http://{LOCALHOST}:{grpc_port}/proxy"
    web_url = f"http://{LOCALHOST}:{web_port}/?url={quote(grpc_url, safe='')}"
    return server, grpc_url, f"{web_url}&renderer={WEB_RENDERER}"


def _end_with_parent() -> Any:
    """On Linux, a function for the child to run before it starts: the kernel sends it SIGTERM
    when eg2scope's process ends, however it ends (prctl PR_SET_PDEATHSIG). None elsewhere,
    and off the main thread (the kernel watches the thread that forks, not the process).
    The C function is looked up here, before the fork: the child only calls it."""
    if not sys.platform.startswith("linux"):
        return None
    if threading.current_thread() is not threading.main_thread():
        return None  # the signal follows the thread that forks: it would end with that thread
    import ctypes

    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None
    set_parent_death_signal = 1  # PR_SET_PDEATHSIG
    return lambda: prctl(set_parent_death_signal, int(signal.SIGTERM), 0, 0, 0)


def _listening(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.settimeout(0.2)
        return s.connect_ex((LOCALHOST, port)) == 0
