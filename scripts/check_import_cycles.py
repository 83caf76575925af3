#!/usr/bin/env python3
"""Reports import circles between the source files of each crate under `crates/`.

A file A depends on file B when A names an item that B defines (through `use crate::…`,
`use super::…`, `use self::…`, a child module's name, or such a path written inline). Re-exports
are followed to the file that defines the item, and a `pub use` alone (a facade) does not make its
file depend on the item. Every strongly connected group of two or more files is a circle.

Usage: scripts/check_import_cycles.py [CRATES_DIR]   (exit status 1 when a circle exists)
"""

import os
import re
import sys

ITEM_DEF = r"\b(?:fn|struct|enum|trait|type|const|static|union|mod|macro_rules!)\s+{}\b"


def strip(src):
    """The source with comments, strings and char literals blanked (newlines kept)."""
    out, i, n = [], 0, len(src)
    while i < n:
        if src.startswith("//", i):
            j = src.find("\n", i)
            j = n if j < 0 else j
        elif src.startswith("/*", i):
            depth, j = 1, i + 2
            while j < n and depth:
                if src.startswith("/*", j):
                    depth, j = depth + 1, j + 2
                elif src.startswith("*/", j):
                    depth, j = depth - 1, j + 2
                else:
                    j += 1
        elif (m := re.match(r'b?r(#*)"', src[i : i + 8])) and (i == 0 or not re.match(r"\w", src[i - 1])):
            end = '"' + m.group(1)
            j = src.find(end, i + len(m.group(0))) + len(end)
        elif src[i] == '"':
            j = i + 1
            while src[j] != '"':
                j += 2 if src[j] == "\\" else 1
            j += 1
        elif src[i] == "'" and (m := re.match(r"'(\\.[^']*|[^\\'])'", src[i : i + 12])):
            j = i + len(m.group(0))
        else:
            out.append(src[i])
            i += 1
            continue
        out.append(re.sub(r"[^\n]", " ", src[i:j]))
        i = j
    return "".join(out)


def expand_tree(tree):
    """`a::{b, c::{d as e}}` → [(['a','b'], 'b'), (['a','c','d'], 'e')]."""
    tree = re.sub(r"\s*::\s*", "::", tree.strip())
    m = re.match(r"^(.*?)\{(.*)\}$", tree, re.S)
    if not m:
        parts = re.split(r"\s+as\s+", tree)
        path = [p.strip() for p in parts[0].split("::") if p.strip()]
        alias = parts[1].strip() if len(parts) > 1 else (path[-1] if path else None)
        return [(path, alias)]
    prefix = [p for p in m.group(1).split("::") if p]
    body, items, depth, cur = m.group(2), [], 0, ""
    for ch in body + ",":
        if ch == "," and depth == 0:
            if cur.strip():
                items.append(cur.strip())
            cur = ""
            continue
        depth += ch == "{"
        depth -= ch == "}"
        cur += ch
    result = []
    for item in items:
        for path, alias in expand_tree(item):
            if path == ["self"]:
                result.append((prefix, prefix[-1] if prefix else None))
            else:
                result.append((prefix + path, alias))
    return result


def inline_modules(text):
    """(start, end, name) of every `mod name { … }` written inside a file."""
    spans = []
    for m in re.finditer(r"\bmod\s+(\w+)\s*\{", text):
        depth, j = 0, m.end() - 1
        while j < len(text):
            depth += text[j] == "{"
            depth -= text[j] == "}"
            if depth == 0:
                break
            j += 1
        spans.append((m.start(), j, m.group(1)))
    return spans


def enclosing(spans, pos):
    """The inline module path (outermost first) around position `pos`."""
    return tuple(name for start, end, name in spans if start < pos < end)


