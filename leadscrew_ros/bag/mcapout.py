# SPDX-License-Identifier: Apache-2.0
"""A lean chunked MCAP writer for many small messages (the replay's annotated log).

The file is laid out as `mcap.writer.Writer` lays it out with its defaults (header; schemas,
channels and messages in zstd chunks, each followed by its message indexes; data end; a summary
with the schemas, channels, statistics, chunk indexes and summary offsets; footer, CRCs of
chunks and summary), so every MCAP reader reads it the same way. What differs is the cost per
message: a message is one `struct` pack appended to the chunk buffer (no record objects), and
the message indexes and statistics are built per chunk, not per message.

Attachments and Metadata records (`add_attachment`, `add_metadata`) go after the chunks, with
their indexes in the summary, so `mcap` readers list them; `reopen` takes a finished file back
(summary read, file cut back to its data) to add more of them: the replay's report.
"""

from __future__ import annotations

import struct
import zlib
from collections import defaultdict
from typing import BinaryIO

import zstandard
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    McapRecord,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)
from mcap.writer import MCAP0_MAGIC

CHUNK_BYTES = 1 << 20  # a chunk is compressed once its messages reach this size
ZSTD_LEVEL = 1  # chunks of small CDR messages: level 1 is ~2x level 3's speed
# Message record: opcode, record length, channel id, sequence, log time, publish time.
_MESSAGE = struct.Struct("<BQHIQQ")
_MESSAGE_FIELDS = 2 + 4 + 8 + 8
_INDEX_HEAD = struct.Struct("<BQHI")  # message index: opcode, length, channel, bytes
_FOOTER_TAIL = 1 + 8 + 20 + len(MCAP0_MAGIC)  # footer record and closing magic [bytes]
_DATA_END_LENGTH = 1 + 8 + 4  # data end record [bytes]


