"""
One streaming reader for recorded bags: rosbag2 (directory, ``.mcap`` or ``.db3``) and ROS 1.

:class:`BagReader` opens a bag with ``rosbags`` (no ROS install), lists its topics with
types and message counts, picks the topic an offline command needs
(:meth:`BagReader.select_topic`) and yields :class:`BagMessage` objects in receive-time
order across the selected topics, one message at a time: a bag is never loaded whole, so
memory stays bounded on multi-GB bags. Each message keeps both times: ``receive_ns``
(when the recorder got it, the bag's clock) and ``header_ns`` (the sensor's stamp, 0 when
the type has no header).

Bad input raises :class:`~accelcal_ros.errors.FileFormatError` (missing path, a directory
without ``metadata.yaml``, unreadable or corrupt data: the message says how many messages
were read and how far into the recording; a bag that ends before its index says is not
taken as complete) or :class:`~accelcal_ros.errors.InputError` (a topic that is missing,
of the wrong type or empty: the message lists the topics there are).
"""
from dataclasses import dataclass
import os
from pathlib import Path
import re
import sqlite3
import struct
from typing import Any, Dict, Iterator, List, Optional, Sequence, Tuple, Type

from accelcal_ros.errors import AccelcalError, FileFormatError, InputError
from accelcal_ros.filecheck import check_regular_file
from accelcal_ros.fileio import record_input
from accelcal_ros.recording.progress import Progress
from accelcal_ros.textformats import load_yaml_mapping

BAG_SUFFIXES = ('.bag', '.mcap', '.db3')
_STORAGE_SUFFIXES = ('.mcap', '.db3')
_DAMAGE_WORDS = ('index', 'magic', 'malformed', 'header could not', 'truncat', 'unexpected end',
                 'not a database')


def damage_errors() -> Tuple[Type[BaseException], ...]:
    """
    Return the exception types ``rosbags`` and its storage back ends raise on a bad bag.

    rosbags' own errors, and what its decoders (struct, lz4, bz2, zstd, sqlite3/apsw) and
    the message deserialiser raise on damaged or cut-short data: an invalid length
    (``ValueError``, ``OverflowError``), a missing index entry (``KeyError``,
    ``IndexError``), a failed internal check (``AssertionError``), bad text
    (``UnicodeDecodeError``), I/O errors, a damaged size field read as gigabytes
    (``MemoryError``), a value of the wrong type in the metadata (``TypeError``: text
    where rosbags adds numbers; :func:`_check_metadata` refuses the known fields first).
    """
    from rosbags.highlevel import AnyReaderError
    from rosbags.rosbag1 import ReaderError as Ros1ReaderError, WriterError as Ros1WriterError
    from rosbags.rosbag2 import ReaderError as Ros2ReaderError, WriterError as Ros2WriterError
    from rosbags.serde import SerdeError
    from rosbags.typesys import TypesysError

    errors: List[Type[BaseException]] = [
        AnyReaderError, Ros1ReaderError, Ros1WriterError, Ros2ReaderError, Ros2WriterError,
        SerdeError, TypesysError, OSError, EOFError, ValueError, ArithmeticError, LookupError,
        AssertionError, RuntimeError, MemoryError, TypeError, struct.error, sqlite3.Error]
    for module, name in (('apsw', 'Error'), ('backports.zstd', 'ZstdError'),
                         ('compression.zstd', 'ZstdError')):
        try:
            errors.append(getattr(__import__(module, fromlist=[name]), name))
        except (ImportError, AttributeError):
            pass
    return tuple(errors)


def normalize_type(msgtype: str) -> str:
    """Return ``pkg/Type`` for ``pkg/msg/Type`` (ROS 2) or ``pkg/Type`` (ROS 1)."""
    return msgtype.replace('/msg/', '/')


def normalize_topic(topic: str) -> str:
    """Return the topic with exactly one leading slash (bags store absolute names)."""
    return '/' + topic.strip().lstrip('/')


MAX_TOPIC_NAME_LENGTH = 247
"""Longest full topic name ROS 2 accepts (rmw: ``RMW_TOPIC_MAX_NAME_LENGTH``, 255 - 8)."""
_TOPIC_TOKEN = re.compile(r'[A-Za-z0-9_]+')


