"""Print the project's requirements for the given extras, one per line, read from pyproject.toml.

The image installs its Python packages BEFORE the project's code is copied in (so a code change does not
reinstall them), and the host downloads the same list as wheels; both use this script, so the list lives
only in pyproject.toml.

usage: python docker/project-requirements.py [PYPROJECT] --extras gesture,vision,speech,record
"""

from __future__ import annotations

import argparse
import re
import sys
import tomllib
from pathlib import Path

SELF_REFERENCE = re.compile(r"^\s*([A-Za-z0-9_.-]+)\s*\[([^\]]*)\]\s*$")


def requirements(project: dict, extras: list[str]) -> list[str]:
    name = project["name"].lower().replace("_", "-")
    optional = project.get("optional-dependencies", {})
    out: list[str] = list(project.get("dependencies", []))
    pending, seen = list(extras), set()
    while pending:
        extra = pending.pop(0)
        if extra in seen:
            continue
        seen.add(extra)
        if extra not in optional:
            raise SystemExit(
                f"project-requirements: no extra {extra!r} in pyproject.toml (known: {', '.join(sorted(optional))})"
            )
        for req in optional[extra]:
            m = SELF_REFERENCE.match(req)
            if m and m.group(1).lower().replace("_", "-") == name:  # "hri-fusion[a,b]" pulls in other extras
                pending += [e.strip() for e in m.group(2).split(",") if e.strip()]
            elif req not in out:
                out.append(req)
    return out


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("pyproject", nargs="?", default="pyproject.toml")
    parser.add_argument("--extras", default="", help="comma-separated extras")
    args = parser.parse_args(argv)
    project = tomllib.loads(Path(args.pyproject).read_text())["project"]
    extras = [e.strip() for e in args.extras.split(",") if e.strip()]
    sys.stdout.write("".join(f"{r}\n" for r in requirements(project, extras)))


if __name__ == "__main__":
    main()
