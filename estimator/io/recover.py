"""The readable part of an ``.mcap`` that was cut off: a recorder killed, a disk filled, a copy
stopped. Such a file has no footer, and rosbags refuses it whole ("File end magic is invalid"),
though every record before the cut is intact. Its records are read in order with the mcap
project's own stream reader up to the first that is not whole, and written to a complete file
with its writer; rosbags then reads that as it reads any log, and the log says what was lost."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from estimator.errors import LogError

MCAP_MAGIC = b"\x89MCAP0\r\n"
"""The first and the last bytes of an mcap file (the last only once its footer is written)."""
_HEADER_OPCODE = b"\x01"


@dataclass(frozen=True)
class Recovered:
    """The whole records of a cut-off ``.mcap``, written to ``path``."""

    path: Path
    messages: int
    lost_bytes: int
    """bytes after the last whole record (a chunk cut in two is lost whole)"""


def ends_whole(path: Path) -> bool:
    """The file ends with the mcap magic (its footer was written)."""
    size = path.stat().st_size
    if size < 2 * len(MCAP_MAGIC):
        return False
    with path.open("rb") as fh:
        fh.seek(-len(MCAP_MAGIC), 2)
        return fh.read() == MCAP_MAGIC


def recover_mcap(source: Path, out: Path) -> Recovered:
    """Copy the schemas, channels and messages of ``source`` that lie in whole records (chunk
    CRCs checked) into a complete ``.mcap`` at ``out``. A one-line :class:`LogError` when not
    one message is whole."""
    from mcap.records import Channel, Header, Message, Schema
    from mcap.stream_reader import StreamReader
    from mcap.writer import CompressionType, Writer

    size = source.stat().st_size
    with source.open("rb") as fh:
        if fh.read(len(MCAP_MAGIC) + 1)[len(MCAP_MAGIC) :] != _HEADER_OPCODE:
            raise LogError(
                source,
                "cannot read the bag, it is truncated or corrupt (no mcap footer, and no mcap "
                "header after the magic)",
            )
    schemas: dict[int, int] = {}
    channels: dict[int, int] = {}
    messages, whole_to, reason = 0, 0, ""
    with source.open("rb") as src, out.open("wb") as dst:
        writer = Writer(dst, compression=CompressionType.NONE)
        started = False
        try:
            for record in StreamReader(src, validate_crcs=True).records:
                if isinstance(record, Header):
                    writer.start(profile=record.profile, library=record.library)
                    started = True
                elif isinstance(record, Schema):
                    schemas[record.id] = writer.register_schema(
                        record.name, record.encoding, record.data
                    )
                elif isinstance(record, Channel):
                    channels[record.id] = writer.register_channel(
                        record.topic,
                        record.message_encoding,
                        schemas.get(record.schema_id, 0),
                        dict(record.metadata),
                    )
                elif isinstance(record, Message) and record.channel_id in channels:
                    writer.add_message(
                        channels[record.channel_id],
                        record.log_time,
                        record.data,
                        record.publish_time,
                        record.sequence,
                    )
                    messages += 1
                whole_to = src.tell()
        except Exception as exc:  # the cut (or damage): what came before it is kept
            reason = str(exc) or type(exc).__name__
        if not started or messages == 0:
            raise LogError(
                source,
                "cannot read the bag, it is truncated or corrupt (no mcap footer, and not one "
                f"whole message before the damage{': ' + reason if reason else ''})",
            )
        writer.finish()  # type: ignore[no-untyped-call]
    return Recovered(out, messages, max(size - whole_to, 0))
