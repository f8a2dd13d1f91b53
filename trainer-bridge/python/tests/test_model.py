"""The network has the paper's exact shapes."""

import pytest
import torch

from formation_trainer.model import PAPER_FLATTEN, PolicyNet, conv_output_side


def test_a_50px_image_flattens_to_144_features():
    model = PolicyNet(50)
    assert conv_output_side(50) == 3
    assert model.flatten_width == PAPER_FLATTEN
    features = model.features(torch.zeros(4, 1, 50, 50))
    assert features.shape == (4, 144)


def test_layers_match_the_paper():
    model = PolicyNet(50)
    convs = [m for m in model.features if isinstance(m, torch.nn.Conv2d)]
    assert [(c.in_channels, c.out_channels, c.kernel_size, c.stride, c.padding) for c in convs] == [
        (1, 32, (8, 8), (4, 4), (1, 1)),
        (32, 16, (4, 4), (2, 2), (0, 0)),
        (16, 16, (3, 3), (1, 1), (0, 0)),
    ]
    linears = [m for m in model.head if isinstance(m, torch.nn.Linear)]
    assert [(l.in_features, l.out_features) for l in linears] == [(146, 32), (32, 2)]


def test_forward_maps_a_batch_to_two_wheel_speeds():
    model = PolicyNet(50)
    out = model(torch.rand(5, 1, 50, 50), torch.rand(5, 2))
    assert out.shape == (5, 2)
    assert out.dtype == torch.float32


def test_aux_reaches_the_output():
    torch.manual_seed(0)
    model = PolicyNet(50)
    image = torch.zeros(1, 1, 50, 50)
    a = model(image, torch.tensor([[0.0, 1.0]]))
    b = model(image, torch.tensor([[1.0, 1.0]]))
    assert not torch.allclose(a, b)


def test_too_small_images_are_refused():
    with pytest.raises(ValueError, match="too small"):
        PolicyNet(10)


def test_the_wide_network_keeps_the_convolution_geometry_and_widens_the_rest():
    model = PolicyNet(50, "wide")
    convs = [m for m in model.features if isinstance(m, torch.nn.Conv2d)]
    assert [(c.in_channels, c.out_channels, c.kernel_size, c.stride) for c in convs] == [
        (1, 32, (8, 8), (4, 4)),
        (32, 64, (4, 4), (2, 2)),
        (64, 64, (3, 3), (1, 1)),
    ]
    linears = [m for m in model.head if isinstance(m, torch.nn.Linear)]
    assert [(l.in_features, l.out_features) for l in linears] == [(578, 256), (256, 256), (256, 2)]
    assert model(torch.rand(3, 1, 50, 50), torch.rand(3, 2)).shape == (3, 2)


def test_an_unknown_architecture_is_refused_by_name():
    with pytest.raises(ValueError, match="unknown network architecture 'huge'"):
        PolicyNet(50, "huge")


def _reflect(occupancy, aux):
    return occupancy.flip(2), torch.stack([-aux[:, 0], aux[:, 1]], dim=1)


@pytest.mark.parametrize("architecture", ["paper", "wide", "wide-head"])
def test_the_mirror_average_makes_the_network_exactly_symmetric(architecture):
    torch.manual_seed(1)
    occupancy = (torch.rand(6, 1, 50, 50) < 0.05).float()
    aux = torch.randn(6, 2)
    plain = PolicyNet(50, architecture)
    averaged = PolicyNet(50, architecture, mirror_averaged=True)
    averaged.load_state_dict(plain.state_dict())
    with torch.no_grad():
        # Random weights are not symmetric by themselves ...
        assert not torch.allclose(plain(*_reflect(occupancy, aux)), plain(occupancy, aux).flip(1), atol=1e-4)
        # ... their mirror average is: reflecting the input swaps the wheels, and nothing else.
        torch.testing.assert_close(averaged(*_reflect(occupancy, aux)), averaged(occupancy, aux).flip(1))
        # It is the mean of the network and its reflection, with the same weights.
        expected = 0.5 * (plain(occupancy, aux) + plain(*_reflect(occupancy, aux)).flip(1))
        torch.testing.assert_close(averaged(occupancy, aux), expected)
        torch.testing.assert_close(averaged.raw(occupancy, aux), plain(occupancy, aux))


