#!/usr/bin/env python3
"""Structure guard (ARCHITECTURE.md, invariants): no Rust source file over 600 lines and no
function over 150 lines under src/ and kernels/ (tests/ is exempt), no subsystem folder
(src/herd, src/flock, src/crowd, src/lift) importing another one, and no circle of imports:
inside every folder, its files and subfolders (each with all below it) import each other
without a loop (so neither two files nor two folders such as herd/fit and herd/author import
each other, directly or round a longer loop). Which file imports which is read by
scripts/imports.py: an import is an arrow to the file that defines the item (re-exports
followed), test code and a module's arrows to its own submodules left out. And no file-system
write outside `src/data/atomic/` (issue #47: every output goes through the run's output plan; a
raw `std::fs::write`, `File::create`, `OpenOptions`, `create_dir*`, `fs::copy` or `fs::rename` in a
verb's code would bypass it; test modules are exempt).

    python3 scripts/check-structure.py            # check; exit 1 and list every violation
    python3 scripts/check-structure.py --report   # also print the longest files and functions
    python3 scripts/check-structure.py --root DIR # check the tree at DIR (its src/, kernels/)

A function's length runs from the line of its `fn` keyword to the line of its closing brace
(closures and nested items inside it count towards it). The scanner understands comments,
strings, raw strings and char literals, so braces inside them are not counted.
"""

import os
import pathlib
import re
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import imports  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CRATES = ["src/lib.rs", "kernels/src/lib.rs"]
# File arrows shown per arrow of a loop (the rest counted).
SHOWN_ARROWS = 3
DIRS = ["src", "kernels"]
MAX_FILE = 600
MAX_FN = 150
SUBSYSTEMS = ["herd", "flock", "crowd", "lift"]
# Violations known when this guard was written, reported as warnings until the restructure
# (issue #13) removes them; anything else fails. Empty once the restructure is done.
KNOWN = {
}


def rust_files():
    for d in DIRS:
        for base, dirs, files in os.walk(os.path.join(ROOT, d)):
            dirs[:] = sorted(x for x in dirs if x not in ("target", "tests"))
            for f in sorted(files):
                if f.endswith(".rs"):
                    yield os.path.join(base, f)


def code_only(text):
    """The text with comments, strings and char literals blanked out (newlines kept)."""
    out = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
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
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c == "r" and re.match(r'r#*"', text[i:]) and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")):
            m = re.match(r'r(#*)"', text[i:])
            end = '"' + m.group(1)
            j = text.find(end, i + len(m.group(0)))
            j = n if j < 0 else j + len(end)
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            j = min(j + 1, n)
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c == "'":
            # A char literal ('x', '\n', '\u{1F600}') or a lifetime ('a): blank only literals.
            m = re.match(r"'(\\u\{[0-9a-fA-F]+\}|\\.|[^\\'\n])'", text[i:])
            if m:
                out.append(" " * len(m.group(0)))
                i += len(m.group(0))
            else:
                out.append(c)
                i += 1
        else:
            out.append(c)
            i += 1
    return "".join(out)


FN = re.compile(r"\bfn\s+([A-Za-z_][A-Za-z0-9_]*)")


def functions(code):
    """(name, first line, last line) of every fn with a body."""
    line_of = []
    ln = 1
    for ch in code:
        line_of.append(ln)
        if ch == "\n":
            ln += 1
    found = []
    for m in FN.finditer(code):
        # The body starts at the first `{` at bracket depth 0 after the signature; a `;` first
        # means a declaration without a body (trait method).
        kind, body = imports.signature_end(code, m.end())
        if kind != "{":
            continue
        k = imports.matching(code, body)
        found.append((m.group(1), line_of[m.start()], line_of[min(k, len(code) - 1)]))
    return found


USE = re.compile(r"\bcrate::(herd|flock|crowd|lift)\b")
RAW_WRITE = re.compile(
    r"\b(fs::write|File::create|OpenOptions|fs::create_dir(_all)?|fs::copy|fs::rename"
    r"|fs::hard_link|os::unix::fs::symlink)\b"
)


