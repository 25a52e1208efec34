"""cnr_store_forward settings from a :class:`cnr_params.Section` (a node's private parameters, loaded from
config/store_forward.yaml). No defaults here: a missing parameter is a one-line ConfigError."""
from __future__ import annotations

import os
from dataclasses import dataclass

from cnr_params import Section
from cnr_store_forward.core.sender import SenderSettings


@dataclass(frozen=True)
class Common:
    stream: str
    topic_prefix: str
    status_rate: float          # [Hz]

    def topic(self, leaf: str) -> str:
        """``<topic_prefix>/<stream>/<leaf>``, e.g. store_forward/measurements/data."""
        return f'{self.topic_prefix}/{self.stream}/{leaf}'


@dataclass(frozen=True)
class SenderConfig:
    common: Common
    input_topic: str
    queue_dir: str              # the stream's queue is <queue_dir>/<stream>
    max_records: int
    max_bytes: int
    segment_bytes: int
    fsync: bool
    sync_period: float          # [s] appended records are synced (and then sendable) this often
    rate: float                 # [Hz] batches sent at most
    retain_records: int         # acknowledged records kept on disk at least (sent again to a receiver behind)
    settings: SenderSettings

    @property
    def stream_dir(self) -> str:
        return os.path.join(self.queue_dir, self.common.stream)


@dataclass(frozen=True)
class ReceiverConfig:
    common: Common
    output_topic: str
    state_dir: str              # the stream's state file is <state_dir>/<stream>.json
    fsync: bool
    require_consumer: bool
    ack_period: float           # [s] the ack is repeated this often while idle (the sender sees the link is up)

    @property
    def state_path(self) -> str:
        return os.path.join(self.state_dir, f'{self.common.stream}.json')


def _name(s: Section, key: str) -> str:
    value = s.string(key)
    if not value or not all(c.isalnum() or c == '_' for c in value) or not value[0].isalpha():
        raise s.error(key, f'must be a ROS name (letters, digits, _; a letter first), got {value!r}')
    return value


def _topic(s: Section, key: str) -> str:
    value = s.string(key)
    if not value or ' ' in value:
        raise s.error(key, f'must be a topic name, got {value!r}')
    return value


def _directory(s: Section, key: str) -> str:
    value = s.string(key)
    if not value:
        raise s.error(key, 'must not be empty')
    return os.path.abspath(os.path.expanduser(value))


def common_from_section(s: Section) -> Common:
    return Common(stream=_name(s, 'stream'), topic_prefix=_topic(s, 'topic_prefix'),
                  status_rate=s.number('status_rate', positive=True))


def sender_from_section(s: Section) -> SenderConfig:
    """Validate the common parameters and the ``sender`` section; raises ConfigError naming the first bad one."""
    common = common_from_section(s)
    p = s.section('sender')
    cfg = SenderConfig(
        common=common,
        input_topic=_topic(p, 'input_topic'),
        queue_dir=_directory(p, 'queue_dir'),
        max_records=p.integer('max_records', minimum=1),
        max_bytes=p.integer('max_bytes', minimum=1024),
        segment_bytes=p.integer('segment_bytes', minimum=1024),
        fsync=p.boolean('fsync'),
        sync_period=p.number('sync_period', nonnegative=True),
        rate=p.number('rate', positive=True),
        retain_records=p.integer('retain_records', minimum=0),
        settings=SenderSettings(
            window=p.integer('window', minimum=1),
            batch_records=p.integer('batch_records', minimum=1),
            batch_bytes=p.integer('batch_bytes', minimum=1),
            ack_timeout=p.number('ack_timeout', positive=True),
            max_backoff=p.number('max_backoff', positive=True)))
    if cfg.settings.batch_records > cfg.settings.window:
        raise p.error('batch_records', f'must be <= window ({cfg.settings.window}), got {cfg.settings.batch_records}')
    if cfg.settings.max_backoff < cfg.settings.ack_timeout:
        raise p.error('max_backoff', f'must be >= ack_timeout ({cfg.settings.ack_timeout:g} s)')
    return cfg


def receiver_from_section(s: Section) -> ReceiverConfig:
    """Validate the common parameters and the ``receiver`` section; raises ConfigError naming the first bad one."""
    common = common_from_section(s)
    p = s.section('receiver')
    return ReceiverConfig(common=common, output_topic=_topic(p, 'output_topic'),
                          state_dir=_directory(p, 'state_dir'), fsync=p.boolean('fsync'),
                          require_consumer=p.boolean('require_consumer'),
                          ack_period=p.number('ack_period', positive=True))
