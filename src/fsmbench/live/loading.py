"""The live bench's controllers: ``LoadController``, checked on the call, and the memory.

:class:`ControllerCommands` is the controller half of the commands of
:class:`~fsmbench.live.core.LiveBench` (:mod:`fsmbench.live.commands` has the others).
``LoadController`` resolves, parses and checks the controller on the client's call
(:mod:`fsmbench.live.controllers`) and only then puts it in the loop (bumplessly, when
closed) or keeps it for the next ``CloseLoop``. A file's parsing once ran off the call: a
bad file then answered OK and failed seconds later, in Status, with the file's first bytes.
Controller files are a few kB: resolving, parsing and checking take ~0.1 s, far below
Tango's 3 s client timeout.

The loaded controller is remembered (:class:`ControllerMemory`) and loaded again, through
the same checks, when the device starts (:meth:`ControllerCommands.restore_controller`).
"""

from __future__ import annotations

import json
import threading
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from fsmbench.live.commands import _command
from fsmbench.live.controllers import (
    BenchCheck,
    ControllerRequest,
    parse_request,
    read_controller_file,
    resolve_controller_file,
)
from fsmbench.live.states import Refused

if TYPE_CHECKING:
    from fsmbench.live.backend import PlaybackBackend, TwinBackend
    from fsmbench.sim.engine import DiscreteController

__all__ = ["MEMORY_FORMAT", "ControllerCommands", "ControllerMemory", "FileMemory"]


class ControllerMemory(Protocol):
    """Where the loaded controller is remembered across restarts."""

    where: str  #: in words, for Status

    def load(self) -> dict[str, str] | None:
        """The remembered ``{"path": ..., "controller": ...}`` or ``{"source": "seed"}``, or
        None."""

    def save(self, doc: dict[str, str] | None) -> None:
        """Remember ``doc`` (None: forget)."""


class FileMemory:
    """A :class:`ControllerMemory` in a small JSON file (the EPICS IOC's).

    Parameters
    ----------
    path : Path
    """

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.where = f"the file {self.path}"

    def load(self) -> dict[str, str] | None:
        try:
            doc = json.loads(self.path.read_text())
        except (OSError, ValueError):
            return None
        if isinstance(doc, dict) and doc.get("format") == MEMORY_FORMAT[0]:
            doc = doc.get("controller")
        # else a file of before the format: the request itself
        return {str(k): str(v) for k, v in doc.items()} if isinstance(doc, dict) and doc \
            else None

    def save(self, doc: dict[str, str] | None) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_suffix(".tmp")
        name, version = MEMORY_FORMAT
        tmp.write_text(json.dumps({"format": name, "format_version": version,
                                   "controller": doc or {}}) + "\n")
        tmp.replace(self.path)


#: The IOC's remembered controller: ``{"format", "format_version", "controller": request}``.
MEMORY_FORMAT = ("fsmbench.ioc_memory", 1)


