"""A disk-backed FIFO of records (sequence number, stamp, bytes) that survives crashes of its process.

Layout of a queue directory (one per stream)::

    queue.json                 format, epoch (random 63-bit number chosen when the queue is created), meta
    acked.json                 the acknowledged high-water mark {"epoch": e, "acked": n}
    00000000000000000001.seg   segments named by their first sequence number, append-only
    lock                       flock()ed while a process has the queue open

A segment is a 16-byte header (magic, epoch) and records framed as::

    crc32 (u32) | length (u32) | seq (u64) | stamp_ns (i64) | payload (length bytes)

little-endian, the CRC over everything after it. A crash in the middle of an append leaves a torn tail:
on open the last segment is truncated at its first record that is short, fails its CRC or breaks the
sequence; every record before it is intact. Damage anywhere else is not a torn write and raises
:class:`QueueCorrupt`. Sequence numbers start at 1, increase by one and are never reused within an epoch,
also across restarts (they continue from the segments; the newest segment is never deleted).

Acknowledged records are compacted by deleting whole segments, but only once at least ``retain_records``
newer records have been acknowledged too: the newest acknowledged records stay on disk (:attr:`DiskQueue.floor`
is the last record no longer held), so a receiver that acknowledges less than an earlier one did (a store
instance promoted with an older state) can be sent them again. The acked mark is written atomically with
every acknowledgement and durably (fsync) before a segment is deleted. A stale mark after a power loss
only means some records are sent again, which the receiver drops as duplicates.

With ``fsync`` a record counts as *synced* once :meth:`DiskQueue.sync` has fsync()ed it; senders send
only synced records, so a power loss can never lose a record the receiver has seen (its sequence number
would otherwise be reused for a different record). Without ``fsync`` a record is synced when written
(safe against a crash of the process, not of the machine).

Bounded by ``max_records`` and ``max_bytes`` of unacknowledged records: an append that would exceed either
is refused (:meth:`DiskQueue.append` returns None), counted in ``rejected`` and ``full`` is set until
there is room again. Nothing stored is ever dropped.

Not thread-safe: one caller at a time.
"""
from __future__ import annotations

import bisect
import fcntl
import os
import random
import struct
import zlib
from array import array
from dataclasses import dataclass
from typing import Any, Dict, List, Optional

from cnr_params.files import fsync_directory, read_json, write_json

FORMAT = 1
MAGIC = b'CNRSFQ1\n'
SEGMENT_HEADER = struct.Struct('<8sQ')          # magic, epoch
RECORD_HEADER = struct.Struct('<IIQq')          # crc32, length, seq, stamp_ns
CRC_PART = struct.Struct('<IQq')                # what the CRC covers before the payload
SEGMENT_SUFFIX = '.seg'


class QueueError(RuntimeError):
    """The queue cannot be used (a problem a person has to look at)."""


class QueueCorrupt(QueueError):
    """Damage in the queue directory that is not a torn tail of the newest segment."""


class QueueLocked(QueueError):
    """Another process has the queue open."""


@dataclass(frozen=True)
class Record:
    seq: int
    stamp_ns: int               # wall-clock time the record was stored [ns since the epoch]
    data: bytes


@dataclass(frozen=True)
class Recovery:
    """What opening the queue found."""
    created: bool               # a new queue (new epoch)
    segments: int
    records: int                # records on disk (acknowledged ones of undeleted segments included)
    unacked: int
    torn_bytes: int             # bytes cut from the tail of the newest segment
    skipped_to: int             # 0, or the seq the queue jumped to because the acked mark was ahead of it


def frame(seq: int, stamp_ns: int, data: bytes) -> bytes:
    """One record as stored: header and payload."""
    crc = zlib.crc32(data, zlib.crc32(CRC_PART.pack(len(data), seq, stamp_ns)))
    return RECORD_HEADER.pack(crc, len(data), seq, stamp_ns) + data


