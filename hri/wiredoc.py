"""docs/wire.md's field tables and the recordings' JSON Schemas, generated from common/schema.py.

    python -m hri.wiredoc            # rewrite the generated tables in docs/wire.md
    python -m hri.wiredoc --check    # exit 1 when docs/wire.md differs from the schemas

A table sits between `<!-- fields: Name -->` and `<!-- /fields -->`; the prose around it is kept as written.
"""

from __future__ import annotations

import argparse
import re
import sys
import types
from pathlib import Path
from typing import Annotated, Any, Literal, Union, get_args, get_origin

import msgspec

from common import schema

DOC = Path(__file__).resolve().parent.parent / "docs" / "wire.md"
_SECTION = re.compile(r"(<!-- fields: (\w+) -->\n)(.*?)(<!-- /fields -->)", re.S)


def _number(value: float) -> str:
    return f"{value:g}" if abs(value) < 1e300 else ""


def _constraints(metas: list[msgspec.Meta]) -> tuple[str, str]:
    """(range text, description) of a field's Meta annotations."""
    rng, desc = [], ""
    for m in metas:
        if m.description:
            desc = m.description
        lo = (">", m.gt) if m.gt is not None else ("≥", m.ge) if m.ge is not None else None
        hi = ("<", m.lt) if m.lt is not None else ("≤", m.le) if m.le is not None else None
        if lo and hi and lo[0] == "≥" and hi[0] == "≤" and _number(lo[1]) and _number(hi[1]):
            rng.append("0–1" if (lo[1], hi[1]) == (0.0, 1.0) else f"{_number(lo[1])}–{_number(hi[1])}")
            continue
        for sign, bound in filter(None, (lo, hi)):
            if _number(bound):
                rng.append(f"{sign} {_number(bound)}")
        if m.min_length is not None and m.min_length == m.max_length:
            rng.append(f"length {m.min_length}")
        elif m.min_length == 1 and m.max_length is None:
            rng.append("non-empty")
    return " ".join(rng), desc


def type_text(tp: Any) -> tuple[str, str]:
    """(wire type as docs/wire.md writes it, description) of an annotation."""
    metas: list[msgspec.Meta] = []
    while get_origin(tp) is Annotated:
        tp, *extra = get_args(tp)
        metas += [m for m in extra if isinstance(m, msgspec.Meta)]
    rng, desc = _constraints(metas)
    origin = get_origin(tp)
    if origin in (Union, types.UnionType):
        inner = [a for a in get_args(tp) if a is not type(None)]
        text, inner_desc = type_text(inner[0])
        text = f"{text}\\|nil"
        desc = desc or inner_desc
    elif origin is Literal:
        text = " \\| ".join(f'`"{v}"`' for v in get_args(tp))
    elif origin is list:
        item, item_desc = type_text(get_args(tp)[0])
        text = f"[{item}]"
    elif origin is dict:
        text = f"{{str: {type_text(get_args(tp)[1])[0]}}}"
    elif isinstance(tp, type) and issubclass(tp, msgspec.Struct):
        text = tp.__name__
    else:
        text = {int: "int", float: "float", str: "str", bool: "bool", bytes: "bin"}.get(
            tp, getattr(tp, "__name__", str(tp))
        )
    if rng == "0–1":
        text = "0–1"
    elif rng:
        text = f"{text} {rng}"
    return text, desc


def table(cls: type[msgspec.Struct]) -> str:
    rows = ["| field | type | |", "|---|---|---|"]
    envelope = (
        {f.name for f in msgspec.structs.fields(schema.Sample)}
        if issubclass(cls, schema.Sample) and cls is not schema.Sample
        else set()
    )
    for f in msgspec.structs.fields(cls):
        if f.name in envelope:
            continue
        text, desc = type_text(f.type)
        optional = "" if f.required else " (optional)"
        rows.append(f"| `{f.name}` | {text}{optional} | {desc} |")
    return "\n".join(rows) + "\n"


def documented_structs() -> dict[str, type[msgspec.Struct]]:
    """Every struct that appears on the wire, by name (samples and the maps nested in them)."""
    found: dict[str, type[msgspec.Struct]] = {}

    def visit(tp: Any) -> None:
        if isinstance(tp, type) and issubclass(tp, msgspec.Struct):
            if tp.__name__ not in found:
                found[tp.__name__] = tp
                for f in msgspec.structs.fields(tp):
                    visit(f.type)
            return
        for arg in get_args(tp):
            visit(arg)

    found["Sample"] = schema.Sample  # the envelope every sample carries
    for sample in schema.ALL_SAMPLES:
        visit(sample)
    return found


def render(text: str) -> str:
    structs = documented_structs()

    def replace(m: re.Match[str]) -> str:
        name = m.group(2)
        if name not in structs:
            raise KeyError(f"docs/wire.md has a table for {name}, which common/schema.py does not define")
        return m.group(1) + table(structs[name]) + m.group(4)

    return _SECTION.sub(replace, text)


def missing_tables(text: str) -> list[str]:
    present = {m.group(2) for m in _SECTION.finditer(text)}
    return sorted(set(documented_structs()) - present)


def json_schema(cls: type[msgspec.Struct]) -> dict[str, Any]:
    """The JSON Schema of a sample (for MCAP channels and other tools)."""
    return msgspec.json.schema(cls)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--check", action="store_true", help="only compare; exit 1 when docs/wire.md is stale")
    args = ap.parse_args(argv)
    text = DOC.read_text()
    new = render(text)
    missing = missing_tables(new)
    if missing:
        print(
            f"docs/wire.md has no generated table for: {', '.join(missing)}; add `<!-- fields: NAME -->` "
            f"`<!-- /fields -->` where each belongs",
            file=sys.stderr,
        )
        return 1
    if args.check:
        if new != text:
            print(
                "docs/wire.md's field tables differ from common/schema.py: run `python -m hri.wiredoc`",
                file=sys.stderr,
            )
            return 1
        return 0
    if new != text:
        DOC.write_text(new)
        print(f"updated {DOC}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
