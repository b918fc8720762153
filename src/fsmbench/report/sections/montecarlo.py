"""The report's Monte Carlo subsection and the robustness row's sentence, from ``montecarlo.json``.

Everything here reads the file ``fsmbench montecarlo`` wrote (format
``fsmbench.montecarlo`` version 3): which draws break which requirement is
counted in :mod:`fsmbench.scale.breaches`, not here.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from fsmbench.report.html import Block, Section, Table
from fsmbench.scale.breaches import breach_values

__all__ = ["MONTECARLO_ANCHOR", "montecarlo_section", "robustness_sentence"]

MONTECARLO_ANCHOR = "monte-carlo"

#: Rows of one requirement's table of breaking draws; the others are named by index above.
_ROWS_SHOWN = 50

_FACTORS = (("resonance_scale", "resonance ×, h/v", "{:.3f}"),
            ("damping_scale", "damping ×, h/v", "{:.2f}"),
            ("qd_gain_scale", "4QD gain ×, h/v", "{:.3f}"),
            ("current_amp_gain_scale", "current amplifier ×, h/v", "{:.3f}"),
            ("newport_gain_scale", "Newport gain ×, h/v", "{:.3f}"))


def _share(r: Mapping[str, Any]) -> str:
    return f"{100 * r['broken'] / r['draws']:.0f} %" if r["draws"] else "—"


def _indices(r: Mapping[str, Any]) -> str:
    return ", ".join(str(b["index"]) for b in r["breaches"])


def robustness_sentence(payload: Mapping[str, Any]) -> str:
    """The sentence the verdict's robustness row adds: the requirements ≥ 5 % of the draws break.

    Parameters
    ----------
    payload : mapping
        ``montecarlo.json``'s content.

    Returns
    -------
    str
        Empty when no requirement is broken by :data:`~fsmbench.scale.breaches.NOTABLE_SHARE`
        of the draws or more (each entry's ``notable``); else one sentence naming each such
        requirement, its count, its share and its draws.
    """
    notable = [r for r in payload.get("requirements", ()) if r.get("notable")]
    if not notable:
        return ""
    parts = [f"{r['description']} broken by {r['broken']} of {r['draws']} draws "
             f"({_share(r)}: draws {_indices(r)})" for r in notable]
    controller = (payload.get("controller") or {}).get("name", "the controller")
    return (f"Monte Carlo of {controller} over {payload['n']} plants drawn around "
            f"{payload.get('bench', 'the bench')}, seed {payload['seed']}: "
            + "; ".join(parts) + " (the Monte Carlo section lists them with their factors).")


_RANGE_WORDS = {"resonance_scale": "Sercalo resonances", "damping_scale": "Sercalo damping",
                "qd_gain_scale": "4QD gains", "current_amp_gain_scale": "current-amplifier gains",
                "newport_gain_scale": "Newport gains", "dac_delay_s": "DAC delay",
                "newport_delay_s": "Newport delay"}


def _range_words(ranges: Mapping[str, Sequence[float]]) -> str:
    words = []
    for key, (lo, hi) in ranges.items():
        name = _RANGE_WORDS.get(key, key)
        words.append(f"{name} {1e6 * lo:+.0f} to {1e6 * hi:+.0f} µs" if key.endswith("_s")
                     else f"{name} ×{lo:g}–{hi:g}")
    return "; ".join(words)


def _breach_table(r: Mapping[str, Any]) -> Table:
    header = ("draw", "noise seed", "value against the limit",
              *(words for _k, words, _f in _FACTORS), "DAC delay [µs]", "Newport delay [µs]")
    rows = []
    for b in r["breaches"][:_ROWS_SHOWN]:
        f = b["factors"]
        rows.append((str(b["index"]), str(b["noise_seed"]), breach_values(r, b),
                     *(f"{fmt.format(f[k]['h'])}/{fmt.format(f[k]['v'])}"
                       for k, _w, fmt in _FACTORS),
                     f"{1e6 * f['dac_delay_offset_s']:+.1f}",
                     f"{1e6 * f['newport_delay_offset_s']:+.1f}"))
    more = r["broken"] - len(rows)
    return Table(caption=f"Draws breaking: {r['description']} ({r['broken']} of {r['draws']}, "
                         f"{_share(r)})", header=header, rows=tuple(rows),
                 note=(f"{more} more draws break it, listed by index above and in full in "
                       "montecarlo.json (requirements[].breaches)." if more > 0 else ""))


def montecarlo_section(payload: Mapping[str, Any]) -> Section:
    """The Monte Carlo subsection: the run, the requirements over the draws, each breaking draw.

    Parameters
    ----------
    payload : mapping
        ``montecarlo.json``'s content (format version 3).
    """
    controller = payload.get("controller") or {}
    reqs = list(payload.get("requirements", ()))
    blocks: list[Block] = [
        f"{payload['n']} plants drawn (seed {payload['seed']}) around "
        f"{payload.get('bench', 'the bench')}, each running the repeatability experiments "
        f"({payload['duration_s']:g} s records, the first {payload['settle_s']:g} s left out) "
        f"in closed loop with {controller.get('name', 'the controller')} "
        f"({controller.get('source', 'source not recorded')}). Ranges drawn: "
        f"{_range_words(payload.get('ranges') or {})}. Every draw that breaks a requirement "
        "is named with its noise seed and its factors: fsmbench montecarlo with the same "
        "seed runs it again (montecarlo.json, draws[index]).",
        Table(caption="Requirements over the draws (a draw passes when both axes do; an "
                      "unstable draw breaks every requirement)",
              header=("requirement", "draws meeting it", "draws breaking it", "share breaking",
                      "draws breaking it (index)"),
              rows=tuple((r["description"], str(r["draws"] - r["broken"]), str(r["broken"]),
                          _share(r), _indices(r) or "none") for r in reqs)),
    ]
    blocks += [_breach_table(r) for r in reqs if r["breaches"]]
    return Section(title="Monte Carlo over the plant's uncertainty", blocks=tuple(blocks),
                   anchor=MONTECARLO_ANCHOR)
