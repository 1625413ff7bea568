"""`hri record` / `hri replay`: sessions on disk as MCAP, and back onto the bus.

File layout (what a reader of the .mcap can count on):
- one channel per concrete key; topic = the key, message_encoding = "protobuf", schema `hri_fusion.RawSample`
  (encoding "protobuf": `message RawSample { bytes data = 1; }`, so that Foxglove and every MCAP tool decode it);
  channel metadata names the contract type ("schema": "Transcript", or "" for a key outside the contract) and the
  zenoh encoding the first sample arrived with;
- message data = a RawSample whose `data` is the payload bytes exactly as received (`raw_payload` unwraps it);
  recordings made before issue #41 have message_encoding "msgpack" and the payload itself as data (and a
  "jsonschema" record of the contract type): they read and replay as before;
- log_time = receive time (ns since the UNIX epoch, the recorder's clock);
- publish_time = the sample's own `stamp` when the payload decodes under the contract, else the
  receive time; sequence = per-channel count from 1;
- one metadata record "hri.record" (key expressions, prefix, start time, host);
- viewer channels (since issue #36, when foxglove-sdk is installed and not --no-viewers): each valid contract
  sample also in the shapes Foxglove decodes (protobuf built-ins, JSON), on topics starting with "/"
  (hri/viewers/foxglove_msgs.py lists them), channel metadata "hri.viewer": "true", same log_time,
  publish_time = the sample's stamp. Replay and `read_samples` read only the raw channels, so recordings
  from before (raw channels only) and after read and replay the same way.

The top half of this module is the functional core (MCAP writing/reading, the replay clock,
progress lines) and imports neither zenoh nor the transport; the `cmd_*` shells at the bottom
import them lazily and are wired into `hri` by hri/cli.py.
"""

from __future__ import annotations

import argparse
import collections
import logging
import os
import queue
import signal
import socket
import struct
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any, BinaryIO, Callable, Iterable, Iterator

from common.codec import ENCODING, decode
from common.keys import Keys
from common.schema import InvalidSample, Sample
from common.settings import add_option
from hri.viewers.foxglove_msgs import VIEWER_METADATA, FoxgloveConverter, ViewerSchema, available

LEGACY_ENCODING = "msgpack"  # raw channels before issue #41: the payload itself as message data
RAW_ENCODING = "protobuf"
RAW_SCHEMA = "hri_fusion.RawSample"
PROFILE = ""  # no well-known MCAP profile fits; the contract lives in channel metadata
METADATA_NAME = "hri.record"
COMPRESSIONS = ("zstd", "lz4", "none")
NS = 1_000_000_000


# ---------------------------------------------------------------------------
# The raw sample as protobuf (`message RawSample { bytes data = 1; }`), written by hand: recording needs no
# protobuf library; tests/test_record_replay.py checks both against google.protobuf and mcap's protobuf decoder.
# ---------------------------------------------------------------------------
def _varint(n: int) -> bytes:
    out = bytearray()
    while True:
        low, n = n & 0x7F, n >> 7
        out.append(low | (0x80 if n else 0))
        if not n:
            return bytes(out)


def _field(number: int, value: bytes | str | int) -> bytes:
    """One protobuf field: a varint (int) or length-delimited (bytes, str) value."""
    if isinstance(value, int):
        return _varint(number << 3) + _varint(value)
    data = value.encode() if isinstance(value, str) else value
    return _varint(number << 3 | 2) + _varint(len(data)) + data


def _raw_sample_descriptor() -> bytes:
    """The FileDescriptorSet of hri_fusion/raw_sample.proto (what Foxglove reads a protobuf schema as)."""
    data_field = _field(1, "data") + _field(3, 1) + _field(4, 1) + _field(5, 12) + _field(10, "data")  # bytes, = 1
    message = _field(1, "RawSample") + _field(2, data_field)
    proto = _field(1, "hri_fusion/raw_sample.proto") + _field(2, "hri_fusion") + _field(4, message)
    return _field(1, proto + _field(12, "proto3"))


RAW_SCHEMA_DATA = _raw_sample_descriptor()


def wrap_raw(payload: bytes) -> bytes:
    """A payload as a RawSample message."""
    return _field(1, payload) if payload else b""  # proto3 leaves an empty field out


