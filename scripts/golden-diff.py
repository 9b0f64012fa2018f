#!/usr/bin/env python3
"""Explains the differences between two scripts/golden.sh output folders.

    python3 scripts/golden-diff.py BASE_OUT NEW_OUT

For every file whose hash differs it says whether the difference is only a top-level `schema`
tag added to a JSON report (the restructure's one intended change of bytes), and lists any other
difference, files that appeared or vanished included. Exit 1 when something else differs.
"""

import json
import sys


def hashes(folder):
    out = {}
    for line in open(f"{folder}/hashes.txt"):
        h, name = line.split(maxsplit=1)
        out[name.strip()] = h
    return out


def main():
    base, new = sys.argv[1], sys.argv[2]
    skip = set(open(f"{new}/nondeterministic.txt").read().split())
    a, b = hashes(base), hashes(new)
    other = []
    tagged = []
    for name in sorted(set(a) | set(b)):
        if name.lstrip("./") in {s.lstrip("./") for s in skip} or a.get(name) == b.get(name):
            continue
        if name not in a or name not in b:
            other.append(f"{name}: only in {'new' if name in b else 'base'}")
            continue
        try:
            x = json.load(open(f"{base}/{name}"))
            y = json.load(open(f"{new}/{name}"))
        except (ValueError, UnicodeDecodeError):
            other.append(f"{name}: differs (not JSON)")
            continue
        tag = y.pop("schema", None) if isinstance(y, dict) else None
        if tag and "schema" not in x and x == y:
            tagged.append(f"{name}: + schema {tag}")
        else:
            other.append(f"{name}: differs")
    for t in tagged:
        print(t)
    for o in other:
        print(f"OTHER {o}")
    print(f"{len(tagged)} file(s) differ only by a schema tag, {len(other)} otherwise")
    sys.exit(1 if other else 0)


if __name__ == "__main__":
    main()
