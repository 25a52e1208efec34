"""Timing the registrations' return after an outage, from a record of the invariant's discrepancies (ROS-free).

A record is a time-ordered list of ``(time, discrepancies)``: every poll of the two masters
(:class:`multimaster_bridge.watch.RestoreWatch`), or only the polls whose discrepancies differ from the poll before
(:func:`changes`, what a bench keeps in ``watch.tsv``); each entry holds from its time until the next one. Two
measures per outage, both from the link's return at ``t`` within the window that lasts until the next outage:

- :func:`discrepancy_restore`: each discrepancy timed from ``t``, or from when it arose if later (the peer
  registered something after the return, e.g. a module's new instance), until it is gone; the restore is the
  longest. When it arose is taken as the entry before the one that first shows it (when it was last seen absent):
  exact to one poll for a record of every poll and for :func:`changes`, which keeps the poll before each change
  (an older record of the changes alone overestimates it: counted from the change before). A discrepancy still
  there when the window ends is open: the outage is not restored, unless it arose less than the bound before the
  window ended (then the next outage cut it short: it can neither meet nor miss it).
- :func:`unbroken_restore`: from ``t`` until the invariant held without a break to the window's end.
"""
from __future__ import annotations

import math
from typing import Dict, List, Optional, Sequence, Tuple

Record = Sequence[Tuple[float, List[str]]]


def changes(samples: Record) -> List[Tuple[float, List[str]]]:
    """The entries whose discrepancies differ from the entry before (the first one too), each preceded by the last
    entry of the state before it (when that state was last seen: a discrepancy that a change shows arose after it),
    unless that is the change itself."""
    out: List[Tuple[float, List[str]]] = []
    last: Optional[Tuple[float, List[str]]] = None
    for t, wrong in samples:
        if not out or wrong != out[-1][1]:
            if last is not None and last[0] != out[-1][0]:
                out.append(last)
            out.append((t, list(wrong)))
        last = (t, list(wrong))
    return out


def _at(record: Record, t: float) -> Tuple[List[str], List[Tuple[float, List[str]]]]:
    """The discrepancies holding at ``t`` (the last entry at or before it; none before the first) and the entries
    after ``t``."""
    before = [w for when, w in record if when <= t]
    return (list(before[-1]) if before else []), [(when, w) for when, w in record if when > t]


def discrepancy_restore(record: Record, t: float, window_end: float = math.inf) -> Tuple[Optional[float], float]:
    """(restore, open age): the longest any discrepancy lasted, counted from ``t`` or from when it arose if later
    (the entry before the first that shows it), to the entry without it (None if one is still there at
    ``window_end``, or at the record's end for an endless window), and how long the oldest of those still there at
    the window's end had been there (0.0: none)."""
    holding, after = _at(record, t)
    since: Dict[str, float] = {item: t for item in holding}
    longest = 0.0
    last_seen = t                       # the entry before: each new discrepancy was last seen absent then
    for when, wrong in after:
        if when >= window_end:
            break
        now_wrong = set(wrong)
        for item in [i for i in since if i not in now_wrong]:
            longest = max(longest, when - since.pop(item))
        for item in now_wrong:
            since.setdefault(item, last_seen)
        last_seen = when
    if since:
        end = window_end if math.isfinite(window_end) else (after[-1][0] if after else t)
        return None, max(0.0, end - min(since.values()))
    return longest, 0.0


def unbroken_restore(record: Record, t: float, window_end: float = math.inf) -> Optional[float]:
    """Seconds from ``t`` until the invariant held without a break to ``window_end`` (None: it did not hold at the
    window's last entry). Counted to the first entry of that unbroken run (or 0.0 if it held at ``t`` already)."""
    holding, after = _at(record, t)
    inside = [(when, w) for when, w in after if when < window_end]
    if (inside[-1][1] if inside else holding):
        return None
    first = len(inside)
    while first > 0 and not inside[first - 1][1]:
        first -= 1
    if first == 0:
        return 0.0 if not holding else inside[0][0] - t
    return inside[first][0] - t


__all__ = ['Record', 'changes', 'discrepancy_restore', 'unbroken_restore']
