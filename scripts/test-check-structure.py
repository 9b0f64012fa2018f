#!/usr/bin/env python3
"""Tests of scripts/check-structure.py's circle guard: a copy of this tree passes, and adding a
circle between two files, round a longer loop, or between two folders (with no circle between
their files) makes it fail, naming the circle; an import down, an import in test code and a
module's import of its own submodule do not. Also: every function ARCHITECTURE.md's equation
table names exists, and scripts/check-docs.py fails on a dated heading, a document over its
limit and a broken link.

    python3 scripts/test-check-structure.py
"""

import os
import pathlib
import re
import shutil
import subprocess
import sys
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
CHECK = os.path.join(HERE, "check-structure.py")


def run(root):
    p = subprocess.run(
        [sys.executable, CHECK, "--root", root], capture_output=True, text=True, check=False
    )
    return p.returncode, p.stdout + p.stderr


class CircleGuard(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.mkdtemp(prefix="check-structure-")
        for d in ("src", "kernels/src"):
            shutil.copytree(os.path.join(REPO, d), os.path.join(self.tmp, d))

    def tearDown(self):
        shutil.rmtree(self.tmp)

    def append(self, rel, text):
        with open(os.path.join(self.tmp, rel), "a", encoding="utf-8") as f:
            f.write("\n" + text + "\n")

    def assert_circle(self, *names):
        rc, out = run(self.tmp)
        self.assertEqual(rc, 1, out)
        lines = [l for l in out.splitlines() if "circle of imports" in l]
        self.assertTrue(any(all(n in l for n in names) for l in lines), out)
        return out

    def test_this_tree_passes(self):
        rc, out = run(self.tmp)
        self.assertEqual(rc, 0, out)
        self.assertIn("no circle of imports", out)

    def test_two_files_importing_each_other_fail(self):
        # crowd/eval.rs imports crowd/features.rs; features importing eval closes a circle.
        self.append("src/crowd/features.rs", "use super::eval::EvalConfig;\n"
                    "pub fn settings() -> EvalConfig { EvalConfig::default() }")
        out = self.assert_circle("src/crowd/", "eval.rs", "features.rs")
        self.assertIn("src/crowd/features.rs -> src/crowd/eval.rs: EvalConfig", out)

    def test_a_longer_loop_through_a_use_path_fails(self):
        # sequence → terms → observe exists; observe using sequence by a full path closes it.
        self.append("src/lift/observe.rs",
                    "pub fn stride() -> usize { crate::lift::sequence::SequenceConfig::default().coarse_stride }")
        self.assert_circle("src/lift/", "observe.rs", "sequence.rs")

    def test_two_folders_importing_each_other_fail(self):
        # herd/fit/log.rs → herd/author/scene.rs and herd/author/nav.rs → herd/fit/config.rs:
        # no two files import each other, but the folders fit and author do.
        self.append("src/herd/fit/log.rs", "pub fn scene(s: &crate::herd::author::scene::Scene) -> usize { s.params.len() }")
        self.append("src/herd/author/nav.rs", "use crate::herd::fit::config::FitConfig;\n"
                    "pub fn fit_seed(c: &FitConfig) -> u64 { c.seed }")
        out = self.assert_circle("src/herd/", "author", "fit")
        self.assertIn("src/herd/fit/log.rs -> src/herd/author/scene.rs: Scene", out)
        self.assertIn("src/herd/author/nav.rs -> src/herd/fit/config.rs: FitConfig", out)

    def test_a_reexport_is_followed_to_the_defining_file(self):
        # `crate::herd::fit::FitConfig` is re-exported by fit/mod.rs from fit/config.rs; the
        # arrow goes to config.rs, so config.rs importing the author folder closes the circle.
        self.append("src/herd/author/nav.rs", "pub fn seed(c: &crate::herd::fit::FitConfig) -> u64 { c.seed }")
        self.append("src/herd/fit/config.rs", "pub fn cells(s: &crate::herd::author::scene::Scene) -> usize { s.grid.nx }")
        out = self.assert_circle("src/herd/", "author", "fit")
        self.assertIn("src/herd/author/nav.rs -> src/herd/fit/config.rs: FitConfig", out)

    def test_imports_down_in_tests_and_to_submodules_pass(self):
        # Down: author uses the zones format. Test code may reach up. A module's file uses its
        # own submodule (zones/mod.rs → zones/mask.rs) while the submodule uses its parent.
        self.append("src/herd/author/nav.rs", "pub fn zones(z: &crate::herd::zones::Zones) -> usize { z.len() }")
        self.append("src/herd/params.rs", "#[cfg(test)]\nmod reach_up {\n"
                    "    use crate::herd::fit::FitConfig;\n"
                    "    #[test]\n    fn seed() { assert_eq!(FitConfig::default().seed, 0); }\n}")
        rc, out = run(self.tmp)
        self.assertEqual(rc, 0, out)


def defined(name, text):
    return re.search(r"\b(fn|struct|enum|trait|type|const|mod)\s+" + re.escape(name) + r"\b", text)


def source_of(path):
    """(file, the names after the module part) of a `crate::path` as ARCHITECTURE.md writes it
    (`kernels::…` for the kernels crate), or None."""
    parts = path.split("::")
    base, segs = ("kernels/src", parts[1:]) if parts[0] == "kernels" else ("src", parts)
    for k in range(len(segs), 0, -1):
        for cand in (os.path.join(base, *segs[:k]) + ".rs", os.path.join(base, *segs[:k], "mod.rs")):
            if os.path.exists(os.path.join(REPO, cand)):
                return cand, segs[k:]
    return None


class EquationTable(unittest.TestCase):
    def test_every_function_the_equation_table_names_exists(self):
        # ARCHITECTURE.md's "Paper equations → code": each `module::item` resolves to a file
        # that defines the item; a bare `item` after it in the same cell is defined in that file.
        text = pathlib.Path(os.path.join(REPO, "ARCHITECTURE.md")).read_text(encoding="utf-8")
        table = text[text.index("## Paper equations") : text.index("## Invariants")]
        checked = 0
        for row in table.splitlines()[4:]:
            cell = row.split("|")[3] if row.count("|") >= 4 else ""
            last = None
            for name in re.findall(r"`([A-Za-z_][A-Za-z0-9_:]*)`", cell):
                if "::" in name and not name[0].isupper():
                    found = source_of(name)
                    self.assertIsNotNone(found, f"{name}: no such module")
                    last, rest = found
                    items = rest
                else:
                    # A bare item, or `Type::method`, of the module named before it in the cell.
                    self.assertIsNotNone(last, f"{name}: no module before it in: {row}")
                    items = name.split("::")
                src = pathlib.Path(os.path.join(REPO, last)).read_text(encoding="utf-8")
                for item in items:
                    self.assertTrue(defined(item, src), f"{name}: {item} is not defined in {last}")
                checked += 1
        self.assertGreater(checked, 30)


class DocGuard(unittest.TestCase):
    """scripts/check-docs.py: passes on this tree; a dated heading, a file over its limit and a
    link to a missing heading each fail it."""

    def setUp(self):
        self.tmp = tempfile.mkdtemp(prefix="check-docs-")
        for name in ("README.md", "ARCHITECTURE.md", "RESULTS.md", "BENCHMARKS.md"):
            shutil.copy(os.path.join(REPO, name), self.tmp)
        shutil.copytree(os.path.join(REPO, "docs"), os.path.join(self.tmp, "docs"))

    def tearDown(self):
        shutil.rmtree(self.tmp)

    def run_docs(self):
        p = subprocess.run(
            [sys.executable, os.path.join(HERE, "check-docs.py"), "--root", self.tmp],
            capture_output=True, text=True, check=False,
        )
        return p.returncode, p.stdout + p.stderr

    def append(self, name, text):
        with open(os.path.join(self.tmp, name), "a", encoding="utf-8") as f:
            f.write(text)

    def test_this_tree_passes(self):
        rc, out = self.run_docs()
        self.assertEqual(rc, 0, out)

    def test_a_dated_heading_fails(self):
        self.append("RESULTS.md", "\n### Session 45 (2026-12-07): more\n")
        rc, out = self.run_docs()
        self.assertEqual(rc, 1, out)
        self.assertIn("heading with a date or diary numbering: 'Session 45 (2026-12-07): more'", out)

    def test_a_file_over_its_limit_fails(self):
        self.append("README.md", "line\n" * 200)
        rc, out = self.run_docs()
        self.assertEqual(rc, 1, out)
        self.assertRegex(out, r"README.md: \d+ lines \(limit 200\)")

    def test_a_link_to_a_missing_heading_fails(self):
        self.append("README.md", "\nSee [there](RESULTS.md#no-such-heading).\n")
        rc, out = self.run_docs()
        self.assertEqual(rc, 1, out)
        self.assertIn("README.md: link to a missing heading: RESULTS.md#no-such-heading", out)


if __name__ == "__main__":
    unittest.main()
