"""gyro_sim logs: MCAP files of the ROS 2 profile (CDR messages, ``ros2msg`` schemas).

One writer serves the node's live recorder and ``gyro-sim run --record``::

    with LogWriter("run.mcap", scene=scene, params={"integrator": "dop853", ...}) as w:
        ch = w.add_channel("/joint_states", "sensor_msgs/msg/JointState")
        w.write(ch, log_time_ns, {"header": {...}, "name": [...], ...})   # encoded here (CDR)
        w.write_raw(ch, log_time_ns, cdr_bytes)                         # bytes from the wire
        w.event(log_time_ns, "reset")                                   # on /gyro_sim/events

What a file holds (docs/logs.md):

- header profile ``ros2``; one channel per topic, message encoding ``cdr``, schema encoding
  ``ros2msg`` whose data is the type's full concatenated definition (:mod:`.msgdefs`), and the
  channel metadata ``offered_qos_profiles`` that rosbag2 writes: the QoS the node's publisher
  of that topic offers (gyro_sim.msgs.messages.topic_qos);
- the scene, as YAML, in the attachment ``scene.yaml`` (media type ``application/yaml``), and
  the run parameters as JSON in the metadata record ``gyro_sim`` (key ``params``), both at the
  start of the file so that a log cut short still replays on its own;
- the chain's URDF on /robot_description (one std_msgs/String at log time 0, :mod:`.urdf`):
  with /tf it lets viewers draw the moving chain from the .mcap alone (``rerun log.mcap``);
- messages in zstd-compressed chunks (lz4, then none, when zstd is not available), with the
  message indexes, chunk indexes, statistics and summary written on close.

Crash safety: the chunk in progress is finished and handed to the operating system at least
every `flush_period` seconds of wall time (``DEFAULT_FLUSH_PERIOD``, 0.2 s; checked on every
write and by a background timer), so after SIGKILL everything written before the last flush is in the file and
:func:`gyro_sim.log.recover.recover` gets it back. The file is not fsync'ed: a crash of the
process loses nothing flushed, a crash of the machine may.

No silent overwrite: the file is created with mode ``"xb"`` (an existing file is refused with
:class:`~.safe_paths.OutputError`) unless ``overwrite=True``, or the caller hands over a file
it has opened itself (``file=``: the node's recorder creates its file before the writer starts).

A write that fails (``OSError``: no space left, a file-size limit...) is raised by the call that
made it, the background flush's included: the timer keeps the error (`failure`) and the next
call raises it. Nothing more is written after it; `close` then finishes what it can and closes
the file without raising again, so the part flushed before stays readable by
:func:`gyro_sim.log.recover.recover`.

Reading verifies (:func:`verify`): :class:`LogReader` (and :func:`read_info`) checks the
summary's CRC and every chunk's CRC (and that it decompresses) on opening, and its `messages`
(and :func:`iter_messages`) read with the chunk CRCs checked; a damaged log is refused with a
:class:`LogError` naming the chunk's byte offset and ``gyro-sim recover``.

The writer is thread-safe (one lock around the MCAP writer).
"""
from __future__ import annotations

import array
import contextlib
import json
import math
import os
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO, Iterator, Mapping

from gyro_sim.errors import GyroSimError
from gyro_sim.safe_paths import raise_interrupt_behind
from gyro_sim.msgs import messages as M
from gyro_sim.msgs import msgdefs

__all__ = ["LogError", "LogWriter", "LogReader", "LogInfo", "read_info", "iter_messages", "EVENTS_TOPIC",
           "FORMAT_VERSION"]

#: version of the layout described above (metadata key ``format``)
FORMAT_VERSION = 1
#: name of the metadata record with the run parameters
METADATA_NAME = "gyro_sim"
#: name of the attachment with the scene file
SCENE_ATTACHMENT = "scene.yaml"
#: topic of event markers (std_msgs/msg/String)
EVENTS_TOPIC = "/gyro_sim/events"
#: topic of the chain's URDF (std_msgs/msg/String, one message at log time 0; see .urdf)
ROBOT_DESCRIPTION_TOPIC = "/robot_description"
#: largest uncompressed chunk before it is written out regardless of the flush period
CHUNK_SIZE = 1 << 20
#: shortest sleep of the background flush timer (s)
MIN_TIMER_WAIT = 0.005
#: default wall-clock seconds between flushes: what SIGKILL can lose (measured cost: README)
#: 0.2 s: a SIGKILL loses at most the promised 0.25 s of simulated time at real time (the last
#: flush, plus up to a publication period and the recorder's queue: `gyro-sim bench soak`)
DEFAULT_FLUSH_PERIOD = 0.2


