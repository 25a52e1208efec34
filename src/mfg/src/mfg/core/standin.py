"""The robot-side stand-in for a goal source that is off the robot or gone (ROS-free).

The goal source (mfg, wherever it runs) gives move_base its goals. Seen from the robot, the *goal path* is what
move_base's status list says (is a goal active?), the source's heartbeat (its ``~activity`` reports: it is alive
and reaches the robot) and the source's mode (its ``~state``: a source in a hold mode, e.g. ``SEARCH``, keeps
the robot still on purpose while it measures a cell).

:class:`GoalPath` turns these into one answer, :meth:`GoalPath.standing_since`: since when the robot has been
standing still *with a task pending* on the source's account (None: it has a goal, or the source holds it on
purpose, or no task was given yet). The stand-in (``goal_standin``) sends its own patrol goal when that has
lasted ``timeout``; the mission monitor reports the longest such interval (:class:`Standstill`).

:class:`CommsLoss` is the field robot's comms-loss behaviour on top: from the multimaster bridge's link quality to
the cloud (:class:`LinkJudge`) it keeps the robot's path where the link was good; when the robot has had neither a
goal of the source pursued, nor a good link, nor the source's heartbeat for ``comms_loss.after``, the stand-in's
goal is the place where the link was last good (instead of a patrol goal), until the link is good again.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Callable, Deque, Iterable, Optional, Tuple

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
class CommsLossParams:
    """The comms-loss behaviour (the ``comms_loss`` section): back to the last place with a good link."""
    enabled: bool
    after: float                   # s without a source's goal pursued, a good link and the source's heartbeat
    margin: float                  # m back along the robot's path with a good link from where it was last good
    link_topic: str                # the multimaster bridge's cnr_msgs/LinkQuality
    peer: str                      # the peer (bridge name) whose link counts
    max_loss: float                # heartbeat loss ratio (the bridge's window) of a good link, at most
    max_rtt: float                 # s, round-trip time of a good link, at most


@dataclass(frozen=True)
class StandinParams:
    watch: WatchParams
    comms_loss: CommsLossParams
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


def read_comms_loss(p: Section) -> CommsLossParams:
    """``comms_loss.*`` of config/goal_standin.yaml (no defaults in code)."""
    s = p.section('comms_loss')
    return CommsLossParams(enabled=s.boolean('enabled'), after=s.number('after', positive=True),
                           margin=s.number('margin', nonnegative=True), link_topic=s.string('link_topic'),
                           peer=s.string('peer'), max_loss=s.number('max_loss', minimum=0.0, maximum=1.0),
                           max_rtt=s.number('max_rtt', positive=True))


def read_params(p: Section) -> StandinParams:
    s = p.section('standin')
    return StandinParams(watch=read_watch(p), comms_loss=read_comms_loss(p),
                         timeout=s.number('timeout', positive=True), ack_timeout=s.number('ack_timeout', positive=True),
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
        self.foreign_last: Optional[float] = None   # the last status list with a pursued goal not the stand-in's
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
        if self.foreign_active:
            self.foreign_last = t
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

    def source_goal(self, now: float) -> bool:
        """A goal of the source (not the stand-in's) is pursued, by a status list that is not stale."""
        return self.foreign_active and not self._stale(now)

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


SEND, RESEND, ON_ITS_WAY, ARRIVED, WAITING = 'send', 'resend', 'on its way', 'arrived', 'waiting'   # CommsLoss.step
TRAIL_STEP = 0.05        # m: a position with a good link joins the trail this far from the last one (resolution)


class LinkJudge:
    """The good-link criterion on the multimaster bridge's ``link_quality`` (cnr_msgs/LinkQuality, per peer): the
    peer is alive, a heartbeat of it arrived since the previous message (``received`` changed: the link carried
    something just now, not only within the bridge's loss timeout), its loss ratio is at most ``max_loss`` and
    its RTT at most ``max_rtt`` (unknown: not good)."""

    def __init__(self, p: CommsLossParams) -> None:
        self.p = p
        self.received: Optional[int] = None

    def good(self, peer: str, alive: bool, loss: float, rtt: float, received: int) -> Optional[bool]:
        """Whether one message says the link is good now (None: the message is of another peer)."""
        if peer != self.p.peer:
            return None
        fresh = self.received is None or received != self.received
        self.received = received
        return bool(alive and fresh and loss <= self.p.max_loss and rtt <= self.p.max_rtt)   # NaN: not good


class CommsLoss:
    """The comms-loss policy: where to drive back to when the robot has lost its goal source and its link.

    It keeps the *trail*: the robot's positions at which the link was good, back to ``margin`` m of path from
    the newest (a jump longer than that, across a dead zone, starts it again). Its target is the trail's oldest
    position: the place where the link was last good, ``margin`` m back along the way the robot came, so that
    the robot stops inside the good region, not at its edge. Times are the robot's clock [s]."""

    def __init__(self, p: CommsLossParams, path: GoalPath) -> None:
        self.p = p
        self.path = path
        self.judge = LinkJudge(p)
        self.trail: Deque[Tuple[float, float]] = deque()
        self.trail_length = 0.0                             # m of path along the trail
        self.last_good: Optional[float] = None              # the newest message that said the link is good
        self.target: Optional[Tuple[float, float]] = None   # the place it drives back to (a comms loss is on)
        self.driving = False                                # its goal to the target is being driven to
        self.arrived: Optional[float] = None                # when that goal ended (waiting there for the link)
        self.given_up = False                               # arrived and waited ``after``: the place does not help

    def link(self, t: float, good: Optional[bool], pose: Optional[Tuple[float, float]]) -> None:
        """A link quality message at ``t`` judged ``good`` (:class:`LinkJudge`), the robot at ``pose`` then."""
        if not good:
            return
        self.last_good = t
        self._end()
        if pose is not None:
            self._extend(pose)

    def _extend(self, pose: Tuple[float, float]) -> None:
        if self.trail:
            step = math.hypot(pose[0] - self.trail[-1][0], pose[1] - self.trail[-1][1])
            if step < TRAIL_STEP:
                return
            self.trail_length += step
        self.trail.append(pose)
        while len(self.trail) > 1 and self.trail_length > self.p.margin:
            first, second = self.trail[0], self.trail[1]
            self.trail_length -= math.hypot(second[0] - first[0], second[1] - first[1])
            self.trail.popleft()

    def _end(self) -> None:
        self.target, self.driving, self.arrived, self.given_up = None, False, None, False

    def lost_since(self, now: float) -> Optional[float]:
        """Since when the robot has had neither a goal of the source pursued nor a good link (None: it has one, or
        the source's heartbeat still reaches it, or no task is pending, or the link was never good here)."""
        path = self.path
        if self.last_good is None or path.pending_since is None or path.alive(now) or path.source_goal(now):
            return None
        return self.last_good if path.foreign_last is None else max(self.last_good, path.foreign_last)

    def goal(self, now: float) -> Optional[Tuple[float, float]]:
        """The place the stand-in's goal is now, (x, y) [m] (None: no comms loss, or the robot reached the place
        and waited ``after`` there without the link: the ordinary stand-in goes on)."""
        if not self.p.enabled:
            return None
        if self.path.source_goal(now):
            self._end()                       # the source's goal crossed: it drives, the loss is over
            return None
        since = self.lost_since(now)
        if since is None or not self.trail or now - since < self.p.after or self.given_up:
            return None
        if self.arrived is not None and now - self.arrived >= self.p.after:
            self.given_up = True
            return None
        if self.target is None:
            self.target = self.trail[0]
        return self.target

    def sent(self) -> None:
        """Its goal to the target was sent."""
        self.driving = True

    def ended(self, now: float) -> None:
        """Its goal to the target ended (reached, or move_base gave up): it waits there for the link."""
        if self.driving:
            self.driving = False
            self.arrived = now

    def step(self, now: float, flying: bool, resend: bool) -> Optional[str]:
        """What the stand-in does about a comms loss now (None: no comms loss, the ordinary stand-in decides).
        ``flying``: the goal it sent last is not over; ``resend``: ... and move_base has not acknowledged it within
        ``ack_timeout``. SEND: send a goal to :attr:`target` (the way back begins); RESEND: send it again;
        ON_ITS_WAY, WAITING: nothing (driving back; back there, waiting for the link); ARRIVED: the goal ended just
        now (there, or move_base gave up), it waits there for the link."""
        if self.goal(now) is None:
            return None
        if self.driving:
            if flying:
                return RESEND if resend else ON_ITS_WAY
            self.ended(now)
            return ARRIVED
        if self.arrived is not None:
            return WAITING
        self.sent()
        return SEND


class Standin:
    """The stand-in's decisions: when to send a patrol goal of its own, when it has handed back."""

    def __init__(self, p: StandinParams, own: Callable[[str], bool]) -> None:
        self.p = p
        self.path = GoalPath(p.watch, own)
        self.comms = CommsLoss(p.comms_loss, self.path)
        self.standing_in = False      # its goals drive the robot (since its first; until the source's goal)

    def handed_back(self) -> bool:
        """True once, when a goal of the source is pursued again while the stand-in was driving."""
        if self.standing_in and self.path.foreign_active:
            self.standing_in = False
            return True
        return False

    def due(self, now: float) -> bool:
        """Send a goal now? After ``timeout`` of standing still; at once after its own goal until a goal of the
        source is pursued again (a patrol of its own, no pause between its goals): a source heard again after an
        outage may not reach move_base yet (its registrations on the robot's master are being restored), and the
        robot would otherwise stand another ``timeout`` waiting for it."""
        since = self.path.standing_since(now)
        if since is None:
            return False
        return self.standing_in or now - since >= self.p.timeout

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
