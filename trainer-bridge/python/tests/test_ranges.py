"""A model that takes the scan's ranges beside its image (issue 34 item 6): trained from a dataset
with ranges, exported with the third input ``ranges`` and ``formation.ranges``, mirrored with its
sectors, and warm-started from a model without ranges with the old model's outputs."""

import json

import numpy as np
import onnx
import onnxruntime as ort
import pytest
import torch

from formation_trainer import __main__ as cli
from formation_trainer import export, train
from formation_trainer.model import PolicyNet, mirror_inputs

from conftest import write_dataset

RANGES = "sectors=12,clip=3"
K = 12


def _meta(path):
    return {p.key: p.value for p in onnx.load(str(path)).metadata_props}


def _run(path, occupancy, aux, ranges=None, output="wheels"):
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    feeds = {"occupancy": occupancy, "aux": aux}
    if ranges is not None:
        feeds["ranges"] = ranges
    return session.run([output], feeds)[0]


def _inputs(batch, seed=1, sectors=K):
    rng = np.random.default_rng(seed)
    occupancy = (rng.random((batch, 1, 50, 50)) < 0.05).astype(np.float32)
    aux = np.stack([rng.uniform(-3, 3, batch), rng.uniform(0.8, 2.5, batch)], 1).astype(np.float32)
    ranges = rng.uniform(0, 3, (batch, sectors)).astype(np.float32)
    return occupancy, aux, ranges


@pytest.fixture(scope="module")
def ranged(tmp_path_factory):
    root = tmp_path_factory.mktemp("ranged")
    data = write_dataset(root / "data", samples=160, shard_size=64, ranges=RANGES)
    plain = write_dataset(root / "plain", samples=160, shard_size=64)
    out = root / "models" / "ranges.onnx"
    config = train.TrainConfig(
        data=[data], out=out, epochs=2, batch_size=16, lr=1e-3, device="cpu", parity_out=root / "parity.json",
        architecture="wide-head",
    )
    lines = []
    report = train.run(config, log=lines.append)
    plain_out = root / "models" / "plain.onnx"
    train.run(
        train.TrainConfig(data=[plain], out=plain_out, epochs=1, batch_size=16, lr=1e-3, device="cpu", architecture="wide-head"),
        log=lambda _: None,
    )
    return {"root": root, "data": data, "plain": plain, "out": out, "plain_out": plain_out, "report": report, "lines": lines}


def test_a_dataset_with_ranges_trains_a_model_that_takes_them(ranged):
    assert any("ranges sectors=12,clip=3" in line for line in ranged["lines"]), ranged["lines"]
    assert ranged["report"]["parity_max_abs_diff"] <= export.PARITY_TOLERANCE
    checkpoint = train.load_checkpoint(ranged["out"].with_suffix(".pt"))
    assert checkpoint["range_sectors"] == K
    model = train.model_from_checkpoint(checkpoint)
    assert model.range_sectors == K


def test_the_export_has_three_inputs_and_declares_the_ranges(ranged):
    meta = _meta(ranged["out"])
    assert meta["formation.ranges"] == "sectors=12,clip=3"
    assert "formation.ranges" not in _meta(ranged["plain_out"])
    session = ort.InferenceSession(str(ranged["out"]), providers=["CPUExecutionProvider"])
    inputs = session.get_inputs()
    assert [i.name for i in inputs] == ["occupancy", "aux", "ranges"]
    assert inputs[2].shape[1] == K and isinstance(inputs[2].shape[0], str), inputs[2].shape
    model = train.model_from_checkpoint(train.load_checkpoint(ranged["out"].with_suffix(".pt"))).eval()
    for batch in (1, 5):
        occupancy, aux, ranges = _inputs(batch)
        wheels = _run(ranged["out"], occupancy, aux, ranges)
        assert wheels.shape == (batch, 2)
        with torch.no_grad():
            expected = model(torch.from_numpy(occupancy), torch.from_numpy(aux), torch.from_numpy(ranges)).numpy()
        np.testing.assert_allclose(wheels, expected, atol=1e-5)
    # The ranges matter to the exported graph.
    occupancy, aux, ranges = _inputs(4)
    assert not np.allclose(_run(ranged["out"], occupancy, aux, ranges), _run(ranged["out"], occupancy, aux, ranges + 1))