class _Segment:
    """One segment file: its first seq, the byte offset of each record, its size, an open descriptor."""

    def __init__(self, path: str, first_seq: int, fd: int, size: int, offsets: array) -> None:
        self.path = path
        self.first_seq = first_seq
        self.fd = fd
        self.size = size
        self.offsets = offsets

    @property
    def count(self) -> int:
        return len(self.offsets)

    @property
    def last_seq(self) -> int:
        """The last record's seq (first_seq - 1 when empty)."""
        return self.first_seq + len(self.offsets) - 1

    def end_of(self, index: int) -> int:
        return self.offsets[index + 1] if index + 1 < len(self.offsets) else self.size

    def close(self) -> None:
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1


def _segment_name(first_seq: int) -> str:
    return f'{first_seq:020d}{SEGMENT_SUFFIX}'


def _parse_records(buf: bytes, first_seq: int) -> tuple:
    """Valid records at the start of a segment's bytes: (offsets, end of the last valid record)."""
    offsets = array('Q')
    pos = SEGMENT_HEADER.size
    seq = first_seq
    size = len(buf)
    while pos < size:
        if size - pos < RECORD_HEADER.size:
            break
        crc, length, rseq, stamp = RECORD_HEADER.unpack_from(buf, pos)
        end = pos + RECORD_HEADER.size + length
        if end > size or rseq != seq:
            break
        payload = buf[pos + RECORD_HEADER.size:end]
        if zlib.crc32(payload, zlib.crc32(CRC_PART.pack(length, rseq, stamp))) != crc:
            break
        offsets.append(pos)
        pos = end
        seq += 1
    return offsets, pos