def unwrap_raw(message: bytes) -> bytes:
    """The payload of a RawSample message; ValueError when it is not one."""
    if not message:
        return b""
    if message[0] != 0x0A:
        raise ValueError(f"not a RawSample: first byte {message[0]:#x}")
    length, shift, k = 0, 0, 1
    while True:
        if k >= len(message) or shift > 63:
            raise ValueError("not a RawSample: its length is cut short")
        byte = message[k]
        length |= (byte & 0x7F) << shift
        shift, k = shift + 7, k + 1
        if not byte & 0x80:
            break
    if k + length != len(message):
        raise ValueError(f"not a RawSample: {len(message) - k} bytes after the tag, the length says {length}")
    return message[k:]


def is_raw_channel(schema: Any, channel: Any) -> bool:
    """A channel `hri record` keeps the received payloads on (today's protobuf RawSample, or the msgpack channels
    of recordings made before issue #41), as opposed to the viewer channels beside them."""
    if channel.metadata.get(VIEWER_METADATA):
        return False
    if channel.message_encoding == LEGACY_ENCODING:
        return True
    return channel.message_encoding == RAW_ENCODING and schema is not None and schema.name == RAW_SCHEMA


def raw_payload(schema: Any, channel: Any, data: bytes) -> bytes:
    """The payload as received of a raw channel's message (`is_raw_channel`)."""
    return data if channel.message_encoding == LEGACY_ENCODING else unwrap_raw(data)


RECORD_EXAMPLES = """\
examples:
  hri record -o session.mcap 'hri/**'                    # everything, until Ctrl-C
  hri record -o inputs.mcap 'hri/speech/**' 'hri/vision/**' 'hri/gesture/*/event'
  hri record -o ten.mcap 'hri/fusion/**' --count 10      # stop after 10 samples
  hri record -o minute.mcap --duration 60                # default key expression: <prefix>/**
The file is finished properly (summary, indexes) on Ctrl-C / SIGTERM, --count or --duration.
"""

REPLAY_EXAMPLES = """\
examples:
  hri replay session.mcap                                # original timing
  hri replay session.mcap --speed 2                      # twice as fast; --speed 0: as fast as possible
  hri replay session.mcap --only 'hri/speech/**' --only 'hri/vision/**'   # only these keys
  hri replay session.mcap --loop                         # over and over until Ctrl-C
Payloads are republished byte for byte (application/msgpack, congestion control BLOCK).
"""


def _mcap():
    try:
        import mcap.reader
        import mcap.writer
    except ImportError:  # pragma: no cover - the record extra is part of the default set-up
        raise SystemExit("hri record/replay need the `mcap` package: pip install 'hri-fusion[record]'") from None
    return mcap


def _viewer_converter(keys: Keys) -> FoxgloveConverter | None:
    if available():
        return FoxgloveConverter(keys)
    logging.getLogger("hri.record").warning(
        "foxglove-sdk is not installed: writing the raw channels only (pip install 'hri-fusion[foxglove]')"
    )
    return None


def human_bytes(n: float) -> str:
    for unit in ("B", "kB", "MB", "GB"):
        if abs(n) < 1000 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000
    return f"{n:.1f} GB"  # unreachable, keeps type checkers calm


# ---------------------------------------------------------------------------
# Writing
# ---------------------------------------------------------------------------
def contract_sample(key: str, payload: bytes, keys: Keys) -> Sample | None:
    """The decoded sample if `payload` is a valid contract sample for `key`, else None."""
    schema = keys.schema_for(key)
    if schema is None:
        return None
    try:
        return decode(payload, schema)
    except InvalidSample:
        return None


def stamp_ns(key: str, payload: bytes, keys: Keys) -> int | None:
    """The sample's `stamp` in ns if `payload` is a valid contract sample for `key`, else None."""
    sample = contract_sample(key, payload, keys)
    return None if sample is None else int(round(sample.stamp * NS))


@dataclass
class KeyTally:
    samples: int = 0
    bytes: int = 0
    not_contract: int = 0  # payloads that did not decode under the contract (publish time = receive time)
    viewer_failed: int = 0  # valid samples the viewer channels could not show (e.g. an undecodable depth PNG)


