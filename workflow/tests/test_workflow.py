"""The many-clips workflow (workflow/Snakefile) run for real, as .ci/run runs it:

    .venv-workflow/bin/python -m pytest workflow/tests -v

Inputs, one of each kind the workflow reads: two small synthetic herd videos (`herdfit synth
--video-file`, 80 animals, 40 frames; extract), the Herds-From-Video reference text of
sheep-narrow from ../shared/data (import-reference; a longer fit, so that it is still running
when the run is killed), 8 tracked fish (trajectorytools' idtracker.ai .npy that
scripts/fetch-testdata.sh puts in .testdata; import-tracks with per-clip flags, fitted and
validated with --tracks) and a corrupt video (the first 30 kB of a good one). The local run (--cores 2) is killed with SIGKILL
midway and run again; then the same workflow runs through a one-node Slurm cluster started here;
the two summaries must be the same bytes. The tests run in file order and share the runs
(module-scoped fixtures); each asserts one thing a user relies on.

HERDFIT_BIN names the binary (default target/release/herdfit), HERDFIT_SHARED_DATA the data.
"""

import base64
import csv
import glob
import hashlib
import json
import os
import pathlib
import re
import signal
import subprocess
import sys
import time

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
SNAKEFILE = ROOT / "workflow" / "Snakefile"
PROFILE = ROOT / "workflow" / "profiles" / "slurm"
CLUSTER = ROOT / "workflow" / "tests" / "slurm-cluster.sh"
HERDFIT = os.environ.get("HERDFIT_BIN") or str(ROOT / "target" / "release" / "herdfit")
SNAKEMAKE = [sys.executable, "-m", "snakemake", "-s", str(SNAKEFILE)]
GOOD = ["fish", "sheep_narrow", "synth1", "synth2"]
FISH = ROOT / ".testdata" / "trajectorytools" / "test_trajectories_idtrackerai.npy"
# The sheep fit's epochs: long enough to be killed in the middle of (about 0.2 s each on one
# core: it runs for more than twice as long as a synthetic clip's extract, fit and validate).
SHEEP_EPOCHS = 60


def shared_data():
    env = os.environ.get("HERDFIT_SHARED_DATA")
    if env:
        return pathlib.Path(env)
    beside = ROOT.parent / "shared" / "data"
    return beside if beside.is_dir() else pathlib.Path("/work/shared/data")


def herdfit(*args, cwd):
    subprocess.run([HERDFIT, *args], cwd=cwd, check=True, capture_output=True, text=True)


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    """The input folder and the settings file both runs share."""
    if not os.access(HERDFIT, os.X_OK):
        pytest.fail(f"{HERDFIT}: no herdfit binary (cargo build --release, or set HERDFIT_BIN)")
    w = tmp_path_factory.mktemp("workflow")
    inp = w / "in"
    inp.mkdir()
    for seed in (1, 2):
        herdfit("synth", "--agents", "80", "--frame-count", "40", "--grid-size", "16x10",
                "--cell-size", "2", "--seed", str(seed), "--out", f"truth{seed}",
                "--video-file", f"in/synth{seed}.avi", cwd=w)
    ref = shared_data() / "herds-from-video" / "sheep_narrow" / "04_20_21_12"
    for part in ("meta", "frame", "cell"):
        os.symlink(f"{ref}_data_{part}.txt", inp / f"sheep_narrow_data_{part}.txt")
    if not FISH.is_file():
        pytest.fail(f"{FISH}: missing (bash scripts/fetch-testdata.sh)")
    os.symlink(FISH, inp / "fish.npy")
    (inp / "corrupt.avi").write_bytes((inp / "synth1.avi").read_bytes()[:30000])
    threads = {"threads": 1, "mem_mb": 1000, "runtime": 10}
    cfg = {
        "inputs": "in",
        "herdfit": HERDFIT,
        "fit": {"epochs": 2, "uncertainty": False, "args": "--eval-seeds 1"},
        "validate": {"seeds": 2},
        "clips": {
            "sheep_narrow": {"fit": {"epochs": SHEEP_EPOCHS}},
            # Pixels without a recorded body length: the flag import-tracks asks for; 100 frames.
            "fish": {"import_tracks": {"args": "--body-length-px 30 --frames 0..100"}},
        },
        # One core per job: two jobs side by side on the 2-core CI machine, here and in Slurm.
        "resources": {r: threads for r in
                      ("extract", "import_reference", "import_tracks", "fit", "validate", "summary")},
    }
    (w / "config.json").write_text(json.dumps(cfg, indent=1))
    return w