class LogError(GyroSimError, RuntimeError):
    """A log cannot be written or read as asked (closed writer, unknown type, bad value...)."""


def compression():
    """The chunk compression every gyro_sim log is written with: zstd, else lz4, else none
    (by the compression library installed)."""
    from mcap.writer import CompressionType

    try:
        import zstandard  # noqa: F401

        return CompressionType.ZSTD
    except ImportError:
        pass
    try:
        import lz4.frame  # noqa: F401

        return CompressionType.LZ4
    except ImportError:
        return CompressionType.NONE


def _plain(x: Any) -> Any:
    """`x` with numpy scalars and arrays turned into Python numbers and lists (for YAML/JSON)."""
    if isinstance(x, Mapping):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if hasattr(x, "tolist"):  # numpy arrays and scalars
        return _plain(x.tolist())
    return x


def scene_yaml(scene) -> str:
    """The scene's source mapping as YAML that loads back to the same numbers (repr floats)."""
    import yaml

    return yaml.safe_dump(_plain(scene.source), sort_keys=False, default_flow_style=None)


def _check_finite(obj: Any, path: str = "") -> None:
    if isinstance(obj, float):
        if not math.isfinite(obj):
            raise LogError(f"non-finite value {obj!r} at {path or 'message'}: refused (NaN never reaches a log)")
    elif isinstance(obj, Mapping):
        for k, v in obj.items():
            _check_finite(v, f"{path}.{k}" if path else str(k))
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            _check_finite(v, f"{path}[{i}]")
    elif isinstance(obj, array.array) or hasattr(obj, "dtype"):  # rclpy float arrays, numpy
        for i, v in enumerate(obj.tolist() if hasattr(obj, "tolist") else obj):
            _check_finite(v, f"{path}[{i}]")
    elif hasattr(obj, "__slots__") and not isinstance(obj, (str, bytes)):
        for k in obj.__slots__:
            _check_finite(getattr(obj, k, None), f"{path}.{k}" if path else k)


class _PackedChunkIndexes:
    """The summary's chunk indexes, held as packed integers between flushes.

    mcap's Writer keeps one ChunkIndex object per chunk until `finish` writes the summary:
    about 1.3 kB each, so at the default flush period (a chunk every 0.2 s) a recording would
    grow by about 23 MB per hour. Packed here after every flush (8 int64 per chunk, and per
    channel in it the id and the offset from the chunk's start as uint32: about 150 B for a
    dozen channels) and turned back into ChunkIndex objects just before `finish`.
    """

    HEAD = 8  # start, end, chunk offset, chunk length, index length, compressed, uncompressed, n

    def __init__(self) -> None:
        self.heads = array.array("q")
        self.items = array.array("I")
        self.compression = ""

    @staticmethod
    def _list(writer) -> list | None:
        return getattr(writer, "_Writer__chunk_indices", None)  # mcap internals; None: left alone

    def pack(self, writer) -> None:
        lst = self._list(writer)
        if not lst:
            return
        for ci in lst:
            base = ci.chunk_start_offset
            if any(not 0 <= off - base < 2**32 or not 0 <= cid < 2**32
                   for cid, off in ci.message_index_offsets.items()):
                return  # not representable (never for gyro_sim's chunks): keep the objects
        for ci in lst:
            base = ci.chunk_start_offset
            self.heads.extend((ci.message_start_time, ci.message_end_time, base, ci.chunk_length,
                               ci.message_index_length, ci.compressed_size, ci.uncompressed_size,
                               len(ci.message_index_offsets)))
            for cid, off in ci.message_index_offsets.items():
                self.items.extend((cid, off - base))
            self.compression = ci.compression
        lst.clear()

    def unpack(self, writer) -> None:
        lst = self._list(writer)
        if lst is None or not self.heads:
            return
        from mcap.records import ChunkIndex

        restored, j = [], 0
        for i in range(0, len(self.heads), self.HEAD):
            start, end, base, length, index_length, compressed, uncompressed, n = self.heads[i:i + self.HEAD]
            offsets = {self.items[j + 2 * k]: base + self.items[j + 2 * k + 1] for k in range(n)}
            j += 2 * n
            restored.append(ChunkIndex(chunk_length=length, chunk_start_offset=base, compression=self.compression,
                                       compressed_size=compressed, message_end_time=end,
                                       message_index_length=index_length, message_index_offsets=offsets,
                                       message_start_time=start, uncompressed_size=uncompressed))
        lst[:0] = restored
        self.heads, self.items = array.array("q"), array.array("I")


