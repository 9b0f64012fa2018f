#!/usr/bin/env python3
"""Executes every notebook in notebooks/ with nbclient (CI runs this after the Rust tests); any
cell error fails the run. Prints 'notebooks: N passed, M failed'."""
import pathlib, sys
import nbformat
from nbclient import NotebookClient

root = pathlib.Path(__file__).resolve().parent.parent
passed = failed = 0
for nb_path in sorted((root / "notebooks").glob("*.ipynb")):
    nb = nbformat.read(nb_path, as_version=4)
    try:
        NotebookClient(nb, timeout=600, kernel_name="python3",
                       resources={"metadata": {"path": str(root / "notebooks")}}).execute()
        passed += 1
        print(f"ok   {nb_path.name}")
    except Exception as e:  # noqa: BLE001 - report and count every failure
        failed += 1
        print(f"FAIL {nb_path.name}: {str(e).splitlines()[-1] if str(e) else e}")
print(f"notebooks: {passed} passed, {failed} failed")
sys.exit(1 if failed or not passed else 0)
