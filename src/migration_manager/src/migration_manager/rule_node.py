"""``migration_rule`` (robot): orders migrations from the link quality by the configured rule
(:mod:`migration_manager.core.rule`, config/migration.yaml ``rule``), through the manager's ``~migrate``.
One order at a time; the manager refuses what it cannot do and the rule tries again later."""
from __future__ import annotations

import threading
import time
from typing import Dict

import rospy

import cnr_params
from cnr_msgs.msg import LinkQuality, Placement
from cnr_msgs.srv import Migrate
from cnr_params.ros import private_section
from cnr_runtime import init_node
from migration_manager.codes import MODE, OUTCOME_WORD, TARGET
from migration_manager.core.config import from_section
from migration_manager.core.rule import PlacementRule, rule_from_section


class RuleNode:
    def __init__(self) -> None:
        p = private_section('~')
        mig = p.section('migration')
        cfg = from_section(mig)
        rs = mig.section('rule')
        self.rule = PlacementRule(rule_from_section(rs, cfg.modules, cfg.hosts, cfg.authority))
        self.placement: Dict[str, str] = {}
        self.lock = threading.Lock()
        self.busy = False
        self.migrate = rospy.ServiceProxy('/migration_manager/migrate', Migrate)
        rospy.Subscriber(rs.string('link_quality_topic'), LinkQuality, self._on_quality, queue_size=10)
        rospy.Subscriber('/migration_manager/placement', Placement, self._on_placement, queue_size=10)
        c = self.rule.cfg
        rospy.loginfo(f'migration_rule: {", ".join(c.modules)} to {c.offload_to} when RTT < {1000 * c.good_rtt:.0f} ms '
                      f'and loss < {100 * c.good_loss:.0f} %, to {c.onload_to} when RTT > {1000 * c.bad_rtt:.0f} ms, '
                      f'loss > {100 * c.bad_loss:.0f} % or the peer is lost; dwell {c.dwell:g} s')

    def _on_quality(self, msg: LinkQuality) -> None:
        with self.lock:
            self.rule.observe(time.monotonic(), msg.alive, msg.rtt, msg.loss)

    def _on_placement(self, msg: Placement) -> None:
        with self.lock:
            self.placement = {m: h for m, h, moving in zip(msg.modules, msg.hosts, msg.migrating) if not moving}

    def _order(self, module: str, target: str) -> None:
        try:
            res = self.migrate(module, TARGET[target], MODE[''])
            rospy.loginfo(f'migration_rule: {module} -> {target}: {OUTCOME_WORD[res.outcome]} ({res.message})')
        except (rospy.ServiceException, rospy.ROSException) as exc:
            rospy.logwarn(f'migration_rule: {module} -> {target} not ordered: {exc}')
        finally:
            with self.lock:
                self.busy = False

    def spin(self) -> None:
        while not rospy.core.is_shutdown_requested():
            now = time.monotonic()
            with self.lock:
                orders = [] if self.busy else self.rule.orders(now, self.placement)
                if orders:
                    module, target = orders[0]
                    self.rule.moved(module, now)
                    self.busy = True
            if orders:
                rospy.loginfo(f'migration_rule: link {self.rule.state}: moving {module} to {target}')
                threading.Thread(target=self._order, args=(module, target), daemon=True).start()
            time.sleep(0.1)


@cnr_params.exit_on_config_error
def main() -> None:
    init_node('migration_rule')
    RuleNode().spin()
