"""Which signs of the bench, or of which records, explain the paths' signs.

Each path a record measures has a sign against the bench file's model: +1 as
the model, −1 reversed. A reversal has two kinds of cause:

* **a property of the bench** that the bench file states otherwise, the same in
  every record: the 4QD's polarity on one axis (``q``), the way the Sercalo
  moves the beam on one axis (its mount, ``m``), the current amplifier's drive
  of the coil (``i``), the Newport's drive (``n``), its metrology output
  (``r``), the coil-voltage monitor (``c``). These are findings about the user's bench, with the
  bench-file key that states them;
* **a record** whose signal was saved with its sign flipped (one file only).

Each path is the product of the signs along it::

    data_cal_pd_h   Vnh → Vph    q·r       (the Newport moves both)
    data_uch        Uch → Vph    q·m·i
    data_uch        Uch → Vch    c·i
    data_unh        Unh → Vph    q·n
    data_rep_h      Unh → Vnh    n·r       (the metrology reads the Newport)
    closed loop     Vph → Uch    q·m·i     (the loop ran stable only with the
                                            controller's sign matching the plant's)

times the flips of the records' own signals. Explaining the observed signs is
a linear system over GF(2); :func:`explain_signs` returns every explanation
with the fewest causes (bench properties and record flips count alike), so a
diagnosis names every cause that fits. Records contradict each other when every
explanation needs a record flipped: only then is a result blocked. When an
explanation with bench properties only fits as well as one with a flipped
record, the records cannot tell them apart: both are named, with the record
that would separate them, and nothing is blocked.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Final, Literal

__all__ = [
    "BENCH_SIGNS",
    "MAX_CAUSES",
    "SignCause",
    "SignDiagnosis",
    "SignObservation",
    "explain_signs",
]

#: The bench's signs per axis: (what it is in words, the bench-file key that states it).
BENCH_SIGNS: Final = {
    "q": ("the 4QD's {axis} output has the opposite polarity of the bench file's",
          "nominal.quad_diode.gain_v_per_rad.{a}"),
    "m": ("the Sercalo's {axis} axis moves the beam the other way from the bench file's "
          "geometry (the mirror or a mirror of the beam path mounted the other way round)",
          "nominal.sercalo.beam_angle_per_mirror_angle.{a}"),
    "i": ("the {axis} current amplifier drives the Sercalo's coil the other way from the bench "
          "file's (an inverting amplifier, or the coil's two wires the other way round)",
          "nominal.current_amplifier.sign.{a}"),
    "n": ("the Newport's {axis} drive turns it the other way from the bench file's",
          "nominal.newport.gain_rad_per_v.{a}"),
    "r": ("the Newport's {axis} metrology reads its angle with the opposite sign of the bench "
          "file's", "nominal.newport.metrology_sign.{a}"),
    "c": ("the {axis} coil-voltage monitor reads with the opposite sign of the bench file's",
          "nominal.voltage_amplifier.sign.{a}"),
}
#: Explanations with more causes than this are not searched: three independent slips
#: of sign on one axis leave the records unexplained (named as such).
MAX_CAUSES: Final = 3

_AXIS_WORDS: Final = {"h": "horizontal", "v": "vertical"}


@dataclass(frozen=True)
class SignObservation:
    """One path's sign against the bench file's model.

    Attributes
    ----------
    record : str
        The record it was measured in (``data_uch``), or a closed-loop record.
    input, output : str
        The path (``Uch``, ``Vph``); for a closed loop the reading and the command.
    bench : tuple of str
        The bench signs along the path (``("q", "m")``).
    sign : int
        +1 as the model, −1 reversed.
    words : str
        The measurement in words (``Uch → Vph −1.05 V/V (model +1.55)``).
    """

    record: str
    input: str
    output: str
    bench: tuple[str, ...]
    sign: int
    words: str = ""


@dataclass(frozen=True, order=True)
class SignCause:
    """One cause: a bench sign or a record's flipped signal.

    Attributes
    ----------
    kind : {"bench", "record"}
    axis : {"h", "v"}
    name : str
        The bench sign's letter (:data:`BENCH_SIGNS`), or the flipped signal.
    record : str
        The record of a flipped signal ("" for a bench sign).
    """

    kind: Literal["bench", "record"]
    axis: str
    name: str
    record: str = ""

    @property
    def key(self) -> str:
        """The bench-file key a bench sign is stated by ("" for a record)."""
        if self.kind != "bench":
            return ""
        return BENCH_SIGNS[self.name][1].format(a=self.axis)

    def words(self) -> str:
        """The cause in words."""
        if self.kind == "bench":
            return BENCH_SIGNS[self.name][0].format(axis=_AXIS_WORDS[self.axis])
        return f"{self.name} in {self.record}.mat is recorded with its sign flipped"


@dataclass(frozen=True)
class SignDiagnosis:
    """Every explanation of one axis's path signs with the fewest causes.

    Attributes
    ----------
    axis : {"h", "v"}
    observations : tuple of SignObservation
    explanations : tuple of tuple of SignCause
        Each a set of causes that explains every observation; all of the same,
        smallest size. Empty with ``explained`` False when none of up to
        :data:`MAX_CAUSES` does; ``((),)`` when every sign is the model's.
    explained : bool
    near : tuple of tuple of SignCause
        Explanations with one cause more that flip exactly one record and hold no
        smallest explanation: a bench sign the smallest explanation states could
        instead be another bench sign and a record flipped (named as alternatives).
    """

    axis: str
    observations: tuple[SignObservation, ...]
    explanations: tuple[tuple[SignCause, ...], ...]
    explained: bool = True
    near: tuple[tuple[SignCause, ...], ...] = ()

    @property
    def agrees(self) -> bool:
        """Every path has the model's sign."""
        return self.explained and self.explanations == ((),)

    @property
    def bench_only(self) -> tuple[tuple[SignCause, ...], ...]:
        """The explanations that need no record flipped (the bench as it is)."""
        return tuple(e for e in self.explanations if all(c.kind == "bench" for c in e))

    @property
    def contradicts(self) -> bool:
        """The records contradict each other: every explanation flips a record."""
        return not self.explained or (not self.agrees and not self.bench_only)

    @property
    def ambiguous(self) -> bool:
        """More than one explanation fits."""
        return len(self.explanations) > 1

    def records(self) -> list[str]:
        """The records a flip of some explanation concerns, in observation order."""
        flipped = {c.record for e in self.explanations for c in e if c.kind == "record"}
        seen: list[str] = []
        for o in self.observations:
            if o.record in flipped and o.record not in seen:
                seen.append(o.record)
        return seen

    def reversed(self) -> list[SignObservation]:
        """The observations with the opposite sign of the model's."""
        return [o for o in self.observations if o.sign < 0]


