"""Which Rust source file of a crate imports which (for scripts/check-structure.py).

A crate is read from its root (`src/lib.rs`): `mod x;` declarations give the module tree, and
every path that names an item of the crate (`use` trees, and `crate::`, `super::`, `self::` or
module-alias paths in the code) is resolved to the file that *defines* the item, following
re-exports (`pub use`) and a module's private imports (which its children see through `super::`).
So `use crate::herd::fit::ParamSets` is an arrow to the file that defines `ParamSets`, not to
`fit/mod.rs` that hands it on. `mod x;` declarations and re-exports are not arrows themselves.
Test code (items under `#[cfg(test)]`) is left out: a test may reach up to build its fixtures.

    graph = crate_graph("src/lib.rs", read)   # {file: {imported file: {names}}}
    circles(graph)                            # loops between the entries of one folder
"""

import os
import re

IDENT = r"[A-Za-z_][A-Za-z0-9_]*"
ITEM = re.compile(
    r"\b(?:fn|struct|enum|trait|type|const|static|union|macro_rules!)\s+(" + IDENT + r")"
)
MOD_DECL = re.compile(r"\bmod\s+(" + IDENT + r")\s*([;{])")
USE = re.compile(r"\buse\b")
PATH = re.compile(r"(?<![A-Za-z0-9_:])((?:" + IDENT + r")(?:\s*::\s*" + IDENT + r")+)")
CFG_TEST = re.compile(r"#\[cfg\(test\)\]")


def matching(code, i, open_="{", close="}"):
    """Index of the bracket closing the one at i."""
    depth = 0
    for k in range(i, len(code)):
        if code[k] == open_:
            depth += 1
        elif code[k] == close:
            depth -= 1
            if depth == 0:
                return k
    return len(code) - 1


def signature_end(code, i):
    """Where the item whose signature starts at i ends its signature: `("{", k)` at the `{` of
    its body, `(";", k)` at a `;` (a declaration without a body), both at bracket depth 0, or
    `(None, len(code))`."""
    depth = 0
    for k in range(i, len(code)):
        c = code[k]
        if c in "([":
            depth += 1
        elif c in ")]":
            depth -= 1
        elif c in ";{" and depth == 0:
            return c, k
    return None, len(code)


def item_end(code, i):
    """End (exclusive) of the item starting at i: its `;` or its body's closing brace."""
    kind, k = signature_end(code, i)
    if kind == "{":
        return matching(code, k) + 1
    return min(k + 1, len(code))


def blank_tests(code):
    """The code with every `#[cfg(test)]` item blanked (newlines kept)."""
    out = code
    for m in reversed(list(CFG_TEST.finditer(code))):
        j = m.end()
        # Further attributes before the item.
        while True:
            while j < len(code) and code[j].isspace():
                j += 1
            if code.startswith("#[", j):
                j = matching(code, j + 1, "[", "]") + 1
            else:
                break
        end = item_end(code, j)
        out = out[: m.start()] + re.sub(r"[^\n]", " ", out[m.start() : end]) + out[end:]
    return out


def split_top(s):
    """Split s at top-level commas (outside braces)."""
    parts, depth, cur = [], 0, []
    for c in s:
        if c == "{":
            depth += 1
        elif c == "}":
            depth -= 1
        if c == "," and depth == 0:
            parts.append("".join(cur))
            cur = []
        else:
            cur.append(c)
    parts.append("".join(cur))
    return [p.strip() for p in parts if p.strip()]


def use_tree(tree, prefix=()):
    """[(path segments, local name or None for a glob)] of a use tree such as `a::{b, c as d}`."""
    tree = re.sub(r"\s*(::|\{|\}|,)\s*", r"\1", tree.strip())
    if tree.startswith("::"):
        tree = tree[2:]
    brace = tree.find("{")
    if brace >= 0:
        head = [s for s in tree[:brace].split("::") if s]
        body = tree[brace + 1 : tree.rfind("}")]
        out = []
        for part in split_top(body):
            out += use_tree(part, prefix + tuple(head))
        return out
    alias = None
    m = re.match(r"^(.*?)\s+as\s+(" + IDENT + r")$", tree)
    if m:
        tree, alias = m.group(1), m.group(2)
    segs = tuple(s for s in tree.split("::") if s)
    if segs and segs[-1] == "*":
        return [(prefix + segs[:-1], None)]
    if segs and segs[-1] == "self":
        segs = segs[:-1]
    full = prefix + segs
    return [(full, alias or (full[-1] if full else None))]


class Module:
    def __init__(self, path, file):
        self.path = path  # tuple of names from the crate root
        self.file = file
        self.children = {}  # name -> module path
        self.defs = set()
        self.imports = {}  # local name -> (absolute path, module path it was written in)
        self.globs = []  # absolute paths of glob imports
        self.inline = False