class LogWriter(contextlib.AbstractContextManager):
    """Write a gyro_sim log (module docstring). A context manager; `close` is idempotent.

    Parameters
    ----------
    path : file to create (refused if it exists, unless `overwrite`).
    scene : the gyro_sim Scene; its ``source`` mapping is embedded as ``scene.yaml``.
    params : run parameters (JSON-serialisable), embedded as metadata ``gyro_sim``/``params``.
    flush_period : wall-clock seconds between flushes of the data to the file (> 0).
    robot_description : also write the scene's URDF on /robot_description at log time 0.
    overwrite : replace an existing file (default: refuse it, OutputError).
    file : an open binary file to write to instead of creating `path` (which then only names it
        in messages); the writer owns it from then on and closes it.
    topics : the topic names of the node whose log this is (its robot description and events;
        default: the root namespace's /robot_description and /gyro_sim/events).

    Attribute `failure`: the first OSError of a write or flush (None while all went well).
    """

    def __init__(self, path: str | os.PathLike, *, scene, params: dict,
                 flush_period: float = DEFAULT_FLUSH_PERIOD, robot_description: bool = True,
                 overwrite: bool = False, file: BinaryIO | None = None, topics: "M.TopicNames" = M.ROOT_TOPICS):
        from mcap.writer import Writer

        if not (flush_period > 0 and math.isfinite(flush_period)):
            raise LogError(f"flush_period must be a positive number of seconds, got {flush_period!r}")
        self.path = Path(path)
        self.topic_names = topics
        self.flush_period = float(flush_period)
        try:
            params_json = json.dumps(_plain(params), allow_nan=False)
        except (TypeError, ValueError) as exc:
            raise LogError(f"params must be JSON-serialisable and finite: {exc}") from exc
        from gyro_sim import __version__

        if file is not None:
            self._file = file
        else:
            try:
                self._file = open(self.path, "wb" if overwrite else "xb")
            except FileExistsError:
                from gyro_sim.safe_paths import OutputError

                raise OutputError(f"log {self.path}: exists; refused to overwrite it "
                                  "(overwrite=True to replace)") from None
        self.failure: OSError | None = None
        self._chunk_indexes = _PackedChunkIndexes()
        self._writer = Writer(self._file, chunk_size=CHUNK_SIZE, compression=compression())
        self._writer.start(profile="ros2", library=f"gyro_sim/{__version__}")
        self._writer.add_metadata(
            METADATA_NAME,
            {"format": str(FORMAT_VERSION), "params": params_json, "scene_name": str(scene.name),
             "scene_path": str(scene.path or ""), "gyro_sim_version": __version__},
        )
        created = time.time_ns()
        self._writer.add_attachment(created, 0, SCENE_ATTACHMENT, "application/yaml", scene_yaml(scene).encode())
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, tuple[int, str]] = {}  # topic -> (id, msgtype)
        self._encoders: dict[int, Any] = {}  # channel id -> encoder
        self._decoders: dict[int, Any] = {}  # channel id -> decoder (canonical raw writes)
        self._sequence: dict[int, int] = {}
        self._lock = threading.RLock()
        self._closed = False
        self._dirty = False
        self.message_count = 0
        self._file.flush()
        self._last_flush = time.monotonic()
        self._stop = threading.Event()
        self._timer = threading.Thread(target=self._flush_loop, name="gyro_sim-log-flush", daemon=True)
        self._timer.start()
        if robot_description:
            from gyro_sim.scene.urdf import urdf

            ch = self.add_channel(topics.robot_description, "std_msgs/msg/String")
            self.write(ch, 0, {"data": urdf(scene)}, check_finite=False)

    # --- channels ------------------------------------------------------------------------------
    def add_channel(self, topic: str, msgtype: str, *, metadata: Mapping[str, str] | None = None) -> int:
        """Channel id of `topic` (created on first call; the same id after). `msgtype`: pkg/msg/Type."""
        try:
            msgtype = msgdefs.normalize(msgtype)
        except ValueError as exc:
            raise LogError(str(exc)) from exc
        with self._lock:
            self._check_open()
            if topic in self._channels:
                cid, known = self._channels[topic]
                if known != msgtype:
                    raise LogError(f"topic {topic} already has type {known}, not {msgtype}")
                return cid
            sid = self._schemas.get(msgtype)
            if sid is None:
                try:
                    text = msgdefs.definition(msgtype)
                except LookupError as exc:
                    raise LogError(str(exc)) from exc
                sid = self._writer.register_schema(msgtype, "ros2msg", text.encode())
                self._schemas[msgtype] = sid
            meta = dict(metadata or {})
            if M.QOS_METADATA_KEY not in meta:  # what rosbag2 writes: the publisher's QoS, for playback
                meta[M.QOS_METADATA_KEY] = M.topic_qos(topic).yaml()
            cid = self._writer.register_channel(topic, "cdr", sid, meta)
            self._channels[topic] = (cid, msgtype)
            self._sequence[cid] = 0
            return cid

    def channel(self, topic: str) -> int:
        """Id of an existing channel."""
        try:
            return self._channels[topic][0]
        except KeyError:
            raise LogError(f"no channel {topic}") from None

    @property
    def topics(self) -> dict[str, str]:
        """topic -> message type of the channels so far."""
        return {t: mt for t, (_, mt) in self._channels.items()}

    # --- messages ------------------------------------------------------------------------------
    def write_raw(self, ch: int, log_time_ns: int, data: bytes, publish_time_ns: int | None = None, *,
                  canonical: bool = False) -> None:
        """Store CDR bytes exactly as given (4-byte encapsulation header included).

        ``canonical=True`` stores them decoded and encoded again instead: for bytes from
        ``rclpy.serialization.serialize_message``, which may carry trailing padding that
        rosbags refuses ("CDR message size mismatch"); the bytes of a raw subscription are
        exact and need no such pass.
        """
        if canonical:
            data = self._canonical(ch, data)
        log_time_ns = int(log_time_ns)
        if log_time_ns < 0:
            raise LogError(f"log time must be >= 0 ns, got {log_time_ns}")
        with self._lock:
            self._check_open()
            if self.failure is not None:
                raise self.failure
            if ch not in self._sequence:
                raise LogError(f"unknown channel id {ch}")
            seq = self._sequence[ch] = self._sequence[ch] + 1
            try:
                self._writer.add_message(ch, log_time_ns, bytes(data),
                                         log_time_ns if publish_time_ns is None else int(publish_time_ns), seq)
            except OSError as exc:  # a full chunk written out: no space left...
                self.failure = exc
                raise
            self.message_count += 1
            self._dirty = True
            if time.monotonic() - self._last_flush >= self.flush_period:
                self._flush_locked()

    def write(self, ch: int, log_time_ns: int, msg: Any, publish_time_ns: int | None = None, *,
              check_finite: bool = True) -> None:
        """Encode `msg` (a mapping, or an object with the fields as attributes) as CDR and store it.

        Raises LogError on a non-finite float anywhere in the message (``check_finite=False``
        skips the scan for messages from :mod:`gyro_sim.msgs.messages`, which refuse them).
        """
        if check_finite:
            _check_finite(msg)
        enc = self._encoders.get(ch)
        if enc is None:
            enc = self._encoder(ch)
        try:
            data = enc(msg)
        except (ValueError, TypeError, KeyError, AttributeError, OverflowError) as exc:
            topic = next((t for t, (cid, _) in self._channels.items() if cid == ch), ch)
            raise LogError(f"cannot encode a message of {topic}: {exc}") from exc
        self.write_raw(ch, log_time_ns, data, publish_time_ns)

    def event(self, log_time_ns: int, text: str) -> None:
        """A marker (e.g. "reset") on /gyro_sim/events (std_msgs/msg/String; ``~/events`` of `topics`)."""
        ch = self.add_channel(self.topic_names.events, "std_msgs/msg/String")
        self.write(ch, log_time_ns, {"data": str(text)})

    def _canonical(self, ch: int, data: bytes) -> bytes:
        dec = self._decoders.get(ch)
        if dec is None:
            from mcap_ros2._dynamic import generate_dynamic

            msgtype = self._msgtype(ch)
            dec = self._decoders[ch] = generate_dynamic(msgtype, msgdefs.definition(msgtype))[msgtype]
        enc = self._encoders.get(ch) or self._encoder(ch)
        try:
            return enc(dec(bytes(data)))
        except Exception as exc:  # any decoding failure means bad bytes
            raise_interrupt_behind(exc)
            raise LogError(f"not a CDR {self._msgtype(ch)}: {type(exc).__name__}: {exc}") from exc

    def _msgtype(self, ch: int) -> str:
        for cid, msgtype in self._channels.values():
            if cid == ch:
                return msgtype
        raise LogError(f"unknown channel id {ch}")

    def _encoder(self, ch: int):
        from mcap_ros2._dynamic import serialize_dynamic

        msgtype = self._msgtype(ch)
        enc = serialize_dynamic(msgtype, msgdefs.definition(msgtype))[msgtype]
        self._encoders[ch] = enc
        return enc

    # --- flushing and closing --------------------------------------------------------------------
    def flush(self) -> None:
        """Finish the chunk in progress and hand everything to the operating system now."""
        with self._lock:
            self._check_open()
            self._flush_locked()

    def _flush_locked(self) -> None:
        if self.failure is not None:
            raise self.failure
        try:
            self._flush_dirty()
        except OSError as exc:
            self.failure = exc
            raise

    def _flush_dirty(self) -> None:
        if self._dirty:
            if hasattr(self._writer, "flush"):  # mcap >= 1.6: finish the chunk, write, flush
                self._writer.flush()
            else:  # older mcap: the same steps through the private method
                self._writer._Writer__finalize_chunk()
                self._file.flush()
            self._dirty = False
            self._chunk_indexes.pack(self._writer)
        self._last_flush = time.monotonic()

    def _flush_loop(self) -> None:
        """Background: flush what has waited `flush_period` when no write came to do it."""
        while True:
            with self._lock:
                if self._closed:
                    return
                now = time.monotonic()
                if now - self._last_flush >= self.flush_period:
                    # nothing pending: nothing to lose, the period starts again
                    try:
                        self._flush_locked()
                    except OSError:  # kept in `failure`: the next write raises it
                        return
                wait = self._last_flush + self.flush_period - now
            if self._stop.wait(max(wait, MIN_TIMER_WAIT)):
                return

    def close(self) -> None:
        """Write the summary and indexes and close the file (idempotent). After a failed write
        (`failure`), the summary is attempted once and the file closed, without raising."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._stop.set()
            failed = self.failure is not None
            try:
                self._chunk_indexes.unpack(self._writer)
                self._writer.finish()
            except OSError as exc:
                self.failure = self.failure or exc
                if not failed:
                    raise
            finally:
                try:
                    self._file.close()
                except OSError as exc:  # the buffer's last bytes did not fit either
                    self.failure = self.failure or exc
                    if not failed:
                        raise
        if self._timer is not threading.current_thread():
            self._timer.join(timeout=5.0)

    def _check_open(self) -> None:
        if self._closed:
            raise LogError(f"log {self.path} is closed")

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self):  # a forgotten writer still leaves a readable file
        try:
            if not self._closed:
                self.close()
        except Exception:  # noqa: BLE001 - nothing sensible to do at interpreter exit
            pass


# =========================================================================================
# Reading
# =========================================================================================
@dataclass(frozen=True)
class LogInfo:
    """What a log says about itself."""

    params: dict  # the run parameters (metadata "gyro_sim"/"params")
    scene_yaml: str | None  # the embedded scene file
    metadata: dict  # the whole "gyro_sim" metadata record
    topics: dict  # topic -> message type (schema name)
    message_count: int | None  # from the summary (None without one)
    start_ns: int | None
    end_ns: int | None

    def scene_source(self) -> dict:
        """The embedded scene file, parsed (safe loader, depth-limited; LogError otherwise)."""
        from gyro_sim.scene.load import SceneError, parse_yaml

        if self.scene_yaml is None:
            raise LogError("the log has no embedded scene (attachment scene.yaml)")
        try:
            return parse_yaml(self.scene_yaml, "scene.yaml")
        except SceneError as exc:
            raise LogError(f"the embedded scene does not load: {'; '.join(exc.errors)}") from None

    def topic_names(self, path: str | os.PathLike = "", topics=None) -> "M.TopicNames":
        """The topic names of the node that wrote the log (`topics`: channel names, default the
        log's): those of its namespace for a namespaced node's log
        (gyro_sim.msgs.messages.log_topic_names), with its frame_prefix. LogError for a log that
        mixes two robots (naming `path`)."""
        prefix = self.params.get("frame_prefix", "")
        try:
            return M.log_topic_names(self.topics if topics is None else topics, str(path),
                                     prefix if isinstance(prefix, str) else "")
        except M.NamespaceError as exc:
            raise LogError(str(exc)) from None

    def scene(self):
        """The embedded scene, validated (LogError if it is missing or does not load)."""
        from gyro_sim.scene.load import SceneError, load_scene

        try:
            return load_scene(self.scene_source())
        except SceneError as exc:
            raise LogError(f"the embedded scene does not load: {'; '.join(exc.errors)}") from None


def _open(path):
    return open(path, "rb")


#: largest uncompressed chunk a reader accepts (ours are CHUNK_SIZE; bounds crafted sizes)
MAX_CHUNK_BYTES = 1 << 28
#: MCAP record opcodes used here (MCAP specification)
OP_CHUNK = 0x06
OP_FOOTER = 0x02
#: the footer record (opcode, length, summary_start, summary_offset_start, summary_crc) + magic
FOOTER_BYTES = 1 + 8 + 8 + 8 + 4
MAGIC_BYTES = 8


class ChunkError(Exception):
    """A chunk that cannot be used: CRC mismatch, undecodable, or of an impossible size."""


def decode_chunk(chunk) -> bytes:
    """The uncompressed records of an mcap ``Chunk``, its CRC checked (ChunkError otherwise)."""
    import zlib

    size = chunk.uncompressed_size
    if size > MAX_CHUNK_BYTES:
        raise ChunkError(f"uncompressed size {size} bytes exceeds the limit of {MAX_CHUNK_BYTES}")
    try:
        if chunk.compression == "zstd":
            import zstandard

            obj = zstandard.ZstdDecompressor().decompressobj()
            data = obj.decompress(bytes(chunk.data))
            if obj.unused_data:  # bytes after the frame: the chunk's data length is wrong
                raise ChunkError(f"{len(obj.unused_data)} bytes after its compressed frame")
        elif chunk.compression == "lz4":
            import lz4.frame

            data = lz4.frame.decompress(bytes(chunk.data))
        elif chunk.compression == "":
            data = bytes(chunk.data)
        else:
            raise ChunkError(f"unknown compression {chunk.compression[:20]!r}")
    except ChunkError:
        raise
    except Exception as exc:  # noqa: BLE001 - each decompressor has its own errors
        raise_interrupt_behind(exc)
        raise ChunkError(f"does not decompress ({type(exc).__name__}: {exc})") from None
    if len(data) != size:
        raise ChunkError(f"decompresses to {len(data)} bytes, its header says {size}")
    if chunk.uncompressed_crc != 0:
        crc = zlib.crc32(data)
        if crc != chunk.uncompressed_crc:
            raise ChunkError(f"CRC mismatch (stored {chunk.uncompressed_crc:#010x}, computed {crc:#010x})")
    return data


def chunk_records(chunk, data: bytes) -> list:
    """The Schema, Channel and Message records of a chunk whose records are `data` (decoded)."""
    from mcap.reader import breakup_chunk
    from mcap.records import Chunk

    plain = Chunk(compression="", data=data, message_start_time=chunk.message_start_time,
                  message_end_time=chunk.message_end_time, uncompressed_crc=0, uncompressed_size=len(data))
    try:
        return breakup_chunk(plain, validate_crc=False)
    except Exception as exc:  # noqa: BLE001 - a damaged record inside can fail anywhere
        raise_interrupt_behind(exc)
        raise ChunkError(f"holds an unreadable record ({type(exc).__name__}: {exc})") from None


def _damaged(path, where: str, reason: str) -> LogError:
    return LogError(f"{path}: damaged log: {where}: {reason}; "
                    f"run `gyro-sim recover {path} -o fixed.mcap` to keep what is intact")


def verify(path: str | os.PathLike):
    """Check a log before reading it: summary present and its CRC, then every chunk's CRC (and
    that it decompresses). Return the mcap ``Summary``; raise LogError naming the first
    damaged chunk's byte offset, or OSError if the file cannot be opened."""
    with _open(path) as f:
        return _verify(f, path)


