#!/usr/bin/env python3
"""Print the cycles between the modules of each crate under crates/*/src.

A module is a file under src (`lib.rs`/`main.rs` is the crate root, `a/mod.rs` is `a`, `a/b.rs` is
`a::b`). Module A depends on module B when A names a path that resolves into B: `use crate::...`,
`super::...` or `self::...` trees, and the same paths written in code. A path to a name that a
module re-exports (`pub use b::Thing`) is followed to the module that defines it, so
`crate::Thing` counts as a dependency on `b`, not on the crate root.

Edges between a module and its own ancestors or descendants are left out: a parent declares and
re-exports its children and a child reaches its parent's items, which is how Rust modules nest,
not a circle. Test code is left out too (files named `tests.rs` or under a `tests/` directory,
anything behind `#[cfg(test)]`, inline `mod tests { ... }` blocks), since tests reach everything.

Every strongly connected component with more than one module is a cycle: the script prints each
one with the edges inside it (and where the first reference of each edge is), then exits 1 if any
crate has one. Standard library only, so it runs anywhere python3 does.

Usage: scripts/module-cycles.py [CRATES_DIR]   (default: crates beside this script's parent)
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
CFG_ATTR = re.compile(r"#\s*\[\s*cfg\s*\((?P<body>[^\]]*)\)\s*\]")
ATTR = re.compile(r"\s*#\s*!?\s*\[")
INLINE_MOD = re.compile(r"\bmod\s+(?P<name>[A-Za-z_][A-Za-z0-9_]*)\s*\{")
DECLARED_MOD = re.compile(r"\bmod\s+(?P<name>[A-Za-z_][A-Za-z0-9_]*)\s*;")
USE = re.compile(r"(?<![A-Za-z0-9_$])(?P<vis>pub\s*(\([^)]*\))?\s*)?\buse\s+(?P<tree>[^;]*);")
# A path in code: `crate::a::b`, `super::super::a`, `self::a` (not `$crate::` in macros).
CODE_PATH = re.compile(
    r"(?<![A-Za-z0-9_$:])(?:crate|super|self)(?:\s*::\s*[A-Za-z_][A-Za-z0-9_]*)+"
)
RAW_STRING = re.compile(r'(?:b|c)?r(#*)"')
VISIBILITY_IN = re.compile(r"\bpub\s*\(\s*in\s+[^)]*\)")


def strip_comments_and_strings(text: str) -> str:
    """Blank out comments, string and char literals, keeping every newline (for line numbers)."""
    out: list[str] = []
    i, n = 0, len(text)

    def blank(s: str) -> str:
        return "".join("\n" if c == "\n" else " " for c in s)

    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(blank(text[i:j]))
            i = j
        elif text.startswith("/*", i):
            depth, j = 1, i + 2
            while j < n and depth:
                if text.startswith("/*", j):
                    depth, j = depth + 1, j + 2
                elif text.startswith("*/", j):
                    depth, j = depth - 1, j + 2
                else:
                    j += 1
            out.append(blank(text[i:j]))
            i = j
        elif (m := RAW_STRING.match(text, i)) and not _word_before(text, i):
            end = '"' + m.group(1)
            j = text.find(end, m.end())
            j = n if j < 0 else j + len(end)
            out.append('""' + blank(text[i + 2 : j]))
            i = j
        elif c == '"' or (c in "bc" and text.startswith('"', i + 1) and not _word_before(text, i)):
            j = i + (1 if c == '"' else 2)
            while j < n and text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            j += 1
            out.append('""' + blank(text[i + 2 : j]))
            i = j
        elif c == "'":
            # A char literal ('a', '\n', '\u{1F600}') or a lifetime ('a, 'static).
            if text.startswith("\\", i + 1):
                j = text.find("'", i + 2)
                j = n if j < 0 else j + 1
                out.append(blank(text[i:j]))
                i = j
            elif i + 2 < n and text[i + 2] == "'":
                out.append("   ")
                i += 3
            else:
                out.append(c)
                i += 1
        else:
            out.append(c)
            i += 1
    return "".join(out)


def _word_before(text: str, i: int) -> bool:
    return i > 0 and (text[i - 1].isalnum() or text[i - 1] == "_")


def matching_brace(text: str, open_at: int) -> int:
    """Index just past the `}` that closes the `{` at open_at."""
    depth = 0
    for j in range(open_at, len(text)):
        if text[j] == "{":
            depth += 1
        elif text[j] == "}":
            depth -= 1
            if depth == 0:
                return j + 1
    return len(text)


def item_end(text: str, start: int) -> tuple[int, str]:
    """End of the item starting at start (past its `;` or its `{...}` body), and its head."""
    depth = 0
    for j in range(start, len(text)):
        c = text[j]
        if c in "([":
            depth += 1
        elif c in ")]":
            depth -= 1
        elif depth == 0 and c == ";":
            return j + 1, text[start:j]
        elif depth == 0 and c == "{":
            return matching_brace(text, j), text[start:j]
    return len(text), text[start:]


def blank_span(text: str, start: int, end: int) -> str:
    return text[:start] + "".join("\n" if c == "\n" else " " for c in text[start:end]) + text[end:]


def is_test_cfg(body: str) -> bool:
    return (
        re.search(r"\btest\b", body) is not None and re.search(r"\bnot\s*\(\s*test\b", body) is None
    )


def remove_test_code(text: str) -> tuple[str, set[str]]:
    """Blank out `#[cfg(test)]` items and `mod tests { }` blocks; names of test-only `mod x;`."""
    test_mods: set[str] = set()
    pos = 0
    while m := CFG_ATTR.search(text, pos):
        if not is_test_cfg(m.group("body")):
            pos = m.end()
            continue
        start = m.end()
        # Further attributes on the same item.
        while a := ATTR.match(text, start):
            depth, j = 0, a.end() - 1
            while j < len(text):
                depth += {"[": 1, "]": -1}.get(text[j], 0)
                j += 1
                if depth == 0:
                    break
            start = j
        end, head = item_end(text, start)
        if d := DECLARED_MOD.search(text[start:end]):
            if head.strip().endswith(d.group("name")):
                test_mods.add(d.group("name"))
        text = blank_span(text, m.start(), end)
        pos = m.start()
    pos = 0
    while m := INLINE_MOD.search(text, pos):
        name = m.group("name")
        if name == "tests" or name.endswith("_tests"):
            text = blank_span(text, m.start(), matching_brace(text, m.end() - 1))
        pos = m.end()
    return text, test_mods


def expand_use_tree(tree: str) -> list[tuple[list[str], str]]:
    """Expand `a::{b, c::d as e, f::*}` into (path, name it is imported as) pairs."""
    tokens = re.findall(r"[A-Za-z_][A-Za-z0-9_]*|::|[{},*]", tree)
    pos = 0

    def parse(prefix: list[str]) -> list[tuple[list[str], str]]:
        nonlocal pos
        path = list(prefix)
        while pos < len(tokens):
            tok = tokens[pos]
            if tok == "{":
                pos += 1
                found: list[tuple[list[str], str]] = []
                while pos < len(tokens) and tokens[pos] != "}":
                    found += parse(path)
                    if pos < len(tokens) and tokens[pos] == ",":
                        pos += 1
                pos += 1
                return found
            if tok == "*":
                pos += 1
                return [(path, "*")]
            if tok == "::":
                pos += 1
                continue
            if tok in (",", "}"):
                break
            if tok == "as":
                alias = tokens[pos + 1] if pos + 1 < len(tokens) else path[-1]
                pos += 2
                return [(path, alias)]
            path.append(tok)
            pos += 1
        if path and path[-1] == "self":
            path = path[:-1]
        return [(path, path[-1] if path else "")]

    out: list[tuple[list[str], str]] = []
    while pos < len(tokens):
        out += parse([])
        if pos < len(tokens) and tokens[pos] in (",", "}"):
            pos += 1
    return out


class Module:
    def __init__(self, path: tuple[str, ...], file: Path, text: str):
        self.path = path
        self.file = file
        self.text = text
        # Inline (non-test) modules: (start, end, name), to know where `super::` points.
        self.inline: list[tuple[int, int, str]] = [
            (m.end(), matching_brace(text, m.end() - 1), m.group("name"))
            for m in INLINE_MOD.finditer(text)
        ]
        # `pub use` re-exports: name -> absolute path (relative paths of uses resolved later).
        self.reexports: dict[str, tuple[str, ...]] = {}

    def scope_at(self, pos: int) -> tuple[str, ...]:
        inner = [(s, name) for s, e, name in self.inline if s <= pos < e]
        return self.path + tuple(name for _, name in sorted(inner))


def module_path(src: Path, file: Path) -> tuple[str, ...]:
    parts = list(file.relative_to(src).with_suffix("").parts)
    if parts[-1] == "mod" or (len(parts) == 1 and parts[0] in ("lib", "main")):
        parts = parts[:-1]
    return tuple(parts)


def absolute(scope: tuple[str, ...], segments: list[str]) -> tuple[str, ...] | None:
    """The crate-absolute form of a path written in scope, or None if it is not crate-relative."""
    if not segments:
        return None
    head = segments[0]
    if head == "crate":
        return tuple(segments[1:])
    if head == "self":
        return scope + tuple(segments[1:])
    if head == "super":
        base = list(scope)
        i = 0
        while i < len(segments) and segments[i] == "super":
            if not base:
                return None
            base.pop()
            i += 1
        return tuple(base) + tuple(segments[i:])
    return None


def load_crate(src: Path) -> dict[tuple[str, ...], Module]:
    modules: dict[tuple[str, ...], Module] = {}
    test_only: set[tuple[str, ...]] = set()
    for file in sorted(src.rglob("*.rs")):
        rel = file.relative_to(src)
        if file.name == "tests.rs" or "tests" in rel.parts[:-1] or rel.parts[0] == "bin":
            continue
        text, test_mods = remove_test_code(strip_comments_and_strings(file.read_text()))
        text = VISIBILITY_IN.sub(lambda m: " " * len(m.group(0)), text)
        path = module_path(src, file)
        modules[path] = Module(path, file, text)
        test_only |= {path + (name,) for name in test_mods}
    for path in list(modules):
        if any(path[: len(t)] == t for t in test_only):
            del modules[path]
    for mod in modules.values():
        for m in USE.finditer(mod.text):
            if not m.group("vis"):
                continue
            scope = mod.scope_at(m.start())
            for segments, name in expand_use_tree(m.group("tree")):
                full = absolute(scope, segments)
                if full is None and segments and (scope + (segments[0],)) in modules:
                    full = scope + tuple(segments)
                if full is not None and name != "*":
                    mod.reexports[name] = full
    return modules


def owner(modules: dict[tuple[str, ...], Module], full: tuple[str, ...]) -> tuple[str, ...]:
    """The file module a crate-absolute path lands in, following re-exports."""
    for _ in range(16):
        k = len(full)
        while full[:k] not in modules:
            k -= 1
        target = full[:k]
        if k == len(full):
            return target
        nxt = modules[target].reexports.get(full[k])
        if nxt is None or nxt == full[: k + 1]:
            return target
        full = nxt + full[k + 1 :]
    return target


def related(a: tuple[str, ...], b: tuple[str, ...]) -> bool:
    short, long = (a, b) if len(a) <= len(b) else (b, a)
    return long[: len(short)] == short


def edges_of(modules: dict[tuple[str, ...], Module], root: Path) -> dict[tuple, dict[tuple, str]]:
    """module -> {module it depends on: where the first reference is}."""
    edges: dict[tuple, dict[tuple, str]] = {p: {} for p in modules}
    for mod in modules.values():
        refs: list[tuple[int, list[str]]] = []
        text = mod.text
        for m in USE.finditer(text):
            refs += [(m.start(), segs) for segs, _ in expand_use_tree(m.group("tree"))]
        code = USE.sub(lambda m: "".join("\n" if c == "\n" else " " for c in m.group(0)), text)
        for m in CODE_PATH.finditer(code):
            refs.append((m.start(), [s.strip() for s in m.group(0).split("::")]))
        for pos, segments in refs:
            full = absolute(mod.scope_at(pos), segments)
            if full is None:
                continue
            target = owner(modules, full)
            if target == mod.path or related(target, mod.path):
                continue
            line = text.count("\n", 0, pos) + 1
            edges[mod.path].setdefault(target, f"{mod.file.relative_to(root)}:{line}")
    return edges


def strongly_connected(nodes: list, edges: dict) -> list[list]:
    """Tarjan's algorithm, iterative (deep module chains must not hit the recursion limit)."""
    index: dict = {}
    low: dict = {}
    on_stack: set = set()
    stack: list = []
    found: list[list] = []
    counter = 0
    for root in nodes:
        if root in index:
            continue
        work = [(root, iter(sorted(edges[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            for child in children:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(edges[child]))))
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            else:
                work.pop()
                if work:
                    parent = work[-1][0]
                    low[parent] = min(low[parent], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        top = stack.pop()
                        on_stack.discard(top)
                        component.append(top)
                        if top == node:
                            break
                    found.append(sorted(component))
    return found


def name(path: tuple[str, ...]) -> str:
    return "::".join(path) if path else "crate"


def main() -> int:
    default = Path(__file__).resolve().parent.parent / "crates"
    crates = (Path(sys.argv[1]) if len(sys.argv) > 1 else default).resolve()
    any_cycle = False
    for src in sorted(crates.glob("*/src")):
        crate = src.parent.name
        modules = load_crate(src)
        edges = edges_of(modules, crates.parent)
        cycles = [c for c in strongly_connected(sorted(modules), edges) if len(c) > 1]
        count = sum(len(e) for e in edges.values())
        verdict = f"{len(cycles)} cycle(s)" if cycles else "no cycle"
        print(f"{crate}: {len(modules)} modules, {count} edges, {verdict}")
        for component in cycles:
            any_cycle = True
            members = set(component)
            print(f"  cycle: {', '.join(name(p) for p in component)}")
            for a in component:
                for b, where in sorted(edges[a].items()):
                    if b in members:
                        print(f"    {name(a)} -> {name(b)}  ({where})")
    return 1 if any_cycle else 0


if __name__ == "__main__":
    sys.exit(main())
