#!/usr/bin/env python3
"""What the Snakefile, its rules and the summary share: which inputs are clips, and how one step
runs herdfit (its log, its one-line error, the fit's checkpoint and resume).

Inputs (`discover`): every entry of the input folder(s) that herdfit can read is one clip, named
after the file (the stem; characters outside [A-Za-z0-9._-] become `_`):
  video      .avi .mp4 .mov .mkv .m4v .mpg .mpeg .wmv .webm     -> herdfit extract
  reference  PREFIX_data_meta.txt (+ _data_frame, _data_cell)   -> herdfit import-reference
             (the clip is named after PREFIX)
  tracks     .npy (idtracker.ai/trajectorytools), .csv (herdfit.tracks/1 with its .json
             sidecar), other .txt (ETH/UCY: needs --fps and --body-length-m in the config)
                                                                -> herdfit import-tracks
  clip       a folder holding clip.json (a clip herdfit already made: synth, extract, …)
                                                                -> fitted in place
Hidden entries and anything else (images, .json sidecars, notes) are left out.

Steps (`python3 herdfit_wf.py run|fit …`): run the herdfit command line given after `--` with its
stdout and stderr in the step's log; on failure print `herdfit <step> <clip>: <herdfit's error
line>` to stderr and exit with herdfit's status, so Snakemake marks that job failed (retries,
--keep-going) and the summary can quote the same line from the log.
"""

import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass, field

VIDEO_EXT = {".avi", ".mp4", ".mov", ".mkv", ".m4v", ".mpg", ".mpeg", ".wmv", ".webm"}
TRACKS_EXT = {".npy", ".csv", ".txt"}
REFERENCE_PARTS = ("_data_meta.txt", "_data_frame.txt", "_data_cell.txt")
# The step that turns each kind of input into a clip folder (Snakemake rule names).
INGEST = {"video": "extract", "reference": "import_reference", "tracks": "import_tracks"}


class InputError(Exception):
    """Bad input folder or clash of clip names: one line naming the path or config key."""


@dataclass
class Clip:
    name: str
    kind: str  # video | reference | tracks | clip
    path: str  # the file, the reference prefix, or the clip folder
    files: list = field(default_factory=list)  # the files the ingest step reads

    def ingest_rule(self):
        return INGEST.get(self.kind)


def clip_name(stem):
    return re.sub(r"[^A-Za-z0-9._-]", "_", stem)


def _entry(folder, entry):
    """The clip an entry of an input folder stands for, or None."""
    path = os.path.join(folder, entry)
    if entry.startswith("."):
        return None
    if os.path.isdir(path):
        if os.path.isfile(os.path.join(path, "clip.json")):
            return Clip(clip_name(entry), "clip", path, [path])
        return None
    low = entry.lower()
    if low.endswith(REFERENCE_PARTS[0]):
        prefix = path[: -len(REFERENCE_PARTS[0])]
        files = [prefix + p for p in REFERENCE_PARTS if os.path.isfile(prefix + p)]
        return Clip(clip_name(os.path.basename(prefix)), "reference", prefix, files)
    if low.endswith(REFERENCE_PARTS[1:]):
        return None  # part of a reference clip, named by its _data_meta.txt
    stem, ext = os.path.splitext(entry)
    ext = ext.lower()
    if ext in VIDEO_EXT:
        return Clip(clip_name(stem), "video", path, [path])
    if ext in TRACKS_EXT:
        return Clip(clip_name(stem), "tracks", path, [path])
    return None


def discover(inputs):
    """Clips of the input folder(s) (config key `inputs`: one folder or a list), by name."""
    folders = [inputs] if isinstance(inputs, str) else list(inputs or [])
    if not folders:
        raise InputError("config key inputs: no input folder given")
    clips = {}
    for folder in folders:
        if not os.path.isdir(folder):
            raise InputError(f"config key inputs: {folder}: no such folder")
        for entry in sorted(os.listdir(folder)):
            clip = _entry(folder, entry)
            if clip is None:
                continue
            if clip.name in clips:
                raise InputError(
                    f"{clip.path}: clip name '{clip.name}' is also that of "
                    f"{clips[clip.name].path} (rename one of them)"
                )
            clips[clip.name] = clip
    if not clips:
        raise InputError(f"config key inputs: {', '.join(folders)}: no video, tracks, reference or clip folder")
    return clips


def split_frame(clip_dir, split):
    """The first held-out frame of a clip, ⌊frames · split⌋, as `validate --split` takes it."""
    with open(os.path.join(clip_dir, "clip.json")) as f:
        frames = int(json.load(f)["frames"])
    return int(frames * float(split))


