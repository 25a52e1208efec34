"""``rosrun network_monitor training``: a robot's training sets on the command line (shared knowledge, thesis
§4.2.5 and its conclusion). No ROS master needed.

    training [--config FILE] [--dir DIR] list
    training [--config FILE] [--dir DIR] show TASK LOCATION
    training [--config FILE] [--dir DIR] export TASK LOCATION FILE      # a copy for another robot
    training [--config FILE] [--dir DIR] import TASK LOCATION FILE ROBOT   # another robot's rows, imported:ROBOT
    training [--config FILE] [--dir DIR] decide TASK LOCATION RTT_MS R_BW  # what the k-NN decides there now

``--dir`` defaults to config/decision.yaml's ``training_dir``. Exit status 0, 2 for a bad argument or file
(one line naming it), 1 otherwise.
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import sys
from typing import List, Optional

from cnr_params import ConfigError
from network_monitor.core.decision import Decider, Exploration
from network_monitor.core.decision_config import load_decision_config
from network_monitor.core.training import SUFFIX, TrainingFileError, TrainingSet, export_set, import_set


def default_config() -> str:
    import rospkg
    return os.path.join(rospkg.RosPack().get_path('cnr_config'), 'config', 'decision.yaml')


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(prog='training', description=__doc__.split('\n')[0])
    ap.add_argument('--config', help='decision.yaml (default: the workspace config/)')
    ap.add_argument('--dir', help='training sets directory (default: the config\'s training_dir)')
    sub = ap.add_subparsers(dest='cmd', required=True)
    sub.add_parser('list')
    for name in ('show', 'export', 'import', 'decide'):
        p = sub.add_parser(name)
        p.add_argument('task')
        p.add_argument('location')
        if name == 'export':
            p.add_argument('file')
        if name == 'import':
            p.add_argument('file')
            p.add_argument('robot')
        if name == 'decide':
            p.add_argument('rtt_ms', type=float)
            p.add_argument('r_bw', type=float)
    a = ap.parse_args(argv)
    try:
        cfg = load_decision_config(a.config or default_config())
        if a.dir:
            cfg = dataclasses.replace(cfg, training_dir=os.path.abspath(a.dir))
        if a.cmd == 'list':
            names = sorted(f for f in os.listdir(cfg.training_dir) if f.endswith(SUFFIX) and '@' in f) \
                if os.path.isdir(cfg.training_dir) else []
            for f in names:
                rows, warnings = TrainingSet(cfg.training_dir, *f[:-len(SUFFIX)].split('@', 1)).read()
                print(f'{f[:-len(SUFFIX)]}\t{len(rows)} rows' + (f', {len(warnings)} corrupt lines' if warnings else ''))
            if not names:
                print(f'no training sets in {cfg.training_dir}')
            return 0
        ts = cfg.training_set(a.task, a.location)
        if a.cmd == 'show':
            rows, warnings = ts.read()
            for w in warnings:
                print(w, file=sys.stderr)
            print(f'{ts.path}: {len(rows)} rows')
            for r in rows:
                print(f'  C_l {1000 * r.c_l:7.1f} ms  R_bw {r.r_bw:9.3g}  {r.decision:7s} {r.mission_status:9s} '
                      f'T {r.t_task:6.1f} s  B {r.b_task:.5f}  value {r.value:.3f}  label {r.label}  {r.source}')
            return 0
        if a.cmd == 'export':
            for w in export_set(ts.path, a.file):
                print(w, file=sys.stderr)
            print(f'exported {ts.path} to {a.file}')
            return 0
        if a.cmd == 'import':
            res = import_set(ts, a.file, a.robot)
            for w in res.warnings:
                print(w, file=sys.stderr)
            print(f'{a.file} into {ts.path}: {res.added} added, {res.duplicates} already there, '
                  f'{res.skipped} of another task or location')
            return 0
        rows, _ = ts.read()
        s = cfg.decision
        d = Decider(dataclasses.replace(s, exploration=Exploration(0.0, s.exploration.max_rtt, 0)), rows).policy(
            a.rtt_ms / 1000.0, a.r_bw)
        print(f'{d.decision} ({d.reason}' + (f', votes {d.votes}' if d.votes else '') + f'; {len(rows)} rows)')
        return 0
    except (ConfigError, TrainingFileError, ValueError, OSError) as exc:
        print(f'training: {exc}', file=sys.stderr)
        return 2
