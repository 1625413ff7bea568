"""Imports run one way (docs/foundation.md, "Layers"): the contract <- the runtime <- the services <- the tools.

Pure: every .py under common/ and services/ is parsed with `ast` (function-level imports included, since a
hidden import is still an import); nothing is imported or run.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("common", "services", "hri")

# The contract: what goes on the wire and how it is checked. msgspec/msgpack and the standard library only.
CONTRACT = {"common.schema", "common.codec", "common.keys", "common.stamps", "common.language", "common.stack"}
# The tools: the `hri` command and what only it uses. No service (and nothing of the contract or runtime)
# may import them.
TOOLS = {"hri"}
# Third-party packages the contract may not touch: the transport and everything heavy.
NOT_IN_CONTRACT = {"zenoh", "numpy", "cv2", "onnxruntime", "mediapipe", "faster_whisper", "aiohttp", "mcap"}


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imports_of(path: Path) -> set[str]:
    """Absolute names of every module `path` imports, wherever the import statement is."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            found.add(base)
            # `from hri import launcher` imports the module hri.launcher
            found.update(f"{base}.{alias.name}" for alias in node.names)
    return found


def project_graph() -> dict[str, set[str]]:
    """{module: the project modules it imports} over common/ and services/."""
    files = {module_name(p): p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")}
    graph = {}
    for name, path in files.items():
        graph[name] = {m for m in imports_of(path) if m in files and m != name}
    return graph


def in_layer(module: str, layer: set[str]) -> bool:
    return any(module == top or module.startswith(top + ".") for top in layer)


GRAPH = project_graph()


def all_imports(module: str) -> set[str]:
    path = ROOT / Path(*module.split("."))
    return imports_of(path / "__init__.py" if path.is_dir() else path.with_suffix(".py"))


def test_the_graph_covers_the_tree():
    assert {"common.schema", "common.codec", "common.runner", "hri.cli", "services.fusion.__main__"} <= set(GRAPH)
    assert "common.schema" in GRAPH["common.codec"] and "common.runner" in GRAPH["services.vision.__main__"]


def test_the_contract_imports_neither_zenoh_nor_the_runtime_nor_the_tools():
    for module in sorted(CONTRACT):
        outside = {m for m in GRAPH[module] if not in_layer(m, CONTRACT)}
        assert not outside, f"{module} (the contract) imports {sorted(outside)}: the contract imports only itself"
        heavy = {m for m in all_imports(module) if m.split(".")[0] in NOT_IN_CONTRACT}
        assert not heavy, f"{module} (the contract) imports {sorted(heavy)}: msgspec, msgpack and the stdlib only"


def test_the_runtime_imports_no_service_and_no_tool():
    runtime = [m for m in GRAPH if m.startswith("common.") and not in_layer(m, CONTRACT | TOOLS)]
    assert "common.runner" in runtime and "common.transport" in runtime
    for module in runtime:
        wrong = {m for m in GRAPH[module] if m.startswith("services") or in_layer(m, TOOLS)}
        assert not wrong, f"{module} (the runtime) imports {sorted(wrong)}: it may use only the contract and runtime"


def test_services_import_no_tool():
    for module, deps in GRAPH.items():
        if module.startswith("services."):
            tools = {m for m in deps if in_layer(m, TOOLS)}
            assert not tools, (
                f"{module} imports the tool(s) {sorted(tools)}: move what it needs into common/'s contract or runtime"
            )


# Test support: the `testkit` package (harness, scenarios, test voice...), the tests and the benchmarks. It may
# import anything; nothing shipped may import it (the demo, not shipped, may: it speaks with testkit's voice).
TEST_SUPPORT = ("testkit", "tests", "benchmarks")


def test_nothing_shipped_imports_test_support():
    assert "testkit.synth" in imports_of(ROOT / "demo" / "__main__.py")  # the check sees what it must refuse
    for module in GRAPH:
        wrong = {m for m in all_imports(module) if m.split(".")[0] in TEST_SUPPORT}
        assert not wrong, (
            f"{module} imports {sorted(wrong)}: common/, services/ and hri/ must not depend on test code "
            "(move what both need into common/, or keep the test-only part in testkit/)"
        )


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_import_cycle():
    # function-level imports count too: an import hidden in a function is still a loop
    found = cycles(GRAPH)
    assert not found, f"import cycles (each group imports itself round the loop): {found}"


def test_the_checks_catch_what_they_claim():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []
    assert in_layer("hri.view.core", TOOLS) and not in_layer("common.viewer", TOOLS)
