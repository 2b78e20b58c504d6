"""Read a report back: the text of an element by id and the tables by id (stdlib parser)."""

from __future__ import annotations

from html.parser import HTMLParser


class ReportReader(HTMLParser):
    """Collects the text of every element with an id, and every table with an id as rows
    of cell texts (header row first)."""

    def __init__(self, text: str) -> None:
        super().__init__()
        self.texts: dict[str, str] = {}
        self.tables: dict[str, list[list[str]]] = {}
        self._open: list[tuple[str, str | None]] = []   # (tag, id)
        self._table: str | None = None
        self._cell: list[str] | None = None
        self.feed(text)
        self.close()

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        ident = dict(attrs).get("id")
        if tag in ("meta", "br", "img", "input", "path", "rect"):
            return
        self._open.append((tag, ident))
        if ident is not None:
            self.texts.setdefault(ident, "")
        if tag == "table" and ident:
            self._table = ident
            self.tables[ident] = []
        elif tag == "tr" and self._table:
            self.tables[self._table].append([])
        elif tag in ("td", "th") and self._table:
            self._cell = []

    def handle_endtag(self, tag: str) -> None:
        if tag in ("td", "th") and self._table and self._cell is not None:
            self.tables[self._table][-1].append("".join(self._cell).strip())
            self._cell = None
        if tag == "table":
            self._table = None
        while self._open:
            opened, _ = self._open.pop()
            if opened == tag:
                break

    def handle_data(self, data: str) -> None:
        if self._cell is not None:
            self._cell.append(data)
        for _, ident in self._open:
            if ident is not None:
                self.texts[ident] += data

    def rows(self, table_id: str) -> list[dict[str, str]]:
        """A table's body rows as {header: cell}."""
        header, *body = self.tables[table_id]
        return [dict(zip(header, row, strict=True)) for row in body]
