"""The one name for raw JSON at a boundary.

zerocal's shell passes typed values (frozen dataclasses, pydantic models). A JSON object
exists only where a document is read or written: a file face parsing a dataset, the journal
reading a line, result.json being emitted. Those boundary functions, and only those, take or
return a ``JsonObject``; everything past the boundary is typed. ``grep JsonObject`` therefore
lists the boundaries, and ``grep "dict\\[str, Any\\]"`` should find almost nothing.
"""
from __future__ import annotations

from typing import Any

JsonObject = dict[str, Any]
"""A parsed JSON object (``json.loads`` of an object) or one about to be dumped."""
