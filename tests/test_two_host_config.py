"""config/two_host.yaml's network_monitor overlays without ROS: over config/network_monitor.yaml they are valid
monitor configurations, and the cloud answers either probe method the robot may use."""
import os

import pytest

from cnr_params import Section, load_yaml
from network_monitor.core.config import from_section

CONFIG = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'config')


def monitors():
    base = load_yaml(os.path.join(CONFIG, 'network_monitor.yaml'))
    two_host = Section.from_file(os.path.join(CONFIG, 'two_host.yaml')).section('two_host').section('network_monitor')
    peers = {'robot': 'cloud', 'cloud': 'robot'}
    return {side: from_section(Section(dict(base, **two_host.section(side).data, name=side, peer=peers[side]), side))
            for side in peers}


@pytest.mark.parametrize('method', ['iperf3', 'train'])
def test_the_cloud_runs_the_responders_for_either_probe(method):
    cloud = monitors()['cloud']
    assert cloud.probe_interval == 0.0
    assert cloud.iperf3_server and cloud.train_server
    server_port = cloud.iperf3_server_port if method == 'iperf3' else cloud.train_server_port
    robot = monitors()['robot']
    assert (robot.probe_port if method == 'iperf3' else robot.train_port) == server_port


def test_the_robot_probes_periodically():
    assert monitors()['robot'].probe_interval > 0.0
