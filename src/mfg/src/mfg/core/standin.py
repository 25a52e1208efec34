"""The robot-side stand-in for a goal source that is off the robot or gone (ROS-free).

The goal source (mfg, wherever it runs) gives move_base its goals. Seen from the robot, the *goal path* is what
move_base's status list says (is a goal active?), the source's heartbeat (its ``~activity`` reports: it is alive
and reaches the robot) and the source's mode (its ``~state``: a source in a hold mode, e.g. ``SEARCH``, keeps
the robot still on purpose while it measures a cell).

:class:`GoalPath` turns these into one answer, :meth:`GoalPath.standing_since`: since when the robot has been
standing still *with a task pending* on the source's account (None: it has a goal, or the source holds it on
purpose, or no task was given yet). The stand-in (``goal_standin``) sends its own patrol goal when that has
lasted ``timeout``; the mission monitor reports the longest such interval (:class:`Standstill`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterable, Optional, Tuple

from cnr_params import Section

# actionlib_msgs/GoalStatus: a goal in one of these states is being pursued (or about to be)
PENDING, ACTIVE, PREEMPTING, RECALLING = 0, 1, 6, 7
PURSUED = (PENDING, ACTIVE, PREEMPTING, RECALLING)


@dataclass(frozen=True)
class WatchParams:
    """How the goal path is judged (the ``standin`` section; shared by the stand-in and the mission monitor)."""
    source_silence: float          # s without a heartbeat: the source is cut off or gone
    status_stale: float            # s: a status list older than this says nothing (no goal known)
    stuck_timeout: float           # s a live source in a hold mode may keep the robot without a goal
    hold_modes: Tuple[str, ...]    # the source's modes in which it keeps the robot still on purpose
    heartbeat_topic: str
    state_topic: str


@dataclass(frozen=True)
class StandinParams:
    watch: WatchParams
    timeout: float                 # s standing still (no goal, no hold) before the stand-in sends a goal
    ack_timeout: float             # wall s: a goal move_base has not acknowledged within this is sent again
    pose_topic: str
    frame_id: str
    rate: float                    # Hz, decisions


def read_watch(p: Section) -> WatchParams:
    """``standin.*`` of config/goal_standin.yaml that judge the goal path (no defaults in code)."""
    s = p.section('standin')
    modes = s.raw('hold_modes')
    if not isinstance(modes, list) or not all(isinstance(m, str) and m for m in modes):
        raise s.error('hold_modes', f'must be a list of mode names, got {modes!r}')
    return WatchParams(source_silence=s.number('source_silence', positive=True),
                       status_stale=s.number('status_stale', positive=True),
                       stuck_timeout=s.number('stuck_timeout', positive=True),
                       hold_modes=tuple(modes),
                       heartbeat_topic=s.string('heartbeat_topic'),
                       state_topic=s.string('state_topic'))


def read_params(p: Section) -> StandinParams:
    s = p.section('standin')
    return StandinParams(watch=read_watch(p), timeout=s.number('timeout', positive=True),
                         ack_timeout=s.number('ack_timeout', positive=True),
                         pose_topic=s.string('pose_topic'), frame_id=s.string('frame_id'),
                         rate=s.number('rate', positive=True))


class GoalPath:
    """What the robot knows of its goal path. Times are the robot's clock [s]; feed it in time order."""

    def __init__(self, p: WatchParams, own: Callable[[str], bool] = lambda goal_id: False) -> None:
        self.p = p
        self.own = own                              # goal id -> sent by the stand-in itself
        self.pending_since: Optional[float] = None  # the first goal seen: a task is pending from then on
        self.last_status: Optional[float] = None
        self.active = False                         # the newest status list holds a pursued goal
        self.foreign_active = False                 # ... one that is not the stand-in's
        self.idle_since: Optional[float] = None     # the first status list without a pursued goal (after one with)
        self.last_heartbeat: Optional[float] = None
        self.mode = ''
        self.hold_left: Optional[float] = None      # when the source's mode last left a hold mode

    def status(self, t: float, goals: Iterable[Tuple[str, int]]) -> None:
        """A status list of move_base at ``t``: (goal id, status) of each goal it lists."""
        goals = list(goals)
        pursued = [gid for gid, st in goals if st in PURSUED]
        if goals and self.pending_since is None:
            self.pending_since = t
        was_active = self.active if self.last_status is not None else True
        self.active = bool(pursued)
        self.foreign_active = any(not self.own(g) for g in pursued)
        if self.active:
            self.idle_since = None
        elif was_active or self.idle_since is None:
            # idle from here; after a stale gap from the last list heard (nothing was known since)
            self.idle_since = self.last_status if self.last_status is not None and self._stale(t) else t
        self.last_status = t

    def heartbeat(self, t: float) -> None:
        self.last_heartbeat = t

    def source_mode(self, t: float, mode: str) -> None:
        if self.mode in self.p.hold_modes and mode not in self.p.hold_modes:
            self.hold_left = t
        self.mode = mode

    def _stale(self, now: float) -> bool:
        return self.last_status is not None and now - self.last_status > self.p.status_stale

    def idle_from(self, now: float) -> Optional[float]:
        """Since when move_base has had no pursued goal (None: it has one, or no status was ever heard).
        A status list older than ``status_stale`` says nothing: no goal is known since it came."""
        if self.last_status is None:
            return None
        if self._stale(now):
            return self.last_status if self.active else self.idle_since
        return None if self.active else self.idle_since

    def alive(self, now: float) -> bool:
        """The source's heartbeat reached the robot within ``source_silence``."""
        return self.last_heartbeat is not None and now - self.last_heartbeat <= self.p.source_silence

    def holding(self, now: float) -> bool:
        """The source keeps the robot still on purpose: alive, in a hold mode, not longer than ``stuck_timeout``."""
        idle = self.idle_from(now)
        return self.mode in self.p.hold_modes and self.alive(now) and \
            (idle is None or now - idle < self.p.stuck_timeout)

    def standing_since(self, now: float) -> Optional[float]:
        """Since when the robot has stood still with a task pending on the source's account (None: not).

        From the later of: move_base's last goal ended (or its status went stale), and the end of the source's
        hold (it left the hold mode, or went silent: from its last heartbeat). A hold longer than
        ``stuck_timeout`` was none (a search measures a cell for less): standing still since the goal ended."""
        if self.pending_since is None:
            return None
        idle = self.idle_from(now)
        if idle is None or self.holding(now):
            return None
        if self.mode in self.p.hold_modes:
            if now - idle < self.p.stuck_timeout and self.last_heartbeat is not None:
                return max(idle, self.last_heartbeat)        # silent (else it would hold)
            return idle
        return idle if self.hold_left is None else max(idle, self.hold_left)


