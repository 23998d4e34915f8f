"""A compressed capture that is cut short or damaged, in words (the readers of ``.gz`` logs
and dumps report it in ``errors``; the words are decoders/messages.py's, and the crate's
readers say the same: native/src/sources/compressed.rs)."""

from __future__ import annotations

import gzip
import zlib
from typing import Final

from decoders import messages as M

NOT_GZIP: Final = "Not a gzipped file"  # gzip.BadGzipFile's words for a start that is no gzip


def compression_damage(exc: BaseException, at_start: bool, after: str = "") -> str | None:
    """What the read error ``exc`` means: a file cut short, damaged data, or data that is no
    gzip at all (``at_start``: nothing was read before it); None for any other error. ``after``
    says where (" after N bytes")."""
    text = str(exc)
    if isinstance(exc, EOFError):  # gzip's: the stream ends before its end marker
        return f"{M.CAPTURE_GZIP_CUT}{after}; {M.CAPTURE_REST_LOST}"
    if isinstance(exc, gzip.BadGzipFile) and at_start and text.startswith(NOT_GZIP):
        return M.CAPTURE_NOT_GZIP
    if isinstance(exc, gzip.BadGzipFile | zlib.error):
        return f"{M.CAPTURE_GZIP_DAMAGED}{after} ({text}); {M.CAPTURE_REST_LOST}"
    return None
