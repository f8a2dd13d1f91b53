"""Reading the on-disk format, and the errors for damaged or mismatched datasets."""

import json

import numpy as np
import pytest

from formation_trainer import dataset as ds
from formation_trainer.train import split_by_episode

from conftest import synthetic_arrays


def test_load_concatenates_shards_in_manifest_order(make_dataset):
    directory = make_dataset(samples=96, shard_size=40)
    samples = ds.load([directory])
    expected = synthetic_arrays(96)
    assert len(samples) == 96
    assert samples.occupancy.shape == (96, 50, 50) and samples.occupancy.dtype == np.uint8
    for name in ("occupancy", "aux", "wheels", "iteration", "run", "robot"):
        np.testing.assert_array_equal(getattr(samples, name), expected[name])
    assert samples.dataset_id == "synthetic0000000"
    assert samples.size_px == 50


def test_loading_holds_the_samples_once_plus_one_shard_not_twice(make_dataset):
    import tracemalloc

    directory = make_dataset(samples=4000, shard_size=500)
    tracemalloc.start()
    try:
        samples = ds.load([directory])
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    held = sum(getattr(samples, name).nbytes for name in ("occupancy", "aux", "wheels", "iteration", "run", "robot", "source"))
    one_shard = held / 8
    # Concatenating loaded shards peaked at twice the samples; filling arrays sized once does not.
    assert peak < held + 2 * one_shard, f"peak {peak} bytes for {held} bytes of samples"
    np.testing.assert_array_equal(samples.occupancy, synthetic_arrays(4000)["occupancy"])


def test_several_datasets_are_combined_with_their_ids(make_dataset):
    a = make_dataset("a", samples=30, seed=1)
    b = make_dataset("b", samples=20, seed=2, iteration=1)
    samples = ds.load([a, b])
    assert len(samples) == 50
    assert samples.dataset_id == "synthetic0000001+synthetic0000002"
    assert samples.max_iteration == 1
    assert set(samples.source.tolist()) == {0, 1}


def test_datasets_with_other_settings_cannot_be_mixed(make_dataset):
    a = make_dataset("a", v_train=0.7)
    b = make_dataset("b", v_train=0.5)
    with pytest.raises(ds.DatasetError, match="cannot be trained together: their v_train differ"):
        ds.load([a, b])


def test_datasets_labelled_by_other_laws_cannot_be_mixed(make_dataset):
    default = make_dataset("default", seed=1)
    unshaped = make_dataset("unshaped", seed=2)
    path = unshaped / "manifest.json"
    manifest = json.loads(path.read_text())
    path.write_text(json.dumps(manifest | {"labels": {"unshaped": True}}))
    assert ds.load([unshaped]).manifests[0].labels == {"unshaped": True}
    assert ds.load([default]).manifests[0].labels == {}
    with pytest.raises(ds.DatasetError, match="cannot be trained together: their label law differ"):
        ds.load([default, unshaped])


def test_a_window_scaled_with_d_star_is_read_and_not_mixed_with_a_fixed_one(make_dataset):
    scaled = make_dataset("scaled", d_star_ref_m=1.25, seed=1)
    fixed = make_dataset("fixed", seed=2)
    assert ds.load([scaled]).manifests[0].occupancy["d_star_ref_m"] == 1.25
    assert "d_star_ref_m" not in ds.load([fixed]).manifests[0].occupancy
    with pytest.raises(ds.DatasetError, match="cannot be trained together: their occupancy differ"):
        ds.load([scaled, fixed])


def test_datasets_of_other_noise_levels_train_together_up_to_the_largest(make_dataset):
    clean = make_dataset("clean", noise_std=0.0, seed=1)
    noisy = make_dataset("noisy", noise_std=0.03, seed=2)
    samples = ds.load([clean, noisy])
    assert samples.lidar == {"beams": 900, "max_range": 10.0, "noise_std": 0.03}
    assert ds.load([clean]).lidar["noise_std"] == 0.0


