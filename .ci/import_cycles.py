#!/usr/bin/env python3
"""Fails when modules of a crate import each other in a circle.

Reads every `crates/*/src/**/*.rs`, takes each module (one file) and the modules its code
names: `use crate::…`, `use super::…`, `use self::…`, `use child::…` lines and
`crate::…`/`super::…`/`self::…`/`child::…` paths in code (comments, strings and `#[cfg(test)]` modules skipped: a test may reach anywhere). A path is resolved to the deepest module file it
reaches; a name that module only re-exports (`pub use`) is followed to where it is defined,
so a crate root's table of contents is not itself a dependency. Re-export lines are not
edges. Prints every circle found (as `a -> b -> a`) and exits 1, or prints a summary and
exits 0.

    python3 .ci/import_cycles.py [crates-dir]
"""
from __future__ import annotations

import os
import re
import sys
from pathlib import Path


def strip_comments_and_strings(src: str) -> str:
    out = []
    i, n = 0, len(src)
    while i < n:
        c = src[i]
        if src.startswith("//", i):
            j = src.find("\n", i)
            i = n if j < 0 else j
        elif src.startswith("/*", i):
            depth, i = 1, i + 2
            while i < n and depth:
                if src.startswith("/*", i):
                    depth, i = depth + 1, i + 2
                elif src.startswith("*/", i):
                    depth, i = depth - 1, i + 2
                else:
                    i += 1
        elif c == "r" and re.match(r'r#*"', src[i:i + 10]) and (i == 0 or not (src[i - 1].isalnum() or src[i - 1] == "_")):
            m = re.match(r'r(#*)"', src[i:])
            close = '"' + m.group(1)
            j = src.find(close, i + len(m.group(0)))
            i = n if j < 0 else j + len(close)
            out.append('""')
        elif c == '"':
            j = i + 1
            while j < n and src[j] != '"':
                j += 2 if src[j] == "\\" else 1
            i = j + 1
            out.append('""')
        elif c == "'" and re.match(r"'(\\.|[^\\'])'|'\\u\{[0-9a-fA-F]+\}'|'\\x..'", src[i:i + 12]):
            m = re.match(r"'(\\.|[^\\'])'|'\\u\{[0-9a-fA-F]+\}'|'\\x..'", src[i:i + 12])
            i += len(m.group(0))
            out.append("' '")
        else:
            out.append(c)
            i += 1
    return "".join(out)


def without_test_modules(text: str) -> str:
    """`text` without its `#[cfg(test)] mod … { … }` blocks: tests may import anything."""
    out, i = [], 0
    for m in re.finditer(r"#\[cfg\(test\)\]\s*(?:pub(?:\([^)]*\))?\s+)?mod\s+\w+\s*\{", text):
        if m.start() < i:
            continue
        out.append(text[i:m.start()])
        depth, j = 1, m.end()
        while j < len(text) and depth:
            depth += text[j] == "{"
            depth -= text[j] == "}"
            j += 1
        i = j
    out.append(text[i:])
    return "".join(out)


def module_files(src_dir: Path) -> dict[tuple[str, ...], Path]:
    """Module path (segments after `crate`) -> file."""
    mods: dict[tuple[str, ...], Path] = {}
    roots = [p for p in (src_dir / "lib.rs", src_dir / "main.rs") if p.exists()]
    if not roots:
        return mods

    def visit(path: tuple[str, ...], file: Path, dir_for_children: Path) -> None:
        mods[path] = file
        text = strip_comments_and_strings(file.read_text())
        for m in re.finditer(r"^\s*(?:pub(?:\([^)]*\))?\s+)?mod\s+([A-Za-z_][A-Za-z0-9_]*)\s*;", text, re.M):
            name = m.group(1)
            for cand in (dir_for_children / f"{name}.rs", dir_for_children / name / "mod.rs"):
                if cand.exists():
                    child_dir = cand.parent if cand.name == "mod.rs" else dir_for_children / name
                    visit(path + (name,), cand, child_dir)
                    break

    visit((), roots[0], src_dir)
    return mods


def use_trees(text: str):
    """Yields (is_reexport, [path segments...]) for every leaf of every `use` statement."""
    for m in re.finditer(r"(?:^|[;{}\s])((?:pub(?:\([^)]*\))?\s+)?)use\s+([^;]*);", text, re.M):
        reexport = bool(m.group(1).strip())
        tree = re.sub(r"\s+", "", m.group(2))
        for leaf in expand(tree):
            yield reexport, leaf


