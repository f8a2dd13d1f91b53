"""A model that takes the neighbours its robot detects in its own scan (issue 34): datasets of
format version 3 read, the neighbours mirrored, the pair network fitted to the teacher's law,
exported with the third input ``neighbours`` and ``formation.neighbours``, and warm-started."""

import json

import numpy as np
import onnx
import onnxruntime as ort
import pytest
import torch
from safetensors.numpy import load_file, save_file

from formation_trainer import __main__ as cli
from formation_trainer import dataset as ds
from formation_trainer import export, train
from formation_trainer.model import PairNet, PolicyNet, mirror_inputs, mirror_neighbours, multiply_adds, pair_profile

from conftest import K_FORMATION_GRAPH, neighbour_sets, pair_law, write_dataset

NEIGHBOURS = "slots=16,threshold=1.3,nearest=2"
SLOTS = 16
#: The bins of the correction's size [m/s] in which `formation gauge` judges a slope.
BINS = ((0.05, 0.1), (0.1, 0.2), (0.2, 0.4), (0.4, 0.8))


def _meta(path):
    return {p.key: p.value for p in onnx.load(str(path)).metadata_props}


def _inputs(batch, seed=1, slots=SLOTS):
    rng = np.random.default_rng(seed)
    occupancy = (rng.random((batch, 1, 50, 50)) < 0.05).astype(np.float32)
    aux = np.stack([rng.uniform(-3, 3, batch), rng.uniform(0.8, 2.5, batch)], 1).astype(np.float32)
    return occupancy, aux, cli.random_neighbours(rng, batch, slots)


def _run(path, occupancy, aux, neighbours):
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    return session.run(["formation_velocity"], {"occupancy": occupancy, "aux": aux, "neighbours": neighbours})[0]


def _slopes(prediction, label):
    """Per bin of |label|: (samples, slope sum p.l / sum |l|^2), as `formation gauge` computes it."""
    size = np.linalg.norm(label, axis=1)
    out = {}
    for lo, hi in BINS:
        chosen = (size >= lo) & (size < hi)
        l, p = label[chosen].astype(np.float64), prediction[chosen].astype(np.float64)
        out[(lo, hi)] = (int(chosen.sum()), float((p * l).sum() / (l * l).sum()))
    return out


def _train_paired(root, architecture=None):
    """A pair network trained by `train.run` on a version 3 dataset (with ranges too, which the
    pair network leaves out) whose labels are the teacher's law on the neighbours."""
    data = write_dataset(
        root / "data", samples=8000, shard_size=3000, neighbours=NEIGHBOURS, ranges="sectors=12,clip=3",
        labels={"unshaped": True, "own_scan": True},
    )
    out = root / "models" / "pair.onnx"
    config = train.TrainConfig(
        data=[data], out=out, epochs=10, batch_size=256, lr=1e-2, device="cpu", output="formation_velocity",
        response_weight=0.05, parity_out=root / "parity.json", architecture=architecture,
    )
    lines = []
    report = train.run(config, log=lines.append)
    return {"root": root, "data": data, "out": out, "report": report, "lines": lines}


@pytest.fixture(scope="module")
def paired(tmp_path_factory):
    """The pair network the trainer picks for a dataset with neighbours."""
    return _train_paired(tmp_path_factory.mktemp("paired"))


@pytest.fixture(scope="module")
def paired_potential(tmp_path_factory):
    """The pair network whose terms carry the law's pair profile (``--architecture pair-potential``)."""
    return _train_paired(tmp_path_factory.mktemp("paired-potential"), "pair-potential")


# --- the dataset ---------------------------------------------------------------------------