def topic_name_problem(name: str) -> Optional[str]:
    """
    Return why ``name`` is not a valid full (absolute) ROS 2 topic name, or None.

    The rules of rmw's ``validate_full_topic_name``: a leading ``/``, tokens of ASCII
    letters, digits and ``_`` separated by single slashes, no token starting with a
    digit, no trailing ``/``, at most :data:`MAX_TOPIC_NAME_LENGTH` characters.
    """
    if not name.startswith('/'):
        return 'it must start with /'
    if name.endswith('/'):
        return 'it must not end with /'
    tokens = name[1:].split('/')
    if not all(tokens):
        return 'it must not contain repeated /'
    if not all(_TOPIC_TOKEN.fullmatch(token) for token in tokens):
        return 'only letters, digits, _ and / are allowed'
    if any(token[0].isdigit() for token in tokens):
        return 'a name token must not start with a digit'
    if len(name) > MAX_TOPIC_NAME_LENGTH:
        return f'it has {len(name)} characters, more than {MAX_TOPIC_NAME_LENGTH}'
    return None


def full_topic_name(text: str, option: str) -> str:
    """
    Return the topic name an option gives, with a leading ``/`` added; InputError if invalid.

    Bags store absolute names, so ``imu/corrected`` is ``/imu/corrected``; an empty name
    or one ROS 2 refuses (:func:`topic_name_problem`) is one line naming ``option``.
    """
    if not text:
        raise InputError(f'{option} is empty: give a topic name (e.g. /imu/corrected)')
    name = text if text.startswith('/') else '/' + text
    problem = topic_name_problem(name)
    if problem:
        raise InputError(f'{option} {text!r} is not a valid ROS topic name: {problem}')
    return name


def is_bag(path: 'os.PathLike[str] | str') -> bool:
    """Return True when ``path`` looks like a bag (by suffix or rosbag2 directory content)."""
    p = Path(path)
    if p.is_dir():
        return (p / 'metadata.yaml').exists() or any(
            c.suffix in _STORAGE_SUFFIXES for c in p.iterdir())
    return p.suffix.lower() in BAG_SUFFIXES


@dataclass
class TopicSummary:
    """One topic of a bag: normalised type (``pkg/Type``) and message count."""

    name: str
    msgtype: str
    count: int


@dataclass
class BagMessage:
    """A deserialised message with its topic, type and both times (ns)."""

    topic: str
    msgtype: str
    receive_ns: int
    msg: Any  # a rosbags message object (None when not decoded)
    raw: bytes = b''

    @property
    def header_ns(self) -> int:
        """Return the header stamp in ns (0 when the message has no header)."""
        header = getattr(self.msg, 'header', None)
        if header is None:
            return 0
        return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def _storage_path(path: Path) -> Tuple[Path, List[str]]:
    """Return the path to open and notes; a directory without metadata.yaml is handled."""
    if not path.exists():
        raise FileFormatError(path, 'no such bag (file or rosbag2 directory)')
    if not path.is_dir():
        if path.suffix.lower() not in BAG_SUFFIXES:
            raise FileFormatError(path, f'not a bag: expected a rosbag2 directory or a file '
                                  f'ending in {", ".join(BAG_SUFFIXES)}')
        check_regular_file(path, 'bag file')
        return path, []
    _check_bag_directory(path)
    if (path / 'metadata.yaml').exists():
        return path, []
    files = sorted(c for c in path.iterdir() if c.suffix in _STORAGE_SUFFIXES)
    if not files:
        raise FileFormatError(path, 'bag directory without metadata.yaml and without '
                              '.mcap/.db3 files: not a rosbag2 recording')
    if len(files) > 1:
        raise FileFormatError(path, 'bag directory without metadata.yaml holds several '
                              f'storage files ({", ".join(f.name for f in files)}): restore '
                              'metadata.yaml (ros2 bag reindex) or pass one file')
    return files[0], [f'{path}: no metadata.yaml; reading {files[0].name} alone']


def _check_bag_directory(path: Path) -> None:
    """Refuse a bag directory whose metadata or storage files are not regular files."""
    try:
        entries = [c for c in path.iterdir()
                   if c.name == 'metadata.yaml' or c.suffix.lower() in _STORAGE_SUFFIXES
                   or c.name.endswith(('.mcap.zstd', '.db3.zstd'))]
    except OSError as exc:
        raise FileFormatError(path, f'cannot list the bag directory: {exc.strerror}') from None
    for entry in entries:
        check_regular_file(entry, 'file of the bag')
        if entry.name == 'metadata.yaml':
            _check_metadata(entry)


#: metadata.yaml keys whose values rosbags computes with: integers (ns, counts, version)
_METADATA_INTEGERS = ('nanoseconds', 'nanoseconds_since_epoch', 'message_count', 'version')


