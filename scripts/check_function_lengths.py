#!/usr/bin/env python3
"""Reports the functions of `crates/*/src` longer than the house's limits: 120 lines, 40 in the
command-line crate (whose functions read arguments and call the facade). Test modules
(`#[cfg(test)]`) are left out; a function's length runs from its `fn` line to its closing brace.

Usage: scripts/check_function_lengths.py [CRATES_DIR]   (exit status 1 when one is too long)
"""

import os
import re
import sys

from check_import_cycles import strip

LIMIT, CLI_LIMIT = 120, 40
FN = re.compile(r"^\s*(?:pub(?:\([^)]*\))?\s+)?(?:const\s+|async\s+|unsafe\s+|extern\s+\"C\"\s+)*fn\s+(\w+)")


def item_end(lines, start):
    """The last line of the item starting at line `start`: its closing brace, or its `;`."""
    depth, j, opened = 0, start, False
    while j < len(lines):
        depth += lines[j].count("{") - lines[j].count("}")
        opened = opened or "{" in lines[j]
        if opened and depth <= 0 or (not opened and lines[j].rstrip().endswith(";")):
            break
        j += 1
    return j


def test_module_lines(lines):
    """Line numbers inside `#[cfg(test)]` items."""
    skip, i = set(), 0
    while i < len(lines):
        if lines[i].strip() == "#[cfg(test)]":
            end = item_end(lines, i + 1)
            skip.update(range(i + 1, end + 1))
            i = end
        i += 1
    return skip


def long_functions(path, limit):
    """(name, first line, length) of each function of `path` over `limit` lines."""
    with open(path, encoding="utf-8") as f:
        lines = strip(f.read()).split("\n")
    skip = test_module_lines(lines)
    found = []
    for i, line in enumerate(lines):
        m = FN.match(line)
        if not m or i in skip:
            continue
        j = item_end(lines, i)
        if j - i + 1 > limit:
            found.append((m.group(1), i + 1, j - i + 1))
    return found


def main():
    crates = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "..", "crates")
    too_long = []
    for crate in sorted(os.listdir(crates)):
        limit = CLI_LIMIT if crate == "cli" else LIMIT
        for root, _, files in os.walk(os.path.join(crates, crate, "src")):
            for name in sorted(files):
                if name.endswith(".rs"):
                    path = os.path.join(root, name)
                    too_long += [(path, *f, limit) for f in long_functions(path, limit)]
    for path, name, line, length, limit in too_long:
        print(f"{os.path.relpath(path, crates)}:{line}: {name} is {length} lines (limit {limit})")
    print(f"{len(too_long)} functions over the limits")
    return 1 if too_long else 0


if __name__ == "__main__":
    sys.exit(main())