def test_the_parity_file_holds_the_ranges(ranged):
    parity = json.loads((ranged["root"] / "parity.json").read_text())
    assert len(parity["cases"]) == train.PARITY_FILE_SAMPLES
    case = parity["cases"][0]
    assert len(case["ranges"]) == K
    occupancy = np.asarray(case["occupancy"], dtype=np.float32).reshape(1, 1, 50, 50)
    wheels = _run(
        ranged["out"], occupancy, np.asarray([case["aux"]], dtype=np.float32), np.asarray([case["ranges"]], dtype=np.float32)
    )
    np.testing.assert_allclose(wheels[0], case["wheels"], atol=1e-4)


def test_a_ranges_onnx_seeds_training_with_its_own_weights(ranged):
    from_pt = train.model_from_checkpoint(train.load_checkpoint(ranged["out"].with_suffix(".pt")))
    from_onnx = train.model_from_checkpoint(train.load_checkpoint(ranged["out"]))
    assert from_onnx.range_sectors == K
    for (name, a), (_, b) in zip(from_pt.state_dict().items(), from_onnx.state_dict().items()):
        torch.testing.assert_close(a, b, atol=0, rtol=0, msg=name)


def test_the_export_command_rebuilds_a_ranges_model(ranged, tmp_path, capsys):
    for extra in (["--data", str(ranged["data"])], []):
        out = tmp_path / f"again{len(extra)}.onnx"
        parity = tmp_path / f"parity{len(extra)}.json"
        code = cli.main(
            ["export", "--checkpoint", str(ranged["out"].with_suffix(".pt")), "--out", str(out), "--parity-out", str(parity), *extra]
        )
        assert code == 0, capsys.readouterr().err
        assert _meta(out) == _meta(ranged["out"])
        assert len(json.loads(parity.read_text())["cases"][0]["ranges"]) == K
    code = cli.main(["export", "--checkpoint", str(ranged["out"].with_suffix(".pt")), "--out", str(tmp_path / "x.onnx"),
                     "--data", str(ranged["plain"])])
    assert code == cli.USAGE_EXIT
    assert "range input is none, the checkpoint's sectors=12,clip=3" in capsys.readouterr().err


def test_warm_starting_a_model_without_ranges_keeps_its_outputs_to_rounding():
    # The new columns are exactly zero, but a wider matrix may be summed in another order by the
    # BLAS (torch 2.15 on an AMD EPYC differs by 1.5e-8), so the outputs agree to float rounding.
    torch.manual_seed(4)
    for architecture, averaged in (("paper", False), ("wide-head", False), ("wide-head", True)):
        old = PolicyNet(50, architecture, averaged).eval()
        new = train.add_range_branch(old, 100).eval()
        assert new.range_sectors == 100 and new.mirror_averaged == averaged
        first = new.head[0]
        assert torch.count_nonzero(first.weight[:, -64:]) == 0
        assert torch.count_nonzero(new.range_features[0].weight) > 0, "the branch is initialised normally"
        occupancy = (torch.rand(16, 1, 50, 50) < 0.05).float()
        aux = torch.randn(16, 2)
        ranges = 3 * torch.rand(16, 100)
        with torch.no_grad():
            before = old(occupancy, aux)
            after = new(occupancy, aux, ranges)
            torch.testing.assert_close(after, before, rtol=0, atol=1e-6)
            torch.testing.assert_close(new(occupancy, aux, ranges + 1), before, rtol=0, atol=1e-6)