class Crate:
    """The module tree of one crate root (`lib.rs` or `main.rs`) and its files' stripped text."""

    def __init__(self, root_file):
        self.files = {}  # module path (tuple) -> file path
        self._walk((), root_file, os.path.dirname(root_file))
        self.text = {f: strip(open(f, encoding="utf-8").read()) for f in self.files.values()}

    def _walk(self, module, path, child_dir):
        self.files[module] = path
        text = strip(open(path, encoding="utf-8").read())
        for m in re.finditer(r"(#\[path[^\]]*\]\s*)?\b(?:pub(?:\([^)]*\))?\s+)?mod\s+(\w+)\s*;", text):
            if m.group(1):
                continue  # a `#[path]` module: outside the tree this script follows
            name = m.group(2)
            for cand in (os.path.join(child_dir, name + ".rs"), os.path.join(child_dir, name, "mod.rs")):
                if os.path.exists(cand):
                    self._walk(module + (name,), cand, os.path.join(child_dir, name))
                    break

    def children(self, module):
        return {k[-1] for k in self.files if len(k) == len(module) + 1 and k[: len(module)] == module}

    def absolute(self, module, path):
        """Absolute module path of `path` written in `module`, or None for external paths."""
        if not path:
            return None
        head = path[0]
        if head == "crate":
            return list(path[1:])
        if head == "self":
            return list(module) + path[1:]
        if head == "super":
            base = list(module)
            while path and path[0] == "super":
                base, path = base[:-1], path[1:]
            return base + list(path)
        if head in self.children(module):
            return list(module) + list(path)
        return None

    def uses(self, file_path):
        """(absolute path, is_facade) for every crate path the file names."""
        file_module = next(k for k, v in self.files.items() if v == file_path)
        text = self.text[file_path]
        inline = inline_modules(text)
        found = []
        body = text
        for m in re.finditer(r"\b(pub(?:\([^)]*\))?\s+)?use\s+([^;]+);", text):
            body = body.replace(m.group(0), " " * len(m.group(0)), 1)
        for m in re.finditer(r"\b(pub(?:\([^)]*\))?\s+)?use\s+([^;]+);", text):
            public = bool(m.group(1))
            module = file_module + enclosing(inline, m.start())
            for path, alias in expand_tree(m.group(2)):
                target = self.absolute(module, path)
                if target is None:
                    continue
                facade = public and alias not in ("*", None) and not re.search(r"\b%s\b" % re.escape(alias), body)
                found.append((target, facade))
        heads = "|".join(["crate", "super", "self"] + sorted(self.children(file_module)))
        for m in re.finditer(r"(?<![\w:])((?:%s)(?:::\w+)+)" % heads, body):
            module = file_module + enclosing(inline, m.start())
            target = self.absolute(module, m.group(1).split("::"))
            if target is not None:
                found.append((target, False))
        return found

    def defining_file(self, target, seen=()):
        """The file that defines the item (or module) at absolute path `target`."""
        target = [t for t in target if t != "self"]
        for cut in range(len(target), -1, -1):
            module = tuple(target[:cut])
            if module in self.files:
                rest = target[cut:]
                break
        else:
            return None
        file_path = self.files[module]
        if not rest or rest[0] == "*" or (module, rest[0]) in seen:
            return file_path
        name = rest[0]
        text = self.text[file_path]
        if re.search(ITEM_DEF.format(re.escape(name)), text):
            return file_path
        for m in re.finditer(r"\bpub(?:\([^)]*\))?\s+use\s+([^;]+);", text):
            for path, alias in expand_tree(m.group(1)):
                if alias == name:
                    absolute = self.absolute(module, path)
                    if absolute is not None:
                        return self.defining_file(absolute + rest[1:], seen + ((module, name),))
        return file_path


def circles(graph):
    """Strongly connected components with two or more files (Tarjan)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                out.append(sorted(group))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def report(crate):
    """Prints the circles of `crate`, each with the dependencies that close it; returns how many."""
    graph = {}
    for file_path in crate.files.values():
        deps = graph.setdefault(file_path, set())
        for target, facade in crate.uses(file_path):
            dep = crate.defining_file(target)
            if dep and dep != file_path and not facade:
                deps.add(dep)
    groups = circles(graph)
    for group in groups:
        print("circle: " + " <-> ".join(group))
        for a in group:
            for b in sorted(graph[a] & set(group)):
                print(f"    {a} uses {b}")
    return len(groups)


def main():
    root = sys.argv[1] if len(sys.argv) > 1 else "crates"
    sys.setrecursionlimit(10000)
    found = 0
    for name in sorted(os.listdir(root)):
        for root_file in ("lib.rs", "main.rs"):
            path = os.path.join(root, name, "src", root_file)
            if os.path.exists(path):
                found += report(Crate(path))
    print(f"{found} import circle(s)")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
