"""The stand-in's comms-loss policy without ROS (mfg.core.standin.CommsLoss, LinkJudge): back to the last place
where the link to the cloud was good, when the robot has neither a goal of the source nor the link."""
import math
import os

import pytest
import yaml

from cnr_params import ConfigError, Section
from mfg.core.standin import ACTIVE, Standin, read_params

PREEMPTED, SUCCEEDED = 2, 3
GOOD = dict(alive=True, loss=0.0, rtt=0.01)


@pytest.fixture
def params(workspace):
    return read_params(Section.from_file(os.path.join(workspace, 'config', 'goal_standin.yaml')))


def own(goal_id):
    return goal_id.startswith('/goal_standin-')


class Robot:
    """A robot driving along x at 0.5 m/s: move_base's status at 5 Hz, the bridge's link_quality at 5 Hz (a
    heartbeat received between two messages while the link is up), the source's heartbeat at 1 Hz while the link
    is up. ``up(x)``: the link at position x."""

    def __init__(self, s, up, x=0.0):
        self.s, self.up, self.x, self.t, self.received = s, up, x, 0.0, 0

    def run(self, until, goals, speed=0.0, peer='cloud'):
        while self.t < until - 1e-9:
            self.x += speed * 0.2
            linked = self.up(self.x)
            self.s.path.status(self.t, goals)
            if linked:
                self.received += 2
                if abs(self.t - round(self.t)) < 1e-6:
                    self.s.path.heartbeat(self.t)
            comms = self.s.comms
            comms.link(self.t, comms.judge.good(peer, linked, 0.0 if linked else 1.0, 0.01, self.received),
                       (self.x, 0.0))
            self.t = round(self.t + 0.2, 6)
        return self.t


def corridor(x):
    """Wi-Fi only for x <= 1.5 m (config/link_map_corridor.yaml's left end)."""
    return x <= 1.5 + 1e-6


def test_the_config_section_is_complete_and_a_missing_field_is_named(params, workspace):
    c = params.comms_loss
    assert c.enabled and c.after > params.watch.source_silence and c.link_topic and c.peer == 'cloud'
    with open(os.path.join(workspace, 'config', 'goal_standin.yaml')) as f:
        data = yaml.safe_load(f)
    for key in ('enabled', 'after', 'margin', 'link_topic', 'peer', 'max_loss', 'max_rtt'):
        broken = yaml.safe_load(yaml.safe_dump(data))
        del broken['comms_loss'][key]
        with pytest.raises(ConfigError, match=f'x.yaml: comms_loss.{key}: missing'):
            read_params(Section(broken, 'x.yaml'))
    del data['comms_loss']
    with pytest.raises(ConfigError, match='x.yaml: comms_loss: missing'):
        read_params(Section(data, 'x.yaml'))


def test_the_link_is_good_only_with_a_fresh_heartbeat_of_the_peer_within_loss_and_rtt(params):
    judge = Standin(params, own).comms.judge
    p = params.comms_loss
    assert judge.good('cloud', received=1, **GOOD) is True
    assert judge.good('cloud', received=1, **GOOD) is False                 # no heartbeat since: not just now
    assert judge.good('cloud', received=3, **GOOD) is True
    assert judge.good('robot', received=9, **GOOD) is None                  # another peer's link says nothing
    assert judge.good('cloud', received=4, alive=False, loss=0.0, rtt=0.01) is False
    assert judge.good('cloud', received=5, alive=True, loss=p.max_loss + 0.1, rtt=0.01) is False
    assert judge.good('cloud', received=6, alive=True, loss=0.0, rtt=p.max_rtt + 0.1) is False
    assert judge.good('cloud', received=7, alive=True, loss=0.0, rtt=math.nan) is False


