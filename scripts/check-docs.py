#!/usr/bin/env python3
"""Document guard (issue #48): the top-level documents stay readable as others add to them.

- Length: README.md ≤ 200 lines, ARCHITECTURE.md ≤ 250, RESULTS.md and BENCHMARKS.md ≤ 400.
- Headings of those four carry no date and no diary numbering ("2026-12-03", "Session 38").
- Every relative link in them and in docs/*.md (not the dated notes, which are history) points
  to a file that exists, and a `#anchor` to a heading of that file (GitHub's anchor rule).

    python3 scripts/check-docs.py              # check; exit 1 and list every violation
    python3 scripts/check-docs.py --root DIR   # check the documents of another checkout
"""

import os
import pathlib
import re
import sys

LIMITS = {"README.md": 200, "ARCHITECTURE.md": 250, "RESULTS.md": 400, "BENCHMARKS.md": 400}
DIARY = re.compile(r"\b(19|20)\d\d-\d\d-\d\d\b|\b[Ss]ession\s+\d+|\b\d{1,2}:\d\d\s*UTC\b")
LINK = re.compile(r"\]\(([^)\s]+)\)")


def anchor(heading):
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"`", "", heading.strip().lower())
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def headings(path):
    out, fence = [], False
    for line in pathlib.Path(path).read_text(encoding="utf-8").splitlines(True):
        if line.startswith("```"):
            fence = not fence
        elif not fence and re.match(r"#{1,6} ", line):
            out.append(line.lstrip("#").strip())
    return out


def check(root):
    bad = []
    for name, limit in LIMITS.items():
        path = os.path.join(root, name)
        if not os.path.exists(path):
            bad.append(f"{name}: missing")
            continue
        n = len(pathlib.Path(path).read_text(encoding="utf-8").splitlines())
        if n > limit:
            bad.append(f"{name}: {n} lines (limit {limit})")
        for h in headings(path):
            if DIARY.search(h):
                bad.append(f"{name}: heading with a date or diary numbering: '{h}'")
    docs = list(LIMITS)
    docs_dir = os.path.join(root, "docs")
    if os.path.isdir(docs_dir):
        docs += [os.path.join("docs", f) for f in sorted(os.listdir(docs_dir)) if f.endswith(".md")]
    docs.append(os.path.join("docs", "notes", "README.md"))
    for rel in docs:
        path = os.path.join(root, rel)
        if not os.path.exists(path):
            continue
        text = pathlib.Path(path).read_text(encoding="utf-8")
        text = re.sub(r"```.*?```", "", text, flags=re.S)
        for target in LINK.findall(text):
            if re.match(r"[a-z]+:", target):
                continue
            file, _, frag = target.partition("#")
            dest = os.path.normpath(os.path.join(os.path.dirname(path), file)) if file else path
            if not os.path.exists(dest):
                bad.append(f"{rel}: link to a missing file: {target}")
            elif frag and dest.endswith(".md") and frag not in {anchor(h) for h in headings(dest)}:
                bad.append(f"{rel}: link to a missing heading: {target}")
    return bad


def main():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    if "--root" in sys.argv:
        root = os.path.abspath(sys.argv[sys.argv.index("--root") + 1])
    bad = check(root)
    for msg in bad:
        print(f"error: {msg}", file=sys.stderr)
    if bad:
        sys.exit(1)
    sizes = ", ".join(
        f"{n} {len(pathlib.Path(root, n).read_text(encoding='utf-8').splitlines())}/{l}"
        for n, l in LIMITS.items()
    )
    print(f"docs: {sizes} lines; headings undated; links resolve")


if __name__ == "__main__":
    main()