def test_the_neighbour_declaration_reads_and_writes_as_rusts():
    spec = ds.NeighbourInput.parse(NEIGHBOURS)
    assert (spec.slots, spec.threshold, spec.nearest) == (16, 1.3, 2)
    assert spec.text() == NEIGHBOURS
    assert ds.NeighbourInput.parse(" nearest = 0 , threshold=1, slots=+4").text() == "slots=4,threshold=1,nearest=0"
    assert ds.NeighbourInput.parse("slots=64,threshold=4,nearest=8").text() == "slots=64,threshold=4,nearest=8"
    for bad in ("slots=16,threshold=1.3", "slots=16,threshold=1.3,nearest=2,nearest=2", "slots=1.5,threshold=1.3,nearest=2",
                "slots=16;threshold=1.3;nearest=2", "slots=16,threshold=x,nearest=2", ""):
        with pytest.raises(ValueError, match="is not a neighbour input: write \"slots=K,threshold=T,nearest=M\""):
            ds.NeighbourInput.parse(bad)
    hidden = ds.NeighbourInput.parse("hidden=1, " + NEIGHBOURS)
    assert (hidden.hidden, hidden.features, spec.features) == (True, 6, 4)
    assert hidden.text() == NEIGHBOURS + ",hidden=1" and ds.NeighbourInput.parse(NEIGHBOURS + ",hidden=0") == spec
    for bad in (NEIGHBOURS + ",hidden=2", NEIGHBOURS + ",hidden=1,hidden=1"):
        with pytest.raises(ValueError, match="is not a neighbour input"):
            ds.NeighbourInput.parse(bad)
    for bad, what in (("slots=0,threshold=1.3,nearest=2", "slots"), ("slots=65,threshold=1.3,nearest=2", "slots"),
                      ("slots=16,threshold=0.9,nearest=2", "threshold"), ("slots=16,threshold=4.5,nearest=2", "threshold"),
                      ("slots=16,threshold=1.3,nearest=9", "nearest")):
        with pytest.raises(ValueError, match=f"neighbour input {what} = .* is out of range"):
            ds.NeighbourInput.parse(bad)


@pytest.mark.parametrize("ranges", [None, "sectors=12,clip=3"])
def test_a_version_3_dataset_reads_its_neighbours(make_dataset, ranges):
    directory = make_dataset(samples=100, shard_size=40, neighbours=NEIGHBOURS, ranges=ranges)
    manifest = ds.read_manifest(directory)
    assert (manifest.version, manifest.neighbours) == (3, ds.NeighbourInput(16, 1.3, 2))
    assert manifest.ranges == (None if ranges is None else ds.RangeInput(12, 3.0))
    samples = ds.load([directory])
    assert samples.neighbour_input.text() == NEIGHBOURS
    assert samples.neighbours.shape == (100, SLOTS, 4) and samples.neighbours.dtype == np.float32
    written = np.concatenate([load_file(str(directory / s["file"]))["neighbours"] for s in manifest.shards])
    np.testing.assert_array_equal(samples.neighbours, written)
    assert samples.ranges.shape == (100, 12 if ranges else 0)
    # Held slots first, then the others, then empty slots of zeros, as collection lays them out.
    held, present = samples.neighbours[..., 2], samples.neighbours[..., 3]
    assert np.all(np.diff(held, axis=1) <= 0) and np.all(np.diff(present, axis=1) <= 0)
    assert np.all(samples.neighbours[present == 0] == 0)


def test_datasets_without_neighbours_read_as_before(make_dataset):
    for ranges, version in ((None, 1), ("sectors=12,clip=3", 2)):
        directory = make_dataset(f"v{version}", samples=30, ranges=ranges)
        samples = ds.load([directory])
        assert samples.manifests[0].version == version and samples.neighbour_input is None
        assert samples.neighbours.shape == (30, 0, 4)


def _rewrite_manifest(directory, **changes):
    manifest = json.loads((directory / "manifest.json").read_text())
    for key, value in changes.items():
        if value is None:
            manifest.pop(key, None)
        else:
            manifest[key] = value
    (directory / "manifest.json").write_text(json.dumps(manifest))


def test_a_version_that_disagrees_with_the_neighbours_is_refused_naming_the_file(make_dataset):
    a = make_dataset("a", samples=20, neighbours=NEIGHBOURS)
    _rewrite_manifest(a, neighbours=None)
    with pytest.raises(ds.DatasetError, match=r"a/manifest\.json is dataset format version 3 but declares no `neighbours`"):
        ds.read_manifest(a)
    for version, ranges in ((1, None), (2, "sectors=12,clip=3")):
        b = make_dataset(f"b{version}", samples=20, ranges=ranges)
        _rewrite_manifest(b, neighbours=NEIGHBOURS)
        with pytest.raises(ds.DatasetError, match=rf"b{version}/manifest\.json is dataset format version {version} but "
                           r"declares neighbours \"slots=16,threshold=1\.3,nearest=2\""):
            ds.read_manifest(b)
    c = make_dataset("c", samples=20, neighbours=NEIGHBOURS)
    _rewrite_manifest(c, neighbours="slots=0,threshold=1.3,nearest=2")
    with pytest.raises(ds.DatasetError, match=r"c/manifest\.json is not a valid dataset manifest \(its `neighbours`: "
                       r"neighbour input slots = 0 is out of range"):
        ds.read_manifest(c)