class DiskQueue:
    """The queue in ``directory`` (created if missing), opened and recovered.

    Args:
        directory: the queue's directory (one per stream).
        max_records: bound on unacknowledged records.
        max_bytes: bound on the bytes of unacknowledged records on disk (headers included).
        segment_bytes: a segment at least this big is closed and a new one started.
        fsync: fsync appended records in :meth:`sync` (and segments, marks and directories where needed).
        retain_records: acknowledged records kept on disk at least (whole segments are deleted only when every
            record in them is acknowledged and at least this many acknowledged records follow them).

    Raises:
        QueueLocked: another process has the queue open.
        QueueCorrupt: damage other than a torn tail.
        OSError: the directory cannot be created or read.
    """

    def __init__(self, directory: str, max_records: int, max_bytes: int, segment_bytes: int, fsync: bool,
                 retain_records: int = 0) -> None:
        if retain_records < 0:
            raise ValueError(f'retain_records must be >= 0, got {retain_records}')
        self.directory = directory
        self.retain_records = retain_records
        self.max_records = max_records
        self.max_bytes = max_bytes
        self.segment_bytes = segment_bytes
        self.fsync = fsync
        self.full = False
        self.appended = 0
        self.rejected = 0
        self._segments: List[_Segment] = []
        self._firsts: List[int] = []
        os.makedirs(directory, exist_ok=True)
        self._lock_fd = os.open(self._path('lock'), os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(self._lock_fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(self._lock_fd)
            raise QueueLocked(f'{directory}: the queue is open in another process') from None
        try:
            self.recovery = self._open()
        except BaseException:
            self.close()
            raise

    # ---------------------------------------------------------------- opening
    def _path(self, name: str) -> str:
        return os.path.join(self.directory, name)

    def _open(self) -> Recovery:
        names = sorted(n for n in os.listdir(self.directory) if n.endswith(SEGMENT_SUFFIX))
        info = read_json(self._path('queue.json'))
        created = info is None
        if created:
            if names:
                raise QueueCorrupt(f'{self.directory}: segments without a readable queue.json')
            info = {'format': FORMAT, 'epoch': random.SystemRandom().getrandbits(63) or 1, 'meta': {}}
            write_json(self._path('queue.json'), info, durable=True)
        if info.get('format') != FORMAT or not isinstance(info.get('epoch'), int) \
                or not isinstance(info.get('meta'), dict):
            raise QueueCorrupt(f'{self.directory}/queue.json: unknown format {info!r}')
        self.epoch: int = info['epoch']
        self.meta: Dict[str, Any] = info['meta']
        mark = read_json(self._path('acked.json')) or {}
        acked_mark = mark['acked'] if mark.get('epoch') == self.epoch and isinstance(mark.get('acked'), int) else 0

        torn = 0
        for i, name in enumerate(names):
            try:
                first = int(name[:-len(SEGMENT_SUFFIX)])
            except ValueError:
                raise QueueCorrupt(f'{self.directory}/{name}: not a segment name') from None
            torn += self._load_segment(name, first, last=(i == len(names) - 1))
        for prev, seg in zip(self._segments, self._segments[1:]):
            if seg.first_seq != prev.last_seq + 1:
                raise QueueCorrupt(f'{seg.path}: starts at seq {seg.first_seq}, the segment before ends at '
                                   f'{prev.last_seq}')
        if not self._segments:
            self._new_segment(acked_mark + 1)
        records = sum(s.count for s in self._segments)
        self.last_seq = self._segments[-1].last_seq
        skipped = 0
        if acked_mark > self.last_seq:
            # the mark is ahead of the records on disk (a tail lost without fsync): new records must not reuse
            # the sequence numbers the receiver has already delivered
            self._skip_to(acked_mark + 1)
            skipped = acked_mark + 1
        self.acked = min(max(acked_mark, self._segments[0].first_seq - 1), self.last_seq)
        if self.fsync:
            os.fdatasync(self._segments[-1].fd)
        self.synced_seq = self.last_seq
        self.unacked_bytes = self._bytes_after(self.acked)
        self._compact()
        return Recovery(created=created, segments=len(self._segments), records=records,
                        unacked=self.last_seq - self.acked, torn_bytes=torn, skipped_to=skipped)

    def _load_segment(self, name: str, first: int, last: bool) -> int:
        """Open and index one segment; returns the torn bytes cut from it (the newest only)."""
        path = self._path(name)
        fd = os.open(path, os.O_RDWR | os.O_APPEND)
        try:
            size = os.fstat(fd).st_size
            buf = os.pread(fd, size, 0)
            header_ok = len(buf) >= SEGMENT_HEADER.size and SEGMENT_HEADER.unpack_from(buf) == (MAGIC, self.epoch)
            if not header_ok:
                if not last or len(buf) >= SEGMENT_HEADER.size:
                    raise QueueCorrupt(f'{path}: not a segment of this queue (bad header)')
                os.ftruncate(fd, 0)                 # created, crashed before its header was written
                os.write(fd, SEGMENT_HEADER.pack(MAGIC, self.epoch))
                buf = SEGMENT_HEADER.pack(MAGIC, self.epoch)
                size = len(buf)
            offsets, end = _parse_records(buf, first)
            torn = size - end
            if torn:
                if not last:
                    raise QueueCorrupt(f'{path}: bad record at byte {end} (not the newest segment)')
                os.ftruncate(fd, end)
                if self.fsync:
                    os.fsync(fd)
        except BaseException:
            os.close(fd)
            raise
        self._add_segment(_Segment(path, first, fd, end, offsets))
        return torn

    def _add_segment(self, seg: _Segment) -> None:
        self._segments.append(seg)
        self._firsts.append(seg.first_seq)

    def _new_segment(self, first_seq: int) -> None:
        path = self._path(_segment_name(first_seq))
        fd = os.open(path, os.O_RDWR | os.O_APPEND | os.O_CREAT | os.O_TRUNC, 0o644)
        try:
            os.write(fd, SEGMENT_HEADER.pack(MAGIC, self.epoch))
            if self.fsync:
                os.fsync(fd)
                fsync_directory(self.directory)
        except BaseException:
            os.close(fd)
            raise
        self._add_segment(_Segment(path, first_seq, fd, SEGMENT_HEADER.size, array('Q')))

    def close(self) -> None:
        for seg in self._segments:
            seg.close()
        if self._lock_fd >= 0:
            os.close(self._lock_fd)         # releases the flock
            self._lock_fd = -1

    # ---------------------------------------------------------------- state
    @property
    def unacked(self) -> int:
        """Records stored and not yet acknowledged."""
        return self.last_seq - self.acked

    @property
    def floor(self) -> int:
        """The newest record no longer on disk (0: none deleted): records after it can be read, up to
        ``last_seq``."""
        return self._segments[0].first_seq - 1

    def has_room(self, size: int = 0) -> bool:
        """Whether one more record of ``size`` payload bytes fits the bounds."""
        return (self.unacked < self.max_records
                and self.unacked_bytes + RECORD_HEADER.size + size <= self.max_bytes)

    def set_meta(self, meta: Dict[str, Any]) -> None:
        """Replace the queue's metadata (JSON values; e.g. the message type of the records), durably."""
        write_json(self._path('queue.json'), {'format': FORMAT, 'epoch': self.epoch, 'meta': meta}, durable=True)
        self.meta = dict(meta)

    def disk_bytes(self) -> int:
        """Bytes of all segments on disk (acknowledged records not yet compacted included)."""
        return sum(s.size for s in self._segments)

    # ---------------------------------------------------------------- writing
    def append(self, data: bytes, stamp_ns: int) -> Optional[int]:
        """Store one record; returns its seq, or None if the queue is full (counted in ``rejected``).

        Raises:
            OSError: writing failed (e.g. the disk is full); the record is not stored, ``rejected`` counts it.
        """
        if not self.has_room(len(data)):
            self.full = True
            self.rejected += 1
            return None
        seq = self.last_seq + 1
        blob = frame(seq, stamp_ns, data)
        try:
            if self._segments[-1].size >= self.segment_bytes:
                self._roll()
            seg = self._segments[-1]
            view = memoryview(blob)
            while view:
                view = view[os.write(seg.fd, view):]
        except OSError:
            self.rejected += 1
            os.ftruncate(self._segments[-1].fd, self._segments[-1].size)    # no partial record stays behind
            raise
        seg.offsets.append(seg.size)
        seg.size += len(blob)
        self.last_seq = seq
        self.unacked_bytes += len(blob)
        self.appended += 1
        self.full = False
        if not self.fsync:
            self.synced_seq = seq
        return seq

    def sync(self) -> int:
        """Make every appended record durable (fdatasync with ``fsync``); returns the synced seq."""
        if self.synced_seq < self.last_seq:
            if self.fsync:
                os.fdatasync(self._segments[-1].fd)
            self.synced_seq = self.last_seq
        return self.synced_seq

    def _roll(self) -> None:
        if self.fsync:
            os.fdatasync(self._segments[-1].fd)
        self.synced_seq = self.last_seq
        self._new_segment(self.last_seq + 1)

    # ---------------------------------------------------------------- reading
    def _locate(self, seq: int) -> tuple:
        if not self._firsts[0] <= seq <= self.last_seq:
            raise KeyError(f'seq {seq} is not on disk')
        seg = self._segments[bisect.bisect_right(self._firsts, seq) - 1]
        return seg, seq - seg.first_seq

    def read(self, seq: int) -> Record:
        """The record ``seq`` (it must still be on disk).

        Raises:
            KeyError: no such record.
            QueueCorrupt: the record no longer matches its CRC.
        """
        seg, index = self._locate(seq)
        start, end = seg.offsets[index], seg.end_of(index)
        buf = os.pread(seg.fd, end - start, start)
        crc, length, rseq, stamp = RECORD_HEADER.unpack_from(buf)
        data = buf[RECORD_HEADER.size:]
        if rseq != seq or len(data) != length or \
                zlib.crc32(data, zlib.crc32(CRC_PART.pack(length, rseq, stamp))) != crc:
            raise QueueCorrupt(f'{seg.path}: record {seq} at byte {start} is damaged')
        return Record(seq, stamp, data)

    def stamp_of(self, seq: int) -> int:
        """The stamp of record ``seq`` [ns] (reads its header only)."""
        seg, index = self._locate(seq)
        return RECORD_HEADER.unpack(os.pread(seg.fd, RECORD_HEADER.size, seg.offsets[index]))[3]

    def records(self, first: int, last: int, max_count: int, max_bytes: int) -> List[Record]:
        """Consecutive records from ``first`` up to ``last`` (inclusive): at most ``max_count`` of them and
        ``max_bytes`` of payload, but at least one if ``first <= last``."""
        out: List[Record] = []
        size = 0
        seq = first
        while seq <= last and len(out) < max_count:
            rec = self.read(seq)
            if out and size + len(rec.data) > max_bytes:
                break
            out.append(rec)
            size += len(rec.data)
            seq += 1
        return out

    # ---------------------------------------------------------------- acknowledging
    def _bytes_after(self, seq: int) -> int:
        """Bytes on disk of the records after ``seq``."""
        total = 0
        for seg in self._segments:
            if seg.last_seq <= seq:
                continue
            start = seg.offsets[seq + 1 - seg.first_seq] if seg.first_seq <= seq else SEGMENT_HEADER.size
            total += seg.size - start
        return total

    def ack(self, seq: int) -> int:
        """Every record up to ``seq`` is acknowledged; returns how many are newly so.

        Raises:
            ValueError: ``seq`` is beyond the newest record (see :meth:`skip_to`).
        """
        if seq <= self.acked:
            return 0
        if seq > self.last_seq:
            raise ValueError(f'ack {seq} beyond the newest record {self.last_seq}')
        newly = seq - self.acked
        self.acked = seq
        self.unacked_bytes = self._bytes_after(seq)
        write_json(self._path('acked.json'), {'epoch': self.epoch, 'acked': seq}, durable=False)
        self._compact()
        if self.full and self.has_room():
            self.full = False
        return newly

    def _compact(self) -> None:
        """Delete the segments whose records are all acknowledged and followed by at least ``retain_records``
        acknowledged ones (never the newest)."""
        done = [s for s in self._segments[:-1] if s.last_seq <= self.acked - self.retain_records]
        if not done:
            return
        # the mark must be durable first: it, or the first remaining segment, is where the acked records end
        write_json(self._path('acked.json'), {'epoch': self.epoch, 'acked': self.acked}, durable=self.fsync)
        for seg in done:
            seg.close()
            os.unlink(seg.path)
        if self.fsync:
            fsync_directory(self.directory)
        self._segments = self._segments[len(done):]
        self._firsts = [s.first_seq for s in self._segments]

    def skip_to(self, seq: int) -> None:
        """Everything before ``seq`` is acknowledged, although the newest record is older (the receiver has
        delivered records this queue lost: only possible without fsync); the next record gets ``seq``."""
        if seq <= self.last_seq + 1:
            raise ValueError(f'skip_to({seq}): not beyond the newest record {self.last_seq}')
        self._skip_to(seq)
        self.acked = self.last_seq
        self.synced_seq = self.last_seq
        self.unacked_bytes = 0
        self.full = False

    def _skip_to(self, seq: int) -> None:
        write_json(self._path('acked.json'), {'epoch': self.epoch, 'acked': seq - 1}, durable=self.fsync)
        for seg in self._segments:
            seg.close()
            os.unlink(seg.path)
        self._segments, self._firsts = [], []
        self._new_segment(seq)
        self.last_seq = seq - 1
