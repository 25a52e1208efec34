"""network_monitor settings from a :class:`cnr_params.Section` (the node's private parameters, loaded
from config/network_monitor.yaml). No defaults here: a missing parameter is a one-line ConfigError."""
from __future__ import annotations

from dataclasses import dataclass

from cnr_params import Section
from network_monitor.core.estimate import PassiveSettings
from network_monitor.core.probe import ProbeSettings
from network_monitor.core.train import MAX_PACKETS, MAX_PAYLOAD, TRAIN_HEADER, TrainSettings

PROBE_METHODS = ('iperf3', 'train')


@dataclass
class MonitorConfig:
    name: str
    peer: str
    peer_address: str
    topic_prefix: str
    link_quality_topic: str
    interface: str
    echo_rate: float
    window: float
    reply_timeout: float
    alive_timeout: float
    link_quality_timeout: float
    publish_rate: float
    sample_period: float
    c_bw_span: float
    c_bw_floor: float
    probe_interval: float
    probe: ProbeSettings
    probe_port: int
    iperf3_executable: str
    iperf3_server: bool
    iperf3_server_port: int
    probe_method: str           # 'iperf3' | 'train'
    train: TrainSettings
    train_port: int
    train_server: bool
    train_server_port: int
    passive: PassiveSettings

    def topic(self, host: str, leaf: str) -> str:
        """``<topic_prefix>/<host>/<leaf>``, e.g. network_monitor/robot/ping."""
        return f'{self.topic_prefix}/{host}/{leaf}'


def _name(section: Section, key: str) -> str:
    value = section.string(key)
    if not value or '/' in value or ' ' in value:
        raise section.error(key, f'must be a non-empty name without / or spaces, got {value!r}')
    return value


def from_section(s: Section) -> MonitorConfig:
    """Validate every parameter; raises ConfigError naming the first bad one."""
    cfg = MonitorConfig(
        name=_name(s, 'name'),
        peer=_name(s, 'peer'),
        peer_address=s.string('peer_address'),
        topic_prefix=s.string('topic_prefix'),
        link_quality_topic=s.string('link_quality_topic'),
        interface=s.string('interface'),
        echo_rate=s.number('echo_rate', positive=True),
        window=s.number('window', positive=True),
        reply_timeout=s.number('reply_timeout', positive=True),
        alive_timeout=s.number('alive_timeout', positive=True),
        link_quality_timeout=s.number('link_quality_timeout', positive=True),
        publish_rate=s.number('publish_rate', positive=True),
        sample_period=s.number('sample_period', positive=True),
        c_bw_span=s.number('c_bw_span', positive=True),
        c_bw_floor=s.number('c_bw_floor', positive=True),
        probe_interval=s.number('probe_interval', nonnegative=True),
        probe=ProbeSettings(seconds=s.integer('probe_seconds', minimum=1),
                            omit=s.integer('probe_omit', minimum=0),
                            max_bytes=s.integer('probe_bytes', minimum=1),
                            timeout=s.number('probe_timeout', positive=True)),
        probe_port=s.integer('probe_port', minimum=1, maximum=65535),
        iperf3_executable=s.string('iperf3_executable'),
        iperf3_server=s.boolean('iperf3_server'),
        iperf3_server_port=s.integer('iperf3_server_port', minimum=1, maximum=65535),
        probe_method=s.string('probe_method', choices=PROBE_METHODS),
        train=TrainSettings(packets=s.integer('train_packets', minimum=3, maximum=MAX_PACKETS),
                            packet_bytes=s.integer('train_packet_bytes', minimum=TRAIN_HEADER.size,
                                                   maximum=MAX_PAYLOAD),
                            gap=s.number('train_gap', positive=True),
                            timeout=s.number('probe_timeout', positive=True)),
        train_port=s.integer('train_port', minimum=1, maximum=65535),
        train_server=s.boolean('train_server'),
        train_server_port=s.integer('train_server_port', minimum=1, maximum=65535),
        passive=PassiveSettings(
            fresh=s.number('probe_fresh', nonnegative=True),
            window=s.number('passive_window', positive=True),
            half_life=s.number('passive_half_life', positive=True),
            floor_fraction=s.number('passive_floor_fraction', minimum=0.0, maximum=1.0)))
    if not cfg.peer_address:
        raise s.error('peer_address', 'must not be empty')
    if cfg.peer == cfg.name:
        raise s.error('peer', f'must differ from name ({cfg.name!r})')
    if cfg.reply_timeout >= cfg.window:
        raise s.error('reply_timeout', f'must be < window ({cfg.window:g} s), got {cfg.reply_timeout:g}')
    if cfg.probe.timeout <= cfg.probe.seconds + cfg.probe.omit:
        raise s.error('probe_timeout', f'must be > probe_seconds + probe_omit '
                                       f'({cfg.probe.seconds + cfg.probe.omit} s), got {cfg.probe.timeout:g}')
    if cfg.train.gap >= cfg.train.timeout:
        raise s.error('train_gap', f'must be < probe_timeout ({cfg.train.timeout:g} s), got {cfg.train.gap:g}')
    if cfg.c_bw_span < cfg.sample_period:
        raise s.error('c_bw_span', f'must be >= sample_period ({cfg.sample_period:g} s)')
    return cfg