class SessionWriter:
    """Writes received samples to an MCAP stream: one channel per key, payload bytes untouched.

    With `viewers` (the default when foxglove-sdk is installed), each valid contract sample is also written in
    the shapes Foxglove decodes, on channels of their own (hri/viewers/foxglove_msgs.py lists them).
    """

    def __init__(
        self,
        stream: IO[bytes],
        keys: Keys,
        *,
        compression: str = "zstd",
        metadata: dict[str, str] | None = None,
        chunk_size: int = 1 << 20,
        viewers: bool | None = None,
    ):
        mcap = _mcap()
        if compression not in COMPRESSIONS:
            raise ValueError(f"compression must be one of {COMPRESSIONS}, not {compression!r}")
        kind = {
            "zstd": mcap.writer.CompressionType.ZSTD,
            "lz4": mcap.writer.CompressionType.LZ4,
            "none": mcap.writer.CompressionType.NONE,
        }[compression]
        self.keys = keys
        self._writer = mcap.writer.Writer(stream, chunk_size=chunk_size, compression=kind)
        self._writer.start(profile=PROFILE, library="hri-fusion record")
        if metadata:
            self._writer.add_metadata(METADATA_NAME, metadata)
        self._channels: dict[str, int] = {}
        self._raw_schema = self._writer.register_schema(name=RAW_SCHEMA, encoding=RAW_ENCODING, data=RAW_SCHEMA_DATA)
        self._viewer_channels: dict[tuple[str, str], int] = {}  # (topic, schema name) -> channel id
        self._viewer_schemas: dict[str, int] = {}  # Foxglove / JSON schema name -> schema id
        self._viewer_sequence: collections.Counter[int] = collections.Counter()
        self.converter = _viewer_converter(keys) if viewers or viewers is None else None
        if viewers and self.converter is None:
            raise SystemExit(
                "viewer channels need foxglove-sdk: pip install 'hri-fusion[foxglove]' (or record with --no-viewers)"
            )
        self.tally: dict[str, KeyTally] = collections.defaultdict(KeyTally)
        self.samples = 0
        self.bytes = 0
        self.finished = False

    def add(self, key: str, payload: bytes, receive_ns: int, zenoh_encoding: str = ENCODING) -> int:
        """Write one sample; returns the publish time written (stamp, or receive time)."""
        channel = self._channels.get(key)
        if channel is None:
            schema = self.keys.schema_for(key)
            channel = self._channels[key] = self._writer.register_channel(
                topic=key,
                message_encoding=RAW_ENCODING,
                schema_id=self._raw_schema,
                metadata={"schema": schema.__name__ if schema else "", "zenoh_encoding": zenoh_encoding},
            )
        sample = contract_sample(key, payload, self.keys)
        stamp = None if sample is None else int(round(sample.stamp * NS))
        tally = self.tally[key]
        tally.samples += 1
        tally.bytes += len(payload)
        if stamp is None:
            tally.not_contract += 1
        publish_ns = receive_ns if stamp is None else stamp
        self._writer.add_message(
            channel_id=channel,
            log_time=receive_ns,
            data=wrap_raw(payload),
            publish_time=publish_ns,
            sequence=tally.samples,
        )
        self.samples += 1
        self.bytes += len(payload)
        if sample is not None and self.converter is not None:
            self._add_viewer(key, sample, receive_ns, tally)
        return publish_ns

    def _viewer_schema_id(self, schema: ViewerSchema) -> int:
        if schema.name not in self._viewer_schemas:
            self._viewer_schemas[schema.name] = self._writer.register_schema(
                name=schema.name, encoding=schema.encoding, data=schema.data
            )
        return self._viewer_schemas[schema.name]

    def _add_viewer(self, key: str, sample: Sample, receive_ns: int, tally: KeyTally) -> None:
        try:
            shown = self.converter.convert(key, sample) if self.converter is not None else []
        except (ValueError, InvalidSample):  # e.g. a depth PNG that does not decode: the raw sample is kept
            tally.viewer_failed += 1
            return
        for m in shown:
            channel = self._viewer_channels.get((m.topic, m.schema.name))
            if channel is None:
                channel = self._viewer_channels[(m.topic, m.schema.name)] = self._writer.register_channel(
                    topic=m.topic, message_encoding=m.message_encoding, schema_id=self._viewer_schema_id(m.schema),
                    metadata={VIEWER_METADATA: "true"},
                )  # fmt: skip
            self._viewer_sequence[channel] += 1
            self._writer.add_message(
                channel_id=channel, log_time=receive_ns, data=m.data, publish_time=m.stamp_ns,
                sequence=self._viewer_sequence[channel],
            )  # fmt: skip

    def finish(self) -> None:
        """Write the summary and indexes (the file is a complete MCAP afterwards)."""
        if not self.finished:
            self._writer.finish()
            self.finished = True


