"""A results archive's URL (`--db URL`) as it may be shown: without its password.

A light module (standard library only): the commands print and store the URL before and
without opening the archive (hostpc.archive imports SQLAlchemy), and the archive's own
messages name it the same way.
"""

from __future__ import annotations


def redacted_url(url: str) -> str:
    """`url` without a password (`postgresql://USER:SECRET@HOST/DB` -> `postgresql://USER@HOST/DB`):
    what a run folder or a printed command may hold. The password comes from PGPASSWORD
    or ~/.pgpass (hostpc.archive.database)."""
    from urllib.parse import urlsplit, urlunsplit

    parts = urlsplit(url)
    if parts.password is None:
        return url
    host = parts.hostname or ""
    netloc = (f"{parts.username}@" if parts.username else "") + host + (
        f":{parts.port}" if parts.port else "")
    return urlunsplit(parts._replace(netloc=netloc))
