"""One check for the header every PerSival file and folder carries: its format name and version.

A response or moment table, a campaign store, a training-data folder, an export's metadata.json
and a surrogate's surrogate.json each start with ``{"format": NAME, <version key>: N, ...}``.
:func:`check_header` refuses a header of another kind or version with one message of the same
shape everywhere, raised as the caller's own error class (its callers catch those).

>>> check_header({"format": "persival-response-table", "version": 3}, "t/header.json", "response table",
...              "persival-response-table", 3)["version"]
3
>>> check_header({"format": "persival-response-table", "version": 2}, "t/header.json", "response table",
...              "persival-response-table", 3, advice="build it again")
Traceback (most recent call last):
ValueError: t/header.json is a response table of format version 2; this PerSival reads version 3: build it again
"""

from __future__ import annotations

from collections.abc import Iterable

__all__ = ["check_header"]


def check_header(header, where, kind: str, format_name: str | None, versions: int | Iterable[int],
                 error: type[Exception] = ValueError, version_key: str = "version", advice: str = "") -> dict:
    """``header`` (a dict read from ``where``) is a ``kind`` of ``format_name`` (None: no format
    name to check) and one of ``versions``; returns it. ``advice``: what to do about another version."""
    readable = sorted({versions} if isinstance(versions, int) else set(versions))
    if not isinstance(header, dict) or (format_name is not None and header.get("format") != format_name):
        found = header.get("format") if isinstance(header, dict) else type(header).__name__
        raise error(f"{where} is not a {kind} (format {found!r}, expected {format_name!r})")
    version = header.get(version_key)
    if version not in readable:
        reads = " or ".join(str(v) for v in readable)
        raise error(f"{where} is a {kind} of format version {version!r}; this PerSival reads version {reads}"
                    + (f": {advice}" if advice else ""))
    return header