def test_a_goal_ending_in_a_dead_zone_sends_the_robot_back_inside_the_good_region_after_the_timeout(params):
    p = params.comms_loss
    s = Standin(params, own)
    r = Robot(s, corridor)
    r.run(4.0, [('/mfg-1-0.0', ACTIVE)], speed=0.5)             # from x = 0 into the dead zone: x = 2.0
    t_goal_end = r.t
    t = r.run(t_goal_end + p.after - 0.4, [('/mfg-1-0.0', SUCCEEDED)])
    assert s.comms.goal(t) is None                               # not yet (the patrol stands in meanwhile)
    assert s.due(t)
    t = r.run(t_goal_end + p.after + 0.2, [('/mfg-1-0.0', SUCCEEDED)])
    target = s.comms.goal(t)
    assert target is not None, 'no comms-loss goal after the timeout'
    assert target[0] == pytest.approx(1.5 - p.margin, abs=0.11)  # margin back from where the link was last good
    assert s.comms.lost_since(t) == pytest.approx(t_goal_end - 0.2)   # its last status list: the link went before
    s.comms.sent()
    s.sent()
    assert s.comms.goal(t + 5.0) == target                       # the same place while it drives there


def test_the_time_counts_from_the_later_of_the_link_lost_and_the_source_goal_ended(params):
    p = params.comms_loss
    s = Standin(params, own)
    r = Robot(s, corridor)
    r.run(3.2, [('/mfg-1-0.0', ACTIVE)], speed=0.5)              # link lost at x > 1.5 (t = 2.8)
    t = r.run(20.0, [('/mfg-1-0.0', ACTIVE)], speed=0.0)         # a goal of the source still pursued: no goal
    assert s.comms.goal(t) is None and s.comms.lost_since(t) is None
    t = r.run(20.0 + p.after - 0.4, [('/mfg-1-0.0', SUCCEEDED)])
    assert s.comms.goal(t) is None
    t = r.run(20.0 + p.after + 0.2, [('/mfg-1-0.0', SUCCEEDED)])
    assert s.comms.goal(t) is not None


def test_no_comms_loss_goal_before_a_task(params):
    s = Standin(params, own)
    r = Robot(s, corridor)
    t = r.run(4.0 + 3 * s.p.comms_loss.after, [], speed=0.5)     # into the dead zone, no goal ever given
    assert s.comms.last_good is not None and s.comms.goal(t) is None


def test_no_comms_loss_goal_while_the_link_is_good_or_the_source_is_heard(params):
    p = params.comms_loss
    s = Standin(params, own)
    r = Robot(s, lambda x: True)
    r.run(1.0, [('/mfg-1-0.0', ACTIVE)])
    t = r.run(1.0 + 3 * p.after, [('/mfg-1-0.0', SUCCEEDED)])    # a good link: the ordinary stand-in only
    assert s.comms.goal(t) is None and s.due(t)
    # no good link message since t; the source's heartbeat still reaches the robot: not lost
    assert s.comms.goal(t + p.after + 0.5) is not None
    s.path.heartbeat(t + p.after + 1.0)
    assert s.comms.goal(t + p.after + 2.0) is None


def returning(params):
    """A robot that drove 2 m from the good end into the dead zone (past x = 1.5 m) and lost its source: its
    comms-loss goal sent.
    Returns (stand-in, robot, time)."""
    p = params.comms_loss
    s = Standin(params, own)
    r = Robot(s, corridor)
    r.run(4.0, [('/mfg-1-0.0', ACTIVE)], speed=0.5)
    t = r.run(4.0 + p.after + 0.2, [('/mfg-1-0.0', SUCCEEDED)])
    assert s.comms.goal(t) is not None
    s.comms.sent()
    s.sent()
    return s, r, t


def test_the_link_back_ends_it_and_the_ordinary_stand_in_goes_on(params):
    s, r, t = returning(params)
    t = r.run(t + 4.0, [('/goal_standin-1-14.0', ACTIVE)], speed=-0.5)    # driving back: x = 0 again, link up
    assert s.comms.goal(t) is None and s.comms.target is None and not s.comms.driving
    assert s.standing_in and s.path.alive(t)          # the link and the source are back: the comms-loss goal ends
    t = r.run(t + 1.0, [('/goal_standin-1-14.0', SUCCEEDED)])
    # no comms-loss goal; the ordinary stand-in chains its own goals until a goal of the source is pursued
    assert s.comms.goal(t) is None and s.due(t)
    s.sent()
    t = r.run(t + 0.5, [('/goal_standin-2-19.5', ACTIVE), ('/mfg-2-19.6', ACTIVE)])
    assert s.handed_back() and s.comms.goal(t) is None