# ---------------------------------------------------------------------------
# Reading
# ---------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Recorded:
    key: str
    payload: bytes
    log_ns: int
    publish_ns: int
    sequence: int


@dataclass
class RecordingInfo:
    """What the summary says (or what a linear scan found when the summary is missing)."""

    keys: dict[str, int] = field(default_factory=dict)  # key -> message count
    start_ns: int = 0
    end_ns: int = 0
    complete: bool = True  # False: no summary (the recorder was killed); read linearly up to the damage

    @property
    def samples(self) -> int:
        return sum(self.keys.values())

    @property
    def span_s(self) -> float:
        return (self.end_ns - self.start_ns) / NS if self.samples else 0.0


class RecordingError(Exception):
    """The file is missing, not MCAP, or not something hri recorded; the message says which."""


class SessionReader:
    """Reads an .mcap written by `hri record` (or any MCAP whose RawSample or msgpack channels are zenoh keys)."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        mcap = _mcap()
        # struct.error: a record cut short inside its length-prefixed fields (a SIGKILLed recorder)
        self._errors = (mcap.exceptions.McapError, EOFError, ValueError, OSError, struct.error)
        try:
            self._stream = open(self.path, "rb")
        except OSError as exc:
            raise RecordingError(f"cannot open {self.path}: {exc.strerror or exc}") from None
        try:
            self._reader = mcap.reader.make_reader(self._stream)
        except self._errors as exc:
            self._stream.close()
            raise RecordingError(f"{self.path} is not an MCAP file ({type(exc).__name__}: {exc})") from None
        self.skipped_encodings: dict[str, str] = {}  # key -> message encoding we cannot republish
        self.damaged: str | None = None  # why a linear read stopped early
        self.info = self._read_info()

    def _read_info(self) -> RecordingInfo:
        try:
            summary = self._reader.get_summary()
        except self._errors:
            summary = None
        if summary is not None and summary.statistics is not None:
            info = RecordingInfo(
                start_ns=summary.statistics.message_start_time, end_ns=summary.statistics.message_end_time
            )
            for cid, channel in summary.channels.items():
                if channel.metadata.get(VIEWER_METADATA):
                    continue  # a copy in a viewer's shape; the raw channel beside it is what replays
                if not is_raw_channel(summary.schemas.get(channel.schema_id), channel):
                    self.skipped_encodings[channel.topic] = channel.message_encoding
                    continue
                info.keys[channel.topic] = info.keys.get(
                    channel.topic, 0
                ) + summary.statistics.channel_message_counts.get(cid, 0)
            return info
        # No summary: the recording was cut short. One linear pass tells what is readable.
        info = RecordingInfo(complete=False)
        first = True
        for item in self._linear():
            info.keys[item.key] = info.keys.get(item.key, 0) + 1
            info.start_ns = item.log_ns if first else min(info.start_ns, item.log_ns)
            info.end_ns = item.log_ns if first else max(info.end_ns, item.log_ns)
            first = False
        return info

    def _linear(self) -> Iterator[Recorded]:
        mcap = _mcap()
        self._stream.seek(0)
        reader = mcap.reader.NonSeekingReader(self._stream)
        try:
            for schema, channel, message in reader.iter_messages(log_time_order=False):
                if channel.metadata.get(VIEWER_METADATA):
                    continue
                if not is_raw_channel(schema, channel):
                    self.skipped_encodings[channel.topic] = channel.message_encoding
                    continue
                yield self._recorded(schema, channel, message)
        except self._errors as exc:
            self.damaged = f"{type(exc).__name__}: {exc}"

    def messages(self, keep: Callable[[str], bool] = lambda key: True) -> Iterator[Recorded]:
        """Messages on kept keys in log-time (receive) order."""
        topics = [k for k in self.info.keys if keep(k)]
        if not topics:
            return
        if not self.info.complete:
            # written in arrival order, which is log-time order up to the writer's queueing
            yield from (m for m in self._linear() if keep(m.key))
            return
        for schema, channel, message in self._reader.iter_messages(topics=topics, log_time_order=True):
            if is_raw_channel(schema, channel):  # a viewer channel could share a raw channel's topic
                yield self._recorded(schema, channel, message)

    @staticmethod
    def _recorded(schema: Any, channel: Any, message: Any) -> Recorded:
        payload = raw_payload(schema, channel, message.data)
        return Recorded(channel.topic, payload, message.log_time, message.publish_time, message.sequence)

    def metadata(self) -> dict[str, str]:
        try:
            for record in self._reader.iter_metadata():
                if record.name == METADATA_NAME:
                    return dict(record.metadata)
        except self._errors:
            pass
        return {}

    def close(self) -> None:
        self._stream.close()


def read_samples(
    path: str | os.PathLike, keys: Keys | None = None, keep: Callable[[str], bool] = lambda key: True
) -> Iterator[tuple[str, float, Sample]]:
    """(key, stamp in seconds, decoded sample) of every valid contract sample of a recording, in receive order.

    Reads recordings of every version (before and after the viewer channels of issue #36, and the msgpack raw
    channels before issue #41's RawSample); payloads outside the contract or invalid under it are skipped. Raises
    RecordingError.
    """
    reader = SessionReader(path)
    keys = keys or Keys(reader.metadata().get("prefix") or Keys().prefix)
    try:
        for m in reader.messages(keep):
            sample = contract_sample(m.key, m.payload, keys)
            if sample is not None:
                yield m.key, sample.stamp, sample
    finally:
        reader.close()


# ---------------------------------------------------------------------------
# Replay timing and progress
# ---------------------------------------------------------------------------
class ReplayClock:
    """When to send each message: original gaps divided by `speed`, anchored at the first one.

    The schedule is absolute, so one late send does not delay the rest (they catch up);
    speed 0 means no waiting at all.
    """

    def __init__(self, speed: float, now: Callable[[], float] = time.monotonic):
        if speed < 0:
            raise ValueError("speed must be >= 0")
        self.speed = speed
        self._now = now
        self._anchor: tuple[int, float] | None = None

    def restart(self) -> None:
        self._anchor = None

    def wait_for(self, log_ns: int) -> float:
        """Seconds to wait before sending the message logged at `log_ns` (0 if due or late)."""
        if self.speed == 0:
            return 0.0
        if self._anchor is None:
            self._anchor = (log_ns, self._now())
            return 0.0
        first_ns, first_wall = self._anchor
        due = first_wall + (log_ns - first_ns) / NS / self.speed
        return max(0.0, due - self._now())


class Progress:
    """A status line on stderr about once a second: rewritten in place on a terminal, appended otherwise."""

    def __init__(self, stream: IO[str] = sys.stderr, interval: float = 1.0, now: Callable[[], float] = time.monotonic):
        self.stream = stream
        self.interval = interval
        self._now = now
        self._last = now()
        self._tty = bool(getattr(stream, "isatty", lambda: False)())
        self._open_line = False

    def due(self) -> bool:
        return self._now() - self._last >= self.interval

    def show(self, line: str) -> None:
        self._last = self._now()
        if self._tty:
            self.stream.write("\r\x1b[2K" + line)
            self._open_line = True
        else:
            self.stream.write(line + "\n")
        self.stream.flush()

    def end(self, line: str) -> None:
        if self._open_line:
            self.stream.write("\r\x1b[2K")
            self._open_line = False
        self.stream.write(line + "\n")
        self.stream.flush()


def rate_line(verb: str, samples: int, nbytes: int, elapsed: float, extra: str = "") -> str:
    elapsed = max(elapsed, 1e-9)
    return (
        f"{verb}: {samples} samples, {human_bytes(nbytes)}, {samples / elapsed:.1f} samples/s "
        f"({human_bytes(nbytes / elapsed)}/s), {elapsed:.1f} s{extra}"
    )


def key_table(counts: dict[str, KeyTally] | dict[str, int]) -> str:
    rows = []
    for key in sorted(counts):
        value = counts[key]
        if isinstance(value, KeyTally):
            note = f", {value.not_contract} outside the contract" if value.not_contract else ""
            note += f", {value.viewer_failed} not shown in the viewer channels" if value.viewer_failed else ""
            rows.append(f"  {key}: {value.samples} ({human_bytes(value.bytes)}{note})")
        else:
            rows.append(f"  {key}: {value}")
    return "\n".join(rows)


# ---------------------------------------------------------------------------
# Shells: `hri record` and `hri replay`
# ---------------------------------------------------------------------------
def add_record_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("keyexpr", nargs="*", help="zenoh key expressions to record (default '<prefix>/**')")
    p.add_argument(
        "-o",
        "--output",
        default=None,
        help="the .mcap file to write (default hri-YYYYmmdd-HHMMSS.mcap in the current folder)",
    )
    p.add_argument("--force", action="store_true", help="overwrite the output file if it exists")
    add_option(p, "--count", None, "stop after N samples", kind=int, at_least=1, metavar="N", default_text="never")
    add_option(p, "--duration", None, "stop after S seconds", kind=float, above=0, metavar="S", default_text="never")
    p.add_argument("--compression", choices=COMPRESSIONS, default="zstd", help="chunk compression (default zstd)")
    p.add_argument(
        "--no-viewers",
        dest="viewers",
        action="store_false",
        default=None,
        help="write only the raw channels (the payloads), not the decoded viewer copies (smaller, cheaper)",
    )
    add_option(
        p,
        "--max-backlog-mb",
        256.0,
        "received but not yet written data above which new samples are dropped and counted",
        above=0,
        metavar="MB",
    )
    p.set_defaults(func=cmd_record)


def add_replay_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", help="an .mcap written by `hri record`")
    add_option(
        p,
        "--speed",
        1.0,
        "time scale: 1 = original timing, 2 = twice as fast, 0 = as fast as possible",
        at_least=0,
        metavar="X",
    )
    p.add_argument(
        "--only",
        action="append",
        default=None,
        metavar="KEYEXPR",
        help="replay only keys intersecting this key expression, repeatable (e.g. 'hri/speech/**')",
    )
    p.add_argument("--loop", action="store_true", help="start over at the end until Ctrl-C")
    add_option(
        p,
        "--wait-subscribers",
        2.0,
        "wait up to S seconds for a subscriber on a replayed key before the first send (0: do not wait)",
        at_least=0,
        metavar="S",
    )
    p.set_defaults(func=cmd_replay)


def _stop_on_signals(stop: threading.Event) -> None:
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())


def _check_keyexprs(exprs: Iterable[str], what: str) -> list[Any] | None:
    import zenoh

    out = []
    for expr in exprs:
        try:
            out.append(zenoh.KeyExpr(expr))
        except zenoh.ZError as exc:
            print(f"hri {what}: {expr!r} is not a valid key expression: {str(exc).split(' at ')[0]}", file=sys.stderr)
            return None
    return out


def _open_output(args: argparse.Namespace) -> tuple[Path, BinaryIO] | None:
    """The output file, opened; None (with the reason printed) when it exists without --force or cannot be written."""
    out = Path(args.output or time.strftime("hri-%Y%m%d-%H%M%S.mcap"))
    if out.exists() and not args.force:
        print(f"hri record: {out} already exists; pass --force to overwrite it or choose another -o", file=sys.stderr)
        return None
    try:
        return out, open(out, "wb")
    except OSError as exc:
        print(f"hri record: cannot write {out}: {exc.strerror or exc}", file=sys.stderr)
        return None


class _Inbox:
    """Zenoh callbacks only enqueue; the main thread decodes stamps and writes, so a slow disk shows up as backlog
    (and, past --max-backlog-mb, as counted drops) instead of stalling the session."""

    def __init__(self, writer: SessionWriter, max_backlog_bytes: int) -> None:
        self.writer = writer
        self.max_backlog = max_backlog_bytes
        self.queue: queue.SimpleQueue[tuple[str, bytes, int, str]] = queue.SimpleQueue()
        self.backlog_bytes = 0
        self.dropped = 0
        self.lock = threading.Lock()

    def on_sample(self, sample: Any) -> None:
        import zenoh

        if sample.kind != zenoh.SampleKind.PUT:
            return  # deletions (and liveliness going away) are not data
        payload = sample.payload.to_bytes()
        with self.lock:
            if self.backlog_bytes + len(payload) > self.max_backlog:
                self.dropped += 1
                return
            self.backlog_bytes += len(payload)
        self.queue.put((str(sample.key_expr), payload, time.time_ns(), str(sample.encoding)))

    def write_next(self, timeout: float | None) -> bool:
        """Writes the next received sample (waiting up to `timeout`; None: not at all); False when none came."""
        try:
            item = self.queue.get(timeout=timeout) if timeout is not None else self.queue.get_nowait()
        except queue.Empty:
            return False
        key, payload, receive_ns, encoding = item
        with self.lock:
            self.backlog_bytes -= len(payload)
        self.writer.add(key, payload, receive_ns, encoding)
        return True

    def extra(self) -> str:
        with self.lock:
            b, d = self.backlog_bytes, self.dropped
        return (
            f", {len(self.writer.tally)} keys"
            + (f", backlog {human_bytes(b)}" if b > 1_000_000 else "")
            + (f", {d} DROPPED (disk too slow)" if d else "")
        )


@dataclass
class _Recording:
    inbox: _Inbox
    args: argparse.Namespace
    stop: threading.Event
    progress: Progress
    started: float


def _record_until_done(rec: _Recording, subscribers: list[Any]) -> None:
    """Writes what arrives until --count, --duration or a signal; then what already arrived, up to --count."""
    inbox, args, stop, progress, started = rec.inbox, rec.args, rec.stop, rec.progress, rec.started
    writer = inbox.writer
    deadline = started + args.duration if args.duration else None
    while not stop.is_set():
        if args.count is not None and writer.samples >= args.count:
            break
        wait = 0.2 if deadline is None else min(0.2, deadline - time.monotonic())
        if wait <= 0:
            break
        inbox.write_next(wait)
        if progress.due():
            progress.show(
                rate_line("recording", writer.samples, writer.bytes, time.monotonic() - started, inbox.extra())
            )
    for sub in subscribers:
        sub.undeclare()
    while (args.count is None or writer.samples < args.count) and inbox.write_next(None):
        pass


def _recording_metadata(exprs: list[str], keys: Keys) -> dict[str, str]:
    return {
        "keyexpr": " ".join(exprs),
        "prefix": keys.prefix,
        "host": socket.gethostname(),
        "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "tool": "hri record",
    }


def cmd_record(args: argparse.Namespace) -> int:
    from common.runner import setup_logging
    from common.transport import open_session, resolve

    resolve(args)
    keys = Keys(args.prefix)
    exprs = args.keyexpr or [f"{keys.prefix}/**"]
    if _check_keyexprs(exprs, "record") is None:
        return 2
    opened = _open_output(args)
    if opened is None:
        return 2
    out, stream = opened
    log = setup_logging("hri.record", args.log_level)
    stop = threading.Event()
    _stop_on_signals(stop)
    writer = SessionWriter(
        stream, keys, compression=args.compression, viewers=args.viewers, metadata=_recording_metadata(exprs, keys)
    )
    inbox = _Inbox(writer, int(args.max_backlog_mb * 1e6))
    session = open_session(args, log, stop)
    progress = Progress()
    started = time.monotonic()
    error = 0
    try:
        if session is not None:
            subscribers = [session.declare_subscriber(expr, inbox.on_sample) for expr in exprs]
            log.info("recording %s to %s (Ctrl-C to finish)", " ".join(repr(e) for e in exprs), out)
            _record_until_done(_Recording(inbox, args, stop, progress, started), subscribers)
    except OSError as exc:
        log.error("writing %s failed: %s; the file is incomplete", out, exc.strerror or exc)
        error = 1
    finally:
        try:
            writer.finish()
            stream.close()
        except OSError as exc:
            log.error("finishing %s failed: %s", out, exc.strerror or exc)
            error = 1
        if session is not None:
            session.close()
    elapsed = time.monotonic() - started
    progress.end(rate_line("recorded", writer.samples, writer.bytes, elapsed, inbox.extra()) + f" -> {out}")
    if writer.tally:
        print(key_table(writer.tally), file=sys.stderr, flush=True)
    return error


def _open_reader(args: argparse.Namespace) -> tuple[SessionReader, list[Any]] | None:
    only = _check_keyexprs(args.only or [], "replay")
    if only is None:
        return None
    try:
        return SessionReader(args.file), only
    except RecordingError as exc:
        print(f"hri replay: {exc}", file=sys.stderr)
        return None


def _selected_keys(reader: SessionReader, args: argparse.Namespace, keep: Callable[[str], bool], log: Any) -> dict:
    """The recorded keys to replay, with their sample counts; warns of what cannot be replayed."""
    info = reader.info
    for key, enc in reader.skipped_encodings.items():
        log.warning("skipping %s: message encoding %r is not a raw sample (RawSample or msgpack)", key, enc)
    if not info.complete:
        log.warning(
            "%s has no summary (the recorder did not finish it); replaying the %d readable samples",
            args.file,
            info.samples,
        )
    selected = {k: n for k, n in info.keys.items() if keep(k)}
    if not selected:
        what = f" matching {' '.join(args.only)}" if args.only else ""
        print(
            f"hri replay: nothing to replay{what} in {args.file} (keys: {', '.join(sorted(info.keys)) or 'none'})",
            file=sys.stderr,
        )
    return selected


@dataclass
class _Replay:
    """One replay's state: what it sends, how far it got (for the progress line and the summary)."""

    reader: SessionReader
    publishers: dict[str, Any]
    keep: Callable[[str], bool]
    args: argparse.Namespace
    total: int
    stop: threading.Event
    log: Any
    progress: Progress = field(default_factory=Progress)
    started: float = field(default_factory=time.monotonic)
    sent: int = 0
    sent_bytes: int = 0
    loops: int = 0

    def run(self) -> None:
        clock = ReplayClock(self.args.speed)
        while not self.stop.is_set():
            self.loops += 1
            clock.restart()
            self._one_pass(clock)
            if not self.args.loop:
                break

    def _one_pass(self, clock: ReplayClock) -> None:
        first_ns = None
        for i, msg in enumerate(self.reader.messages(self.keep), 1):
            delay = clock.wait_for(msg.log_ns)
            if delay > 0 and self.stop.wait(delay):
                break
            if self.stop.is_set():
                break
            self.publishers[msg.key].put(msg.payload)
            self.sent += 1
            self.sent_bytes += len(msg.payload)
            first_ns = msg.log_ns if first_ns is None else first_ns
            if self.progress.due():
                where = f", {(msg.log_ns - first_ns) / NS:.1f}/{self.reader.info.span_s:.1f} s recorded time"
                loop = f", loop {self.loops}" if self.args.loop else ""
                elapsed = time.monotonic() - self.started
                self.progress.show(
                    rate_line("replaying", self.sent, self.sent_bytes, elapsed, f" [{i}/{self.total}{where}{loop}]")
                )
        if self.reader.damaged:
            self.log.warning("stopped reading at damaged data in %s: %s", self.args.file, self.reader.damaged)


def _speed_text(speed: float) -> str:
    return "full speed" if speed == 0 else f"x{speed:g}"


def cmd_replay(args: argparse.Namespace) -> int:
    import zenoh

    from common.runner import setup_logging
    from common.transport import open_session, resolve

    resolve(args)
    opened = _open_reader(args)
    if opened is None:
        return 2
    reader, only = opened
    log = setup_logging("hri.replay", args.log_level)

    def keep(key: str) -> bool:
        return not only or any(zenoh.KeyExpr(key).intersects(o) for o in only)

    info = reader.info
    selected = _selected_keys(reader, args, keep, log)
    if not selected:
        reader.close()
        return 1
    total = sum(selected.values())
    log.info(
        "replaying %d samples on %d keys spanning %.1f s from %s at %s",
        total,
        len(selected),
        info.span_s,
        args.file,
        _speed_text(args.speed),
    )
    stop = threading.Event()
    _stop_on_signals(stop)
    session = open_session(args, log, stop)
    if session is None:
        reader.close()
        return 0
    publishers = {
        key: session.declare_publisher(
            key,
            encoding=zenoh.Encoding(ENCODING),
            congestion_control=zenoh.CongestionControl.BLOCK,
            priority=zenoh.Priority.DATA_HIGH,
        )
        for key in sorted(selected)
    }
    _wait_for_subscribers(publishers, args.wait_subscribers, stop, log)
    replay = _Replay(reader, publishers, keep, args, total, stop, log)
    error = 0
    try:
        replay.run()
    except zenoh.ZError as exc:
        log.error("publishing failed: %s", exc)
        error = 1
    finally:
        time.sleep(0.3)  # let the last puts leave the socket before the session goes away
        for pub in publishers.values():
            pub.undeclare()
        session.close()
        reader.close()
    elapsed = time.monotonic() - replay.started
    replay.progress.end(
        rate_line(
            "replayed",
            replay.sent,
            replay.sent_bytes,
            elapsed,
            f" on {len(selected)} keys (recording spans {info.span_s:.1f} s, "
            f"{_speed_text(args.speed)}"
            f"{f', {replay.loops} loops' if args.loop else ''})",
        )
    )
    return error


def _wait_for_subscribers(publishers: dict[str, Any], seconds: float, stop: threading.Event, log: Any) -> None:
    """Samples sent before anyone subscribes are lost; give late subscribers a moment."""
    if seconds <= 0:
        return
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and not stop.is_set():
        if any(_matching(pub) for pub in publishers.values()):
            return
        stop.wait(0.05)
    if not stop.is_set():
        log.warning("no subscriber on any replayed key after %.1f s; replaying anyway", seconds)


def _matching(pub: Any) -> bool:
    try:
        return bool(pub.matching_status.matching)
    except Exception:  # matching status unsupported by this zenoh build: do not block the replay
        return True