def _check_metadata(path: Path) -> None:
    """
    Check a rosbag2 ``metadata.yaml`` before rosbags reads it (FileFormatError naming it).

    A YAML mapping (at most ``SIZE_LIMITS['yaml']`` bytes) under
    ``rosbag2_bagfile_information`` whose times, counts and version are integers
    (:data:`_METADATA_INTEGERS`: ``1.5`` or text in a nanoseconds field is refused, not
    rounded or raised from inside rosbags) and whose file names are text.
    """
    data = load_yaml_mapping(path, 'bag metadata file')
    info = data.get('rosbag2_bagfile_information')
    if not isinstance(info, dict):
        raise FileFormatError(path, 'not a rosbag2 metadata file (no '
                              'rosbag2_bagfile_information mapping); restore it with `ros2 bag '
                              'reindex`')
    stack: List[Tuple[str, Any]] = [('rosbag2_bagfile_information', info)]
    while stack:
        where, item = stack.pop()
        if isinstance(item, dict):
            for key, value in item.items():
                if key in _METADATA_INTEGERS and (isinstance(value, bool)
                                                  or not isinstance(value, int)):
                    raise FileFormatError(path, f'{where}.{key} must be an integer, got '
                                          f'{value!r} (damaged metadata: `ros2 bag reindex` '
                                          'rewrites it)')
                stack.append((f'{where}.{key}', value))
        elif isinstance(item, list):
            stack.extend((f'{where}[{k}]', v) for k, v in enumerate(item))
    paths = info.get('relative_file_paths', [])
    if not isinstance(paths, list) or not all(isinstance(p, str) for p in paths):
        raise FileFormatError(path, f'relative_file_paths must be a list of file names, got '
                              f'{paths!r}')


def _reason(exc: BaseException) -> str:
    text = ' '.join(str(a) for a in exc.args) or type(exc).__name__
    return text.strip().splitlines()[0] if text.strip() else type(exc).__name__


def _mcap_extent(path: Path) -> str:
    """Return '; <how far the MCAP file can be read>' for a cut-short file ('' if unknown)."""
    from accelcal_ros.recording.mcap_scan import scan_mcap_file

    files = sorted(path.glob('*.mcap')) if path.is_dir() else [path]
    texts = []
    for name in files:
        try:
            extent = scan_mcap_file(str(name))
        except (OSError, ValueError, struct.error):
            continue
        if not extent.complete:
            texts.append(f'; {name.name} is cut short: {extent.text()}')
    return ''.join(texts)


