"""Errors are exceptions carrying herdfit's one-line message and naming the key; Ctrl-C stops a
long fit."""

import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

import herdfit


def test_an_unknown_key_is_a_config_error_naming_it(clip_dir, tmp_path):
    with pytest.raises(herdfit.ConfigError) as e:
        herdfit.simulate(agents=10, steps=5, bogus_key=1, progress=False)
    assert e.value.key == "bogus_key" and "bogus_key" in str(e.value)
    assert isinstance(e.value, ValueError)
    with pytest.raises(herdfit.ConfigError) as e:
        herdfit.fit(clip_dir, tmp_path / "p.json", epochz=3, progress=False)
    assert e.value.key == "epochz"


def test_a_bad_value_names_its_config_key(clip_dir, tmp_path):
    with pytest.raises(herdfit.ConfigError) as e:
        herdfit.fit(clip_dir, tmp_path / "p.json", epochs=0, progress=False)
    assert e.value.key == "epochs" and str(e.value).splitlines()[0] == str(e.value)
    with pytest.raises(herdfit.ConfigError) as e:
        herdfit.simulate(agents=10, steps=0, progress=False)
    assert e.value.key == "steps"
    assert not (tmp_path / "p.json").exists()


def test_a_missing_file_is_a_file_error_and_an_oserror(tmp_path):
    with pytest.raises(herdfit.FileError) as e:
        herdfit.Clip.load(tmp_path / "nope")
    assert isinstance(e.value, OSError) and str(tmp_path / "nope") in str(e.value)
    with pytest.raises(OSError):
        herdfit.Params.load(tmp_path / "nope.json")


def test_progress_callback_sees_every_step():
    seen = []
    herdfit.simulate(agents=10, steps=12, progress=lambda stage, done, total, msg: seen.append((stage, done, total)))
    assert seen[-1] == ("simulate", 12, 12) and len(seen) == 12


def test_sigint_stops_a_long_fit_within_two_seconds(clip_dir, tmp_path):
    # Python installs its KeyboardInterrupt handler only when SIGINT is not ignored at start, and a
    # job started in the background by a non-interactive shell (a CI runner's) inherits it ignored:
    # install it, as an interactive session has it.
    script = textwrap.dedent(f"""
        import signal, sys, herdfit
        signal.signal(signal.SIGINT, signal.default_int_handler)
        def tick(stage, done, total, msg):
            if done == 1:
                print("running", flush=True)
        try:
            herdfit.fit({str(clip_dir)!r}, {str(tmp_path / 'p.json')!r}, epochs=100000, progress=tick)
        except KeyboardInterrupt:
            print("interrupted", flush=True)
            sys.exit(3)
    """)
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "running", proc.stderr.read()
    time.sleep(0.5)
    t0 = time.monotonic()
    os.kill(proc.pid, signal.SIGINT)
    try:
        out, err = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
    waited = time.monotonic() - t0
    assert proc.returncode == 3 and "interrupted" in out, err
    assert waited < 2.0, f"took {waited:.2f} s to stop"
    assert not (tmp_path / "p.json").exists()


def test_a_bad_initial_herd_names_the_herd_key():
    import numpy as np

    init = np.array([[0, 0, 0, 1, 0], [0, 1, 1, 1, 0]], float)
    with pytest.raises(herdfit.ConfigError) as e:
        herdfit.simulate(init=init, steps=2, progress=False)
    assert e.value.key == "herd" and "duplicate id 0" in str(e.value)
    init[1, 0], init[1, 1] = 1, np.nan
    with pytest.raises(herdfit.ConfigError) as e:
        herdfit.simulate(init=init, steps=2, progress=False)
    assert e.value.key == "herd" and "agent 1: x = NaN" in str(e.value)