def tracks_file(clip_dir):
    """The clip's tracked animals, where its folder has them (import-tracks, synth)."""
    for name in ("tracks.csv", "trajectories.csv"):
        if os.path.isfile(os.path.join(clip_dir, name)):
            return os.path.join(clip_dir, name)
    return None


def error_line(log_path):
    """herdfit's one-line error from a step's log (its last `error:` line), or None."""
    try:
        with open(log_path, errors="replace") as f:
            lines = [line.rstrip("\n") for line in f]
    except OSError:
        return None
    for line in reversed(lines):
        if line.startswith("error:"):
            return line[len("error:"):].strip()
    return None


def _run(step, clip, log, cmd, threads):
    env = dict(os.environ)
    env["RAYON_NUM_THREADS"] = str(threads)  # the job's cores, no more (Slurm: --cpus-per-task)
    os.makedirs(os.path.dirname(log) or ".", exist_ok=True)
    with open(log, "a") as out:
        out.write("$ " + " ".join(cmd) + "\n")
        out.flush()
        try:
            code = subprocess.call(cmd, stdout=out, stderr=subprocess.STDOUT, env=env)
        except OSError as e:
            out.write(f"error: {cmd[0]}: cannot run: {e.strerror} (config key herdfit)\n")
            code = 127
    if code != 0:
        line = error_line(log) or f"exit status {code} (see {log})"
        print(f"herdfit {step} {clip}: {line}", file=sys.stderr)
    return code


def _checkpoint_dir(root, clip_dir, cmd):
    """A checkpoint folder keyed by the clip's content and the fit's command line, so a changed
    clip or changed settings start afresh instead of resuming someone else's fit."""
    h = hashlib.sha256()
    for name in ("clip.json", "fields.npz"):
        p = os.path.join(clip_dir, name)
        if os.path.isfile(p):
            with open(p, "rb") as f:
                h.update(f.read())
    h.update("\0".join(cmd).encode())
    return os.path.join(root, h.hexdigest()[:16])


def fit(clip, clip_dir, log, checkpoints, split, threads, cmd):
    """herdfit fit on the frames before the held-out part, checkpointed after every epoch and
    resumed from the last checkpoint when an earlier run of this job was stopped."""
    if split is not None and "--frames" not in cmd:
        cmd = cmd + ["--frames", f"0..{split_frame(clip_dir, split)}"]
    ck = _checkpoint_dir(checkpoints, clip_dir, cmd)
    state = os.path.join(ck, "checkpoint.json")
    resume = []
    # Write the log afresh: a resumed fit's log tells where it took over.
    os.makedirs(os.path.dirname(log) or ".", exist_ok=True)
    with open(log, "w") as out:
        if os.path.isfile(state):
            with open(state) as f:
                done = json.load(f).get("epochs_done")
            msg = f"fit {clip}: resuming from {state} ({done} epochs done)"
            out.write(msg + "\n")
            print(msg, file=sys.stderr)
            resume = ["--resume"]
    # herdfit writes the checkpoint folder itself but not its parents (an output's folder must
    # exist, #47): the clip's folder of checkpoints is made here.
    os.makedirs(checkpoints, exist_ok=True)
    code = _run("fit", clip, log, cmd + ["--checkpoint", ck] + resume, threads)
    if code == 0:
        shutil.rmtree(ck, ignore_errors=True)
        try:
            os.rmdir(checkpoints)  # the clip's folder of checkpoints, once empty
        except OSError:
            pass
    return code


def main(argv):
    """python3 herdfit_wf.py run STEP CLIP LOG THREADS -- CMD…
    python3 herdfit_wf.py fit CLIP CLIP_DIR LOG CHECKPOINTS SPLIT THREADS -- CMD…"""
    if "--" not in argv:
        print(main.__doc__, file=sys.stderr)
        return 2
    sep = argv.index("--")
    head, cmd = argv[:sep], argv[sep + 1:]
    if head[:1] == ["run"] and len(head) == 5:
        _, step, clip, log, threads = head
        if os.path.exists(log):
            os.remove(log)
        return _run(step, clip, log, cmd, int(threads))
    if head[:1] == ["fit"] and len(head) == 7:
        _, clip, clip_dir, log, checkpoints, split, threads = head
        split = None if split in ("", "none") else split
        return fit(clip, clip_dir, log, checkpoints, split, int(threads), cmd)
    print(main.__doc__, file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