def expand(tree: str) -> list[list[str]]:
    # a::b::{c, d::{e, f}} -> [[a,b,c],[a,b,d,e],[a,b,d,f]]
    i = tree.find("{")
    if i < 0:
        segs = [s for s in tree.split("::") if s]
        if segs and " as " in segs[-1]:
            segs[-1] = segs[-1].split(" as ")[0]
        segs = [re.sub(r"as[A-Za-z_0-9]+$", "", s) if False else s for s in segs]
        return [segs]
    prefix = [s for s in tree[:i].split("::") if s]
    body = tree[i + 1: tree.rfind("}")]
    parts, depth, cur = [], 0, ""
    for ch in body:
        if ch == "," and depth == 0:
            parts.append(cur)
            cur = ""
            continue
        depth += ch == "{"
        depth -= ch == "}"
        cur += ch
    if cur:
        parts.append(cur)
    out = []
    for p in parts:
        for leaf in expand(p):
            out.append(prefix + leaf)
    return out


def absolute(mod: tuple[str, ...], segs: list[str], mods=None) -> list[str] | None:
    if not segs:
        return None
    if mods is not None and segs[0] not in ("crate", "self", "super") and mod + (segs[0],) in mods:
        return list(mod) + segs  # a path through a child module: `child::item`
    segs = [s.split("as")[0] if False else s for s in segs]
    if segs[0] == "crate":
        return segs[1:]
    if segs[0] in ("self", "super"):
        base = list(mod)
        rest = list(segs)
        while rest and rest[0] in ("self", "super"):
            if rest.pop(0) == "super":
                if not base:
                    return None
                base.pop()
        return base + rest
    return None  # another crate, std, or a name in scope


def main() -> int:
    crates_dir = Path(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).resolve().parent.parent / "crates")
    failed = False
    total_edges = 0
    for crate in sorted(p for p in crates_dir.iterdir() if (p / "src").is_dir()):
        mods = module_files(crate / "src")
        texts = {m: without_test_modules(strip_comments_and_strings(f.read_text())) for m, f in mods.items()}
        # re-exports: (module, name) -> absolute path it stands for
        reexports: dict[tuple[tuple[str, ...], str], list[str]] = {}
        for m, text in texts.items():
            for reexport, segs in use_trees(text):
                if not reexport:
                    continue
                leaf = segs[-1]
                name = leaf.split("as")[-1] if False else leaf
                if name == "*" or name == "self":
                    continue
                ab = absolute(m, segs)
                if ab is None and segs and (m + (segs[0],)) in mods:
                    ab = list(m) + segs  # `pub use child::X;`
                if ab is not None:
                    reexports[(m, leaf)] = ab

        def resolve(path: list[str], depth: int = 0) -> tuple[str, ...] | None:
            # deepest module that is a prefix, following re-exports of the next name
            best = ()
            for k in range(len(path), -1, -1):
                if tuple(path[:k]) in mods:
                    best = tuple(path[:k])
                    break
            if len(path) > len(best) and depth < 20:
                key = (best, path[len(best)])
                if key in reexports:
                    target = reexports[key] + path[len(best) + 1:]
                    r = resolve(target, depth + 1)
                    if r is not None:
                        return r
            return best

        edges: dict[tuple[str, ...], set[tuple[str, ...]]] = {m: set() for m in mods}
        for m, text in texts.items():
            paths = []
            for reexport, segs in use_trees(text):
                if reexport:
                    continue
                ab = absolute(m, segs, mods)
                if ab is not None:
                    paths.append(ab)
            code = re.sub(r"(?:pub(?:\([^)]*\))?\s+)?use\s+[^;]*;", "", text)
            for p in re.finditer(r"(?<![A-Za-z0-9_:])((?:[a-z_][a-z0-9_]*)(?:::[A-Za-z_][A-Za-z0-9_]*)+)", code):
                ab = absolute(m, p.group(1).split("::"), mods)
                if ab is not None:
                    paths.append(ab)
            for ab in paths:
                target = resolve(ab)
                if target is None or target == m:
                    continue
                # a module naming its own descendant or ancestor through a path is still an edge
                edges[m].add(target)
        total_edges += sum(len(v) for v in edges.values())

        # strongly connected components (Tarjan)
        index, low, stack, on, sccs = {}, {}, [], set(), []
        counter = [0]
        sys.setrecursionlimit(10000)

        def strong(v):
            index[v] = low[v] = counter[0]
            counter[0] += 1
            stack.append(v)
            on.add(v)
            for w in edges[v]:
                if w not in index:
                    strong(w)
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
                    sccs.append(comp)

        for v in sorted(edges):
            if v not in index:
                strong(v)

        def name(m):
            return "::".join(m) if m else "(root)"

        for comp in sccs:
            failed = True
            members = set(comp)
            print(f"{crate.name}: {len(comp)} modules import each other in a circle: "
                  + ", ".join(sorted(name(c) for c in comp)))
            for a in sorted(comp):
                for b in sorted(edges[a] & members):
                    print(f"    {name(a)} -> {name(b)}")
    if failed:
        print("import circles found: make the dependencies between these modules point one way")
        return 1
    print(f"no circle of imports ({total_edges} module dependencies read)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