def test_a_shard_whose_neighbours_disagree_with_the_manifest_is_refused(make_dataset):
    directory = make_dataset(samples=20, shard_size=20, neighbours=NEIGHBOURS)
    shard = directory / "shard-000000.safetensors"
    meta = {"format": "formation-dataset", "version": "3", "iteration": "0"}
    tensors = load_file(str(shard))
    save_file({k: v for k, v in tensors.items() if k != "neighbours"}, str(shard), metadata=meta)
    with pytest.raises(ds.DatasetError, match=r"shard-000000\.safetensors is corrupt \(no `neighbours` tensor\)"):
        ds.load([directory])
    save_file(tensors | {"neighbours": np.zeros((20, 16, 3), np.float32)}, str(shard), metadata=meta)
    with pytest.raises(ds.DatasetError, match=r"`neighbours` is F32 \[20, 16, 3\], the manifest needs float32 \[20, 16, 4\]"):
        ds.load([directory])
    plain = make_dataset("plain", samples=20, shard_size=20)
    plain_shard = plain / "shard-000000.safetensors"
    save_file(load_file(str(plain_shard)) | {"neighbours": tensors["neighbours"]}, str(plain_shard),
              metadata={"format": "formation-dataset", "version": "1", "iteration": "0"})
    with pytest.raises(ds.DatasetError, match="a `neighbours` tensor, but the manifest declares no neighbours"):
        ds.load([plain])


def test_datasets_of_different_neighbour_inputs_are_not_mixed(make_dataset):
    first = make_dataset("first", samples=20, neighbours=NEIGHBOURS)
    for name, other in (("fewer", "slots=8,threshold=1.3,nearest=2"), ("rule", "slots=16,threshold=1.5,nearest=2"), ("none", None)):
        second = make_dataset(name, samples=20, neighbours=other)
        with pytest.raises(ds.DatasetError, match="cannot be trained together: their neighbour input differ"):
            ds.load([first, second])
    same = make_dataset("same", samples=20, neighbours="threshold=1.3, nearest=2, slots=16", seed=3)
    assert len(ds.load([first, same])) == 40


def test_the_own_scan_label_law_is_read_and_compared(make_dataset):
    own = {"unshaped": True, "own_scan": True}
    a = make_dataset("a", samples=20, neighbours=NEIGHBOURS, labels=own)
    b = make_dataset("b", samples=20, neighbours=NEIGHBOURS, labels=dict(own), seed=1)
    assert ds.read_manifest(a).labels == own
    assert len(ds.load([a, b])) == 40
    c = make_dataset("c", samples=20, neighbours=NEIGHBOURS, labels={"unshaped": True}, seed=2)
    with pytest.raises(ds.DatasetError, match="their label law differ"):
        ds.load([a, c])


# --- mirroring -----------------------------------------------------------------------------


def test_mirroring_negates_the_neighbours_y_and_keeps_flags_and_order():
    neighbours = torch.from_numpy(neighbour_sets(np.random.default_rng(0), 5, SLOTS))
    mirrored = mirror_neighbours(neighbours)
    torch.testing.assert_close(mirrored[..., 1], -neighbours[..., 1])
    torch.testing.assert_close(mirrored[..., [0, 2, 3]], neighbours[..., [0, 2, 3]])
    # The teacher's law on the mirrored neighbours is the mirrored law: y -> -y is a symmetry.
    law, law_mirrored = pair_law(neighbours.numpy()), pair_law(mirrored.numpy())
    np.testing.assert_allclose(law_mirrored, law * np.array([1, -1], np.float32), atol=1e-6)
    occupancy, aux, _ = (torch.from_numpy(a) for a in _inputs(5))
    o, a, n = mirror_inputs(occupancy, aux, neighbours=neighbours)
    torch.testing.assert_close(n, mirrored)
    torch.testing.assert_close(o, occupancy.flip(2))