def _verify(f: BinaryIO, path):
    """`verify` of the log open as `f` (read from its start; the position is left anywhere)."""
    import io as _io
    import zlib

    from mcap.data_stream import ReadDataStream
    from mcap.reader import make_reader
    from mcap.records import Chunk

    f.seek(0)
    size = os.fstat(f.fileno()).st_size
    try:
        summary = make_reader(f, validate_crcs=True).get_summary()
    except Exception as exc:  # noqa: BLE001 - mcap raises many kinds on a damaged file
        raise_interrupt_behind(exc)
        raise LogError(f"{path}: not a readable MCAP log, no summary ({type(exc).__name__}: {exc}); "
                       f"if the run was killed, run `gyro-sim recover {path} -o fixed.mcap`") from None
    if summary is None:
        raise LogError(f"{path}: no summary (cut short? run `gyro-sim recover {path} -o fixed.mcap`)")
    f.seek(size - MAGIC_BYTES - FOOTER_BYTES)
    footer = f.read(FOOTER_BYTES)
    summary_start = int.from_bytes(footer[9:17], "little")
    summary_crc = int.from_bytes(footer[25:29], "little")
    if footer[0] != OP_FOOTER or summary_start > size:
        raise _damaged(path, f"footer at byte {size - MAGIC_BYTES - FOOTER_BYTES}", "not a footer record")
    if summary_crc and summary_start:
        f.seek(summary_start)
        crc = zlib.crc32(f.read(size - MAGIC_BYTES - 4 - summary_start))
        if crc != summary_crc:
            raise _damaged(path, f"summary section at byte {summary_start}",
                           f"CRC mismatch (stored {summary_crc:#010x}, computed {crc:#010x})")
    for index in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
        off = index.chunk_start_offset
        try:
            f.seek(off)
            head = f.read(9)
            if len(head) < 9 or head[0] != OP_CHUNK:
                raise ChunkError("no chunk record there")
            length = int.from_bytes(head[1:], "little")
            if length > size - off:
                raise ChunkError(f"record length {length} runs past the end of the file")
            chunk = Chunk.read(ReadDataStream(_io.BytesIO(f.read(length))))
            chunk_records(chunk, decode_chunk(chunk))
        except ChunkError as exc:
            raise _damaged(path, f"chunk at byte {off}", str(exc)) from None
        except Exception as exc:  # noqa: BLE001 - a damaged header fails in the record parser
            raise_interrupt_behind(exc)
            raise _damaged(path, f"chunk at byte {off}", f"unreadable ({type(exc).__name__}: {exc})") from None
    return summary