def test_a_truncated_shard_names_the_file_and_the_fix(make_dataset):
    directory = make_dataset(samples=96, shard_size=40)
    shard = directory / "shard-000001.safetensors"
    shard.write_bytes(shard.read_bytes()[:-100])
    with pytest.raises(ds.DatasetError, match=r"shard-000001\.safetensors is truncated.*formation collect"):
        ds.load([directory])


def test_a_missing_shard_is_reported(make_dataset):
    directory = make_dataset(samples=96, shard_size=40)
    (directory / "shard-000002.safetensors").unlink()
    with pytest.raises(ds.DatasetError, match=r"shard-000002\.safetensors is listed in the manifest but missing"):
        ds.load([directory])


def test_an_unknown_manifest_version_is_reported(make_dataset):
    directory = make_dataset()
    manifest = json.loads((directory / "manifest.json").read_text())
    manifest["version"] = 4
    (directory / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(ds.DatasetError, match="format version 4, but this trainer reads versions 1, 2 and 3"):
        ds.load([directory])


def test_an_unknown_shard_version_is_reported(make_dataset, tmp_path):
    from safetensors.numpy import save_file

    directory = make_dataset(samples=10, shard_size=10)
    arrays = synthetic_arrays(10)
    save_file(arrays, str(directory / "shard-000000.safetensors"),
              metadata={"format": "formation-dataset", "version": "9", "iteration": "0"})
    with pytest.raises(ds.DatasetError, match=r"shard-000000\.safetensors has dataset format version 9"):
        ds.load([directory])


def test_a_shard_whose_shape_disagrees_with_the_manifest_is_corrupt(make_dataset):
    directory = make_dataset(samples=10, shard_size=10)
    manifest = json.loads((directory / "manifest.json").read_text())
    manifest["shards"][0]["samples"] = 11
    manifest["samples"] = 11
    (directory / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(ds.DatasetError, match="is corrupt .*`occupancy`"):
        ds.load([directory])


def test_not_a_dataset_and_empty_datasets_are_reported(tmp_path, make_dataset):
    with pytest.raises(ds.DatasetError, match="not a formation dataset"):
        ds.load([tmp_path])
    with pytest.raises(ds.DatasetError, match="holds no samples"):
        ds.load([make_dataset("empty", samples=0)])


def test_validation_holds_out_whole_runs():
    keys = np.repeat(np.arange(10), 7)
    train, val = split_by_episode(keys, 0.2, seed=3)
    assert len(train) + len(val) == 70
    assert set(train.tolist()).isdisjoint(val.tolist())
    assert len(np.unique(keys[val])) == 2
    assert set(keys[train].tolist()).isdisjoint(keys[val].tolist())
    again_train, again_val = split_by_episode(keys, 0.2, seed=3)
    np.testing.assert_array_equal(val, again_val)


def test_a_single_run_is_split_by_sample_and_zero_fraction_keeps_everything():
    keys = np.zeros(20, dtype=np.int64)
    train, val = split_by_episode(keys, 0.25, seed=0)
    assert (len(train), len(val)) == (15, 5)
    train, val = split_by_episode(keys, 0.0, seed=0)
    assert (len(train), len(val)) == (20, 0)


RANGES = "sectors=12,clip=3"


def test_a_dataset_with_ranges_loads_them_beside_the_images(make_dataset):
    directory = make_dataset(samples=50, shard_size=20, ranges=RANGES)
    samples = ds.load([directory])
    expected = synthetic_arrays(50, sectors=12)
    assert samples.range_input == ds.RangeInput(12, 3.0)
    assert samples.ranges.shape == (50, 12) and samples.ranges.dtype == np.float32
    for name in ("occupancy", "aux", "wheels", "ranges", "run"):
        np.testing.assert_array_equal(getattr(samples, name), expected[name])
    manifest = ds.read_manifest(directory)
    assert (manifest.version, manifest.ranges) == (2, ds.RangeInput(12, 3.0))


def test_a_dataset_without_ranges_has_none(make_dataset):
    samples = ds.load([make_dataset(samples=10)])
    assert samples.range_input is None
    assert samples.ranges.shape == (10, 0)
    assert ds.read_manifest(samples.manifests[0].directory).version == 1


def test_the_range_text_is_rusts(make_dataset):
    # What formation_proto::RangeInput's Display writes, and what its parse reads.
    for text, expected in (
        ("sectors=100,clip=3", "sectors=100,clip=3"),
        ("clip = 2.5, sectors = 12", "sectors=12,clip=2.5"),
        ("sectors=100,clip=3.0", "sectors=100,clip=3"),
        ("sectors=100,clip=0.1", "sectors=100,clip=0.1"),
    ):
        assert ds.RangeInput.parse(text).text() == expected
    for bad in ("sectors=3,clip=3", "sectors=100", "sectors=100,clip=0", "sectors=12,clip=3,clip=3", "x", "sectors=361,clip=1"):
        with pytest.raises(ValueError):
            ds.RangeInput.parse(bad)
    assert ds.RangeInput(100, 3.0).mirrored()[:3] == [0, 99, 98]


def test_a_version_that_disagrees_with_the_ranges_is_refused_naming_the_file(make_dataset):
    with_ranges = make_dataset("a", samples=10, ranges=RANGES)
    manifest = json.loads((with_ranges / "manifest.json").read_text())
    manifest["version"] = 1
    (with_ranges / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(ds.DatasetError, match=r"a/manifest\.json is dataset format version 1 but declares ranges \"sectors=12,clip=3\""):
        ds.load([with_ranges])
    without = make_dataset("b", samples=10)
    manifest = json.loads((without / "manifest.json").read_text())
    manifest["version"] = 2
    (without / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(ds.DatasetError, match=r"b/manifest\.json is dataset format version 2 but declares no `ranges`"):
        ds.load([without])
    manifest["ranges"] = "sectors=2,clip=3"
    (without / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(ds.DatasetError, match="its `ranges`: .*out of range"):
        ds.load([without])


def test_a_shard_whose_ranges_disagree_with_the_manifest_is_corrupt(make_dataset):
    from safetensors.numpy import save_file

    directory = make_dataset(samples=10, shard_size=10, ranges=RANGES)
    arrays = synthetic_arrays(10, sectors=8)
    meta = {"format": "formation-dataset", "version": "2", "iteration": "0"}
    save_file(arrays, str(directory / "shard-000000.safetensors"), metadata=meta)
    with pytest.raises(ds.DatasetError, match=r"`ranges` is F32 \[10, 8\], the manifest needs float32 \[10, 12\]"):
        ds.load([directory])
    del arrays["ranges"]
    save_file(arrays, str(directory / "shard-000000.safetensors"), metadata=meta)
    with pytest.raises(ds.DatasetError, match="no `ranges` tensor"):
        ds.load([directory])
    plain = make_dataset("plain", samples=10, shard_size=10)
    save_file(synthetic_arrays(10, sectors=12), str(plain / "shard-000000.safetensors"),
              metadata={"format": "formation-dataset", "version": "1", "iteration": "0"})
    with pytest.raises(ds.DatasetError, match="a `ranges` tensor, but the manifest declares no ranges"):
        ds.load([plain])


def test_datasets_with_other_ranges_cannot_be_mixed(make_dataset):
    a = make_dataset("a", samples=10, ranges=RANGES)
    b = make_dataset("b", samples=10)
    with pytest.raises(ds.DatasetError, match="their range input differ"):
        ds.load([a, b])
    c = make_dataset("c", samples=10, ranges="sectors=12,clip=2")
    with pytest.raises(ds.DatasetError, match="their range input differ"):
        ds.load([a, c])