def test_mirroring_a_batch_reflects_its_neighbours_where_it_flips():
    occupancy, aux, neighbours = (torch.from_numpy(a) for a in _inputs(4))
    ranges = torch.rand(4, 12)
    f = torch.randn(4, 2)
    flip = torch.tensor([True, False, False, True])
    o, a, w, r, n = train.mirror_batch(occupancy, aux, f, flip, "formation_velocity", ranges, neighbours)
    o2, a2, w2, n2 = train.mirror_batch(occupancy, aux, f, flip, "formation_velocity", neighbours=neighbours)
    for i in range(4):
        expected = mirror_neighbours(neighbours[i : i + 1])[0] if flip[i] else neighbours[i]
        torch.testing.assert_close(n[i], expected)
        torch.testing.assert_close(n2[i], expected)
        torch.testing.assert_close(w[i], f[i] * torch.tensor([1.0, -1.0]) if flip[i] else f[i])
    torch.testing.assert_close(r, train.mirror_batch(occupancy, aux, f, flip, "formation_velocity", ranges)[3])


# --- the network ---------------------------------------------------------------------------


def test_the_pair_network_costs_a_seventh_of_the_paper_network():
    paper = multiply_adds(PolicyNet(50, "paper"))
    assert multiply_adds(PairNet(SLOTS)) == SLOTS * (4 * 64 + 64 * 64 + 64 * 4) == 73_728
    assert multiply_adds(PairNet(SLOTS)) * 7 < paper
    assert multiply_adds(PairNet(8)) == 8 * 4_608


def test_the_pair_network_sums_per_neighbour_terms_and_ignores_the_image():
    torch.manual_seed(0)
    model = PairNet(SLOTS).eval()
    occupancy, aux, neighbours = (torch.from_numpy(a) for a in _inputs(6))
    with torch.no_grad():
        f = model(occupancy, aux, neighbours)
        assert f.shape == (6, 2)
        torch.testing.assert_close(model(torch.rand_like(occupancy), aux, neighbours), f)
        # Empty slots add nothing, wherever their numbers point.
        empty = neighbours.clone()
        empty[..., :3] = torch.where(empty[..., 3:4] == 0, torch.full_like(empty[..., :3], 0.7), empty[..., :3])
        torch.testing.assert_close(model(occupancy, aux, empty), f)
        # Linear in d*: the terms are in units of d*.
        doubled = aux.clone()
        doubled[:, 1] *= 2
        torch.testing.assert_close(model(occupancy, doubled, neighbours), 2 * f)
        # The sum of one term per slot.
        terms = model.terms(neighbours)
        torch.testing.assert_close(terms.sum(1) * aux[:, 1:2], f)
        assert not torch.equal(model(occupancy, aux, mirror_neighbours(neighbours)), f)
    with pytest.raises(ValueError, match=r"takes neighbours \[B, 16, 4\], got \[6, 8, 4\]"):
        model(occupancy, aux, neighbours[:, :8])
    with pytest.raises(ValueError, match="answers a formation velocity, not 'wheels'"):
        PairNet(SLOTS, output="wheels")


def test_the_pair_profile_is_the_shape_of_the_laws_pair_term():
    r = torch.tensor([0.5, 0.9, 1.0, 1.01, 1.5, 3.0], dtype=torch.float64)
    torch.testing.assert_close(pair_profile(r), (r**4 - 1) / r**3)
    assert pair_profile(torch.tensor([1.0])).item() == 0.0
    # Closer than 0.1 d* (never detected) the profile holds its value there: finite, repulsive.
    assert pair_profile(torch.tensor([0.0])).item() == pytest.approx(pair_profile(torch.tensor([0.1])).item())