def raw_writes(rel, code):
    """File-system writes outside data::atomic (before any test module)."""
    if rel.startswith(os.path.join("src", "data", "atomic")) or os.path.basename(rel) == "tests.rs":
        return []
    if "tests" in rel.split(os.sep)[:-1] or rel.startswith("kernels"):
        return []
    cut = code.find("#[cfg(test)]")
    body = code if cut < 0 else code[:cut]
    out = []
    for m in RAW_WRITE.finditer(body):
        line = body.count("\n", 0, m.start()) + 1
        out.append((rel, f"{rel}:{line}: {m.group(1)} writes past the output plan (use data::atomic)"))
    return out


def circle_errors():
    """(key, message) of every circle of imports between the entries of one folder."""
    out = []
    for root in CRATES:
        if not os.path.exists(os.path.join(ROOT, root)):
            continue

        def read(rel):
            return code_only(pathlib.Path(os.path.join(ROOT, rel)).read_text(encoding="utf-8"))

        graph = imports.crate_graph(root, read, ROOT)
        for folder, units, loops in imports.circles(graph):
            short = lambda u: u[len(folder) + 1 :] if folder else u  # noqa: E731
            lines = [f"circle of imports in {folder}/: {', '.join(short(u) for u in units)}"]
            for loop in loops:
                lines.append("  loop: " + " -> ".join(short(u) for u, _, _ in loop + loop[:1]))
                for u, v, fs in loop:
                    for a, b, n in fs[:SHOWN_ARROWS]:
                        lines.append(f"    {a} -> {b}: {', '.join(n)}")
                    if len(fs) > SHOWN_ARROWS:
                        lines.append(f"    … and {len(fs) - SHOWN_ARROWS} more from {short(u)} to {short(v)}")
            out.append((f"circle {folder}: {' '.join(units)}", "\n".join(lines)))
    return out


def main():
    global ROOT
    report = "--report" in sys.argv
    if "--root" in sys.argv:
        ROOT = os.path.abspath(sys.argv[sys.argv.index("--root") + 1])
    bad = []
    sizes, fns = [], []
    for path in rust_files():
        rel = os.path.relpath(path, ROOT)
        text = pathlib.Path(path).read_text(encoding="utf-8")
        lines = text.count("\n") + (0 if text.endswith("\n") or not text else 1)
        sizes.append((lines, rel))
        if lines > MAX_FILE:
            bad.append((rel, f"{rel}: {lines} lines (limit {MAX_FILE})"))
        code = code_only(text)
        for name, a, b in functions(code):
            fns.append((b - a + 1, f"{rel}:{a} fn {name}"))
            if b - a + 1 > MAX_FN:
                bad.append((f"{rel} fn {name}", f"{rel}:{a}: fn {name} is {b - a + 1} lines (limit {MAX_FN})"))
        bad.extend(raw_writes(rel, code))
        parts = rel.split(os.sep)
        if len(parts) > 2 and parts[0] == "src" and parts[1] in SUBSYSTEMS:
            for m in USE.finditer(code):
                if m.group(1) != parts[1]:
                    line = code.count("\n", 0, m.start()) + 1
                    bad.append((rel, f"{rel}:{line}: subsystem {parts[1]} imports crate::{m.group(1)}"))
    circles = circle_errors()
    bad += circles
    if report:
        print("longest files:")
        for n, rel in sorted(sizes, reverse=True)[:15]:
            print(f"  {n:5} {rel}")
        print("longest functions:")
        for n, what in sorted(fns, reverse=True)[:15]:
            print(f"  {n:5} {what}")
    known = [msg for key, msg in bad if key in KNOWN]
    new = [msg for key, msg in bad if key not in KNOWN]
    for msg in known:
        print(f"warning (known, issue #13): {msg}", file=sys.stderr)
    for msg in new:
        print(f"error: {msg}", file=sys.stderr)
    if new:
        sys.exit(1)
    if known:
        print(f"structure: {len(known)} known violation(s) left, no new ones")
        return
    print(
        f"structure: {len(sizes)} files ≤ {MAX_FILE} lines, {len(fns)} functions ≤ {MAX_FN} lines, "
        "subsystems independent, no circle of imports, no write past data::atomic"
    )


if __name__ == "__main__":
    main()
