"""Fill a results page with the tables the benchmark scripts wrote (never hand-copied).

A page marks where a table goes with two comment lines naming the table file, relative to
the page's folder::

    <!-- table: tables/rooms.md -->
    ... (replaced by the file's contents) ...
    <!-- end table -->

Usage: ``python benchmarks/results_page.py docs/results/learned-arbitration.md`` (after
the scripts that write the tables). A table file that does not exist yet leaves a line
saying so.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

BLOCK = re.compile(r"(<!-- table: (?P<path>[^ ]+) -->\n)(?P<body>.*?)(<!-- end table -->)",
                   re.S)


def fill(page: Path) -> str:
    """The page's text with every marked table's block replaced by the table file."""
    text = page.read_text()

    def sub(m: re.Match[str]) -> str:
        table = page.parent / m.group("path")
        body = table.read_text() if table.is_file() else f"(not measured yet: {table})\n"
        return f"{m.group(1)}{body}{m.group(4)}"

    return BLOCK.sub(sub, text)


def main(argv: list[str] | None = None) -> int:
    for name in argv if argv is not None else sys.argv[1:]:
        page = Path(name)
        page.write_text(fill(page))
        print(f"filled {page}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