class ControllerCommands:
    """``LoadController`` and the remembered controller of :class:`~.core.LiveBench`."""

    if TYPE_CHECKING:  # provided by LiveBench
        backend: TwinBackend | PlaybackBackend
        fs_hz: float
        qd_gain_v_per_rad: tuple[float, float]
        controllers_folder: Path
        bench_check: BenchCheck
        memory: ControllerMemory | None
        _lock: threading.RLock
        _loaded: DiscreteController | None
        _loaded_doc: dict[str, str] | None
        _good: list[tuple[DiscreteController, dict[str, str]]]
        _notice: str

        def log(self, level: str, message: str) -> None: ...
        def publish(self) -> None: ...
        def check_allowed(self, command: str) -> None: ...
        def _locked(self, command: str) -> Any: ...
        def _set_loop(self, controller: DiscreteController | None, *, hold: bool,
                      cause: str) -> None: ...
        def _remember(self) -> None: ...
        def _seed_controller(self) -> DiscreteController: ...
        @property
        def controller_name(self) -> str: ...

    @_command("LoadController")
    def load_controller(self, argument: str) -> str:
        """Check a controller on the bench and load it, on the call.

        The argument is a controllers file in the controllers folder (its path, relative
        to the folder or absolute, or ``{"path": ..., "controller": name}``), ``seed`` (the
        ESRF study's controller, 9.2) or ``last-good`` (the latest controller before the
        one in effect that ran without tripping). In closed loop it takes over
        bumplessly; otherwise the next :meth:`close_loop` uses it.

        Returns
        -------
        str
            What it loaded, and the figures it passed the check with.

        Raises
        ------
        Refused
            ``FSM_BadArgument``: the argument, the path, the file, or the check on the
            bench (the margin that failed, with units); the loop runs on unchanged.
        """
        request = parse_request(argument)
        self.check_allowed("LoadController")  # the state first: nothing is read in FAULT
        k, doc, where = self._controller_for(request)
        check = self.bench_check.check(k)
        if not check.passed:
            raise Refused("FSM_BadArgument", f"LoadController refused: {k.name} fails the "
                                             f"check on the device's bench ({check.bench}): "
                                             f"{'; '.join(check.failures)}. The loop runs on "
                                             f"with {self.controller_name}.")
        with self._locked("LoadController"):
            self.check_allowed("LoadController")
            closed = self._install(k, doc)
            self._notice = f"Controller {k.name} loaded from {where}."
        use = "in the loop (bumpless)" if closed else "loaded for the next CloseLoop"
        return f"{k.name} {use}; checked on the device's bench: {check.summary}"

    def _controller_for(self, request: ControllerRequest
                        ) -> tuple[DiscreteController, dict[str, str], str]:
        """The controller a request names, its memory document and where it came from."""
        if request.kind == "seed":
            return self._seed_controller(), {"source": "seed"}, "seed (the ESRF study's, 9.2)"
        if request.kind == "last-good":
            with self._lock:
                now = self.backend.controller or self._loaded
                earlier = [g for g in self._good if g[0] is not now]
                names = ", ".join(g[0].name for g in self._good) or "none"
            if not earlier:
                raise Refused("FSM_BadArgument", "LoadController refused: last-good: no "
                                                 "controller before the one in effect ran "
                                                 "without tripping since the device started "
                                                 f"(loaded since: {names}); give a file or "
                                                 "seed")
            k, doc = earlier[-1]
            return k, dict(doc), f"{doc.get('path', 'seed')} (last-good)"
        path = resolve_controller_file(request.path, folder=self.controllers_folder)
        k, name = read_controller_file(path, typed=request.path, name=request.controller,
                                       ts_s=1.0 / self.fs_hz,
                                       gd_v_per_rad=self.qd_gain_v_per_rad)
        # The file and the controller chosen in it: the same controller, however named.
        return k, {"path": str(path), "controller": name}, request.path

    def _install(self, k: DiscreteController, doc: dict[str, str]) -> bool:
        """Load ``k`` (in the loop when closed) and remember it; True when it is in the loop.
        Under the bench's lock."""
        self._loaded, self._loaded_doc = k, dict(doc)
        # The latest of each source, newest last: last-good walks back through them.
        self._good = [g for g in self._good if g[0] is not k and g[1] != doc]
        self._good.append((k, dict(doc)))
        closed = self.backend.controller is not None
        if closed:
            self._set_loop(k, hold=True, cause="LoadController")
        self._remember()
        return closed

    def restore_controller(self) -> str:
        """Load the controller remembered from the last run (``memory``), through the same
        checks as :meth:`load_controller`; what it did, in words (also in Status)."""
        doc = self.memory.load() if self.memory is not None else None
        if not doc or not (doc.get("source") == "seed" or doc.get("path")):
            return "no controller remembered"
        if not self.backend.acts:
            return "a playback runs no controller"
        assert self.memory is not None
        request = (ControllerRequest(kind="seed") if doc.get("source") == "seed" else
                   ControllerRequest(kind="file", path=doc["path"],
                                     controller=doc.get("controller")))
        try:
            k, new_doc, _ = self._controller_for(request)
            check = self.bench_check.check(k)
            if not check.passed:
                raise Refused("FSM_BadArgument", f"{k.name} fails the check on the device's "
                                                 f"bench ({check.bench}): "
                                                 f"{'; '.join(check.failures)}")
        except Refused as refused:
            why = refused.sentence.removeprefix("LoadController refused: ").rstrip(".")
            self._notice = f"The controller remembered in {self.memory.where} was not loaded: " \
                           f"{why}."
            self.log("WARNING", self._notice)
            self.publish()
            return self._notice
        with self._locked("Init"):
            self._install(k, new_doc)
            self._notice = (f"Controller {k.name} loaded (restored from the last run: "
                            f"{self.memory.where}; checked on the device's bench).")
        self.publish()
        return f"restored the controller {k.name} from {self.memory.where}"