def _variables(observations: Sequence[SignObservation], axis: str) -> list[SignCause]:
    """Every cause that appears in an observation: the bench signs, then the flips."""
    names = sorted({b for o in observations for b in o.bench}, key="qminrc".index)
    out = [SignCause("bench", axis, n) for n in names]
    seen = set()
    for o in observations:
        for signal in (o.input, o.output):
            if (o.record, signal) not in seen:
                seen.add((o.record, signal))
                out.append(SignCause("record", axis, signal, o.record))
    return out


def _touches(cause: SignCause, o: SignObservation) -> bool:
    if cause.kind == "bench":
        return cause.name in o.bench
    return cause.record == o.record and cause.name in (o.input, o.output)


def explain_signs(observations: Iterable[SignObservation], *, axis: str) -> SignDiagnosis:
    """The explanations of the observed signs with the fewest causes (module notes).

    Parameters
    ----------
    observations : iterable of SignObservation
        One axis's judged paths (a path whose sign could not be judged is left out).
    axis : {"h", "v"}

    Returns
    -------
    SignDiagnosis
    """
    obs = tuple(observations)
    variables = _variables(obs, axis)
    # Each observation's parity: which variables it touches, and whether it is reversed.
    touched = [[_touches(v, o) for o in obs] for v in variables]
    target = [o.sign < 0 for o in obs]
    def explaining(size: int) -> list[tuple[SignCause, ...]]:
        found = []
        for combo in itertools.combinations(range(len(variables)), size):
            parity = [False] * len(obs)
            for i in combo:
                parity = [p != t for p, t in zip(parity, touched[i], strict=True)]
            if parity == target:
                found.append(tuple(variables[i] for i in combo))
        return found

    for size in range(MAX_CAUSES + 1):
        found = explaining(size)
        if not found:
            continue
        near: list[tuple[SignCause, ...]] = []
        if 0 < size < MAX_CAUSES:
            near = [e for e in explaining(size + 1)
                    if sum(c.kind == "record" for c in e) == 1
                    and not any(set(m) <= set(e) for m in found)]
        return SignDiagnosis(axis, obs, tuple(found), near=tuple(near))
    return SignDiagnosis(axis, obs, (), explained=False)
