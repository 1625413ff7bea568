"""The settings tables of the docs, generated from the declarations (common/settings.py).

Each page holds `<!-- settings: NAME -->` … `<!-- /settings -->` blocks; NAME is a service (the flags its own
parser declares) or `common` (the flags every service shares, from common/runner.py's `service_parser`).
`python -m hri.settingsdoc` rewrites the blocks; `--check` only compares (tests/test_settings.py runs it).
"""

from __future__ import annotations

import argparse
import importlib
import re
import sys
from pathlib import Path

from common.runner import service_parser
from common.settings import Setting, declared, table
from common.stack import NODES

DOCS = Path(__file__).resolve().parent.parent / "docs"
# where each table lives
PAGES = {
    "fusion": "fusion.md",
    "vision": "vision.md",
    "gesture": "gesture.md",
    "speech": "speech.md",
    "camera": "foundation.md",
    "ros2": "ros2.md",
    "common": "foundation.md",
}
BLOCK = re.compile(r"(<!-- settings: (\w+) -->\n)(.*?)(<!-- /settings -->)", re.S)


def shared_settings() -> list[Setting]:
    """The flags every node's parser has (--max-pixels only where a node reads images: common/stack.py)."""
    per_node = [declared(service_parser(n.name, "")) for n in NODES]
    return [s for s in per_node[0] if all(s in other for other in per_node[1:])]


def settings_for(name: str) -> list[Setting]:
    shared = shared_settings()
    if name == "common":
        return shared
    parser = importlib.import_module(f"services.{name}.__main__").build_parser()
    return [s for s in declared(parser) if s not in shared]


def render(text: str) -> str:
    return BLOCK.sub(lambda m: m.group(1) + table(settings_for(m.group(2))) + m.group(4), text)


def missing(pages: dict[str, str] = PAGES) -> list[str]:
    """The names whose page has no block for them."""
    return [name for name, page in pages.items() if f"<!-- settings: {name} -->" not in (DOCS / page).read_text()]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--check", action="store_true", help="only compare; exit 1 when a page's table is stale")
    args = ap.parse_args(argv)
    absent = missing()
    if absent:
        print(
            "no settings table for: "
            + ", ".join(f"{n} (add `<!-- settings: {n} -->` `<!-- /settings -->` to docs/{PAGES[n]})" for n in absent),
            file=sys.stderr,
        )
        return 1
    stale = []
    for page in sorted(set(PAGES.values())):
        path = DOCS / page
        text = path.read_text()
        new = render(text)
        if new == text:
            continue
        if args.check:
            stale.append(f"docs/{page}")
        else:
            path.write_text(new)
            print(f"updated {path}")
    if stale:
        print(
            f"{', '.join(stale)}: settings tables differ from the declarations: run `python -m hri.settingsdoc`",
            file=sys.stderr,
        )
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
