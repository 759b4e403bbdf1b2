"""ROS 2 bags through rosbags (no rosbag2_py, no ros2 CLI): open, list, stream, write.

Messages are serialised with rclpy (CDR, the bytes a live publisher sends), so raw bag records
go straight into ``rclpy.serialization.deserialize_message`` or ``Publisher.publish``. Bags are
written with metadata version 8, which the rosbag2 of Jazzy and later reads, optionally
zstd-compressed the way rosbag2 does it: MCAP chunks (storage compression, what rosbag2's
`zstd_fast`/`zstd_small` storage presets write) and per-message compression for sqlite3.
"""
from __future__ import annotations

import re
import shutil
import sqlite3
from pathlib import Path

from rclpy.serialization import serialize_message
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
from rosbags.typesys import Stores, get_typestore

from ..ros.dds import ros_distro
from .cli import raise_ctrl_c

STORAGES = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}
COMPRESSIONS = ("none", "zstd")
# zstd in the form each storage's rosbag2 plugin reads natively.
_ZSTD_MODE = {"mcap": CompressionMode.STORAGE, "sqlite3": CompressionMode.MESSAGE}
BAG_VERSION = 8


class BagError(RuntimeError):
    """A bag that cannot be used as asked; the message says why and what the bag holds."""


# Errors whose text is empty, said in words.
_SILENT_ERRORS = {"EndOfFile": "truncated: the file ends in the middle of a record"}


def error_text(exc: BaseException) -> str:
    """'Type: text' of a reading error, or what it means when its text is empty (mcap's
    EndOfFile has none: a note ended in '(EndOfFile: )')."""
    name, text = type(exc).__name__, str(exc).strip()
    return f"{name}: {text}" if text else _SILENT_ERRORS.get(name, name)


def typestore():
    """The rosbags type store of the ROS distribution in use (message definitions and hashes)."""
    return get_typestore(Stores.ROS2_JAZZY if ros_distro() == "jazzy" else Stores.ROS2_KILTED)


def type_name(msg_class) -> str:
    """'sensor_msgs/msg/Image' for rclpy's sensor_msgs.msg.Image."""
    module = msg_class.__module__.split(".")
    return f"{module[0]}/msg/{msg_class.__name__}"


class BagWriter:
    """Write rclpy messages to a new bag; topics are added on first use.

    ``compression="zstd"`` compresses MCAP chunks or, for sqlite3, every message. A failed write
    (disk full, read-only) raises OSError; sqlite3's own errors are turned into OSError too.
    Leaving the ``with`` block through an exception closes the bag as far as it can without
    raising a second exception over the first."""

    def __init__(self, path, storage: str = "mcap", compression: str = "none"):
        if storage not in STORAGES:
            raise BagError(f"unknown storage {storage!r}; use one of {sorted(STORAGES)}")
        if compression not in COMPRESSIONS:
            raise BagError(f"unknown compression {compression!r}; use one of {list(COMPRESSIONS)}")
        path = Path(path)
        if path.exists():
            raise BagError(f"{path} exists; rosbag2 bags are directories that must not exist yet")
        self._writer = Writer(path, version=BAG_VERSION, storage_plugin=STORAGES[storage])
        if compression == "zstd":
            self._writer.set_compression(_ZSTD_MODE[storage], CompressionFormat.ZSTD)
        self._ts = typestore()
        self._conns = {}
        self._open = False
        self.path = path

    def __enter__(self):
        with _os_errors(self.path):
            self._writer.open()
        self._open = True
        return self

    def __exit__(self, exc_type, exc, tb):
        if not self._open:
            return
        self._open = False
        if exc_type is None:
            with _os_errors(self.path):
                self._writer.close()
        else:
            try:
                self._writer.close()
            except Exception:  # noqa: BLE001 - the exception in flight is the one to report
                pass

    def write(self, topic: str, msg, stamp_ns: int) -> None:
        self.write_raw(topic, type_name(type(msg)), serialize_message(msg), stamp_ns)

    def write_raw(self, topic: str, msgtype: str, data: bytes, stamp_ns: int) -> None:
        with _os_errors(self.path):
            conn = self._conns.get(topic)
            if conn is None:
                conn = self._conns[topic] = self._writer.add_connection(
                    topic, msgtype, typestore=self._ts)
            self._writer.write(conn, int(stamp_ns), data)