class Crate:
    def __init__(self, root_file, read, base="."):
        self.read = read  # file -> code (comments and strings blanked)
        self.base = base  # the folder the file paths are relative to
        self.root_file = root_file
        self.mods = {}
        self.files = {}  # file -> code with tests blanked
        self.spans = {}  # file -> [(start, end, module path)] of inline modules
        self._load((), root_file)
        for file, code in self.files.items():
            self._scan_uses(file, code)

    # Module tree and definitions -------------------------------------------------------------
    def _load(self, path, file):
        code = blank_tests(self.read(file))
        self.files[file] = code
        self.spans[file] = []
        self._load_body(path, file, code, 0, len(code), file_level=True)

    def _load_body(self, path, file, code, start, end, file_level):
        mod = Module(path, file)
        mod.inline = not file_level
        self.mods[path] = mod
        body = code[start:end]
        # Items at depth 0 of this body only.
        depth, k, top = 0, 0, []
        for ch in body:
            top.append(ch if depth == 0 else (" " if ch != "\n" else ch))
            if ch == "{":
                depth += 1
            elif ch == "}":
                depth -= 1
        top = "".join(top)
        for m in ITEM.finditer(top):
            mod.defs.add(m.group(1))
        base = os.path.dirname(file)
        stem = os.path.splitext(os.path.basename(file))[0]
        folder = base if stem in ("lib", "main", "mod") else os.path.join(base, stem)
        for m in MOD_DECL.finditer(top):
            name, kind = m.group(1), m.group(2)
            child = path + (name,)
            mod.children[name] = child
            if kind == ";" and file_level:
                for cand in (os.path.join(folder, name + ".rs"), os.path.join(folder, name, "mod.rs")):
                    if os.path.exists(os.path.join(self.base, cand)):
                        self._load(child, cand)
                        break
            elif kind == "{":
                a = start + m.end() - 1
                b = matching(code, a)
                self.spans[file].append((a, b, child))
                self._load_body(child, file, code, a + 1, b, file_level=False)

    def module_at(self, file, pos, file_mod):
        best = file_mod
        for a, b, p in self.spans[file]:
            if a < pos < b and len(p) > len(best):
                best = p
        return best

    # Imports ---------------------------------------------------------------------------------
    def _use_statements(self, code):
        for m in USE.finditer(code):
            j = code.find(";", m.end())
            j = len(code) if j < 0 else j
            yield m.start(), j + 1, code[m.end() : j]

    def _scan_uses(self, file, code):
        file_mod = next(p for p, m in self.mods.items() if m.file == file and not m.inline)
        for a, b, tree in self._use_statements(code):
            here = self.module_at(file, a, file_mod)
            mod = self.mods[here]
            for segs, name in use_tree(tree):
                absolute = self.absolute(segs, here)
                if absolute is None:
                    continue
                if name is None:
                    mod.globs.append(absolute)
                elif name != "_":
                    mod.imports[name] = absolute

    def absolute(self, segs, here):
        """The path from the crate root that segs (written in module `here`) names, or None
        when it leaves the crate (std, another crate)."""
        if not segs:
            return None
        first = segs[0]
        if first == "crate":
            return segs[1:]
        if first == "self":
            return here + segs[1:]
        if first == "super":
            base = here
            i = 0
            while i < len(segs) and segs[i] == "super":
                base = base[:-1]
                i += 1
            return base + segs[i:]
        mod = self.mods.get(here)
        if mod is not None and first in mod.children:
            return here + segs
        if mod is not None and first in mod.imports:
            target = mod.imports[first]
            return target + segs[1:]
        return None

    def resolve(self, path, seen=None):
        """(file, name) defining the item that the absolute `path` names; a module resolves to
        None (a module import is no arrow by itself)."""
        seen = seen or set()
        if path in seen:
            return None
        seen.add(path)
        mod = self.mods[()]
        i = 0
        while i < len(path) and path[i] in mod.children:
            mod = self.mods[mod.children[path[i]]]
            i += 1
        if i == len(path):
            return None
        name = path[i]
        if name in mod.defs:
            return (mod.file, name)
        if name in mod.imports:
            target = mod.imports[name]
            if target in self.mods:
                # A module alias: go on inside it.
                return self.resolve(target + path[i + 1 :], seen)
            return self.resolve(target + path[i + 1 :], seen) or self.resolve_item(target, seen)
        for g in mod.globs:
            got = self.resolve(g + (name,) + path[i + 1 :], seen)
            if got:
                return got
        # An associated item or variant of something defined here, or a macro: this module.
        return (mod.file, name)

    def contains(self, parent, child):
        """Whether file `child` holds a module declared (at any depth) under file `parent`."""
        pmods = [p for p, m in self.mods.items() if m.file == parent and not m.inline]
        cmods = [p for p, m in self.mods.items() if m.file == child and not m.inline]
        return any(len(c) > len(p) and c[: len(p)] == p for p in pmods for c in cmods)

    def resolve_item(self, target, seen):
        return self.resolve(target, seen)

    def graph(self):
        """{file: {imported file: set of names}} for every file of the crate."""
        out = {f: {} for f in self.files}
        for file, code in self.files.items():
            file_mod = next(p for p, m in self.mods.items() if m.file == file and not m.inline)
            refs = []
            uses = list(self._use_statements(code))
            outside = list(code)
            for a, b, _ in uses:
                outside[a:b] = re.sub(r"[^\n]", " ", code[a:b])
            outside = "".join(outside)
            for a, b, tree in uses:
                here = self.module_at(file, a, file_mod)
                reexport = re.search(r"\bpub\s*(\([^)]*\))?\s*$", code[max(0, a - 40) : a])
                for segs, name in use_tree(tree):
                    if name is None:
                        continue
                    # A re-export hands a name on; it is an arrow only where this file uses it.
                    if reexport and not re.search(r"\b" + re.escape(name) + r"\b", outside):
                        continue
                    absolute = self.absolute(segs, here)
                    if absolute is not None:
                        refs.append((absolute, here))
            # Paths in the code, outside use statements.
            for m in PATH.finditer(outside):
                segs = tuple(s.strip() for s in m.group(1).split("::"))
                here = self.module_at(file, m.start(), file_mod)
                absolute = self.absolute(segs, here)
                if absolute is not None:
                    refs.append((absolute, here))
            for absolute, here in refs:
                got = self.resolve(tuple(absolute))
                # A module's file contains its children: its arrows to them are no arrows up.
                if got and got[0] != file and not self.contains(file, got[0]):
                    out[file].setdefault(got[0], set()).add(got[1])
        return out