def test_a_source_goal_takes_over_from_the_comms_loss_goal(params):
    s, r, t = returning(params)
    t = r.run(t + 0.4, [('/goal_standin-1-14.0', PREEMPTED), ('/mfg-2-14.0', ACTIVE)])
    assert s.comms.goal(t) is None and s.handed_back() and s.comms.target is None


def test_back_at_the_place_without_the_link_it_waits_then_gives_up_until_the_link_returns(params):
    """The link lost everywhere (the cloud gone): the place does not help; the patrol goes on after a wait."""
    p = params.comms_loss
    s = Standin(params, own)
    r = Robot(s, lambda x: r.t < 3.0)
    r.run(3.0, [('/mfg-1-0.0', ACTIVE)], speed=0.5)
    t = r.run(3.0 + p.after + 0.2, [('/mfg-1-0.0', SUCCEEDED)])
    target = s.comms.goal(t)
    assert target is not None
    s.comms.sent()
    s.sent()
    t = r.run(t + 2.0, [('/goal_standin-1-13.2', ACTIVE)])
    s.comms.ended(t)                                            # there
    t_there = t
    t = r.run(t_there + p.after - 0.4, [('/goal_standin-1-13.2', SUCCEEDED)])
    assert s.comms.goal(t) == target                            # waiting there for the link
    t = r.run(t_there + p.after + 0.2, [('/goal_standin-1-13.2', SUCCEEDED)])
    assert s.comms.goal(t) is None and s.comms.given_up and s.due(t)   # the patrol, at once (source silent)
    t = r.run(t + 3 * p.after, [('/goal_standin-2-24.0', SUCCEEDED)])
    assert s.comms.goal(t) is None                              # given up until the link is good again
    r.up = lambda x: True
    t = r.run(t + 0.4, [('/goal_standin-2-24.0', SUCCEEDED)])
    assert not s.comms.given_up


def test_the_trail_keeps_margin_of_path_and_a_jump_across_a_dead_zone_starts_it_again(params):
    p = params.comms_loss
    s = Standin(params, own)
    c = s.comms
    for i in range(0, 31):
        c.link(0.1 * i, True, (0.1 * i, 0.0))                  # x = 0 .. 3 with a good link
    assert c.trail[-1][0] == pytest.approx(3.0)
    assert c.trail[0][0] == pytest.approx(3.0 - p.margin, abs=0.11)
    c.link(4.0, True, (9.0, 0.0))                                # next heard at the far end
    assert list(c.trail) == [(9.0, 0.0)]
    c.link(4.1, True, (9.01, 0.0))                               # less than a step: not added
    assert len(c.trail) == 1


def test_disabled_it_gives_no_goal(params, workspace):
    with open(os.path.join(workspace, 'config', 'goal_standin.yaml')) as f:
        data = yaml.safe_load(f)
    data['comms_loss']['enabled'] = False
    s = Standin(read_params(Section(data, 'x.yaml')), own)
    r = Robot(s, corridor)
    r.run(4.0, [('/mfg-1-0.0', ACTIVE)], speed=0.5)
    t = r.run(4.0 + 3 * s.p.comms_loss.after, [('/mfg-1-0.0', SUCCEEDED)])
    assert s.comms.goal(t) is None and s.due(t)


def test_the_steps_of_a_comms_loss_the_node_acts_on(params):
    """step(): the goal sent once, sent again when move_base has not acknowledged it, nothing on the way, the arrival
    once, then waiting; no comms loss: None."""
    from mfg.core.standin import ARRIVED, ON_ITS_WAY, RESEND, SEND, WAITING
    p = params.comms_loss
    s = Standin(params, own)
    r = Robot(s, corridor)
    r.run(4.0, [('/mfg-1-0.0', ACTIVE)], speed=0.5)
    t = r.run(4.0 + p.after - 1.0, [('/mfg-1-0.0', SUCCEEDED)])
    assert s.comms.step(t, False, False) is None
    t = r.run(4.0 + p.after + 0.2, [('/mfg-1-0.0', SUCCEEDED)])
    assert s.comms.step(t, False, False) == SEND and s.comms.driving
    assert s.comms.step(t + 0.1, True, True) == RESEND
    assert s.comms.step(t + 0.2, True, False) == ON_ITS_WAY
    assert s.comms.step(t + 0.3, False, False) == ARRIVED and s.comms.arrived == t + 0.3
    assert s.comms.step(t + 0.4, False, False) == WAITING
