"""The house's floors, read from the source: imports point down, never up or sideways, and never in a circle.

Floors, lowest first: aesop_torch (the library), sim (the world), then train/: common, learning, the three rooms
(runner, sweeps, battery: none imports another), and the scripts at train/'s top (run.py, sweep.py, ask.py,
report.py). Every import counts, a function's lazy one too: a circle through a lazy import is still a circle.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("aesop_torch", "sim", "train")
ROOMS = ("runner", "sweeps", "battery")


def modules() -> dict[str, Path]:
    out = {}
    for pkg in PACKAGES:
        for path in (ROOT / pkg).rglob("*.py"):
            parts = path.relative_to(ROOT).with_suffix("").parts
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def imports(path: Path, name: str, known: dict) -> set[str]:
    """The project's modules that `name` (at `path`) imports anywhere in its body."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package.split(".")[:len(package.split(".")) - node.level + 1] + ([base] if base else []))
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in known else base for a in node.names]
        else:
            continue
        for t in targets:
            while t and t not in known:   # `import a.b.c` of a name inside a module: its module
                t = t.rpartition(".")[0]
            if t and t != name:
                found.add(t)
    return found


def floor(name: str) -> tuple[int, str]:
    """(height, room): the library 0, the world 1, train's common 2, learning 3, a room 4, train's scripts 5."""
    parts = name.split(".")
    if parts[0] == "aesop_torch":
        return 0, "aesop_torch"
    if parts[0] == "sim":
        return 1, "sim"
    if len(parts) == 1 or (len(parts) == 2 and parts[1] not in ("common", "learning") + ROOMS):
        return 5, "scripts"
    return {"common": 2, "learning": 3}.get(parts[1], 4), parts[1]


GRAPH = {n: imports(p, n, modules()) for n, p in modules().items()}


def test_the_graph_is_read():   # the test sees the imports it guards (a parser that found nothing would pass all)
    assert "train.learning.experiment" in GRAPH["train.runner.loop"]
    assert "aesop_torch.som" in GRAPH["aesop_torch.encoders"]
    assert floor("train.run") == (5, "scripts") and floor("train.runner.loop") == (4, "runner")


def test_imports_point_down():
    wrong = []
    for name, targets in GRAPH.items():
        (h, room) = floor(name)
        for t in targets:
            (ht, room_t) = floor(t)
            if ht > h or (ht == h == 4 and room_t != room):
                wrong.append(f"{name} imports {t}")
    assert not wrong, "imports that climb or cross between rooms: " + "; ".join(sorted(wrong))


def test_no_import_circles():
    """Tarjan's strongly connected components of the module graph: every one a single module."""
    index, low, stack, on, circles, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in GRAPH.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                circles.append(sorted(comp))

    for v in sorted(GRAPH):
        if v not in index:
            visit(v)
    assert not circles, f"import circles: {circles}"


def test_one_atomic_writer():
    """Atomic writes have one home (sim/output_files.py, the lowest floor that writes such files): make_objects, the
    checkpoints and the sweeps each had their own copy of the temporary-file dance."""
    writers = sorted(str(p.relative_to(ROOT)) for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")
                     if "mkstemp(" in p.read_text())
    assert writers == ["sim/output_files.py"]
