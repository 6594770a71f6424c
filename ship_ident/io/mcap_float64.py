"""The Float64 messages of one MCAP file, read straight from its chunks.

A bag of ``std_msgs/msg/Float64`` inputs at 10 Hz holds 36,000 messages an hour per topic. A general
reader builds an object per message, and reading an hour's bag took as long as a tenth of its
replay; here each chunk is decompressed once and its records are walked with ``struct``, each
wanted message's 12 bytes (the little-endian CDR header, then the double) read in place. The
messages come out in the order a general reader gives them: by log time, ties in file order.

Anything else returns None and the caller reads the file with the general reader (rosbags), which
also words every error: a topic of another type, a message not in little-endian CDR, a message
outside a chunk, a compression other than none, zstd or lz4, a checksum that does not match, a
file cut short.
"""

from __future__ import annotations

import mmap
import struct
import zlib
from pathlib import Path

FLOAT64 = "std_msgs/msg/Float64"
MAGIC = b"\x89MCAP0\r\n"
LITTLE_ENDIAN_CDR = b"\x00\x01\x00\x00"
RECORD_HEAD = struct.Struct("<BQ")  # opcode, content length
MESSAGE_HEAD = struct.Struct("<HIQQ")  # channel id, sequence, log time (ns), publish time (ns)
FLOAT64_DATA = struct.Struct("<4sd")  # CDR header, data
NAME = struct.Struct("<HI")  # a schema's id and its name's length
CHANNEL_HEAD = struct.Struct("<HHI")  # a channel's id, its schema's id and its topic's length
CHUNK_HEAD = struct.Struct("<QQQII")  # start and end time, uncompressed size, its CRC, compression's length
SIZE = struct.Struct("<Q")
FOOTER, SCHEMA, CHANNEL, MESSAGE, CHUNK = 0x02, 0x03, 0x04, 0x05, 0x06  # record opcodes
FLOAT64_RECORD = MESSAGE_HEAD.size + FLOAT64_DATA.size  # content length of a Float64 message record


class NotPlain(Exception):
    """The file holds something the plain reading does not handle."""


def float64_messages(path: Path, topics: set[str]) -> list[tuple[int, str, float]] | None:
    """(log time ns, topic, data) of every message on ``topics``, by log time (ties in file order),
    or None when the file is not plain Float64 CDR in chunks (see the module docstring).

    Parameters
    ----------
    path : Path
        One MCAP file.
    topics : set of str
        The wanted topics, each of type std_msgs/msg/Float64.

    Returns
    -------
    list of (int, str, float) or None
        The messages, or None where the general reader must read the file.
    """
    messages: list[tuple[int, str, float]] = []
    schemas: dict[int, str] = {}
    channels: dict[int, str | None] = {}  # id -> a wanted topic, None for another
    try:
        with path.open("rb") as stream, mmap.mmap(stream.fileno(), 0, access=mmap.ACCESS_READ) as data:
            if data[: len(MAGIC)] != MAGIC:
                raise NotPlain
            _records(data, len(MAGIC), len(data), schemas, channels, topics, messages, top=True)
    except (NotPlain, struct.error, OSError, ValueError, KeyError, UnicodeDecodeError):
        return None
    messages.sort(key=lambda message: message[0])
    return messages


def _wanted(topic: str, schema: str | None, topics: set[str]) -> str | None:
    """``topic`` when it is wanted (of type Float64, else NotPlain), None for another topic."""
    if topic not in topics:
        return None
    if schema != FLOAT64:
        raise NotPlain
    return topic


def _chunk(data, at: int) -> bytes:
    """The records of the chunk whose content starts at ``at``, decompressed and checked against
    its CRC (when it has one)."""
    _, _, size, crc, name_length = CHUNK_HEAD.unpack_from(data, at)
    at += CHUNK_HEAD.size
    compression = bytes(data[at : at + name_length]).decode()
    at += name_length
    (length,) = SIZE.unpack_from(data, at)
    at += SIZE.size
    packed = data[at : at + length]
    if len(packed) != length:
        raise NotPlain
    if compression == "":
        records = bytes(packed)
    elif compression == "zstd":
        import zstandard

        records = zstandard.decompress(packed, size)
    elif compression == "lz4":
        import lz4.frame

        records = lz4.frame.decompress(packed)
    else:
        raise NotPlain
    if len(records) != size or (crc and zlib.crc32(records) != crc):
        raise NotPlain
    return records


def _records(data, at: int, end: int, schemas: dict, channels: dict, topics: set[str], out: list, top: bool) -> None:
    """Walk the records of ``data[at:end]`` (the file's when ``top``, else a chunk's), keeping the
    schemas' names and the channels' topics and appending (log time ns, topic, data) of each wanted
    message in file order; a chunk's records are walked in turn, a message outside one is not plain."""
    head, message_head, float64 = RECORD_HEAD.unpack_from, MESSAGE_HEAD.unpack_from, FLOAT64_DATA.unpack_from
    while at < end:
        opcode, length = head(data, at)
        at += RECORD_HEAD.size
        if opcode == MESSAGE:
            if top:
                raise NotPlain
            channel, _, log_time, _ = message_head(data, at)
            topic = channels[channel]
            if topic is not None:
                if length != FLOAT64_RECORD:
                    raise NotPlain
                header, value = float64(data, at + MESSAGE_HEAD.size)
                if header != LITTLE_ENDIAN_CDR:
                    raise NotPlain
                out.append((log_time, topic, value))
        elif opcode == CHUNK and top:
            records = _chunk(data, at)
            _records(records, 0, len(records), schemas, channels, topics, out, top=False)
        elif opcode == SCHEMA:
            schema, size = NAME.unpack_from(data, at)
            schemas[schema] = bytes(data[at + NAME.size : at + NAME.size + size]).decode()
        elif opcode == CHANNEL:
            channel, schema, size = CHANNEL_HEAD.unpack_from(data, at)
            topic = bytes(data[at + CHANNEL_HEAD.size : at + CHANNEL_HEAD.size + size]).decode()
            channels[channel] = _wanted(topic, schemas.get(schema), topics)
        elif opcode == FOOTER and top:
            return
        at += length
    if at != end or top:  # a file ends with its footer; a chunk's records fill it
        raise NotPlain