class LogReader:
    """A gyro_sim log open for reading: the file opened once and verified on entry (:func:`verify`:
    the summary's and every chunk's CRC), then its parameters, scene and topics (`info`) and its
    messages, as often as asked::

        with LogReader("run.mcap") as log:
            log.info.params["integrator"], log.info.topics, log.info.scene()
            for topic, msgtype, t_ns, msg in log.messages(["/joint_states"]):
                ...

    LogError on entry for a damaged, cut-short or crafted log (naming the damaged chunk's byte
    offset and ``gyro-sim recover``); OSError if the file cannot be opened.
    """

    def __init__(self, path: str | os.PathLike):
        self.path = path
        self.info: LogInfo | None = None
        self._f: BinaryIO | None = None

    def __enter__(self) -> "LogReader":
        self._f = _open(self.path)
        try:
            summary = _verify(self._f, self.path)
            self.info = _read_info(self._f, self.path, summary)
        except (LogError, OSError):
            self._f.close()
            raise
        except Exception as exc:  # noqa: BLE001 - mcap raises many kinds on a damaged file
            self._f.close()
            raise_interrupt_behind(exc)
            raise LogError(f"{self.path}: not a readable gyro_sim log ({type(exc).__name__}: {exc}); "
                           f"if it is damaged, run `gyro-sim recover {self.path} -o fixed.mcap`") from None
        return self

    def __exit__(self, *exc) -> None:
        self._f.close()

    def messages(self, topics=None, *, decode: bool = True,
                 log_time_order: bool = True) -> Iterator[tuple[str, str, int, Any]]:
        """The log's messages, as :func:`iter_messages` gives them (one iteration at a time)."""
        return _messages(self._f, self.path, topics, decode, log_time_order)

    def topic_names(self) -> "M.TopicNames":
        """The topic names of the node that wrote the log (:meth:`LogInfo.topic_names`)."""
        return self.info.topic_names(self.path)