class _os_errors:
    """sqlite3 reports a full disk or a read-only file as its own error: make it an OSError."""

    def __init__(self, path):
        self.path = path

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is not None and issubclass(exc_type, sqlite3.Error):
            raise OSError(f"{self.path}: {exc}") from exc
        return False


def _metadata_fault(bag: Path, exc: BaseException) -> str:
    """What is wrong with a bag's metadata.yaml that rosbags refused with ``exc``, in one line:
    the YAML error and its line, else rosbags' own word."""
    import yaml

    try:
        meta = yaml.safe_load((bag / "metadata.yaml").read_text(encoding="utf-8"))
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        at = f" at line {mark.line + 1}" if mark is not None else ""
        return f"not valid YAML{at}: {getattr(err, 'problem', None) or err}"
    except (OSError, UnicodeDecodeError) as err:
        return getattr(err, "strerror", None) or error_text(err)
    if not isinstance(meta, dict) or "rosbag2_bagfile_information" not in meta:
        return "no rosbag2_bagfile_information in it"
    return " ".join(error_text(exc).split())


class BagSource:
    """Stream the messages of a bag, surviving damage where the storage allows it.

    A bag rosbags can open is read through rosbags. MCAP that rosbags cannot open is read
    sequentially with the mcap library, in file order: a bare ``.mcap`` file (Foxglove, a
    converter), a bag directory whose recorder died before writing metadata.yaml, or a
    truncated file (no summary at its end), up to the damage; ``damaged`` then says what
    happened. When rosbags fails but the .mcap files read to their end, metadata.yaml is what
    is broken, not the messages: ``metadata_problem`` says so (the caller tells the user), and
    ``damaged`` stays empty. A damaged sqlite3 bag cannot be salvaged: BagError.
    """

    def __init__(self, path):
        self.path = Path(path)
        self.damaged = ""
        self.metadata_problem = ""
        self._reader = None
        if not self.path.exists():
            raise BagError(f"bag not found: {self.path}")
        if self.path.is_file():
            if self.path.suffix != ".mcap":
                raise BagError(f"{self.path} is a file; give the bag directory (the one holding "
                               "metadata.yaml) or an .mcap file")
            self._read_mcap([self.path], "")
            return
        if not (self.path / "metadata.yaml").is_file():
            mcaps = sorted(self.path.glob("*.mcap"))
            if not mcaps:
                raise BagError(f"{self.path} is not a ROS 2 bag directory (no metadata.yaml, "
                               "no .mcap file)")
            self._read_mcap(mcaps, "")
            return
        try:
            reader = Reader(self.path)
            reader.open()
            self._reader = reader
            self.topics = {c.topic: c.msgtype for c in reader.connections}
            self.counts = {}
            for c in reader.connections:
                self.counts[c.topic] = self.counts.get(c.topic, 0) + c.msgcount
        except Exception as exc:  # rosbags raises several types for damaged metadata or storage
            raise_ctrl_c(exc)
            why = " ".join(f"{type(exc).__name__}: {exc}".split())
            mcaps = sorted(self.path.glob("*.mcap"))
            if not mcaps:
                raise BagError(f"cannot open bag {self.path}: {why}") from exc
            self._read_mcap(mcaps, why, exc)
            if not self.damaged:  # the storage reads to its end: metadata.yaml is at fault
                self.metadata_problem = (
                    f"{self.path}/metadata.yaml is unreadable ({_metadata_fault(self.path, exc)})"
                    f": its .mcap files were read without it; `ros2 bag reindex -s mcap "
                    f"{self.path}` rewrites it")

    def _read_mcap(self, files, why_not_rosbags: str = "", cause=None) -> None:
        """Read ``files`` with the mcap library; ``why_not_rosbags``: why rosbags could not
        ('' when rosbags was not asked)."""
        self._mcap = files
        self.topics, self.counts = self._scan_mcap()
        if not self.topics:
            why = self.damaged or why_not_rosbags
            why = f" ({why})" if why else ""
            raise BagError(f"cannot open bag {self.path}{why} and no message is "
                           "readable") from cause

    def _records(self):
        """(topic, type, log time, raw) of every readable MCAP message, in file order."""
        from mcap.records import Channel, Message, Schema
        from mcap.stream_reader import StreamReader

        for file in self._mcap:
            schemas, channels, n = {}, {}, 0
            try:
                fh = open(file, "rb")
            except OSError as exc:
                self.damaged = f"{file.name} unreadable ({exc.strerror or error_text(exc)})"
                return
            with fh:
                try:
                    for rec in StreamReader(fh).records:
                        if isinstance(rec, Schema):
                            schemas[rec.id] = rec.name
                        elif isinstance(rec, Channel):
                            channels[rec.id] = (rec.topic, schemas.get(rec.schema_id, ""))
                        elif isinstance(rec, Message) and rec.channel_id in channels:
                            topic, msgtype = channels[rec.channel_id]
                            n += 1
                            yield topic, msgtype, rec.log_time, rec.data
                except Exception as exc:  # the damage: stop here, say where
                    raise_ctrl_c(exc)
                    pos, size = fh.tell(), file.stat().st_size
                    at = f"its end, byte {size}" if pos >= size else f"byte {pos} of {size}"
                    self.damaged = (f"{file.name} unreadable after its {n} messages, at {at} "
                                    f"({error_text(exc)})")
                    return

    def _scan_mcap(self):
        topics, counts = {}, {}
        for topic, msgtype, _, _ in self._records():
            topics[topic] = msgtype
            counts[topic] = counts.get(topic, 0) + 1
        return topics, counts

    def messages(self, topics):
        """Yield (topic, timestamp ns, raw CDR bytes) of the given topics in time order."""
        wanted = set(topics)
        if self._reader is not None:
            conns = [c for c in self._reader.connections if c.topic in wanted]
            for conn, ts, raw in self._reader.messages(connections=conns):
                yield conn.topic, ts, raw
        else:
            for topic, _, ts, raw in self._records():
                if topic in wanted:
                    yield topic, ts, raw

    def describe(self) -> str:
        return ", ".join(f"{t} ({ty}, {self.counts.get(t, 0)} msgs)"
                         for t, ty in sorted(self.topics.items())) or "no topics"

    def close(self) -> None:
        if self._reader is not None:
            self._reader.close()


