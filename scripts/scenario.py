"""The synthetic scenes shared by recovery.py, landscape.py and identifiability.py."""
import json
import os
import subprocess

# Obstacle cells on the 14×10 grid of 4-BL cells: in the herd's path ("crossing"), or off it
# ("drift", the session-1 protocol), or walls along the path ("corridor").
CROSSING_CELLS = [[7, 4], [7, 5], [8, 4], [8, 5], [11, 2], [11, 7]]
DRIFT_CELLS = [[8, 4], [8, 5], [3, 8]]
# Walls along both long sides ("corridor"): the herd is pressed between them and does not split.
CORRIDOR_CELLS = [[x, y] for x in range(14) for y in (0, 1, 8, 9)]


def crossing_truth(herdfit, tmp):
    """The built-in parameter set with the herd at 2 BL/s (speed noise 0.3), written to
    tmp/truth-in.json; returns (path, parameters)."""
    probe = os.path.join(tmp, "probe")
    subprocess.run([herdfit, "synth", "--agents", "2", "--frame-count", "1", "--grid-size", "1x1",
                    "--cell-size", "1", "--out", probe], check=True, capture_output=True)
    t = json.load(open(os.path.join(probe, "truth.json")))
    t.pop("physical", None)
    t["speed"]["mean"], t["speed"]["std"] = 2.0, 0.3
    path = os.path.join(tmp, "truth-in.json")
    json.dump(t, open(path, "w"))
    return path, t