def read_info(path: str | os.PathLike) -> LogInfo:
    """Parameters, scene, topics and span of a log, after :func:`verify` (every CRC checked).

    LogError for a damaged, cut-short or crafted log; OSError if it cannot be opened."""
    with LogReader(path) as log:
        return log.info


def _read_info(f: BinaryIO, path, summary) -> LogInfo:
    from mcap.reader import make_reader

    f.seek(0)
    reader = make_reader(f, validate_crcs=True)
    params: dict = {}
    meta: dict = {}
    for m in reader.iter_metadata():
        if m.name == METADATA_NAME:
            meta = dict(m.metadata)
            try:
                params = json.loads(meta.get("params", "{}"))
            except ValueError as exc:
                raise LogError(f"{path}: metadata {METADATA_NAME}/params is not JSON ({exc})") from None
            if not isinstance(params, dict):
                raise LogError(f"{path}: metadata {METADATA_NAME}/params must be a JSON object, "
                               f"got {type(params).__name__}")
    scene = None
    for a in reader.iter_attachments():
        if a.name == SCENE_ATTACHMENT:
            try:
                scene = bytes(a.data).decode()
            except UnicodeDecodeError as exc:
                raise LogError(f"{path}: the embedded scene is not UTF-8 text ({exc.reason})") from None
    topics = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()
              if c.schema_id in summary.schemas}
    st = summary.statistics
    return LogInfo(params, scene, meta, topics,
                   st.message_count if st else None,
                   st.message_start_time if st else None, st.message_end_time if st else None)