def test_the_potential_pair_network_is_the_law_when_its_layers_give_the_gain():
    """With layers that answer a constant 2k along the line to a held neighbour and nothing else,
    the network is the teacher's law exactly; a held neighbour at d* adds nothing whatever the
    layers, and one the robot does not hold keeps the plain term (not grown with r)."""
    model = PairNet(SLOTS, potential=True).eval()
    assert model.architecture == "pair-potential" and PairNet(SLOTS).architecture == "pair"
    assert multiply_adds(model) == multiply_adds(PairNet(SLOTS))
    occupancy, aux, neighbours = (torch.from_numpy(a) for a in _inputs(64, seed=3))
    with torch.no_grad():
        at_d_star = neighbours.clone()
        r = torch.linalg.vector_norm(at_d_star[..., :2], dim=-1, keepdim=True).clamp(min=1e-6)
        at_d_star[..., :2] = at_d_star[..., :2] / r
        at_d_star[..., 2] = at_d_star[..., 3]
        torch.testing.assert_close(model(occupancy, aux, at_d_star), torch.zeros(64, 2), atol=1e-5, rtol=0)
        others = neighbours.clone()
        others[..., 2] = 0.0
        plain = PairNet(SLOTS)
        plain.load_state_dict(model.state_dict())
        torch.testing.assert_close(model(occupancy, aux, others), plain.eval()(occupancy, aux, others))
        last = model.pair_term[-1]
        last.weight.zero_()
        last.bias.copy_(torch.tensor([2.0 * K_FORMATION_GRAPH, 0.0, 0.0, 0.0]))
        law = pair_law(neighbours.numpy(), K_FORMATION_GRAPH) * aux[:, 1:2].numpy()
        np.testing.assert_allclose(model(occupancy, aux, neighbours).numpy(), law, rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("fixture", ["paired", "paired_potential"])
def test_the_trained_pair_network_answers_small_corrections_at_the_teachers_slope(fixture, request):
    """The gauge's measure on fresh neighbour sets: slope sum p.l / sum |l|^2 above 0.9 (and at most
    1.1) in every bin of the correction's size, the smallest ones included."""
    paired = request.getfixturevalue(fixture)
    rng = np.random.default_rng(99)
    neighbours = neighbour_sets(rng, 20000, SLOTS)
    aux = np.stack([rng.uniform(-np.pi, np.pi, 20000), rng.uniform(0.8, 2.5, 20000)], 1).astype(np.float32)
    label = pair_law(neighbours, K_FORMATION_GRAPH) * aux[:, 1:2]
    model = train.model_from_checkpoint(train.load_checkpoint(paired["out"].with_suffix(".pt"))).eval()
    with torch.no_grad():
        prediction = model(torch.zeros(20000, 1, 50, 50), torch.from_numpy(aux), torch.from_numpy(neighbours)).numpy()
    slopes = _slopes(prediction, label)
    for (lo, hi), (count, slope) in slopes.items():
        assert count >= 500, slopes
        assert 0.9 < slope <= 1.1, f"slope {slope:.3f} in {lo}-{hi} m/s: {slopes}"


def test_training_on_neighbours_builds_the_pair_network_and_leaves_out_saturated_samples(paired):
    assert isinstance(train.model_from_checkpoint(train.load_checkpoint(paired["out"].with_suffix(".pt"))), PairNet)
    assert any("pair network, neighbours slots=16,threshold=1.3,nearest=2" in line for line in paired["lines"]), paired["lines"]
    assert "left out 1 of 8000 samples whose expert wheels saturated (the pair network fits the law)" in paired["lines"]
    assert paired["report"]["neighbours"] == NEIGHBOURS and paired["report"]["ranges"] is None
    wheels = np.array([[0.2, 0.9], [0.5, -0.3], [-0.9, 0.1], [0.8985, 0.0]], np.float32)
    np.testing.assert_array_equal(train.unsaturated(wheels), [False, True, False, True])


# --- the export ----------------------------------------------------------------------------


def test_the_export_takes_the_neighbours_and_declares_them(paired):
    meta = _meta(paired["out"])
    manifest = json.loads((paired["data"] / "manifest.json").read_text())
    assert meta["formation.neighbours"] == manifest["neighbours"] == NEIGHBOURS
    assert meta["formation.output"] == "formation_velocity"
    assert meta["formation.train.architecture"] == "pair"
    assert meta["formation.aux"] == "delta_phi,d_star"
    assert "formation.ranges" not in meta
    session = ort.InferenceSession(str(paired["out"]), providers=["CPUExecutionProvider"])
    inputs = session.get_inputs()
    assert [i.name for i in inputs] == ["occupancy", "aux", "neighbours"]
    assert inputs[2].shape[1:] == [SLOTS, 4] and isinstance(inputs[2].shape[0], str), inputs[2].shape
    assert isinstance(inputs[0].shape[0], str), "the unused image keeps its dynamic batch"
    assert [o.name for o in session.get_outputs()] == ["formation_velocity"]
    model = train.model_from_checkpoint(train.load_checkpoint(paired["out"].with_suffix(".pt"))).eval()
    for batch in (1, 7, 64):
        occupancy, aux, neighbours = _inputs(batch, seed=batch)
        actual = _run(paired["out"], occupancy, aux, neighbours)
        with torch.no_grad():
            expected = model(*(torch.from_numpy(a) for a in (occupancy, aux, neighbours))).numpy()
        assert np.max(np.abs(actual - expected)) < 1e-5
    occupancy, aux, neighbours = _inputs(4, seed=5)
    np.testing.assert_array_equal(_run(paired["out"], occupancy, aux, neighbours), _run(paired["out"], 1 - occupancy, aux, neighbours))
    assert not np.allclose(_run(paired["out"], occupancy, aux, neighbours), _run(paired["out"], occupancy, aux, neighbours * 1.1))


def test_the_parity_file_holds_the_neighbours(paired):
    parity = json.loads((paired["root"] / "parity.json").read_text())
    case = parity["cases"][0]
    assert len(case["neighbours"]) == SLOTS * 4
    actual = _run(
        paired["out"], np.asarray(case["occupancy"], np.float32).reshape(1, 1, 50, 50), np.asarray([case["aux"]], np.float32),
        np.asarray(case["neighbours"], np.float32).reshape(1, SLOTS, 4),
    )
    np.testing.assert_allclose(actual[0], case["wheels"], atol=1e-5)


def test_the_export_command_rebuilds_a_pair_model(paired, tmp_path, capsys):
    for extra in (["--data", str(paired["data"])], []):
        out = tmp_path / f"again{len(extra)}.onnx"
        code = cli.main(["export", "--checkpoint", str(paired["out"].with_suffix(".pt")), "--out", str(out), *extra])
        assert code == 0, capsys.readouterr().err
        assert _meta(out) == _meta(paired["out"])
    other = write_dataset(tmp_path / "other", samples=40, neighbours="slots=8,threshold=1.3,nearest=2")
    code = cli.main(["export", "--checkpoint", str(paired["out"].with_suffix(".pt")), "--out", str(tmp_path / "x.onnx"),
                     "--data", str(other)])
    assert code == cli.USAGE_EXIT
    assert "neighbour input is slots=8,threshold=1.3,nearest=2, the checkpoint's slots=16" in capsys.readouterr().err


def test_a_mirror_averaged_pair_network_is_exactly_symmetric_in_onnxruntime(paired, tmp_path):
    out = tmp_path / "mirror.onnx"
    config = train.TrainConfig(
        data=[paired["data"]], out=out, epochs=1, batch_size=256, lr=1e-3, device="cpu", mirror=True,
        output="formation_velocity", init_from=paired["out"].with_suffix(".pt"),
    )
    train.run(config, log=lambda _: None)
    assert _meta(out)["formation.policy.mirror_averaged"] == "true"
    occupancy, aux, neighbours = _inputs(8, seed=3)
    reflected = [np.ascontiguousarray(x.numpy()) for x in mirror_inputs(*(torch.from_numpy(v) for v in (occupancy, aux)),
                                                                         neighbours=torch.from_numpy(neighbours))]
    v = _run(out, occupancy, aux, neighbours)
    np.testing.assert_allclose(_run(out, *reflected), v * np.array([1, -1], np.float32), atol=1e-6)


# --- warm starts and the command line -------------------------------------------------------


@pytest.mark.parametrize("fixture", ["paired", "paired_potential"])
def test_a_pair_network_warm_starts_from_its_checkpoint_or_its_onnx(fixture, request, tmp_path):
    paired = request.getfixturevalue(fixture)
    from_pt = train.model_from_checkpoint(train.load_checkpoint(paired["out"].with_suffix(".pt")))
    from_onnx = train.model_from_checkpoint(train.load_checkpoint(paired["out"]))
    assert isinstance(from_onnx, PairNet) and from_onnx.neighbour_slots == SLOTS
    assert from_onnx.architecture == from_pt.architecture == _meta(paired["out"])["formation.train.architecture"]
    for (name, a), (_, b) in zip(from_pt.state_dict().items(), from_onnx.state_dict().items()):
        torch.testing.assert_close(a, b, atol=0, rtol=0, msg=name)
    occupancy, aux, neighbours = _inputs(6, seed=8)
    before = _run(paired["out"], occupancy, aux, neighbours)
    for init in (paired["out"].with_suffix(".pt"), paired["out"]):
        lines = []
        out = tmp_path / f"warm-{init.suffix[1:]}.onnx"
        config = train.TrainConfig(
            data=[paired["data"]], out=out, epochs=1, batch_size=256, lr=1e-12, device="cpu", init_from=init,
            output="formation_velocity", architecture=from_pt.architecture,
        )
        train.run(config, log=lines.append)
        assert f"warm start from {init}" in lines
        np.testing.assert_allclose(_run(out, occupancy, aux, neighbours), before, atol=1e-5)


def test_a_pair_network_needs_data_with_its_neighbours_and_a_formation_velocity(paired, tmp_path, capsys):
    plain = write_dataset(tmp_path / "plain", samples=40)
    fewer = write_dataset(tmp_path / "fewer", samples=40, neighbours="slots=8,threshold=1.3,nearest=2")
    init = paired["out"].with_suffix(".pt")
    cases = (
        (dict(data=[plain], init_from=init), "takes the neighbours each robot detects in its own scan, but .*plain holds none: "
         "collect the data with `formation collect --neighbours K`"),
        (dict(data=[plain], architecture="pair"), "plain holds none"),
        (dict(data=[fewer], init_from=init), "takes neighbours in 16 slots of 4 values but the data's are slots=8,threshold=1.3,nearest=2"),
        (dict(data=[paired["data"]], architecture="pair", output="wheels"), "the pair network answers a formation velocity, "
         "not 'wheels': add --output formation_velocity"),
    )
    for options, message in cases:
        config = train.TrainConfig(out=tmp_path / "m.onnx", epochs=1, device="cpu", **{"output": "formation_velocity", **options})
        with pytest.raises(train.TrainError, match=message):
            train.run(config, log=lambda _: None)
    code = cli.main(["train", "--data", str(fewer), "--out", str(tmp_path / "c.onnx"), "--device", "cpu"])
    assert code == cli.USAGE_EXIT
    assert ("declares neighbours (slots=8,threshold=1.3,nearest=2), so the trainer builds the pair network, which answers "
            "a formation velocity, not 'wheels': add --output formation_velocity") in capsys.readouterr().err
    assert not (tmp_path / "m.onnx").exists() and not (tmp_path / "c.onnx").exists()


def test_the_command_line_trains_a_pair_network_on_neighbours_and_a_cnn_when_named(tmp_path, capsys):
    data = write_dataset(tmp_path / "data", samples=120, shard_size=64, neighbours="slots=6,threshold=1.3,nearest=2")
    out = tmp_path / "cli.onnx"
    code = cli.main(["train", "--data", str(data), "--out", str(out), "--device", "cpu", "--epochs", "1",
                     "--output", "formation_velocity", "--response-weight", "0.05"])
    assert code == 0, capsys.readouterr().err
    report = json.loads(capsys.readouterr().out.splitlines()[-1].removeprefix(train.REPORT_PREFIX))
    assert report["neighbours"] == "slots=6,threshold=1.3,nearest=2"
    assert _meta(out)["formation.neighbours"] == "slots=6,threshold=1.3,nearest=2"
    # A CNN named on the same data learns from the images alone and takes no neighbours.
    cnn = tmp_path / "cnn.onnx"
    code = cli.main(["train", "--data", str(data), "--out", str(cnn), "--device", "cpu", "--epochs", "1",
                     "--architecture", "paper"])
    assert code == 0, capsys.readouterr().err
    assert "formation.neighbours" not in _meta(cnn)
    session = ort.InferenceSession(str(cnn), providers=["CPUExecutionProvider"])
    assert [i.name for i in session.get_inputs()] == ["occupancy", "aux"]
    # What the Rust bridge passes for `formation train --architecture pair`.
    assert cli._parser().parse_args(["train", "--data", "d", "--out", "o.onnx", "--architecture", "pair"]).architecture == "pair"


# --- the hidden pairs' step aside (hidden=1) -------------------------------------------------


@pytest.fixture(scope="module")
def hidden_paired(tmp_path_factory):
    """A pair-potential network trained on neighbours with ``hidden=1``, whose labels add each
    slot's step aside at the team gain."""
    root = tmp_path_factory.mktemp("hidden")
    data = write_dataset(
        root / "data", samples=8000, shard_size=3000, neighbours=NEIGHBOURS + ",hidden=1",
        labels={"unshaped": True, "own_scan": True, "unblock_hidden_pairs": True},
    )
    out = root / "pair.onnx"
    config = train.TrainConfig(
        data=[data], out=out, epochs=10, batch_size=256, lr=1e-2, device="cpu", output="formation_velocity",
        response_weight=0.05, architecture="pair-potential",
    )
    train.run(config, log=lambda _: None)
    return {"data": data, "out": out}


def test_the_hidden_pairs_step_is_learnt_as_one_gain_and_exported_with_six_numbers_a_slot(hidden_paired, tmp_path):
    model = train.model_from_checkpoint(train.load_checkpoint(hidden_paired["out"].with_suffix(".pt")))
    assert model.hidden_pairs and model.neighbour_features == 6
    # Started at the teacher's team gain, and held there by labels that step aside at it (a
    # step of the input and of the labels that disagreed would pull it away).
    assert model.hidden_pair_gain.item() == pytest.approx(K_FORMATION_GRAPH, rel=0.1)
    assert multiply_adds(model) == multiply_adds(PairNet(SLOTS))
    meta = _meta(hidden_paired["out"])
    assert meta["formation.neighbours"] == NEIGHBOURS + ",hidden=1"
    session = ort.InferenceSession(str(hidden_paired["out"]), providers=["CPUExecutionProvider"])
    shape = next(i.shape for i in session.get_inputs() if i.name == "neighbours")
    assert shape[1:] == [SLOTS, 6]
    # The step moves the answer by the gain times its sum over the slots, times d*; and it
    # reflects with y.
    rng = np.random.default_rng(4)
    occupancy, aux, _ = _inputs(6, seed=4)
    neighbours = cli.random_neighbours(rng, 6, SLOTS, 6)
    still = neighbours.copy()
    still[..., 4:6] = 0.0
    moved = _run(hidden_paired["out"], occupancy, aux, neighbours) - _run(hidden_paired["out"], occupancy, aux, still)
    step = neighbours[..., 4:6].sum(axis=1) * aux[:, 1:2] * model.hidden_pair_gain.item()
    np.testing.assert_allclose(moved, step, atol=1e-4)
    mirrored = mirror_neighbours(torch.from_numpy(neighbours)).numpy()
    np.testing.assert_array_equal(mirrored[..., 5], -neighbours[..., 5])
    np.testing.assert_array_equal(mirrored[..., 4], neighbours[..., 4])
    # A warm start from the .onnx reads the gain back.
    from_onnx = train.model_from_checkpoint(train.load_checkpoint(hidden_paired["out"]))
    assert from_onnx.hidden_pairs and from_onnx.hidden_pair_gain.item() == model.hidden_pair_gain.item()


def test_a_network_without_the_step_does_not_warm_start_on_data_with_it(paired, hidden_paired, tmp_path):
    config = train.TrainConfig(
        data=[hidden_paired["data"]], out=tmp_path / "x.onnx", epochs=1, batch_size=256, lr=1e-3, device="cpu",
        output="formation_velocity", init_from=paired["out"], architecture="pair",
    )
    with pytest.raises(train.TrainError, match="slots of 4 values but the data's are .*hidden=1"):
        train.run(config, log=lambda _: None)
