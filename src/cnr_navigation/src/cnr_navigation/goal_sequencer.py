"""``goal_sequencer``: drive through a sequence of goals with the move_base action, printing progress.

    rosrun cnr_navigation goal_sequencer --goals config/goals_corridor.yaml
    rosrun cnr_navigation goal_sequencer --goal 5.0 0.5 0.0

Exit status: 0 when every goal was reached, 1 otherwise, 2 for a bad goal file.

``launch_scripts/send_goals.sh`` (:func:`send_goals`, this module's ``__main__``) runs it on a master of one's
choice.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time
from dataclasses import dataclass
from typing import List, Optional

import cnr_params
from cnr_harness.script import WS, Parser, Processes, ScriptError, master_address, master_up, port_number, run
from cnr_params import ConfigError, Section
from cnr_runtime import init_node

SEND_GOALS = 'send_goals.sh'
SEND_GOALS_DOC = """Send navigation goals to move_base through its action interface, printing progress.

FILE holds `goals: [{name: .., x: .., y: .., yaw: ..}, ...]` (all required) in the map frame (default
config/goals_corridor.yaml); or one goal X Y YAW. Needs a master with move_base (launch_scripts/bringup.sh).
Exit status: 0 when every goal succeeded, 1 otherwise, 2 for a bad option or goal file, 130 interrupted.
"""


@dataclass
class Goal:
    name: str
    x: float
    y: float
    yaw: float


def load_goals(path: str) -> List[Goal]:
    """Goals from a YAML file ``goals: [{name, x, y, yaw}, ...]`` (m, m, rad; every field required)."""
    doc = Section.from_file(path)
    items = doc.sections('goals')
    if not items:
        raise doc.error('goals', 'expected a non-empty list of {name, x, y, yaw}')
    return [Goal(g.string('name'), g.number('x'), g.number('y'), g.number('yaw')) for g in items]


def wait_for_server(client, timeout: float) -> bool:
    """Wait up to ``timeout`` WALL seconds for the action server (and for /clock under use_sim_time).

    actionlib's own timeout is in ROS time, which is 0 until the first /clock message arrives and then
    jumps forward, so a plain ``wait_for_server(Duration(t))`` can expire at once under sim time.
    """
    import rospy
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and not rospy.is_shutdown():
        if not rospy.Time.now().is_zero() and client.wait_for_server(rospy.Duration(0.5)):
            return True
        time.sleep(0.1)
    return False


def _parse_args(argv: List[str]) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog='goal_sequencer', description=__doc__.split('\n')[1])
    src = ap.add_mutually_exclusive_group(required=True)
    src.add_argument('--goals', metavar='FILE', help='YAML goal file')
    src.add_argument('--goal', nargs=3, type=float, metavar=('X', 'Y', 'YAW'), help='one goal in the map frame')
    ap.add_argument('--frame', default='map', help='frame of the goals (default: map)')
    ap.add_argument('--timeout', type=float, default=300.0, help='sim seconds allowed per goal (default: 300)')
    ap.add_argument('--server-timeout', type=float, default=60.0, help='wall seconds to wait for move_base')
    return ap.parse_args(argv)


@cnr_params.exit_on_config_error
def main() -> None:
    import rospy
    args = _parse_args(rospy.myargv(sys.argv)[1:])
    if args.goals:
        goals = load_goals(args.goals)
    else:
        if not all(math.isfinite(v) for v in args.goal):
            raise ConfigError('--goal', 'X Y YAW', f'must be finite numbers, got {args.goal}')
        goals = [Goal('goal', *args.goal)]
    import actionlib
    from actionlib_msgs.msg import GoalStatus
    from move_base_msgs.msg import MoveBaseAction, MoveBaseGoal
    init_node('goal_sequencer', anonymous=True)
    client = actionlib.SimpleActionClient('move_base', MoveBaseAction)
    print(f'goal_sequencer: waiting for the move_base action server ({client.action_client.ns})', flush=True)
    if not wait_for_server(client, args.server_timeout):
        print(f'goal_sequencer: move_base action server not available after {args.server_timeout:g} s '
              f'(is move_base running on {rospy.get_master().target._ServerProxy__host}?)', file=sys.stderr)
        sys.exit(1)
    reached = 0
    for i, g in enumerate(goals, 1):
        goal = MoveBaseGoal()
        goal.target_pose.header.frame_id = args.frame
        goal.target_pose.header.stamp = rospy.Time.now()
        goal.target_pose.pose.position.x, goal.target_pose.pose.position.y = g.x, g.y
        goal.target_pose.pose.orientation.z = math.sin(0.5 * g.yaw)
        goal.target_pose.pose.orientation.w = math.cos(0.5 * g.yaw)
        last = {'t': 0.0}
        start_sim = rospy.Time.now().to_sec()
        start_wall = time.monotonic()

        def feedback(fb, g=g, i=i, last=last):
            now = time.monotonic()
            if now - last['t'] >= 3.0:
                last['t'] = now
                p = fb.base_position.pose.position
                print(f'  [{i}/{len(goals)}] {g.name}: at ({p.x:6.2f}, {p.y:6.2f}), '
                      f'{math.hypot(g.x - p.x, g.y - p.y):5.2f} m to go', flush=True)

        print(f'[{i}/{len(goals)}] {g.name}: driving to ({g.x:.2f}, {g.y:.2f}, yaw {g.yaw:.2f})', flush=True)
        client.send_goal(goal, feedback_cb=feedback)
        deadline = start_sim + args.timeout
        while not client.wait_for_result(rospy.Duration(0.5)):
            if rospy.is_shutdown():
                sys.exit(1)
            if rospy.Time.now().to_sec() > deadline:
                client.cancel_goal()
                break
        state = client.get_state()
        text = client.get_goal_status_text()
        sim = rospy.Time.now().to_sec() - start_sim
        wall = time.monotonic() - start_wall
        if state == GoalStatus.SUCCEEDED:
            reached += 1
            print(f'[{i}/{len(goals)}] {g.name}: reached in {sim:.1f} s sim ({wall:.1f} s wall)', flush=True)
        else:
            name = GoalStatus.to_string(state) if hasattr(GoalStatus, 'to_string') else str(state)
            print(f'[{i}/{len(goals)}] {g.name}: FAILED ({name}: {text or "timeout"})', flush=True)
    print(f'goal_sequencer: {reached}/{len(goals)} goals reached', flush=True)
    sys.exit(0 if reached == len(goals) else 1)


def _send_goals(argv: Optional[List[str]]) -> int:
    ap = Parser(SEND_GOALS, SEND_GOALS_DOC)
    ap.add_argument('--host', help='master host (default: ROS_MASTER_URI, else localhost)')
    ap.add_argument('--port', type=port_number, help='master port (default: ROS_MASTER_URI, else 11311)')
    ap.add_argument('--goals', type=os.path.realpath, metavar='FILE',
                    default=os.path.join(WS, 'config', 'goals_corridor.yaml'), help='YAML goal file')
    ap.add_argument('goal', nargs='*', metavar='X Y YAW', help='one goal in the map frame instead of a file')
    args = ap.parse_args(argv)
    if len(args.goal) not in (0, 3):
        ap.error('expected X Y YAW or --goals FILE')
    master_address(args.host, args.port)
    if not master_up():
        raise ScriptError(f'no master at {os.environ["ROS_MASTER_URI"]} (start one with launch_scripts/bringup.sh)')
    goals = ['--goal', *args.goal] if args.goal else ['--goals', args.goals]
    with Processes() as procs:
        return procs.start(['rosrun', 'cnr_navigation', 'goal_sequencer', *goals]).wait()


def send_goals(argv: Optional[List[str]] = None) -> int:
    """``send_goals.sh [--host H] [--port P] [--goals FILE | X Y YAW]``: the goal sequencer on a running master."""
    return run(lambda: _send_goals(argv), SEND_GOALS)


if __name__ == '__main__':
    sys.exit(send_goals())