class Standin:
    """The stand-in's decisions: when to send a patrol goal of its own, when it has handed back."""

    def __init__(self, p: StandinParams, own: Callable[[str], bool]) -> None:
        self.p = p
        self.path = GoalPath(p.watch, own)
        self.standing_in = False      # its goals drive the robot (since its first; until the source's goal)

    def handed_back(self) -> bool:
        """True once, when a goal of the source is pursued again while the stand-in was driving."""
        if self.standing_in and self.path.foreign_active:
            self.standing_in = False
            return True
        return False

    def due(self, now: float) -> bool:
        """Send a goal now? After ``timeout`` of standing still; at once after its own goal while the source
        stays silent (a patrol of its own, no pause between its goals)."""
        since = self.path.standing_since(now)
        if since is None:
            return False
        chained = self.standing_in and not self.path.alive(now)
        return chained or now - since >= self.p.timeout

    def sent(self) -> None:
        self.standing_in = True


class Standstill:
    """The standstills with a task pending: :meth:`GoalPath.standing_since` sampled over time (the mission
    monitor's ``standstill`` in summary.json). ``since`` and ``now`` on the robot's clock [s]; ``wall`` the wall
    clock time (UNIX s) at which the interval began."""

    def __init__(self) -> None:
        self.longest = 0.0
        self.longest_since: Optional[float] = None
        self.longest_wall: Optional[float] = None
        self.intervals = 0
        self.closed_total = 0.0
        self.current: Optional[Tuple[float, float, float]] = None      # since, now, wall of since

    def sample(self, now: float, since: Optional[float], wall: float) -> None:
        if self.current is not None and since != self.current[0]:
            self.closed_total += self.current[1] - self.current[0]
            self.current = None
        if since is None:
            return
        if self.current is None:
            self.intervals += 1
            self.current = (since, now, wall)
        self.current = (since, now, self.current[2])
        if now - since > self.longest:
            self.longest, self.longest_since, self.longest_wall = now - since, since, self.current[2]

    @property
    def total(self) -> float:
        return self.closed_total + (self.current[1] - self.current[0] if self.current is not None else 0.0)

    @property
    def open(self) -> bool:
        """The robot stood still at the last sample."""
        return self.current is not None
