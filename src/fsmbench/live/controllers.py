"""Controllers the live bench loads: which, from where, what they are, and whether they are safe.

``LoadController`` decides all of it on the client's call, so that a refusal is
its reply and the loop never meets a controller that was not checked:

1. **which** (:func:`parse_request`): a file (its path, or ``{"path": ..., "controller":
   name}``), ``seed`` (the ESRF study's controller, 9.2) or ``last-good`` (the latest
   controller before the one in effect that ran without tripping);
2. **where** (:func:`resolve_controller_file`): a path is taken inside the controllers
   folder (a relative one from it), symbolic links resolved, and refused when it lies
   outside, is not a regular file (a FIFO blocks a reader, a device never ends), is empty
   or is over :data:`MAX_CONTROLLER_BYTES`; a ``fsmbench design`` folder means its
   controllers file, checked the same way;
3. **what** (:func:`read_controller_file`): parsed on the call, at most
   :data:`MAX_CONTROLLER_STATES` states;
4. **whether the bench runs it** (:class:`BenchCheck`): closed on the device's bench
   model, the loop must be stable and keep the margins of :class:`ControllerRequirements`.

What a client reads of a file: its path as the user typed it and, once the file is
recognised as an fsmbench controllers file, the names of its controllers. Never its bytes:
the loader words its problems without quoting the file (:mod:`fsmbench.control.load`), and
any other error while reading is reported by its type alone.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import stat
import threading
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fsmbench.bench.blocks import physical_plant
from fsmbench.control.design import DesignOptions
from fsmbench.control.load import load_controllers, select_controller
from fsmbench.control.loops import discrete_axis_margins
from fsmbench.control.study import CONTROLLERS_MAT, CONTROLLERS_SOS_JSON
from fsmbench.io.errors import RecordingError
from fsmbench.live.states import Refused
from fsmbench.sim.controller import closed_loop_spectral_radius
from fsmbench.sim.plant import ADC_CHANNELS, DAC_CHANNELS, bench_discrete

if TYPE_CHECKING:
    from fsmbench.bench.params import Bench
    from fsmbench.control.freq import Margins
    from fsmbench.sim.engine import DiscreteController

__all__ = ["KEYWORDS", "MAX_CONTROLLER_BYTES", "MAX_CONTROLLER_STATES", "BenchCheck",
           "ControllerCheck", "ControllerRequest", "ControllerRequirements", "parse_request",
           "read_controller_file", "resolve_controller_file"]

#: Arguments that name a controller rather than a file (``./seed`` is a file called seed).
KEYWORDS = ("seed", "last-good")
#: Largest controller file read [bytes]. ``fsmbench design`` writes 4 kB (controllers.mat)
#: and 12 kB (controllers_sos.json) for its four controllers: 256 KiB is 20 times that and
#: parses in milliseconds, and a file named by mistake (a recording, an archive) is refused
#: before a byte of it is read rather than holding the call for seconds.
MAX_CONTROLLER_BYTES = 256 * 1024
#: Most states a loaded controller may have. fsmbench's largest has 14 (its loop-shaped
#: controller, both axes) and is checked in 0.03-0.1 s; the check's cost grows with the
#: order (62 states: 0.65 s measured on two busy cores), and 64 keeps the worst call well
#: inside Tango's 3 s (a cascade's realisation is refused before it is built).
MAX_CONTROLLER_STATES = 64
_DESIGN = DesignOptions()
_USAGE = ('give a controllers file in the controllers folder (its path, or {"path": ..., '
          '"controller": name}), seed (the ESRF study\'s controller) or last-good')


def _refuse(text: str) -> Refused:
    return Refused("FSM_BadArgument", f"LoadController refused: {text}")


# ------------------------------------------------------------------------------ which


@dataclass(frozen=True)
class ControllerRequest:
    """What ``LoadController`` was asked for.

    Attributes
    ----------
    kind : {"file", "seed", "last-good"}
    path : str
        The file's path as the user typed it (``file`` only).
    controller : str or None
        The controller named in the file (None: fsmbench's own, else the first that fits).
    """

    kind: str
    path: str = ""
    controller: str | None = None


def parse_request(argument: str) -> ControllerRequest:
    """The request in ``argument``: a path, ``{"path": ..., "controller": name}``, or a keyword.

    Raises
    ------
    Refused
        ``FSM_BadArgument``: empty, malformed JSON, unknown keys.
    """
    text = argument.strip()
    if not text:
        raise _refuse(f"the argument is empty; {_USAGE}")
    if text in KEYWORDS:
        return ControllerRequest(kind=text)
    if not text.startswith("{"):
        return ControllerRequest(kind="file", path=text)
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise _refuse(f"the argument is not valid JSON ({exc}); {_USAGE}") from None
    except RecursionError:
        raise _refuse(f"the argument's JSON nests too deeply; {_USAGE}") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("path"), str) or \
            not doc["path"].strip() or not set(doc) <= {"path", "controller"}:
        raise _refuse(_USAGE)
    name = doc.get("controller")
    return ControllerRequest(kind="file", path=doc["path"].strip(),
                             controller=None if name is None else str(name))


# ------------------------------------------------------------------------------ where


def _kind(mode: int) -> str:
    for test, words in ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                        (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                        (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return words
    return "not a regular file"


def _inside(path: Path, folder: Path, typed: str) -> None:
    if not path.is_relative_to(folder):
        raise _refuse(f"{typed}: is outside the controllers folder {folder} (a symbolic link "
                      "counts where it points); controllers are loaded only from there")


def resolve_controller_file(typed: str, *, folder: Path) -> Path:
    """The regular file ``typed`` names inside ``folder``, symbolic links resolved.

    Parameters
    ----------
    typed : str
        The path as the user typed it: relative to ``folder``, or absolute.
    folder : Path
        The controllers folder, absolute and resolved.

    Returns
    -------
    Path
        Absolute, resolved. A ``fsmbench design`` folder gives its ``controllers.mat``, or
        its ``controllers_sos.json`` when it has no MAT-file (as :func:`load_controllers`).

    Raises
    ------
    Refused
        ``FSM_BadArgument``, naming ``typed``: a path the filesystem does not take, outside
        ``folder`` (judged before the file is looked at: nothing is said of what lies
        outside), missing, not a regular file, empty or over :data:`MAX_CONTROLLER_BYTES`.
    """
    shown = typed if len(typed) <= 200 else f"{typed[:200]}..."
    try:
        path = (folder / typed).resolve()  # an absolute ``typed`` replaces ``folder``
    except (OSError, ValueError, RuntimeError) as exc:  # NUL, a name too long, a link loop
        why = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise _refuse(f"the path {shown!r} is not one the filesystem takes ({why})") from None
    _inside(path, folder, shown)
    try:
        mode = path.stat()
        if stat.S_ISDIR(mode.st_mode):
            inner = next((path / name for name in (CONTROLLERS_MAT, CONTROLLERS_SOS_JSON)
                          if os.path.lexists(path / name)), None)
            if inner is None:
                raise _refuse(f"{shown}: is a folder without {CONTROLLERS_MAT} or "
                              f"{CONTROLLERS_SOS_JSON} (the files fsmbench design writes)")
            path = inner.resolve()
            _inside(path, folder, f"{shown} ({inner.name})")
            shown = f"{shown} ({inner.name})"
            mode = path.stat()
    except FileNotFoundError:
        raise _refuse(f"{shown}: does not exist in the controllers folder {folder}") from None
    except OSError as exc:
        raise _refuse(f"{shown}: cannot be read ({exc.strerror or type(exc).__name__})") \
            from None
    if not stat.S_ISREG(mode.st_mode):
        raise _refuse(f"{shown}: is {_kind(mode.st_mode)}, not a controllers file")
    if mode.st_size == 0:
        raise _refuse(f"{shown}: is empty (0 bytes), not a controllers file")
    if mode.st_size > MAX_CONTROLLER_BYTES:
        raise _refuse(f"{shown}: is {mode.st_size / 1024:.0f} KiB, over the "
                      f"{MAX_CONTROLLER_BYTES // 1024} KiB of a controllers file (fsmbench "
                      "design writes 4-12 kB)")
    return path


# ------------------------------------------------------------------------------ what


def read_controller_file(path: Path, *, typed: str, name: str | None, ts_s: float,
                         gd_v_per_rad: tuple[float, float]) -> tuple[DiscreteController, str]:
    """The controller ``name`` of the file at ``path``, wired as the bench runs it.

    Parameters
    ----------
    path : Path
        From :func:`resolve_controller_file`.
    typed : str
        The path as the user typed it (for the messages).
    name : str or None
        The controller in the file; None: fsmbench's own, else the first that fits.
    ts_s : float
        The bench's sample time [s]: the file's must be it.
    gd_v_per_rad : (float, float)
        4QD gains [V/rad] the readings are divided by when the file records none.

    Returns
    -------
    DiscreteController
        ``u = -K Vp / Gd`` (:attr:`~fsmbench.control.controller.Controller.feedback`), named
        ``"NAME (FILE)"``.
    str
        ``NAME``, the controller's name in the file.

    Raises
    ------
    Refused
        ``FSM_BadArgument``, naming ``typed``, never quoting the file.
    """
    where = typed if Path(typed).name == path.name else f"{typed} ({path.name})"
    try:
        chosen = select_controller(load_controllers(path, ts_s=ts_s,
                                                    max_states=MAX_CONTROLLER_STATES), name)
    except RecordingError as exc:  # worded without the file's bytes (control.load)
        what = f"variable '{exc.variable}' {exc.problem}" if exc.variable else exc.problem
        raise _refuse(f"{where}: {what}") from None
    except OSError as exc:
        raise _refuse(f"{where}: cannot be read ({exc.strerror or type(exc).__name__})") \
            from None
    except Exception as exc:  # a reader's own words may quote the file: its type only
        raise _refuse(f"{where}: is not a controllers file fsmbench reads (a "
                      f"{CONTROLLERS_SOS_JSON} or {CONTROLLERS_MAT} from fsmbench design; "
                      f"reading it raised {type(exc).__name__})") from None
    gd = chosen.gd_v_per_rad or gd_v_per_rad
    if not all(math.isfinite(g) and g != 0.0 for g in gd):
        raise _refuse(f"{where}: controller {chosen.name!r} records a 4QD gain of "
                      f"({gd[0]:g}, {gd[1]:g}) V/rad; the readings cannot be divided by it")
    running = dataclasses.replace(chosen, gd_v_per_rad=gd, name=f"{chosen.name} ({path.name})")
    return running.feedback, chosen.name


# ------------------------------------------------------------------------------ whether


@dataclass(frozen=True)
class ControllerRequirements:
    """What a controller must show on the device's bench model before it reaches the loop.

    The margins are ``fsmbench design``'s own requirements
    (:class:`~fsmbench.control.design.DesignOptions`; the gain margin is also ``fsmbench
    tune``'s for a candidate), on each axis's sampled loop ``L_ii = (G Kd)_ii`` below Nyquist
    (:func:`~fsmbench.control.loops.discrete_axis_margins`). The design's 30° phase margin
    is not one of them: the ESRF study's controller has 28.6° on h (errata E27) and ran the
    bench; the modulus margin bounds the phase margin from below (2 asin(0.2) = 23.1° at
    0.4) and the gain margin too (4.4 dB), a disk around -1 that no gain and phase error
    together may cross.

    Attributes
    ----------
    max_pole_modulus : float
        Every pole of the closed loop, sampled as the twin runs it, inside this circle [1].
    gain_margin_db : float
        Least gain margin of each axis [dB]: the loop gain may double (a gain error, the
        issue's 20x controller) before it is unstable.
    modulus_margin : float
        Least ``min |1 + L_ii|`` of each axis [1] (0.4: ``|S|`` below 8 dB).
    """

    max_pole_modulus: float = 1.0
    gain_margin_db: float = _DESIGN.gain_margin_db
    modulus_margin: float = _DESIGN.modulus_margin


@dataclass(frozen=True, eq=False)
class ControllerCheck:
    """A controller closed on the device's bench model.

    Attributes
    ----------
    name : str
    bench : str
        The bench in words.
    largest_pole : float
        Largest ``|z|`` of the closed loop's poles [1] (below 1: stable).
    margins : dict of axis to Margins
        Each axis's margins; empty when the loop is unstable (they would mislead).
    failures : tuple of str
        Each requirement not met, in words with units (empty: passed).
    """

    name: str
    bench: str
    largest_pole: float
    margins: Mapping[str, Margins] = field(default_factory=dict)
    failures: tuple[str, ...] = ()

    @property
    def passed(self) -> bool:
        """Every requirement met."""
        return not self.failures

    @property
    def summary(self) -> str:
        """The figures in words."""
        words = f"largest closed-loop pole |z| = {self.largest_pole:.5f}"
        if self.margins:
            gm = ", ".join(f"{m.gain_margin_db:.1f} dB ({a})" for a, m in self.margins.items())
            mm = ", ".join(f"{m.modulus_margin:.2f} ({a})" for a, m in self.margins.items())
            pm = ", ".join(f"{m.phase_margin_deg:.0f} deg ({a})"
                           for a, m in self.margins.items())
            words += f"; gain margins {gm}; modulus margins {mm}; phase margins {pm}"
        return words


class BenchCheck:
    """Controllers closed on a bench model: :meth:`check`.

    Parameters
    ----------
    bench : Bench
        The device's bench: the plant the twin runs (:func:`~fsmbench.sim.plant.bench_discrete`,
        the identified one for an identified bench) and, for the margins, its physical or
        identified plant with exact delays (as the Monte Carlo draws judge a controller).
    requirements : ControllerRequirements, optional
    """

    def __init__(self, bench: Bench, *,
                 requirements: ControllerRequirements | None = None) -> None:
        self.bench = bench
        self.requirements = requirements or ControllerRequirements()
        self._lock = threading.Lock()
        self._model: tuple[Any, Any, np.ndarray] | None = None

    def _parts(self) -> tuple[Any, Any, np.ndarray]:
        # Built on the first check (~0.1 s), then kept: the bench model does not change.
        with self._lock:
            if self._model is None:
                b = self.bench
                plant = (physical_plant(b.true, source="the device's bench")
                         if b.model is None else b.model.plant)
                gd = b.true.quad_diode.gain_v_per_rad
                self._model = (bench_discrete(b), plant, np.array([float(gd.h), float(gd.v)]))
            return self._model

    def check(self, k: DiscreteController) -> ControllerCheck:
        """``k`` closed on the bench: its largest pole, its margins, what it fails.

        Parameters
        ----------
        k : DiscreteController
            As the loop runs it: ``Vph, Vpv`` [V] in, ``Uch, Ucv`` [V] out, the feedback
            sign and the 4QD gains included.
        """

        if k.adc_inputs != (ADC_CHANNELS.index("Vph"), ADC_CHANNELS.index("Vpv")) or \
                k.dac_outputs != (DAC_CHANNELS.index("Uch"), DAC_CHANNELS.index("Ucv")):
            raise ValueError(f"{k.name} is not wired Vph, Vpv -> Uch, Ucv")
        discrete, plant, gd = self._parts()
        req = self.requirements
        label = self.bench.label
        with np.errstate(all="ignore"):
            rho = closed_loop_spectral_radius(discrete, k, n_adc=len(ADC_CHANNELS))
        if not rho < req.max_pole_modulus:
            return ControllerCheck(name=k.name, bench=label, largest_pole=rho, failures=(
                f"the closed loop is unstable: its largest pole has |z| = {rho:.5f}, not "
                f"below {req.max_pole_modulus:g} (required: every pole inside the unit circle)",))
        # The loop runs u = c x + d Vp (sign and 1/Gd inside): K from the volts read is
        # -(c, d); the plant's volts are its angle times the 4QD gain it has.
        margins = discrete_axis_margins(plant, a=k.a, b=k.b, c=-k.c, d=-k.d,
                                        ts_s=float(self.bench.true.converter.ts_s),
                                        loop_scale=tuple(gd))
        failures = []
        for axis, m in margins.items():
            if not m.gain_margin_db >= req.gain_margin_db:
                failures.append(f"axis {axis}: gain margin {m.gain_margin_db:.1f} dB, at least "
                                f"{req.gain_margin_db:g} dB required")
            if not m.modulus_margin >= req.modulus_margin:
                peak = -20 * math.log10(m.modulus_margin) if m.modulus_margin > 0 else math.inf
                failures.append(f"axis {axis}: modulus margin {m.modulus_margin:.2f} (|S| peaks "
                                f"at {peak:.1f} dB), at least {req.modulus_margin:g} required")
        return ControllerCheck(name=k.name, bench=label, largest_pole=rho, margins=margins,
                               failures=tuple(failures))