def iter_messages(path: str | os.PathLike, topics=None, *, decode: bool = True,
                  log_time_order: bool = True) -> Iterator[tuple[str, str, int, Any]]:
    """(topic, msgtype, log_time_ns, message) in log-time order (file order among equal times;
    ``log_time_order=False``: file order).

    `message` is the decoded message (mcap-ros2-support's dynamic classes, fields as
    attributes) or, with ``decode=False``, the CDR bytes. Chunk CRCs are checked as chunks are
    read: a damaged chunk, or a message its schema cannot decode, raises LogError.
    """
    with _open(path) as f:
        yield from _messages(f, path, topics, decode, log_time_order)


def _messages(f: BinaryIO, path, topics, decode: bool, log_time_order: bool):
    from mcap.reader import make_reader

    factories = []
    if decode:
        from mcap_ros2.decoder import DecoderFactory

        factories = [DecoderFactory()]
    topic = None
    try:
        f.seek(0)
        reader = make_reader(f, validate_crcs=True, decoder_factories=factories)
        if decode:
            it = reader.iter_decoded_messages(topics=topics, log_time_order=log_time_order)
            for schema, channel, message, msg in it:
                topic = channel.topic
                yield channel.topic, schema.name, message.log_time, msg
        else:
            for schema, channel, message in reader.iter_messages(topics=topics, log_time_order=log_time_order):
                topic = channel.topic
                yield channel.topic, schema.name if schema else "", message.log_time, bytes(message.data)
    except (LogError, OSError, GeneratorExit):
        raise
    except Exception as exc:  # noqa: BLE001 - damaged chunks and crafted schemas fail in many ways
        raise_interrupt_behind(exc)
        _verify(f, path)  # names the damaged chunk's offset if there is one
        raise LogError(f"{path}: cannot read the messages (after {topic or 'the start'}): "
                       f"{type(exc).__name__}: {str(exc)[:200]}") from None


def log_topic_names(path: str | os.PathLike, topics=None) -> "M.TopicNames":
    """The topic names of the node that wrote the log at `path` (`topics`: its channels' names,
    read from the log when not given): those of its namespace for a namespaced node's log
    (gyro_sim.msgs.messages.log_topic_names), with the node's frame_prefix. LogError for a log
    that mixes two robots."""
    return read_info(path).topic_names(path, topics)

