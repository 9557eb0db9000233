"""What a log may cost to decompress, checked before rosbags reads it.

rosbags decompresses a whole chunk at once, trusting the chunk: a 64 kB ``.mcap`` holding one
zstd chunk of zeros cost 4.3 GB of memory and two minutes. The chunk records say how large their
content is (an mcap chunk's ``uncompressed_size``, a ROS 1 chunk's ``size``; a zstd frame's own
content size too, which is what zstd actually produces), so walking the records, without
decompressing anything, bounds the cost: a log whose chunks add up to more than
:data:`MAX_EXPANSION` times its size and more than :data:`MAX_UNCOMPRESSED_BYTES` is refused.
A ROS 1 chunk's bz2 or lz4 stream carries no size of its own, so it is decompressed once here,
in pieces and never past what the chunk declares: a chunk that holds more than it declares is
refused before rosbags, which trusts the declaration, decompresses it whole."""

from __future__ import annotations

import struct
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import BinaryIO

from estimator.errors import LogError

MAX_EXPANSION = 200
"""Real logs compress 2-10x; zeros compress ~30 000x with zstd."""
MAX_UNCOMPRESSED_BYTES = 1 << 30
"""Below this total any ratio is accepted (a small, very regular log)."""

_MCAP_CHUNK = 0x06
_ZSTD_MAGIC = b"\x28\xb5\x2f\xfd"


def check_decompressed_size(source: Path) -> None:
    """A one-line :class:`LogError` naming the file if the log (a ``.mcap``, a ROS 1 ``.bag``,
    or a ROS 2 bag folder's ``.mcap`` files) would decompress to out of proportion to its size."""
    files = sorted(source.glob("*.mcap")) if source.is_dir() else [source]
    for path in files:
        if path.suffix.lower() == ".mcap":
            _check(path, _mcap_chunk_sizes)
        elif path.suffix.lower() == ".bag":
            _check(path, _ros1_chunk_sizes)


def _check(path: Path, chunk_sizes: Callable[[BinaryIO, int], Iterator[int]]) -> None:
    size = path.stat().st_size
    limit = max(MAX_EXPANSION * size, MAX_UNCOMPRESSED_BYTES)
    total = 0
    try:
        with path.open("rb") as fh:
            for declared in chunk_sizes(fh, size):
                total += declared
                if total > limit:
                    raise LogError(
                        path,
                        f"refused: its chunks decompress to more than {total / 1e9:.1f} GB "
                        f"({total / max(size, 1):.0f}x the file's {size} bytes); "
                        "a corrupt or hostile log",
                    )
    except OSError as exc:
        raise LogError(path, f"cannot read the file ({exc.strerror or exc})") from None
    except ChunkLies as exc:
        raise LogError(
            path,
            f"refused: a compressed chunk {exc} (it would decompress past its size); "
            "a corrupt or hostile log",
        ) from None
    except (struct.error, ValueError):
        return  # malformed records: rosbags reports them (it stops before a chunk it cannot frame)


def _mcap_chunk_sizes(fh: BinaryIO, size: int) -> Iterator[int]:
    fh.seek(8)
    pos = 8
    while pos + 9 <= size:
        op, length = struct.unpack("<BQ", fh.read(9))
        if op == _MCAP_CHUNK:
            head = fh.read(min(length, 28 + 4))
            declared = struct.unpack_from("<Q", head, 16)[0]
            (name_len,) = struct.unpack_from("<I", head, 28)
            if name_len > 64:
                raise ValueError("compression name")
            compression = fh.read(name_len)
            fh.read(8)
            frame = fh.read(18)
            yield max(declared, _zstd_content_size(frame) if compression == b"zstd" else 0)
        pos += 9 + length
        if op == 0x0F or length > size:  # data end: the summary's chunk indexes repeat these
            return
        fh.seek(pos)


def _zstd_content_size(frame: bytes) -> int:
    if not frame.startswith(_ZSTD_MAGIC):
        return 0
    try:
        import zstandard

        return max(int(zstandard.frame_content_size(frame)), 0)
    except Exception:  # unknown or malformed header: rosbags' own check applies
        return 0


def _ros1_chunk_sizes(fh: BinaryIO, size: int) -> Iterator[int]:
    pos = 13
    fh.seek(pos)
    while pos + 8 <= size:
        (header_len,) = struct.unpack("<I", fh.read(4))
        if header_len > min(size, 1 << 20):
            raise ValueError("header length")
        fields = _ros1_fields(fh.read(header_len))
        (data_len,) = struct.unpack("<I", fh.read(4))
        if fields.get("op") == b"\x05" and len(fields.get("size", b"")) == 4:
            declared = struct.unpack("<I", fields["size"])[0]
            compression = fields.get("compression", b"none")
            if compression in (b"bz2", b"lz4") and data_len <= size:
                _within_declared(fh.read(data_len), compression, declared)
            yield declared
        pos += 8 + header_len + data_len
        fh.seek(pos)


def _within_declared(data: bytes, compression: bytes, declared: int) -> None:
    """Decompress a ROS 1 chunk in bounded pieces; a ``ValueError`` (read as a lying chunk by
    :func:`_check`) if it holds more than ``declared`` bytes."""
    if compression == b"bz2":
        import bz2

        out = bz2.BZ2Decompressor().decompress(data, max_length=declared + 1)
    else:
        import lz4.frame

        out = lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=declared + 1)
    if len(out) > declared:
        raise ChunkLies(f"holds more than its declared {declared} bytes")


class ChunkLies(ValueError):
    """A chunk that decompresses to more than it declares."""


def _ros1_fields(header: bytes) -> dict[str, bytes]:
    fields: dict[str, bytes] = {}
    i = 0
    while i + 4 <= len(header):
        (n,) = struct.unpack_from("<I", header, i)
        name, _, value = header[i + 4 : i + 4 + n].partition(b"=")
        fields[name.decode("ascii", "replace")] = value
        i += 4 + n
    return fields