class McapOut:
    """Writes an MCAP file to `stream` (a binary file opened for writing; not closed here).

    Parameters
    ----------
    stream : BinaryIO
        Where the file goes, from its start.
    profile, library : str
        The header's profile (e.g. 'ros2') and writing library.
    chunk_bytes : int
        Uncompressed chunk size [bytes] at which a chunk is written.
    """

    def __init__(
        self, stream: BinaryIO, profile: str, library: str, chunk_bytes: int = CHUNK_BYTES
    ):
        self._setup(stream, chunk_bytes)
        stream.write(MCAP0_MAGIC)
        self._write(Header(profile, library))

    def _setup(self, stream: BinaryIO, chunk_bytes: int) -> None:
        self.stream, self.chunk_bytes = stream, chunk_bytes
        self._zstd = zstandard.ZstdCompressor(level=ZSTD_LEVEL)
        self.schemas: list[Schema] = []
        self.channels: list[Channel] = []
        self._chunk = bytearray()
        self._index: defaultdict[int, list[int]] = defaultdict(list)  # channel -> t, offset
        self._start: int | None = None  # log time range of the chunk [ns]
        self._end = 0
        self._chunk_indexes: list[ChunkIndex] = []
        self._counts: defaultdict[int, int] = defaultdict(int)
        self._first: int | None = None  # log time range of the file [ns]
        self._last = 0
        self._attachments: list[AttachmentIndex] = []
        self._metadata: list[MetadataIndex] = []

    @classmethod
    def reopen(cls, stream: BinaryIO) -> McapOut:
        """A file this class finished, taken back to add attachments and metadata.

        Parameters
        ----------
        stream : BinaryIO
            The file, opened for reading and writing ('r+b'). Its summary is read and the file
            is cut back to the end of its data: it is whole again only after `finish`.

        Returns
        -------
        McapOut
            The writer, with the file's schemas, channels, chunks, attachments and metadata.

        Raises
        ------
        ValueError
            The file has no summary, or does not end its data where this class does.
        """
        try:
            summary = make_reader(stream).get_summary()
            stream.seek(stream.seek(0, 2) - _FOOTER_TAIL)
            data_end = struct.unpack_from("<Q", stream.read(_FOOTER_TAIL), 9)[0] - _DATA_END_LENGTH
            stream.seek(data_end)
            finished = (
                summary is not None
                and summary.statistics is not None
                and stream.read(1) == bytes([Opcode.DATA_END])
            )
        except Exception:  # the mcap reader raises several unrelated types
            finished = False
        if not finished:
            raise ValueError("not an MCAP file finished by McapOut")
        assert summary is not None and summary.statistics is not None  # as `finished` found
        out = cls.__new__(cls)
        out._setup(stream, CHUNK_BYTES)
        out.schemas = [summary.schemas[i] for i in sorted(summary.schemas)]
        out.channels = [summary.channels[i] for i in sorted(summary.channels)]
        out._chunk_indexes = list(summary.chunk_indexes)
        out._attachments = list(summary.attachment_indexes)
        out._metadata = list(summary.metadata_indexes)
        stats = summary.statistics
        out._counts.update(stats.channel_message_counts)
        if stats.chunk_count:
            out._first, out._last = stats.message_start_time, stats.message_end_time
        stream.seek(data_end)
        stream.truncate()
        return out

    def _write(self, *records: McapRecord) -> int:
        """Write `records` at the end of the file; returns their length [bytes]."""
        rb = RecordBuilder()
        for r in records:
            r.write(rb)
        data = rb.end()
        self.stream.write(data)
        return len(data)

    def _record(self, record: Schema | Channel) -> None:
        """A schema or channel record, into the chunk (as `mcap.writer.Writer` does)."""
        rb = RecordBuilder()
        record.write(rb)
        self._chunk += rb.end()

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        """A new schema; returns its id (1, 2, ...)."""
        schema = Schema(id=len(self.schemas) + 1, name=name, encoding=encoding, data=data)
        self.schemas.append(schema)
        self._record(schema)
        return schema.id

    def register_channel(
        self, topic: str, message_encoding: str, schema_id: int, metadata: dict[str, str]
    ) -> int:
        """A new channel; returns its id (1, 2, ...)."""
        channel = Channel(
            id=len(self.channels) + 1,
            topic=topic,
            message_encoding=message_encoding,
            schema_id=schema_id,
            metadata=dict(metadata),
        )
        self.channels.append(channel)
        self._record(channel)
        return channel.id

    def add_message(
        self, channel_id: int, log_time_ns: int, data: bytes, publish_time_ns: int, sequence: int
    ) -> None:
        """One message; the chunk is written once it is `chunk_bytes` long."""
        chunk = self._chunk
        index = self._index[channel_id]
        index.append(log_time_ns)
        index.append(len(chunk))
        chunk += _MESSAGE.pack(
            Opcode.MESSAGE,
            _MESSAGE_FIELDS + len(data),
            channel_id,
            sequence,
            log_time_ns,
            publish_time_ns,
        )
        chunk += data
        if self._start is None or log_time_ns < self._start:
            self._start = log_time_ns
        if log_time_ns > self._end:
            self._end = log_time_ns
        if len(chunk) >= self.chunk_bytes:
            self._finish_chunk()

    def add_attachment(
        self, name: str, media_type: str, data: bytes, log_time_ns: int, create_time_ns: int
    ) -> None:
        """One attachment (e.g. 'episodes.json', 'application/json'), after the messages so
        far; times [ns] as MCAP defines them (log time: on the messages' clock)."""
        self._finish_chunk()
        offset = self.stream.tell()
        length = self._write(
            Attachment(
                create_time=create_time_ns,
                log_time=log_time_ns,
                name=name,
                media_type=media_type,
                data=data,
            )
        )
        self._attachments.append(
            AttachmentIndex(
                offset=offset,
                length=length,
                log_time=log_time_ns,
                create_time=create_time_ns,
                data_size=len(data),
                name=name,
                media_type=media_type,
            )
        )

    def add_metadata(self, name: str, metadata: dict[str, str]) -> None:
        """One Metadata record (a string -> string map), after the messages so far."""
        self._finish_chunk()
        offset = self.stream.tell()
        length = self._write(Metadata(name=name, metadata=dict(metadata)))
        self._metadata.append(MetadataIndex(offset=offset, length=length, name=name))

    def _finish_chunk(self) -> None:
        if not self._index:  # no message yet: schemas and channels wait
            return
        assert self._start is not None  # set by the chunk's first message
        data = bytes(self._chunk)
        compressed = self._zstd.compress(data)
        start = self.stream.tell()
        length = self._write(
            Chunk(
                message_start_time=self._start,
                message_end_time=self._end,
                uncompressed_size=len(data),
                uncompressed_crc=zlib.crc32(data),
                compression="zstd",
                data=compressed,
            )
        )
        offsets, index = {}, bytearray()
        for channel_id, entries in self._index.items():
            offsets[channel_id] = start + length + len(index)
            body = struct.pack(f"<{len(entries)}Q", *entries)
            index += _INDEX_HEAD.pack(Opcode.MESSAGE_INDEX, 6 + len(body), channel_id, len(body))
            index += body
            self._counts[channel_id] += len(entries) // 2
        self.stream.write(index)
        self._chunk_indexes.append(
            ChunkIndex(
                message_start_time=self._start,
                message_end_time=self._end,
                chunk_start_offset=start,
                chunk_length=length,
                message_index_offsets=offsets,
                message_index_length=len(index),
                compression="zstd",
                compressed_size=len(compressed),
                uncompressed_size=len(data),
            )
        )
        self._first = self._start if self._first is None else min(self._first, self._start)
        self._last = max(self._last, self._end)
        self._chunk.clear()
        self._index.clear()
        self._start, self._end = None, 0

    def finish(self) -> None:
        """The last chunk, the summary and the footer."""
        self._finish_chunk()  # schemas and channels after it: in the summary only
        self._write(DataEnd(0))
        summary_start = self.stream.tell()
        rb, offsets = RecordBuilder(), []
        stats = Statistics(
            message_count=sum(self._counts.values()),
            schema_count=len(self.schemas),
            channel_count=len(self.channels),
            attachment_count=len(self._attachments),
            metadata_count=len(self._metadata),
            chunk_count=len(self._chunk_indexes),
            message_start_time=self._first or 0,
            message_end_time=self._last,
            channel_message_counts=dict(self._counts),
        )
        for opcode, group in (
            (Opcode.SCHEMA, self.schemas),
            (Opcode.CHANNEL, self.channels),
            (Opcode.STATISTICS, [stats]),
            (Opcode.CHUNK_INDEX, self._chunk_indexes),
            (Opcode.ATTACHMENT_INDEX, self._attachments),
            (Opcode.METADATA_INDEX, self._metadata),
        ):
            group_start = rb.count
            for record in group:
                record.write(rb)
            offsets.append(
                SummaryOffset(
                    group_opcode=opcode,
                    group_start=summary_start + group_start,
                    group_length=rb.count - group_start,
                )
            )
        offset_start = summary_start + rb.count
        for o in offsets:
            o.write(rb)
        summary = rb.end()
        crc = zlib.crc32(
            struct.pack("<BQQQ", Opcode.FOOTER, 20, summary_start, offset_start),
            zlib.crc32(summary),
        )
        self.stream.write(summary)
        self._write(
            Footer(summary_start=summary_start, summary_offset_start=offset_start, summary_crc=crc)
        )
        self.stream.write(MCAP0_MAGIC)
