"""At-rest encodings of one event's JSON: none, gzip, zstd, zstd with a dictionary.

Measured on this project's events (docs/benchmarks.md): zstd with a 16 KiB dictionary
trained on UDM events stores an event in about a tenth of its JSON size and is faster
to write than raw JSON (fewer bytes reach the WAL); zstd without a dictionary gains
under 3x, gzip less, so ``zstd`` always means zstd with the dictionary. The codec and
dictionary id are stored with each row, so changing ``QUEUE_COMPRESSION`` never makes
old rows unreadable.

python-zstandard's compressors and decompressors must not be shared between threads:
each thread that encodes or decodes gets its own.
"""

from __future__ import annotations

import functools
import gzip
import threading
import zlib
from dataclasses import dataclass
from importlib import resources

import zstandard

NONE, GZIP, ZSTD_DICT = 0, 1, 2
CODEC_BY_SETTING = {"none": NONE, "gzip": GZIP, "zstd": ZSTD_DICT}
ZSTD_LEVEL = 3
GZIP_LEVEL = 6
DICTIONARY_FILE = "udm-events.zdict"


@dataclass(frozen=True)
class Encoded:
    codec: int
    dict_id: int | None
    body: bytes


@functools.cache
def packaged_dictionary() -> tuple[int, bytes]:
    """The zstd dictionary shipped with this version: (dict_id, content)."""
    content = resources.files("phytrace_edge.queue.encoding").joinpath(DICTIONARY_FILE).read_bytes()
    return zstandard.ZstdCompressionDict(content).dict_id(), content


class _PerThread(threading.local):
    compressor: zstandard.ZstdCompressor | None = None
    decompressors: dict[int, zstandard.ZstdDecompressor]

    def __init__(self) -> None:
        self.decompressors = {}


class Codecs:
    """Encoders for one setting, decoders for every codec and known dictionary."""

    def __init__(self, setting: str) -> None:
        self.codec = CODEC_BY_SETTING[setting]
        self._dict_id, content = packaged_dictionary()
        self._dictionaries: dict[int, zstandard.ZstdCompressionDict] = {}
        self.add_dictionary(self._dict_id, content)
        self._local = _PerThread()

    @property
    def dict_id(self) -> int:
        return self._dict_id

    def add_dictionary(self, dict_id: int, content: bytes) -> None:
        """Make a dictionary stored in the database usable for decoding."""
        self._dictionaries[dict_id] = zstandard.ZstdCompressionDict(content)

    def encode(self, json_bytes: bytes) -> Encoded:
        if self.codec == ZSTD_DICT:
            return Encoded(ZSTD_DICT, self._dict_id, self._compressor().compress(json_bytes))
        if self.codec == GZIP:
            return Encoded(GZIP, None, gzip.compress(json_bytes, GZIP_LEVEL, mtime=0))
        return Encoded(NONE, None, json_bytes)

    def decode(self, codec: int, dict_id: int | None, body: bytes) -> bytes:
        if codec == NONE:
            return bytes(body)
        if codec == GZIP:
            return zlib.decompress(body, wbits=31)
        if codec == ZSTD_DICT and dict_id is not None:
            return self._decompressor(dict_id).decompress(body)
        raise ValueError(f"unknown codec {codec}")

    def _compressor(self) -> zstandard.ZstdCompressor:
        compressor = self._local.compressor
        if compressor is None:
            compressor = zstandard.ZstdCompressor(
                level=ZSTD_LEVEL, dict_data=self._dictionaries[self._dict_id]
            )
            self._local.compressor = compressor
        return compressor

    def _decompressor(self, dict_id: int) -> zstandard.ZstdDecompressor:
        decompressor = self._local.decompressors.get(dict_id)
        if decompressor is None:
            if dict_id not in self._dictionaries:
                raise ValueError(f"zstd dictionary {dict_id} is not in the queue database")
            decompressor = zstandard.ZstdDecompressor(dict_data=self._dictionaries[dict_id])
            self._local.decompressors[dict_id] = decompressor
        return decompressor