def snakemake(work, *args, log=None, env=None):
    out = subprocess.run(SNAKEMAKE + ["--configfile", "config.json", *args], cwd=work,
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    if log:
        (work / log).write_text(out.stdout)
    return out


def jobs_run(log_text):
    """(rule, clip) of every job a Snakemake log shows starting."""
    jobs, rule = [], None
    for line in log_text.splitlines():
        m = re.match(r"^(?:local)?rule (\w+):$", line)
        if m:
            rule = m.group(1)
            if rule in ("summary", "all"):
                jobs.append((rule, None))
            continue
        m = re.match(r"^\s+wildcards: clip=(\S+)$", line)
        if m and rule:
            jobs.append((rule, m.group(1)))
            rule = None
    return jobs


def incomplete(work):
    """Outputs Snakemake marks as incomplete (a job started, not recorded as finished)."""
    out = set()
    for p in glob.glob(str(work / ".snakemake" / "incomplete" / "*")):
        try:
            out.add(base64.b64decode(os.path.basename(p)).decode())
        except ValueError:
            pass
    return out


STEPS = {
    "synth1": [("extract", "clips/synth1")], "synth2": [("extract", "clips/synth2")],
    "corrupt": [("extract", "clips/corrupt")],
    "sheep_narrow": [("import_reference", "clips/sheep_narrow")],
    "fish": [("import_tracks", "clips/fish")],
}
for _c in STEPS:
    STEPS[_c] += [("fit", f"fits/{_c}/params.json"), ("validate", f"validation/{_c}")]


def finished_jobs(work, results):
    """(rule, clip) of every job whose output is on disk and not marked incomplete."""
    inc = incomplete(work)
    return {
        (rule, clip)
        for clip, steps in STEPS.items()
        for rule, out in steps
        if (work / results / out).exists() and f"{results}/{out}" not in inc
    }


def summary_rows(path):
    with open(path, newline="") as f:
        return {r["clip"]: r for r in csv.DictReader(f)}


@pytest.fixture(scope="module")
def local(work):
    """The local run: started, killed with SIGKILL while the sheep fit is in its epochs and at
    least one synthetic clip is done, then unlocked and run again with --keep-going."""
    log = open(work / "local-1.log", "w")
    t_start = time.time()
    proc = subprocess.Popen(
        SNAKEMAKE + ["--configfile", "config.json", "--cores", "2", "--keep-going"],
        cwd=work, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    deadline = time.time() + 600
    ck_pattern = str(work / "results" / "checkpoints" / "sheep_narrow" / "*" / "checkpoint.json")
    epochs = 0
    while True:
        if proc.poll() is not None:
            pytest.fail(f"the run ended (exit {proc.returncode}) before it could be killed midway: "
                        + (work / "local-1.log").read_text()[-2000:])
        if time.time() > deadline:
            os.killpg(proc.pid, signal.SIGKILL)
            pytest.fail("no midway point within 600 s")
        # A clip is done when Snakemake has recorded its validation as finished.
        done = [c for c in ("synth1", "synth2") if ("validate", c) in finished_jobs(work, "results")]
        cks = glob.glob(ck_pattern)
        if done and cks:
            try:
                with open(cks[0]) as f:
                    epochs = json.load(f)["epochs_done"]
            except (OSError, ValueError):
                epochs = 0  # being replaced right now
            if epochs >= 1:
                break
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)  # snakemake and every herdfit it started
    killed_s = time.time() - t_start
    proc.wait()
    log.close()
    finished = finished_jobs(work, "results")
    unlock = snakemake(work, "--unlock")
    assert unlock.returncode == 0, unlock.stdout
    t0 = time.time()
    rerun = snakemake(work, "--cores", "2", "--keep-going", "--rerun-incomplete", log="local-2.log")
    return {"finished": finished, "epochs_at_kill": epochs, "rerun": rerun,
            "killed_s": killed_s, "rerun_s": time.time() - t0}


def test_killed_run_reruns_only_the_unfinished_jobs(work, local):
    ran = jobs_run(local["rerun"].stdout)
    per_clip = [(r, c) for r, c in ran if c is not None]
    print(f"\nkilled after {local['killed_s']:.0f} s; finished before the kill: "
          f"{sorted(local['finished'])}\nthe rerun ({local['rerun_s']:.0f} s) ran: {ran}")
    assert per_clip, "the rerun ran nothing"
    redone = [j for j in per_clip if j in local["finished"]]
    assert not redone, f"the rerun redid finished jobs: {redone}"
    complete = {c for c in STEPS if ("validate", c) in local["finished"]}
    assert complete, "no clip was complete at the kill"
    assert not [c for _, c in per_clip if c in complete], "a complete clip was touched again"
    assert ("fit", "sheep_narrow") in per_clip


def test_killed_fit_resumes_from_its_checkpoint(work, local):
    text = (work / "results" / "logs" / "fit" / "sheep_narrow.log").read_text()
    m = re.search(r"resuming from \S+checkpoint\.json \((\d+) epochs done\)", text)
    assert m, text[:2000]
    assert 1 <= int(m.group(1)) < SHEEP_EPOCHS
    assert "fit sheep_narrow: resuming from" in local["rerun"].stdout
    # The checkpoint of a finished fit is gone.
    assert not glob.glob(str(work / "results" / "checkpoints" / "sheep_narrow" / "*"))


def test_corrupt_video_fails_alone_with_herdfit_error(work, local):
    out = local["rerun"].stdout
    assert local["rerun"].returncode != 0
    m = re.search(r"^herdfit extract corrupt: (.+)$", out, re.M)
    assert m, out[-3000:]
    assert "truncated" in m.group(1) and "in/corrupt.avi" in m.group(1)
    for c in GOOD:
        assert (work / "results" / "validation" / c / "report.json").is_file(), c


def test_summary_lists_the_failure_and_the_finished_clips(work, local):
    rows = summary_rows(work / "results" / "summary.csv")
    assert sorted(rows) == sorted(GOOD + ["corrupt"])
    bad = rows["corrupt"]
    assert (bad["status"], bad["failed_step"]) == ("failed", "extract")
    log_err = (work / "results" / "logs" / "extract" / "corrupt.log").read_text()
    assert f"error: {bad['error']}" in log_err
    assert "truncated" in bad["error"]
    for c in GOOD:
        r = rows[c]
        assert r["status"] == "ok", r
        for col in ("density_error", "velocity_error", "polarization_error", "aspect_ratio_error"):
            assert 0 <= float(r[col]) < 5, (c, col, r[col])
        for p in ("cohesion.weight", "alignment.angular"):
            assert 0 <= float(r[p]) <= 1
    # Held-out frames are the second half: sheep_narrow has 199 frames, the synthetic clips 40.
    assert rows["sheep_narrow"]["heldout_frames"] == "99..199"
    assert rows["sheep_narrow"]["fit_frames"] == "0..99"
    assert rows["synth1"]["heldout_frames"] == "20..40"
    # The fish (import-tracks with the clip's own flags: 100 frames) fitted and validated from
    # their tracks; the sheep's open boundary (validate --boundary auto) found, the synthetic
    # clips' closed arenas left closed.
    assert rows["fish"]["kind"] == "tracks" and rows["fish"]["tracks"] == "yes"
    assert rows["fish"]["heldout_frames"] == "50..100"
    assert [rows[c]["tracks"] for c in ("sheep_narrow", "synth1")] == ["no", "no"]
    assert int(rows["sheep_narrow"]["boundary_entry_cells"]) > 0
    assert int(rows["sheep_narrow"]["boundary_exit_cells"]) > 0
    assert (rows["synth1"]["boundary_entry_cells"], rows["synth1"]["boundary_exit_cells"]) == ("0", "0")
    md = (work / "results" / "summary.md").read_text()
    assert "**corrupt**" in md and bad["error"] in md
    assert (work / "results" / "summary.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def slurm(work, tmp_path_factory, local):
    """The same workflow through a one-node Slurm cluster started for it (stopped after)."""
    cdir = tmp_path_factory.mktemp("slurm")
    up = subprocess.run(["bash", str(CLUSTER), "start", str(cdir)], capture_output=True, text=True)
    if up.returncode != 0:
        pytest.fail(f"the Slurm cluster did not start: {up.stderr[-3000:]}")
    env = dict(os.environ)
    env["PATH"] = f"{cdir}/bin:{env['PATH']}"
    env["SLURM_CONF"] = str(cdir / "slurm.conf")
    try:
        t0 = time.time()
        run = snakemake(
            work, "--profile", str(PROFILE), "--config", "results=results-slurm",
            # No accounting database on the test cluster: job status from squeue; check often.
            "--slurm-status-command", "squeue", "--slurm-init-seconds-before-status-checks", "1",
            "--seconds-between-status-checks", "2", log="slurm.log", env=env)
        wall = time.time() - t0
        sacct = subprocess.run(["squeue", "--states=all", "-h", "-o", "%i %j %T %C %m"],
                               capture_output=True, text=True, env=env).stdout
    finally:
        subprocess.run(["bash", str(CLUSTER), "stop", str(cdir)], capture_output=True)
    return {"run": run, "wall_s": wall, "jobs": sacct}


def test_slurm_run_writes_the_local_summary_bytes(work, slurm):
    out = slurm["run"].stdout
    print(f"\nSlurm run: {slurm['wall_s']:.0f} s; jobs:\n{slurm['jobs']}")
    assert "has been submitted with SLURM jobid" in out, out[-3000:]
    assert slurm["run"].returncode != 0  # the corrupt clip fails there too
    for name in ("summary.csv", "summary.md", "summary.png"):
        local = (work / "results" / name).read_bytes()
        remote = (work / "results-slurm" / name).read_bytes()
        print(f"{name}: local sha256 {hashlib.sha256(local).hexdigest()[:16]} ({len(local)} B), "
              f"Slurm {hashlib.sha256(remote).hexdigest()[:16]} ({len(remote)} B)")
        assert local == remote, name


def test_slurm_jobs_ask_for_the_rules_resources(slurm):
    # Every job of the run asked for the config's 1 CPU and 1000 MB (the fixture's resources).
    rows = [line.split() for line in slurm["jobs"].splitlines() if line.strip()]
    rows = [r for r in rows if r[1] != "hostname"]  # the cluster's own check at start
    assert rows, "squeue shows no jobs"
    assert all(r[3] == "1" for r in rows), rows
    assert all(r[4] in ("1000M", "1000") for r in rows), rows


def test_mended_input_reruns_only_the_summary(work, slurm):
    # After the bad input is taken away, a rerun makes the summary (which the failed runs could
    # not) and nothing else; a further run has nothing to do.
    (work / "in" / "corrupt.avi").unlink()
    rerun = snakemake(work, "--cores", "2", "--keep-going", log="local-3.log")
    assert rerun.returncode == 0, rerun.stdout[-3000:]
    assert sorted(jobs_run(rerun.stdout)) == [("all", None), ("summary", None)]
    rows = summary_rows(work / "results" / "summary.csv")
    assert sorted(rows) == GOOD and all(r["status"] == "ok" for r in rows.values())
    again = snakemake(work, "--cores", "2", "-n")
    assert "Nothing to be done" in again.stdout, again.stdout[-2000:]