def test_a_range_branch_joins_the_head_after_the_image_features_and_aux():
    from formation_trainer.model import RANGE_FEATURES

    model = PolicyNet(50, "wide-head", range_sectors=100)
    assert RANGE_FEATURES == 64
    branch = [m for m in model.range_features if isinstance(m, torch.nn.Linear)]
    assert [(l.in_features, l.out_features) for l in branch] == [(100, 64)]
    linears = [m for m in model.head if isinstance(m, torch.nn.Linear)]
    assert [(l.in_features, l.out_features) for l in linears] == [(144 + 2 + 64, 256), (256, 256), (256, 2)]
    out = model(torch.rand(5, 1, 50, 50), torch.rand(5, 2), torch.rand(5, 100))
    assert out.shape == (5, 2)
    # The ranges reach the output.
    torch.manual_seed(0)
    image, aux = torch.zeros(1, 1, 50, 50), torch.tensor([[0.0, 1.0]])
    assert not torch.allclose(model(image, aux, torch.ones(1, 100)), model(image, aux, 2 * torch.ones(1, 100)))


def test_a_network_refuses_ranges_it_does_not_take_and_needs_those_it_does():
    with pytest.raises(ValueError, match="takes ranges of 12 sectors"):
        PolicyNet(50, range_sectors=12)(torch.zeros(1, 1, 50, 50), torch.zeros(1, 2))
    with pytest.raises(ValueError, match="takes no ranges"):
        PolicyNet(50)(torch.zeros(1, 1, 50, 50), torch.zeros(1, 2), torch.zeros(1, 12))


def test_multiply_adds_are_the_documented_ones_and_within_issue_34s_cap():
    from formation_trainer.model import multiply_adds

    paper = multiply_adds(PolicyNet(50, "paper"))
    assert paper == 525_184
    assert multiply_adds(PolicyNet(50, "wide-head")) == 623_872
    assert multiply_adds(PolicyNet(50, "paper", range_sectors=100)) == 533_632
    with_ranges = multiply_adds(PolicyNet(50, "wide-head", range_sectors=100))
    assert with_ranges == 623_872 + 100 * 64 + 64 * 256 == 646_656
    assert multiply_adds(PolicyNet(50, "wide")) == 1_659_904
    assert with_ranges <= 1.3 * paper


def test_mirroring_ranges_maps_sector_s_to_k_minus_s():
    from formation_trainer.model import mirror_inputs, mirror_ranges

    ranges = torch.arange(10, dtype=torch.float32).reshape(1, 10) + torch.tensor([[0.0], [100.0]])
    mirrored = mirror_ranges(ranges)
    for s in range(10):
        torch.testing.assert_close(mirrored[:, s], ranges[:, (10 - s) % 10])
    torch.testing.assert_close(mirror_ranges(mirrored), ranges)
    occupancy, aux = torch.rand(2, 1, 50, 50), torch.randn(2, 2)
    assert len(mirror_inputs(occupancy, aux)) == 2
    *_, reflected = mirror_inputs(occupancy, aux, ranges)
    torch.testing.assert_close(reflected, mirrored)


@pytest.mark.parametrize("architecture", ["paper", "wide-head"])
def test_the_mirror_average_with_ranges_is_exactly_symmetric(architecture):
    from formation_trainer.model import mirror_inputs

    torch.manual_seed(2)
    occupancy = (torch.rand(6, 1, 50, 50) < 0.05).float()
    aux = torch.randn(6, 2)
    ranges = 3 * torch.rand(6, 100)
    plain = PolicyNet(50, architecture, range_sectors=100)
    averaged = PolicyNet(50, architecture, mirror_averaged=True, range_sectors=100)
    averaged.load_state_dict(plain.state_dict())
    with torch.no_grad():
        reflected = mirror_inputs(occupancy, aux, ranges)
        assert not torch.allclose(plain(*reflected), plain(occupancy, aux, ranges).flip(1), atol=1e-4)
        # Exactly: the reflection of a reflection is the input itself, bit for bit, so the two
        # evaluations of the average swap places.
        assert torch.equal(averaged(*reflected), averaged(occupancy, aux, ranges).flip(1))
        expected = 0.5 * (plain(occupancy, aux, ranges) + plain(*reflected).flip(1))
        torch.testing.assert_close(averaged(occupancy, aux, ranges), expected)