class BagReader:
    """Read a bag lazily; use as a context manager (``with BagReader(path) as bag:``)."""

    def __init__(self, path: 'os.PathLike[str] | str', stamp: str = 'header') -> None:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import get_typestore, Stores

        if stamp not in ('header', 'receive'):
            raise InputError(f"stamp must be 'header' or 'receive', not {stamp!r}")
        self.path = Path(path)
        self.stamp = stamp
        storage, self.notes = _storage_path(self.path)
        record_input(self.path)
        ros1 = storage.suffix.lower() == '.bag'
        store = Stores.ROS1_NOETIC if ros1 else Stores.ROS2_JAZZY
        self.format = 'ros1' if ros1 else ('mcap' if self._is_mcap(storage) else 'sqlite3')
        try:
            self._reader = AnyReader([storage], default_typestore=get_typestore(store))
            self._reader.open()
        except damage_errors() as exc:
            hint = ''
            if any(w in _reason(exc).lower() for w in _DAMAGE_WORDS):
                hint = (' (damaged or cut short, e.g. the recorder was killed: `rosbag '
                        'reindex` / `ros2 bag reindex` / `mcap recover` repair it)')
            if self.format == 'mcap':
                hint = _mcap_extent(storage) + hint
            reason = _reason(exc).rstrip('.')
            raise FileFormatError(self.path, f'cannot open bag: {reason}{hint}') from None
        self._open = True

    @staticmethod
    def _is_mcap(storage: Path) -> bool:
        if storage.is_dir():
            return any(storage.glob('*.mcap'))
        return storage.suffix.lower() == '.mcap'

    def __enter__(self) -> 'BagReader':
        """Return the open reader."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Close the bag (exceptions propagate)."""
        self.close()

    def close(self) -> None:
        """Close the bag (idempotent)."""
        if self._open:
            self._open = False
            try:
                self._reader.close()
            except damage_errors():  # closing a damaged bag must not hide the first error
                pass

    @property
    def is_ros1(self) -> bool:
        """Return True for a ROS 1 bag (messages in ROS 1 serialisation)."""
        return not self._reader.is2

    def topics(self) -> Dict[str, TopicSummary]:
        """Return ``{topic: TopicSummary}`` of every topic in the bag."""
        found: Dict[str, TopicSummary] = {}
        for conn in self._reader.connections:
            item = found.get(conn.topic)
            if item is None:
                found[conn.topic] = TopicSummary(conn.topic, normalize_type(conn.msgtype),
                                                 int(conn.msgcount))
            else:
                item.count += int(conn.msgcount)
        return found

    def connection_of(self, topic: str) -> Any:
        """Return the rosbags Connection of a topic (type, definition, digest, QoS)."""
        for conn in self._reader.connections:
            if conn.topic == topic:
                return conn
        raise InputError(f'{self.path} has no topic {topic}; it has: {self.listing()}')

    def listing(self, only_types: Sequence[str] = ()) -> str:
        """Return ``topic (type, N messages)`` of every topic, or of those of some types."""
        items = [t for t in self.topics().values() if not only_types or t.msgtype in only_types]
        if not items:
            return 'no topics'
        return ', '.join(f'{t.name} ({t.msgtype}, {t.count} messages)'
                         for t in sorted(items, key=lambda t: t.name))

    def select_topic(self, requested: Optional[str], types: Sequence[str],
                     option: str = '--topic') -> str:
        """
        Return the bag topic to read for a command that needs one of ``types``.

        ``requested`` (with or without the leading slash) must exist, have one of the
        types and hold messages; when None, the only topic of those types is used, else
        the error lists the candidates with types and message counts.
        """
        topics = self.topics()
        wanted = ' or '.join(types)
        topic: Optional[TopicSummary]
        if requested is None:
            candidates = [t for t in topics.values() if t.msgtype in types]
            if len(candidates) == 1:
                topic = candidates[0]
            elif not candidates:
                raise InputError(f'{self.path} has no {wanted} topic; it has: '
                                 f'{self.listing()}')
            else:
                raise InputError(f'{self.path} has several {wanted} topics: '
                                 f'{self.listing(types)}; choose one with {option}')
        else:
            name = normalize_topic(requested)
            topic = topics.get(name) or topics.get(name.lstrip('/'))
            if topic is None:
                raise InputError(f'{self.path} has no topic {requested}; it has: '
                                 f'{self.listing()}')
            if topic.msgtype not in types:
                others = self.listing(types) if any(
                    t.msgtype in types for t in topics.values()) else 'none'
                raise InputError(f'topic {topic.name} of {self.path} is {topic.msgtype}, not '
                                 f'{wanted} (topics of that type: {others})')
        if topic.count == 0:
            raise InputError(f'topic {topic.name} of {self.path} is empty (0 messages)')
        return topic.name

    def deserialize(self, raw: bytes, msgtype: str) -> Any:
        """Deserialise one message of this bag (``pkg/Type`` or ``pkg/msg/Type``)."""
        parts = msgtype.split('/')
        full = msgtype if len(parts) == 3 else f'{parts[0]}/msg/{parts[-1]}'
        try:
            return self._reader.deserialize(raw, full)
        except damage_errors() as exc:
            raise FileFormatError(self.path, f'cannot decode a {msgtype}: {_reason(exc)}') \
                from None

    def messages(self, topics: Sequence[str], label: Optional[str] = None,
                 decode: Optional[Sequence[str]] = None) -> Iterator[BagMessage]:
        """
        Yield the messages of ``topics`` in receive-time order, deserialised one by one.

        ``decode`` limits deserialisation to some topics (the others' ``msg`` is None;
        ``raw`` always holds the serialised bytes).

        A read or decode failure, or fewer messages than the bag's index lists, raises
        FileFormatError saying how many messages were read and up to which time.
        """
        conns = [c for c in self._reader.connections if c.topic in set(topics)]
        total = sum(int(c.msgcount) for c in conns)
        progress = Progress(total, label or f'reading {self.path.name}')
        read, first_ns, last_ns = 0, None, None
        try:
            for conn, receive_ns, raw in self._reader.messages(connections=conns):
                msg = (self._reader.deserialize(raw, conn.msgtype)
                       if decode is None or conn.topic in decode else None)
                read += 1
                first_ns = receive_ns if first_ns is None else first_ns
                last_ns = receive_ns
                progress.update()
                yield BagMessage(conn.topic, normalize_type(conn.msgtype), receive_ns, msg, raw)
        except AccelcalError:
            raise
        except damage_errors() as exc:
            raise FileFormatError(self.path, self._damage(read, total, first_ns, last_ns,
                                                          _reason(exc))) from None
        finally:
            progress.close()
        if total and read < total:
            raise FileFormatError(self.path, self._damage(
                read, total, first_ns, last_ns, 'the bag ends before the messages its index '
                'lists'))

    @staticmethod
    def _damage(read: int, total: int, first_ns: Optional[int], last_ns: Optional[int],
                reason: str) -> str:
        span = ('' if first_ns is None or last_ns is None
                else f', {(last_ns - first_ns) / 1e9:.3f} s into the data')
        of = f' of {total}' if total else ''
        return (f'corrupt or truncated: read {read}{of} messages{span} before: {reason}; '
                'nothing is computed from a partial bag (repair it with `ros2 bag reindex` / '
                '`rosbag reindex`, or cut it before the damage)')
