"""The package and the CLI give the same numbers for the same seed."""

import json

import numpy as np

import herdfit


def test_simulate_equals_the_cli_trajectory_for_the_same_seed(cli, tmp_path):
    cli("simulate", "--agents", 40, "--steps", 25, "--seed", 7, "--out", tmp_path / "t.csv")
    rows = np.genfromtxt(tmp_path / "t.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    ids, frames = herdfit.simulate(agents=40, steps=25, seed=7, progress=False)
    assert frames.shape == (26, 40, 5)
    assert np.array_equal(rows["id"].reshape(26, 40), np.broadcast_to(ids, (26, 40)))
    for k, col in enumerate(["x", "y", "vx", "vy"]):
        # Every value equal to the last bit: the CSV holds shortest round-trip decimals.
        assert np.array_equal(rows[col].reshape(26, 40), frames[:, :, k]), col
    leaders = (rows["role"] == "leader").reshape(26, 40)
    assert np.array_equal(leaders, frames[:, :, 4] == 1.0)


def test_simulate_from_an_initial_herd_equals_the_cli_from_its_csv(cli, tmp_path):
    init = np.array([[i, (i % 5) * 1.5, (i // 5) * 1.5, 1.0, 0.0] for i in range(20)], float)
    np.savetxt(tmp_path / "init.csv", init, delimiter=",", header="id,x,y,vx,vy", comments="", fmt="%.17g")
    cli("simulate", "--init", tmp_path / "init.csv", "--steps", 10, "--seed", 1, "--out", tmp_path / "t.csv")
    rows = np.genfromtxt(tmp_path / "t.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    _, frames = herdfit.simulate(init=init, steps=10, seed=1, progress=False)
    assert np.array_equal(rows["x"].reshape(11, 20), frames[:, :, 0])
    assert np.array_equal(rows["vy"].reshape(11, 20), frames[:, :, 3])


def test_short_fit_equals_the_cli_parameters_for_the_same_seed(cli, clip_dir, tmp_path):
    cli("fit", clip_dir, "--frames", "0..9", "--epochs", 2, "--seed", 5, "--eval-seeds", 1,
        "--no-uncertainty", "--out", tmp_path / "cli.json")
    p = herdfit.fit(clip_dir, tmp_path / "py.json", frames=(0, 9), epochs=2, seed=5, eval_seeds=1,
                    uncertainty={"enabled": False}, progress=False)
    a = json.loads((tmp_path / "cli.json").read_text())
    b = json.loads((tmp_path / "py.json").read_text())
    assert a["forces"] == b["forces"] and a["speed"] == b["speed"]
    assert p.values == herdfit.Params.load(tmp_path / "cli.json").values
    # The start was moved: the fit did something.
    assert p.values != herdfit.Params.from_json(json.dumps({**a, "forces": {
        f: {"weight": 0.5, "radial": 0.5, "angular": 0.5} for f in a["forces"]}})).values


def test_simulate_on_the_gpu_follows_the_cpu_run(monkeypatch):
    # The package is built with the GPU backend; CI has Mesa's lavapipe (a software Vulkan).
    monkeypatch.setenv("CUBECL_WGPU_DEFAULT_DEVICE", "Cpu")
    _, cpu = herdfit.simulate(agents=100, steps=30, seed=3, speed_noise=0, progress=False)
    _, gpu = herdfit.simulate(agents=100, steps=30, seed=3, speed_noise=0, device="gpu", progress=False)
    assert gpu.shape == cpu.shape == (31, 100, 5)
    # f32 on both, rounded differently: positions within 1e-3 BL, the herd having moved metres.
    assert np.abs(gpu[:, :, :2] - cpu[:, :, :2]).max() < 1e-3
    assert np.abs(cpu[-1, :, :2] - cpu[0, :, :2]).max() > 1.0


def test_validate_on_the_gpu_reports_the_cpu_errors(monkeypatch, clip_dir, tmp_path):
    # ``device`` reaches the validation's config like any other key; its report says where it ran.
    monkeypatch.setenv("CUBECL_WGPU_DEFAULT_DEVICE", "Cpu")
    params = clip_dir / "truth.json"
    cpu = herdfit.validate(clip_dir, params, tmp_path / "cpu", seeds=2, progress=False)
    gpu = herdfit.validate(clip_dir, params, tmp_path / "gpu", seeds=2, device="gpu", progress=False)
    assert gpu["device"] == "gpu" and "device" not in cpu
    for g, c in zip(gpu["sets"][0]["rows"], cpu["sets"][0]["rows"]):
        assert g["measure"] == c["measure"]
        assert abs(g["error"]["mean"] - c["error"]["mean"]) <= 1e-3 * (1 + abs(c["error"]["mean"])), g["measure"]