def crate_graph(root_file, read, base="."):
    """{file: {imported file: names}} of the crate whose root is `root_file` (relative to
    `base`); `read(file)` gives a file's code with comments and strings blanked."""
    return Crate(root_file, read, base).graph()


def cycles(graph):
    """Strongly connected components with more than one node (Tarjan, iterative)."""
    index, low, on, stack, out = {}, {}, set(), [], []
    counter = [0]
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph.get(start, ()))))]
        index[start] = low[start] = counter[0]
        counter[0] += 1
        stack.append(start)
        on.add(start)
        while work:
            v, it = work[-1]
            nxt = next(it, None)
            if nxt is not None:
                if nxt not in index:
                    index[nxt] = low[nxt] = counter[0]
                    counter[0] += 1
                    stack.append(nxt)
                    on.add(nxt)
                    work.append((nxt, iter(sorted(graph.get(nxt, ())))))
                elif nxt in on:
                    low[v] = min(low[v], index[nxt])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        out.append(sorted(comp))
    return out


def unit_graphs(graph):
    """{folder: {unit: {unit: [(file, imported file, names)]}}}: each arrow between two files
    seen from the deepest folder that holds both, as an arrow between the two entries of that
    folder (a file, or a subfolder with all below it) that hold them."""
    out = {}
    for a, targets in graph.items():
        for b, names in targets.items():
            pa, pb = a.split("/"), b.split("/")
            k = 0
            while k < min(len(pa), len(pb)) - 1 and pa[k] == pb[k]:
                k += 1
            folder = "/".join(pa[:k])
            ua, ub = "/".join(pa[: k + 1]), "/".join(pb[: k + 1])
            if ua == ub:
                continue
            g = out.setdefault(folder, {})
            g.setdefault(ua, {}).setdefault(ub, []).append((a, b, sorted(names)))
            g.setdefault(ub, {})
    return out


def shortest_loop(g, nodes):
    """The shortest loop [u0, u1, …] (u_last → u0 closing it) among `nodes` of graph `g`
    ({u: {v: …}}), or None."""
    from collections import deque

    best = None
    for s in sorted(nodes):
        prev = {s: None}
        queue = deque([s])
        found = None
        while queue and found is None:
            u = queue.popleft()
            for v in sorted(g.get(u, ())):
                if v not in nodes:
                    continue
                if v == s:
                    found = u
                    break
                if v not in prev:
                    prev[v] = u
                    queue.append(v)
        if found is not None:
            path = [found]
            while prev[path[-1]] is not None:
                path.append(prev[path[-1]])
            path.reverse()
            if best is None or len(path) < len(best):
                best = path
    return best


def circles(graph, most=3):
    """[(folder, [units of the circle], [loop, …])]: every circle of imports between the entries
    (files or subfolders) of one folder. Each loop is [(unit, next unit, [(file, file, names)])]:
    the shortest loop first, then (its arrow with the fewest file arrows taken out, as the likely
    back door) the next shortest, up to `most`."""
    found = []
    for folder, g in sorted(unit_graphs(graph).items()):
        for comp in cycles({u: set(t) for u, t in g.items()}):
            inside = set(comp)
            left = {u: dict(g[u]) for u in comp}
            loops = []
            while len(loops) < most:
                loop = shortest_loop(left, inside)
                if loop is None:
                    break
                edges = [(u, loop[(i + 1) % len(loop)]) for i, u in enumerate(loop)]
                loops.append([(u, v, g[u][v]) for u, v in edges])
                u, v = min(edges, key=lambda e: len(left[e[0]][e[1]]))
                del left[u][v]
            found.append((folder, comp, loops))
    return found