# What a bag directory holds: metadata.yaml and its storage's files.
_BAG_FILE = re.compile(r"\.(mcap|db3)(-journal|-wal|-shm)?$")


def not_a_bag_of(out_bag: Path, prefix: str) -> str:
    """Why ``out_bag`` is not a bag a tool of ours wrote, whose topics all start with ``prefix``
    ('' when it is, or is absent, or is a symbolic link, whose removal loses nothing): a tool
    replaces its own outputs, never the user's files (a thesis in o/fcop_output was deleted)."""
    if out_bag.is_symlink() or not out_bag.exists():
        return ""
    if not out_bag.is_dir():
        return "a file"
    try:
        others = sorted(p.name for p in out_bag.iterdir() if not (
            p.is_file() and (p.name == "metadata.yaml" or _BAG_FILE.search(p.name))))
    except OSError as exc:
        return f"unreadable: {exc.strerror or exc}"
    if others:
        more = f" and {len(others) - 3} more" if len(others) > 3 else ""
        return f"it holds {', '.join(others[:3])}{more}"
    try:  # a bag recorded elsewhere has topics outside the tool's
        import yaml

        meta = yaml.safe_load((out_bag / "metadata.yaml").read_text(encoding="utf-8"))
        topics = [t["topic_metadata"]["name"] for t in
                  meta["rosbag2_bagfile_information"]["topics_with_message_count"]]
    except Exception:  # noqa: BLE001 - no metadata (a run cut short): judged by its files
        return ""
    foreign = [t for t in topics if not str(t).startswith(prefix)]
    return f"it records {foreign[0]}" if foreign else ""


def remove_bag(path: Path) -> None:
    """Remove a previous bag at ``path`` (checked with :func:`not_a_bag_of` first): a bag
    directory, or a file or symbolic link in its place."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif path.exists() or path.is_symlink():
        path.unlink()
