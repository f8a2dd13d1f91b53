"""Training end to end on a tiny synthetic dataset: artefacts, ONNX contract, parity, warm start, CLI."""

import csv
import json

import numpy as np
import onnx
import onnxruntime as ort
import pytest
import torch

from formation_trainer import __main__ as cli
from formation_trainer import export, train

from conftest import write_dataset


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    root = tmp_path_factory.mktemp("trained")
    data = write_dataset(root / "data", samples=160, shard_size=64)
    out = root / "models" / "bc.onnx"
    config = train.TrainConfig(
        data=[data], out=out, epochs=2, batch_size=16, lr=1e-3, device="cpu", parity_out=root / "parity.json"
    )
    lines = []
    report = train.run(config, log=lines.append)
    return {"root": root, "data": data, "out": out, "report": report, "lines": lines}


def test_training_writes_every_artefact_beside_the_model(trained):
    out = trained["out"]
    for suffix in (".onnx", ".pt", ".loss.csv", ".loss.png"):
        path = out.with_name("bc" + suffix)
        assert path.is_file() and path.stat().st_size > 0, path
    assert out.with_name("bc.loss.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rows = list(csv.DictReader(out.with_name("bc.loss.csv").open()))
    assert [r["epoch"] for r in rows] == ["1", "2"]
    assert set(rows[0]) == {"epoch", "train_loss", "val_loss", "seconds"}
    assert float(rows[-1]["train_loss"]) == pytest.approx(trained["report"]["final_train_loss"], rel=1e-6)
    assert not list(out.parent.glob(".*tmp*")), "temporary files left behind"


def test_report_and_progress_lines(trained):
    report, lines = trained["report"], trained["lines"]
    assert report["epochs"] == 2 and report["samples"] == 160
    assert report["train_samples"] + report["val_samples"] == 160 and report["val_samples"] > 0
    assert report["device"] == "cpu"
    assert report["parity_max_abs_diff"] <= export.PARITY_TOLERANCE
    assert sum(line.startswith("epoch ") for line in lines) == 2
    parsed = json.loads(train.report_line(report).removeprefix(train.REPORT_PREFIX))
    assert parsed["model"] == str(trained["out"])


def test_onnx_has_the_contract_metadata(trained):
    model = onnx.load(str(trained["out"]))
    meta = {p.key: p.value for p in model.metadata_props}
    assert meta["formation.format"] == "formation-policy/1"
    assert meta["formation.occupancy.size_px"] == "50"
    assert meta["formation.occupancy.resolution_m"] == "0.1"
    assert meta["formation.occupancy.beyond"] == "drop"
    assert meta["formation.lidar.beams"] == "900"
    assert meta["formation.lidar.max_range"] == "10"
    assert meta["formation.v_train"] == "0.7"
    assert meta["formation.dataset_id"] == "synthetic0000000"
    assert meta["formation.train.epochs"] == "2"
    assert meta["formation.train.samples"] == "160"
    assert meta["formation.dagger.iteration"] == "0"
    # The envelope: d* drawn in [0.5, 3) by the synthetic data, every run of 3 robots.
    assert 0.5 <= float(meta["formation.envelope.d_star_min"]) < float(meta["formation.envelope.d_star_max"]) < 3.0
    assert meta["formation.envelope.team_sizes"] == "3"
    assert meta["formation.created_by"].startswith("formation_trainer ")
    assert float(meta["formation.train.final_train_loss"]) == trained["report"]["final_train_loss"]
    assert float(meta["formation.train.final_val_loss"]) == trained["report"]["final_val_loss"]


def test_the_metadata_declares_the_input_and_a_window_scaled_with_d_star():
    common = dict(
        lidar={"beams": 900, "max_range": 10.0, "noise_std": 0.0},
        v_train=0.7,
        dataset_id="d",
        epochs=1,
        final_train_loss=0.1,
        final_val_loss=0.1,
        samples=1,
        dagger_iteration=0,
    )
    fixed = export.model_metadata(occupancy={"size_px": 50, "resolution_m": 0.1, "beyond": "border"}, **common)
    scaled = export.model_metadata(
        occupancy={"size_px": 50, "resolution_m": 0.1, "beyond": "border", "d_star_ref_m": 1.25}, **common
    )
    assert fixed["formation.input"] == scaled["formation.input"] == "occupancy"
    assert "formation.occupancy.d_star_ref_m" not in fixed
    assert scaled["formation.occupancy.d_star_ref_m"] == "1.25"


def test_onnx_batch_is_dynamic_and_matches_torch(trained):
    session = ort.InferenceSession(str(trained["out"]), providers=["CPUExecutionProvider"])
    assert [i.name for i in session.get_inputs()] == ["occupancy", "aux"]
    assert [o.name for o in session.get_outputs()] == ["wheels"]
    checkpoint = train.load_checkpoint(trained["out"].with_suffix(".pt"))
    model = train.model_from_checkpoint(checkpoint).eval()
    rng = np.random.default_rng(1)
    for batch in (1, 5):
        occupancy = (rng.random((batch, 1, 50, 50)) < 0.05).astype(np.float32)
        aux = rng.uniform(-1, 1, (batch, 2)).astype(np.float32)
        (wheels,) = session.run(None, {"occupancy": occupancy, "aux": aux})
        assert wheels.shape == (batch, 2)
        with torch.no_grad():
            expected = model(torch.from_numpy(occupancy), torch.from_numpy(aux)).numpy()
        np.testing.assert_allclose(wheels, expected, atol=1e-5)


def test_parity_file_holds_inputs_and_torch_outputs(trained):
    parity = json.loads((trained["root"] / "parity.json").read_text())
    assert parity["size_px"] == 50 and parity["tolerance"] == export.PARITY_TOLERANCE
    assert len(parity["cases"]) == train.PARITY_FILE_SAMPLES
    session = ort.InferenceSession(str(trained["out"]), providers=["CPUExecutionProvider"])
    case = parity["cases"][0]
    occupancy = np.asarray(case["occupancy"], dtype=np.float32).reshape(1, 1, 50, 50)
    (wheels,) = session.run(None, {"occupancy": occupancy, "aux": np.asarray([case["aux"]], dtype=np.float32)})
    np.testing.assert_allclose(wheels[0], case["wheels"], atol=1e-4)


def test_parity_check_fails_on_a_model_that_differs(trained):
    checkpoint = train.load_checkpoint(trained["out"].with_suffix(".pt"))
    model = train.model_from_checkpoint(checkpoint)
    with torch.no_grad():
        model.head[-1].bias += 0.01
    occupancy = np.zeros((3, 1, 50, 50), dtype=np.float32)
    aux = np.zeros((3, 2), dtype=np.float32)
    with pytest.raises(export.ParityError, match="differ by"):
        export.check_parity(model, trained["out"], occupancy, aux)


def test_warm_start_begins_from_the_checkpoint(trained, tmp_path):
    checkpoint_path = trained["out"].with_suffix(".pt")
    base = train.model_from_checkpoint(train.load_checkpoint(checkpoint_path))
    config = train.TrainConfig(
        data=[trained["data"]], out=tmp_path / "warm.onnx", epochs=1, batch_size=16, lr=1e-12,
        device="cpu", init_from=checkpoint_path,
    )
    lines = []
    train.run(config, log=lines.append)
    warm = train.model_from_checkpoint(train.load_checkpoint(tmp_path / "warm.pt"))
    # With a negligible learning rate the weights stay those of the checkpoint, not a fresh init.
    for a, b in zip(base.state_dict().values(), warm.state_dict().values()):
        torch.testing.assert_close(a, b, atol=1e-6, rtol=0)
    assert any(line.startswith("warm start from") for line in lines)
    meta = {p.key: p.value for p in onnx.load(str(tmp_path / "warm.onnx")).metadata_props}
    assert meta["formation.train.init_from"] == "bc.pt"


def test_export_command_rebuilds_the_model_from_its_checkpoint(trained, tmp_path, capsys):
    out = tmp_path / "again.onnx"
    code = cli.main(["export", "--checkpoint", str(trained["out"].with_suffix(".pt")), "--out", str(out),
                     "--data", str(trained["data"])])
    assert code == 0, capsys.readouterr().err
    original = {p.key: p.value for p in onnx.load(str(trained["out"])).metadata_props}
    again = {p.key: p.value for p in onnx.load(str(out)).metadata_props}
    assert again == original


def test_cli_reports_data_problems_with_exit_status_2(tmp_path, capsys):
    data = write_dataset(tmp_path / "data", samples=20)
    manifest = json.loads((data / "manifest.json").read_text())
    manifest["version"] = 5
    (data / "manifest.json").write_text(json.dumps(manifest))
    code = cli.main(["train", "--data", str(data), "--out", str(tmp_path / "m.onnx"), "--device", "cpu"])
    assert code == cli.USAGE_EXIT
    assert "format version 5" in capsys.readouterr().err
    assert not (tmp_path / "m.onnx").exists()


def test_a_missing_checkpoint_is_a_clear_error(tmp_path):
    with pytest.raises(train.TrainError, match="does not exist"):
        train.load_checkpoint(tmp_path / "nope.pt")


def test_a_declared_d_star_range_becomes_the_envelope_if_it_holds_the_data(trained):
    samples = train.ds.load([trained["data"]])
    lo, hi = float(samples.aux[:, 1].min()), float(samples.aux[:, 1].max())
    assert train.envelope_metadata(samples)["envelope.d_star_min"] == export.number_text(lo)
    meta = train.envelope_metadata(samples, (0.5, 3.0))
    assert (meta["envelope.d_star_min"], meta["envelope.d_star_max"]) == ("0.5", "3")
    with pytest.raises(train.TrainError, match="does not hold the training data"):
        train.envelope_metadata(samples, (lo + 0.01, hi))
    with pytest.raises(train.TrainError, match="0 < MIN < MAX"):
        train.envelope_metadata(samples, (2.0, 1.0))


def test_the_wide_network_trains_exports_and_warm_starts_as_itself(trained, tmp_path):
    config = train.TrainConfig(
        data=[trained["data"]], out=tmp_path / "wide.onnx", epochs=1, batch_size=16, lr=1e-3,
        device="cpu", architecture="wide",
    )
    report = train.run(config, log=lambda _: None)
    assert report["parity_max_abs_diff"] <= export.PARITY_TOLERANCE
    meta = {p.key: p.value for p in onnx.load(str(tmp_path / "wide.onnx")).metadata_props}
    assert meta["formation.train.architecture"] == "wide"
    paper_meta = {p.key: p.value for p in onnx.load(str(trained["out"])).metadata_props}
    assert paper_meta["formation.train.architecture"] == "paper"
    wide = train.model_from_checkpoint(train.load_checkpoint(tmp_path / "wide.pt"))
    assert wide.architecture == "wide" and wide.flatten_width == 576
    # A warm start keeps the checkpoint's network when none is named ...
    again = train.TrainConfig(
        data=[trained["data"]], out=tmp_path / "again.onnx", epochs=1, batch_size=16, lr=1e-3,
        device="cpu", init_from=tmp_path / "wide.pt",
    )
    train.run(again, log=lambda _: None)
    assert train.model_from_checkpoint(train.load_checkpoint(tmp_path / "again.pt")).architecture == "wide"
    # ... and refuses to turn it into another one.
    clash = train.TrainConfig(
        data=[trained["data"]], out=tmp_path / "clash.onnx", epochs=1, batch_size=16, lr=1e-3,
        device="cpu", init_from=tmp_path / "wide.pt", architecture="paper",
    )
    with pytest.raises(train.TrainError, match="holds the 'wide' network, not 'paper'"):
        train.run(clash, log=lambda _: None)
    assert not (tmp_path / "clash.onnx").exists()


def test_an_unknown_architecture_is_a_usage_error(trained, tmp_path, capsys):
    from formation_trainer.model import ARCHITECTURE_NAMES

    assert cli.ARCHITECTURE_NAMES == list(ARCHITECTURE_NAMES)
    with pytest.raises(SystemExit) as exit_info:
        cli.main(["train", "--data", str(trained["data"]), "--out", str(tmp_path / "m.onnx"), "--architecture", "wdie"])
    assert exit_info.value.code == 2
    assert "invalid choice: 'wdie'" in capsys.readouterr().err


def test_mirroring_reverses_rows_negates_the_heading_error_and_swaps_wheels():
    torch.manual_seed(3)
    occupancy = (torch.rand(4, 1, 50, 50) < 0.05).float()
    aux = torch.tensor([[0.3, 1.0], [-0.2, 1.5], [0.1, 2.0], [0.0, 0.8]])
    wheels = torch.tensor([[0.1, 0.4], [0.5, -0.2], [0.3, 0.3], [-0.1, 0.2]])
    flip = torch.tensor([True, False, True, False])
    o, a, w = train.mirror_batch(occupancy, aux, wheels, flip)
    for i in (0, 2):
        assert torch.equal(o[i, 0], occupancy[i, 0].flip(0))
        assert a[i].tolist() == pytest.approx([-aux[i, 0].item(), aux[i, 1].item()])
        assert w[i].tolist() == pytest.approx([wheels[i, 1].item(), wheels[i, 0].item()])
    for i in (1, 3):
        assert torch.equal(o[i], occupancy[i]) and torch.equal(a[i], aux[i]) and torch.equal(w[i], wheels[i])
    # A reflection undoes itself.
    back = train.mirror_batch(o, a, w, flip)
    for got, want in zip(back, (occupancy, aux, wheels)):
        assert torch.equal(got, want)


def test_mirrored_training_is_recorded_in_the_model(trained, tmp_path):
    config = train.TrainConfig(
        data=[trained["data"]], out=tmp_path / "mirror.onnx", epochs=1, batch_size=16, lr=1e-3,
        device="cpu", mirror=True,
    )
    lines = []
    train.run(config, log=lines.append)
    meta = {p.key: p.value for p in onnx.load(str(tmp_path / "mirror.onnx")).metadata_props}
    assert meta["formation.train.mirror"] == "true"
    assert any("mirrored" in line for line in lines)
    assert meta["formation.policy.mirror_averaged"] == "true"
    plain = {p.key: p.value for p in onnx.load(str(trained["out"])).metadata_props}
    assert plain["formation.train.mirror"] == "false"


def test_mirror_augmentation_alone_exports_the_network_itself(trained, tmp_path):
    config = train.TrainConfig(
        data=[trained["data"]], out=tmp_path / "augmented.onnx", epochs=1, batch_size=16, lr=1e-3,
        device="cpu", mirror=True, mirror_average=False,
    )
    train.run(config, log=lambda _: None)
    model = onnx.load(str(tmp_path / "augmented.onnx"))
    meta = {p.key: p.value for p in model.metadata_props}
    assert meta["formation.train.mirror"] == "true"
    assert meta["formation.policy.mirror_averaged"] == "false"
    # One evaluation: the graph holds each convolution once (an averaged graph holds it twice).
    convs = sum(node.op_type == "Conv" for node in model.graph.node)
    assert convs == 3, convs


def test_a_policy_onnx_seeds_training_with_its_own_weights(trained, tmp_path):
    from_pt = train.model_from_checkpoint(train.load_checkpoint(trained["out"].with_suffix(".pt")))
    from_onnx = train.model_from_checkpoint(train.load_checkpoint(trained["out"]))
    assert from_onnx.architecture == from_pt.architecture == "paper"
    for (name, a), (_, b) in zip(from_pt.state_dict().items(), from_onnx.state_dict().items()):
        torch.testing.assert_close(a, b, atol=0, rtol=0, msg=name)
    # A warm start from the .onnx alone (no .pt beside it) trains on from those weights.
    alone = tmp_path / "shipped.onnx"
    alone.write_bytes(trained["out"].read_bytes())
    config = train.TrainConfig(
        data=[trained["data"]], out=tmp_path / "tuned.onnx", epochs=1, batch_size=16, lr=1e-12,
        device="cpu", init_from=alone,
    )
    train.run(config, log=lambda _: None)
    tuned = train.model_from_checkpoint(train.load_checkpoint(tmp_path / "tuned.pt"))
    for a, b in zip(from_pt.state_dict().values(), tuned.state_dict().values()):
        torch.testing.assert_close(a, b, atol=1e-6, rtol=0)


def test_an_onnx_not_written_by_the_trainer_cannot_seed_training(trained, tmp_path):
    model = onnx.load(str(trained["out"]))
    del model.metadata_props[:]
    foreign = tmp_path / "foreign.onnx"
    onnx.save(model, str(foreign))
    with pytest.raises(train.TrainError, match="cannot seed training: its formation.format is None"):
        train.load_checkpoint(foreign)
    model = onnx.load(str(trained["out"]))
    (first,) = [init for init in model.graph.initializer if init.name == "features.0.weight"]
    model.graph.initializer.remove(first)
    pruned = tmp_path / "pruned.onnx"
    onnx.save(model, str(pruned))
    with pytest.raises(train.TrainError, match="has no weights named"):
        train.load_checkpoint(pruned)
    garbage = tmp_path / "garbage.onnx"
    garbage.write_bytes(b"not a model")
    with pytest.raises(train.TrainError, match="not a readable ONNX file"):
        train.load_checkpoint(garbage)


def test_an_epoch_can_draw_a_fixed_number_of_samples(trained, tmp_path):
    train_samples = trained["report"]["train_samples"]
    config = train.TrainConfig(
        data=[trained["data"]], out=tmp_path / "drawn.onnx", epochs=2, batch_size=16, lr=1e-3,
        device="cpu", samples_per_epoch=40,
    )
    lines = []
    report = train.run(config, log=lines.append)
    assert report["samples_per_epoch"] == 40 < train_samples
    assert any("2 epochs of 40 samples drawn at random" in line for line in lines)
    meta = {p.key: p.value for p in onnx.load(str(tmp_path / "drawn.onnx")).metadata_props}
    assert meta["formation.train.samples_per_epoch"] == "40"
    # More than the training split holds is every sample; the full run records its own size.
    more = train.run(
        train.TrainConfig(data=[trained["data"]], out=tmp_path / "all.onnx", epochs=1, batch_size=16,
                          lr=1e-3, device="cpu", samples_per_epoch=10**9),
        log=lambda _: None,
    )
    assert more["samples_per_epoch"] == train_samples == trained["report"]["samples_per_epoch"]


def test_a_zero_sample_epoch_is_a_usage_error(trained, tmp_path):
    config = train.TrainConfig(
        data=[trained["data"]], out=tmp_path / "none.onnx", epochs=1, device="cpu", samples_per_epoch=0,
    )
    with pytest.raises(train.TrainError, match="samples-per-epoch must be >= 1"):
        train.run(config, log=lambda _: None)


def test_a_mirrored_model_is_exactly_symmetric_in_onnxruntime_and_stays_so_when_warm_started(trained, tmp_path):
    config = train.TrainConfig(
        data=[trained["data"]], out=tmp_path / "mirror.onnx", epochs=1, batch_size=16, lr=1e-3,
        device="cpu", mirror=True,
    )
    train.run(config, log=lambda _: None)
    meta = {p.key: p.value for p in onnx.load(str(tmp_path / "mirror.onnx")).metadata_props}
    assert meta["formation.policy.mirror_averaged"] == "true"
    plain = {p.key: p.value for p in onnx.load(str(trained["out"])).metadata_props}
    assert plain["formation.policy.mirror_averaged"] == "false"

    rng = np.random.default_rng(3)
    occupancy = (rng.random((8, 1, 50, 50)) < 0.05).astype(np.float32)
    aux = np.stack([rng.uniform(-3, 3, 8), rng.uniform(0.8, 2.5, 8)], 1).astype(np.float32)
    reflected = (np.ascontiguousarray(occupancy[:, :, ::-1, :]), aux * np.array([-1, 1], dtype=np.float32))

    def wheels(path, occupancy, aux):
        session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
        return session.run(["wheels"], {"occupancy": occupancy, "aux": aux})[0]

    symmetric = tmp_path / "mirror.onnx"
    np.testing.assert_allclose(wheels(symmetric, *reflected), wheels(symmetric, occupancy, aux)[:, ::-1], atol=1e-6)
    # The plain model is not (one epoch on a tiny set does not teach the symmetry).
    assert not np.allclose(wheels(trained["out"], *reflected), wheels(trained["out"], occupancy, aux)[:, ::-1], atol=1e-4)

    # A warm start from the .onnx alone, without --mirror, keeps the average and its weights.
    alone = tmp_path / "shipped.onnx"
    alone.write_bytes(symmetric.read_bytes())
    seeded = train.model_from_checkpoint(train.load_checkpoint(alone))
    assert seeded.mirror_averaged
    tuned_config = train.TrainConfig(
        data=[trained["data"]], out=tmp_path / "tuned.onnx", epochs=1, batch_size=16, lr=1e-3,
        device="cpu", init_from=alone,
    )
    train.run(tuned_config, log=lambda _: None)
    assert train.model_from_checkpoint(train.load_checkpoint(tmp_path / "tuned.pt")).mirror_averaged
    tuned = tmp_path / "tuned.onnx"
    np.testing.assert_allclose(wheels(tuned, *reflected), wheels(tuned, occupancy, aux)[:, ::-1], atol=1e-6)


def test_relative_weights_scale_with_the_inverse_square_of_d_star_and_average_one_over_training():
    d_star = np.array([0.8, 1.6, 2.4, 0.8], dtype=np.float32)
    weights = train.relative_weights(d_star, np.array([0, 1, 2]))
    assert weights[:3].mean() == pytest.approx(1.0, rel=1e-6)
    assert weights[0] / weights[1] == pytest.approx(4.0, rel=1e-6)
    assert weights[0] / weights[2] == pytest.approx(9.0, rel=1e-6)
    assert weights[3] == weights[0]
    for bad in ([1.0, 0.0], [1.0, float("nan")], []):
        with pytest.raises(train.TrainError, match="relative-loss"):
            train.relative_weights(np.array(bad, dtype=np.float32), np.array([0]))


def test_the_weighted_loss_is_each_samples_squared_error_times_its_weight():
    class Constant(torch.nn.Module):
        def forward(self, occupancy, aux):
            return torch.zeros(len(aux), 2)

    tensors = {
        "occupancy": torch.zeros(3, 4, 4, dtype=torch.uint8),
        "aux": torch.zeros(3, 2),
        "targets": torch.tensor([[1.0, 1.0], [2.0, 0.0], [0.0, 0.0]]),
    }
    indices = torch.arange(3)
    assert train.mean_loss(Constant(), tensors, indices) == pytest.approx((2 + 4) / 6)
    tensors["weights"] = torch.tensor([3.0, 0.5, 1.0])
    assert train.mean_loss(Constant(), tensors, indices) == pytest.approx((3 * 2 + 0.5 * 4) / 6)


def test_training_with_the_relative_loss_is_recorded_in_the_model(trained, tmp_path, capsys):
    out = tmp_path / "relative.onnx"
    cli.main(["train", "--data", str(trained["data"]), "--out", str(out), "--epochs", "1",
              "--batch-size", "16", "--device", "cpu", "--relative-loss"])
    assert "loss relative to d*" in capsys.readouterr().out
    meta = {p.key: p.value for p in onnx.load(str(out)).metadata_props}
    assert meta["formation.train.relative_loss"] == "true"
    plain = {p.key: p.value for p in onnx.load(str(trained["out"])).metadata_props}
    assert plain["formation.train.relative_loss"] == "false"


def test_training_threads_follow_the_environment(monkeypatch):
    monkeypatch.setenv("FORMATION_TRAIN_THREADS", "1")
    assert train.training_threads() == 1
    monkeypatch.delenv("FORMATION_TRAIN_THREADS")
    assert train.training_threads() >= 1
    monkeypatch.setenv("FORMATION_TRAIN_THREADS", "two")
    with pytest.raises(train.TrainError, match="FORMATION_TRAIN_THREADS must be a positive number"):
        train.training_threads()


def test_formation_velocity_targets_invert_the_point_kinematics():
    # Straight on at v_train on heading: no correction.
    wheels = np.array([[0.7, 0.7], [0.8, 0.6], [0.0, 0.0]], dtype=np.float32)
    aux = np.array([[0.0, 1.5], [0.0, 1.5], [np.pi / 2, 1.5]], dtype=np.float32)
    f = train.formation_velocity_targets(wheels, aux, 0.7)
    assert f[0] == pytest.approx([0.0, 0.0], abs=1e-6)
    # A right turn at v_train: the point is asked to move to the right (negative y) by 0.1 m/s.
    assert f[1] == pytest.approx([0.0, -0.1], abs=1e-6)
    # Standing still while the goal heading is 90° to the left: the reference term is all
    # correction, -v_train along y.
    assert f[2] == pytest.approx([0.0, -0.7], abs=1e-6)
    # Collected above the expert's reference cap, the labels carry the cap's reference term.
    fast = train.formation_velocity_targets(wheels, aux, 0.8)
    assert fast == pytest.approx(f, abs=1e-6)
    assert train.MAX_REFERENCE_SPEED == 0.7


def test_response_weights_favour_small_corrections_and_average_one_over_training():
    targets = np.array([[0.0, 0.05], [0.0, 0.5], [0.3, 0.4]], dtype=np.float32)
    weights = train.response_weights(targets, 0.05, np.array([0, 1, 2]))
    assert weights.mean() == pytest.approx(1.0, rel=1e-6)
    assert weights[0] / weights[1] == pytest.approx(0.55 / 0.1, rel=1e-5)
    with pytest.raises(train.TrainError, match="--response-weight"):
        train.response_weights(targets, 0.0, np.array([0]))


def test_mirroring_a_formation_velocity_negates_its_sideways_part():
    occupancy = torch.zeros(2, 1, 50, 50)
    aux = torch.tensor([[0.3, 1.5], [0.3, 1.5]])
    f = torch.tensor([[0.1, 0.2], [0.1, 0.2]])
    flip = torch.tensor([True, False])
    _, mirrored_aux, mirrored = train.mirror_batch(occupancy, aux, f, flip, "formation_velocity")
    assert mirrored[0].tolist() == pytest.approx([0.1, -0.2])
    assert mirrored[1].tolist() == pytest.approx([0.1, 0.2])
    assert mirrored_aux[0, 0].item() == pytest.approx(-0.3)


def test_a_formation_velocity_model_declares_its_output_and_runs_in_onnxruntime(trained, tmp_path):
    out = tmp_path / "fv.onnx"
    config = train.TrainConfig(
        data=[trained["data"]], out=out, epochs=1, batch_size=16, lr=1e-3, device="cpu",
        output="formation_velocity", response_weight=0.05, mirror=True,
    )
    report = train.run(config, log=lambda _line: None)
    assert report["parity_max_abs_diff"] <= export.PARITY_TOLERANCE
    model = onnx.load(str(out))
    meta = {p.key: p.value for p in model.metadata_props}
    assert meta["formation.output"] == "formation_velocity"
    assert meta["formation.train.response_weight"] == "0.05"
    assert [o.name for o in model.graph.output] == ["formation_velocity"]
    session = ort.InferenceSession(str(out), providers=["CPUExecutionProvider"])
    (values,) = session.run(["formation_velocity"], {
        "occupancy": np.zeros((3, 1, 50, 50), np.float32),
        "aux": np.array([[0.1, 1.0], [-0.1, 1.0], [0.0, 2.0]], np.float32),
    })
    assert values.shape == (3, 2) and np.all(np.isfinite(values))
    # Mirror-averaged: the reflected input gives the reflected output.
    assert values[0][0] == pytest.approx(values[1][0], abs=1e-5)
    assert values[0][1] == pytest.approx(-values[1][1], abs=1e-5)
    # The export command rebuilds it from its checkpoint with the same output.
    again = tmp_path / "again.onnx"
    assert cli.main(["export", "--checkpoint", str(out.with_suffix(".pt")), "--out", str(again)]) == 0
    assert [o.name for o in onnx.load(str(again)).graph.output] == ["formation_velocity"]


def test_an_unknown_output_is_a_usage_error(trained, tmp_path, capsys):
    with pytest.raises(SystemExit) as exit:
        cli.main(["train", "--data", str(trained["data"]), "--out", str(tmp_path / "x.onnx"), "--output", "torques"])
    assert exit.value.code == 2
    assert "invalid choice: 'torques'" in capsys.readouterr().err
    config = train.TrainConfig(data=[trained["data"]], out=tmp_path / "y.onnx", output="torques")
    with pytest.raises(train.TrainError, match="--output must be one of wheels, formation_velocity"):
        train.run(config, log=lambda _line: None)