def test_a_warm_start_without_ranges_on_data_with_them_trains_a_ranges_model_from_the_old_outputs(ranged, tmp_path):
    for init in (ranged["plain_out"].with_suffix(".pt"), ranged["plain_out"]):
        lines = []
        out = tmp_path / f"warm-{init.suffix[1:]}.onnx"
        config = train.TrainConfig(
            data=[ranged["data"]], out=out, epochs=1, batch_size=16, lr=1e-12, device="cpu", init_from=init,
        )
        train.run(config, log=lines.append)
        assert any(
            line.startswith(f"warm start from {init}, a network without ranges: added a range branch for the data's "
                            "sectors=12,clip=3 with zero weights into the head") for line in lines
        ), lines
        assert _meta(out)["formation.ranges"] == "sectors=12,clip=3"
        occupancy, aux, ranges = _inputs(6, seed=5)
        # A negligible learning rate: the new model answers as the old one, whatever the ranges.
        old = _run(ranged["plain_out"], occupancy, aux)
        np.testing.assert_allclose(_run(out, occupancy, aux, ranges), old, atol=1e-6)
        np.testing.assert_allclose(_run(out, occupancy, aux, ranges + 1), old, atol=1e-6)


def test_a_model_with_ranges_needs_a_dataset_with_ranges(ranged, tmp_path, capsys):
    config = train.TrainConfig(
        data=[ranged["plain"]], out=tmp_path / "m.onnx", epochs=1, device="cpu", init_from=ranged["out"].with_suffix(".pt"),
    )
    with pytest.raises(train.TrainError, match="takes the scan's ranges \\(12 sectors\\) but .*plain holds none: a model "
                       "with ranges needs a dataset with ranges; collect one with `formation collect --ranges"):
        train.run(config, log=lambda _: None)
    other = write_dataset(tmp_path / "other", samples=40, ranges="sectors=8,clip=3")
    config.data = [other]
    with pytest.raises(train.TrainError, match="takes ranges of 12 sectors but the data's are sectors=8,clip=3"):
        train.run(config, log=lambda _: None)
    code = cli.main(["train", "--data", str(ranged["plain"]), "--out", str(tmp_path / "c.onnx"), "--device", "cpu",
                     "--init-from", str(ranged["out"])])
    assert code == cli.USAGE_EXIT
    assert "a model with ranges needs a dataset with ranges" in capsys.readouterr().err


def test_mirroring_a_batch_reflects_its_ranges():
    occupancy, aux, ranges = (torch.from_numpy(a) for a in _inputs(4))
    wheels = torch.randn(4, 2)
    flip = torch.tensor([True, False, True, False])
    o, a, w, r = train.mirror_batch(occupancy, aux, wheels, flip, "wheels", ranges)
    reflected = mirror_inputs(occupancy, aux, ranges)
    for i in range(4):
        source = reflected if flip[i] else (occupancy, aux, ranges)
        torch.testing.assert_close(o[i], source[0][i])
        torch.testing.assert_close(a[i], source[1][i])
        torch.testing.assert_close(r[i], source[2][i])
        torch.testing.assert_close(w[i], wheels[i].flip(0) if flip[i] else wheels[i])
    assert len(train.mirror_batch(occupancy, aux, wheels, flip)) == 3


def test_a_mirrored_ranges_model_is_exactly_symmetric_in_onnxruntime(ranged, tmp_path):
    out = tmp_path / "mirror.onnx"
    config = train.TrainConfig(
        data=[ranged["data"]], out=out, epochs=1, batch_size=16, lr=1e-3, device="cpu", mirror=True,
        output="formation_velocity",
    )
    train.run(config, log=lambda _: None)
    assert _meta(out)["formation.policy.mirror_averaged"] == "true"
    occupancy, aux, ranges = _inputs(8, seed=3)
    reflected = [np.ascontiguousarray(x.numpy()) for x in mirror_inputs(*(torch.from_numpy(v) for v in (occupancy, aux, ranges)))]
    assert reflected[2][0, 1] == ranges[0, K - 1]
    v = _run(out, occupancy, aux, ranges, "formation_velocity")
    v_reflected = _run(out, *reflected, output="formation_velocity")
    np.testing.assert_allclose(v_reflected, v * np.array([1, -1], dtype=np.float32), atol=1e-6)
