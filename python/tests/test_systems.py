"""The other systems from Python write the CLI's bytes for the same inputs and settings."""

import numpy as np
import pytest

import herdfit

ROOT_FLOCK = "examples/flocks/v.csv"


def test_crowd_learn_and_simulate_write_the_cli_bytes(cli, shared_data, tmp_path):
    d = shared_data / "pedestrians" / "eth-ucy"
    cli("crowd", "learn", d / "biwi_eth.txt", "--out", tmp_path / "model-cli.json")
    model = herdfit.crowd.learn(d / "biwi_eth.txt", tmp_path / "model-py.json", progress=False)
    assert (tmp_path / "model-cli.json").read_bytes() == (tmp_path / "model-py.json").read_bytes()
    assert model["schema"] == "herdfit.crowd-model/1"
    cli("crowd", "simulate", tmp_path / "model-cli.json", "--entries", d / "biwi_hotel.txt", "--out", tmp_path / "cli.csv")
    t = herdfit.crowd.simulate(tmp_path / "model-py.json", entries=d / "biwi_hotel.txt", out=tmp_path / "py.csv",
                               progress=False)
    assert (tmp_path / "cli.csv").read_bytes() == (tmp_path / "py.csv").read_bytes()
    assert t.units == "m" and len(np.unique(t.id)) == 389


def test_flock_animate_writes_the_cli_tracks(cli, tmp_path):
    from conftest import ROOT

    cli("flock", "extract", ROOT / ROOT_FLOCK, "--out", tmp_path / "v.shape.json")
    cli("flock", "animate", tmp_path / "v.shape.json", "--birds", 9, "--frames", 60, "--seed", 1, "--out", tmp_path / "cli")
    rep = herdfit.flock.animate(tmp_path / "v.shape.json", tmp_path / "py", birds=9, frames=60, seed=1, progress=False)
    for f in ("tracks.csv", "savings.csv"):
        assert (tmp_path / "cli" / f).read_bytes() == (tmp_path / "py" / f).read_bytes(), f
    assert rep["birds"] == 9


def test_lift_run_and_export_gltf_write_the_cli_bytes(cli, shared_data, tmp_path):
    truth = shared_data / "jackdaws" / "transit_05.csv"
    cam = tmp_path / "cam.json"
    cli("lift", "camera", "--out", cam, "--position=3.6,-65.1,-16.8", "--look-at=3.6,-5.1,-0.7")
    cli("lift", "project", truth, "--camera", cam, "--out", tmp_path / "2d.csv")
    cli("lift", "run", tmp_path / "2d.csv", "--camera", cam, "--out", tmp_path / "cli.csv", "--v-target", 0.15,
        "--d-near", 10, "--d-far", 150)
    t, report = herdfit.lift.run(tmp_path / "2d.csv", cam, out=tmp_path / "py.csv", v_target=0.15, d_near=10,
                                 d_far=150, progress=False)
    assert (tmp_path / "cli.csv").read_bytes() == (tmp_path / "py.csv").read_bytes()
    assert t.dimension == 3 and t.units == "m" and "schema" in report
    cli("export-gltf", tmp_path / "cli.csv", "--out", tmp_path / "cli.glb")
    s = herdfit.export_gltf(tmp_path / "py.csv", tmp_path / "py.glb")
    assert (tmp_path / "cli.glb").read_bytes() == (tmp_path / "py.glb").read_bytes()
    assert s["nodes"] == len(np.unique(t.id))


def test_an_output_whose_sidecar_is_an_input_is_refused_and_the_input_kept(shared_data, tmp_path):
    d = shared_data / "pedestrians" / "eth-ucy"
    herdfit.crowd.learn(d / "biwi_eth.txt", tmp_path / "m.json", progress=False)
    before = (tmp_path / "m.json").read_bytes()
    with pytest.raises(herdfit.ConfigError) as e:
        herdfit.crowd.simulate(tmp_path / "m.json", entries=d / "biwi_hotel.txt", out=tmp_path / "m.csv", progress=False)
    assert e.value.key == "out" and "m.json" in str(e.value)
    assert (tmp_path / "m.json").read_bytes() == before and not (tmp_path / "m.csv").exists()
