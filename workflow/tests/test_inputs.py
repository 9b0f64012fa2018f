"""The workflow's input discovery and step wrapper (workflow/scripts/herdfit_wf.py), without
herdfit or Snakemake: which entries of an input folder become which clips, the one-line errors
for bad inputs, and the error line a failed step reports.

    .venv-workflow/bin/python -m pytest workflow/tests/test_inputs.py -v
"""

import pathlib
import subprocess
import sys

import pytest

SCRIPTS = pathlib.Path(__file__).resolve().parents[1] / "scripts"
sys.path.insert(0, str(SCRIPTS))
import herdfit_wf  # noqa: E402


def touch(folder, *names):
    for n in names:
        p = folder / n
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text("x")


def test_each_input_kind_becomes_one_clip_with_its_ingest_step(tmp_path):
    touch(tmp_path, "herd 07.MP4", "b.avi", "fish.npy", "people.txt", "walk.csv", "walk.json",
          "sheep_data_meta.txt", "sheep_data_frame.txt", "sheep_data_cell.txt",
          "made/clip.json", "made/fields.npz", "notes.md", "frame.png", ".hidden.avi",
          "empty_folder/readme")
    clips = herdfit_wf.discover(str(tmp_path))
    kinds = {n: (c.kind, c.ingest_rule()) for n, c in clips.items()}
    assert kinds == {
        "herd_07": ("video", "extract"),  # the space becomes _, the extension's case is ignored
        "b": ("video", "extract"),
        "fish": ("tracks", "import_tracks"),
        "people": ("tracks", "import_tracks"),
        "walk": ("tracks", "import_tracks"),  # its .json sidecar is no clip of its own
        "sheep": ("reference", "import_reference"),
        "made": ("clip", None),
    }
    sheep = clips["sheep"]
    assert sheep.path == str(tmp_path / "sheep")
    assert [pathlib.Path(f).name for f in sheep.files] == [
        "sheep_data_meta.txt", "sheep_data_frame.txt", "sheep_data_cell.txt"]


def test_two_inputs_with_one_clip_name_is_an_error_naming_both(tmp_path):
    touch(tmp_path, "a/herd.avi", "b/herd.mp4")
    with pytest.raises(herdfit_wf.InputError) as e:
        herdfit_wf.discover([str(tmp_path / "a"), str(tmp_path / "b")])
    msg = str(e.value)
    assert "'herd'" in msg and "a/herd.avi" in msg and "b/herd.mp4" in msg
    assert "\n" not in msg


def test_missing_or_empty_input_folder_names_the_config_key(tmp_path):
    with pytest.raises(herdfit_wf.InputError, match=r"^config key inputs: .*/nope: no such folder$"):
        herdfit_wf.discover(str(tmp_path / "nope"))
    touch(tmp_path, "notes.md")
    with pytest.raises(herdfit_wf.InputError, match=r"^config key inputs: .*: no video, tracks"):
        herdfit_wf.discover(str(tmp_path))
    with pytest.raises(herdfit_wf.InputError, match=r"^config key inputs: no input folder given$"):
        herdfit_wf.discover([])


def test_failed_step_prints_herdfits_error_line_and_its_exit_status(tmp_path):
    log = tmp_path / "logs" / "extract" / "c.log"
    cmd = [sys.executable, "-c",
           "import sys; print('reading'); print('error: in/c.avi: truncated', file=sys.stderr); "
           "sys.exit(3)"]
    out = subprocess.run([sys.executable, str(SCRIPTS / "herdfit_wf.py"), "run", "extract", "c",
                          str(log), "1", "--", *cmd], capture_output=True, text=True)
    assert out.returncode == 3
    assert out.stderr.strip() == "herdfit extract c: in/c.avi: truncated"
    text = log.read_text()
    assert "reading\n" in text and "error: in/c.avi: truncated\n" in text
    assert herdfit_wf.error_line(str(log)) == "in/c.avi: truncated"


def test_step_whose_program_cannot_run_names_the_config_key(tmp_path):
    log = tmp_path / "x.log"
    code = herdfit_wf.main(["run", "fit", "c", str(log), "1", "--", str(tmp_path / "no-herdfit")])
    assert code == 127
    assert herdfit_wf.error_line(str(log)).endswith("cannot run: No such file or directory (config key herdfit)")
