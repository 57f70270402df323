"""SOM: winners, QE and TE on hand-set codebooks; MiniSom's update and decay by hand; batch SOM by hand;
training orders a map and lowers its error; determinism, state_dict, batch shapes, bad input."""

import math

import pytest
import torch

from aesop_torch.som import SOMConfig, SelfOrganizingMap


def som_with(weights, rows, cols, **kw):
    w = torch.tensor(weights, dtype=torch.float32)
    if w.ndim == 1:
        w = w[:, None]
    som = SelfOrganizingMap(SOMConfig(rows=rows, cols=cols, dim=w.shape[1], **kw))
    som.weights.copy_(w)
    return som


def test_grid_is_row_major_like_minisom():
    som = SelfOrganizingMap(SOMConfig(rows=2, cols=3, dim=1))
    assert som.locations.tolist() == [[0, 0], [0, 1], [0, 2], [1, 0], [1, 1], [1, 2]]


def test_winner_qe_te_on_a_hand_set_3x1_codebook():
    # units on a 3x1 line at grid rows 0, 1, 2 hold 0, 5, 1: unit 2 is next to unit 0 in input space, not on the grid
    som = som_with([0.0, 5.0, 1.0], rows=3, cols=1)
    data = torch.tensor([[0.2], [4.0], [0.6], [6.0]])
    assert som.winner(data).tolist() == [0, 1, 2, 1]
    assert som.quantization(data).flatten().tolist() == [0.0, 5.0, 1.0, 5.0]
    # |0.2-0|, |4-5|, |0.6-1|, |6-5|
    assert som.quantization_error(data) == pytest.approx((0.2 + 1 + 0.4 + 1) / 4)
    # 0.2: best 0, second 2 (grid distance 2): error. 4: 1 then 2, adjacent. 0.6: 2 then 0: error. 6: 1 then 2.
    assert som.topographic_error(data) == 0.5


def test_topographic_error_counts_diagonal_neighbours_as_adjacent():
    # 2x3 grid; unit 0 at grid (0,0), unit 4 at (1,1) (diagonal, distance 1.414), unit 2 at (0,2) (distance 2)
    far = [[100.0 + u, 100.0] for u in range(6)]
    far[0], far[4], far[2] = [0.0, 0.0], [1.0, 0.0], [0.0, 1.0]
    som = som_with(far, rows=2, cols=3)
    assert som.topographic_error(torch.tensor([[0.4, 0.0]])) == 0.0   # best 0, second 4: diagonal neighbours
    assert som.topographic_error(torch.tensor([[0.0, 0.4]])) == 1.0   # best 0, second 2: two apart
    assert math.isnan(som_with([0.0], rows=1, cols=1).topographic_error(torch.zeros(3, 1)))


def test_graded_activity_by_hand():
    som = som_with([0.0, 5.0, 1.0], rows=3, cols=1, activity_sigma=0.5)
    a = som.activity(torch.tensor([0.2]))
    expected = [math.exp(-d * d / (2 * 0.25)) for d in (0.2, 4.8, 0.8)]
    assert a.tolist() == pytest.approx(expected, rel=1e-5)
    assert som.activity(torch.tensor([5.0]))[1] == pytest.approx(1.0)  # an input on a codebook vector: 1


def test_leading_batch_dims():
    som = som_with([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]], rows=2, cols=2)
    x = torch.tensor([[[0.1, 0.0], [0.9, 0.1]], [[0.0, 0.8], [1.0, 1.0]], [[0.2, 0.2], [0.7, 0.9]]])  # (3, 2, 2)
    assert som.winner(x).tolist() == [[0, 1], [2, 3], [0, 3]]
    assert som.activity(x).shape == (3, 2, 4)
    assert som.quantization(x).shape == (3, 2, 2)
    assert som.winner(torch.tensor([0.9, 0.1])).shape == ()


def test_online_update_follows_minisom_decay_by_hand():
    # one sample, two iterations: t=0 eta=lr, sigma=s; t=1 (T=2) both halved: x / (1 + t / (T/2))
    som = som_with([0.0, 1.0, 2.0], rows=1, cols=3, sigma=1.0, learning_rate=0.5)
    x = 0.4
    w = [0.0, 1.0, 2.0]
    for eta, sig in ((0.5, 1.0), (0.25, 0.5)):
        bmu = min(range(3), key=lambda u: abs(w[u] - x))
        w = [w[u] + eta * math.exp(-((u - bmu) ** 2) / (2 * sig * sig)) * (x - w[u]) for u in range(3)]
    som.train_online(torch.tensor([[x]]), 2, torch.Generator().manual_seed(0))
    assert som.weights.flatten().tolist() == pytest.approx(w, rel=1e-6)


def test_batch_epoch_by_hand():
    # 1x2 map at 0 and 10; samples 1, 3 -> unit 0, 9 -> unit 1; one epoch uses sigma_end = 1: h(0, 1) = e^-0.5
    som = som_with([0.0, 10.0], rows=1, cols=2, sigma=3.0, sigma_end=1.0)
    som.train_batch(torch.tensor([[1.0], [3.0], [9.0]]), epochs=1)
    h = math.exp(-0.5)
    assert som.weights.flatten().tolist() == pytest.approx([(4 + 9 * h) / (2 + h), (4 * h + 9) / (2 * h + 1)],
                                                           rel=1e-6)


def test_batch_chunking_does_not_change_the_result():
    data = torch.rand(500, 3, generator=torch.Generator().manual_seed(0))
    maps = []
    for chunk in (7, 8192):
        som = SelfOrganizingMap(SOMConfig(rows=4, cols=4, dim=3, chunk_size=chunk))
        som.init_weights(data)
        som.train_batch(data, 5)
        maps.append(som.weights)
    assert torch.allclose(maps[0], maps[1], atol=1e-6)


def test_a_large_map_takes_its_samples_in_blocks_and_finds_the_same_winners():
    """30x30 units: at most 2^20 distances a block, so 3000 samples go in 3 blocks of 1165; each sample's winner is
    still the argmin of its distances to every unit, computed here in one piece."""
    som = SelfOrganizingMap(SOMConfig(rows=30, cols=30, dim=3)).double()
    som.weights.copy_(torch.rand(900, 3, generator=torch.Generator().manual_seed(1), dtype=torch.float64))
    data = torch.rand(3000, 3, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    assert [len(c) for c in som._chunks(data)] == [1165, 1165, 670]
    assert torch.equal(som.winner(data), torch.cdist(data, som.weights).argmin(-1))


def test_pca_init_spans_the_data_along_its_principal_axis():
    data = torch.tensor([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0], [4.0, 0.0]])
    som = SelfOrganizingMap(SOMConfig(rows=1, cols=5, dim=2))
    som.init_weights(data)
    half = math.sqrt(3.0) * math.sqrt(2.5)          # sqrt(3) x the (unbiased) std along x
    xs = sorted(som.weights[:, 0].tolist())
    assert xs == pytest.approx([2 - half, 2 - half / 2, 2, 2 + half / 2, 2 + half], abs=1e-5)
    assert som.weights[:, 1].abs().max() < 1e-6
    # units follow the grid order (monotonic, in either direction: an eigenvector's sign is arbitrary)
    d = som.weights[1:, 0] - som.weights[:-1, 0]
    assert (d > 0).all() or (d < 0).all()


@pytest.mark.parametrize("online", [False, True])
def test_training_orders_the_map_and_lowers_qe(online):
    # four clusters on a line; a 1x4 map must put one unit on each, in grid order
    g = torch.Generator().manual_seed(0)
    centres = torch.tensor([0.0, 1.0, 2.0, 3.0])
    data = (centres.repeat_interleave(50) + 0.05 * torch.randn(200, generator=g))[:, None]
    som = SelfOrganizingMap(SOMConfig(rows=1, cols=4, dim=1, sigma=1.0, sigma_end=0.2))
    som.init_weights(data, torch.Generator().manual_seed(1))
    before = som.quantization_error(data)
    if online:
        som.train_online(data, 2000, g)
    else:
        som.train_batch(data, 20)
    after = som.quantization_error(data)
    assert after < 0.5 * before
    w = som.winner(centres[:, None]).tolist()
    assert w in ([0, 1, 2, 3], [3, 2, 1, 0])
    assert som.topographic_error(data) == 0.0
    if not online:  # batch with a small final radius: each unit sits on its cluster's mean
        assert som.quantization(centres[:, None]).flatten().tolist() == pytest.approx(centres.tolist(), abs=0.05)


def test_fit_with_ordering_phase_separates_categories():
    # 12 one-hot categories; the ordering phase gives each its own unit of a 4x4 map
    data = torch.eye(12).repeat(30, 1)
    som = SelfOrganizingMap(SOMConfig(rows=4, cols=4, dim=12, sigma=1.5, sigma_end=0.3, ordering_iterations=600))
    som.fit(data, 10, torch.Generator().manual_seed(0))
    assert len(som.winner(torch.eye(12)).unique()) == 12
    assert som.quantization_error(data) < 0.05
    with pytest.raises(ValueError, match="generator"):
        som.fit(data, 10)


def test_same_seed_same_weights():
    data = torch.rand(300, 3, generator=torch.Generator().manual_seed(0))
    runs = []
    for seed in (5, 5, 6):
        som = SelfOrganizingMap(SOMConfig(rows=3, cols=3, dim=3))
        g = torch.Generator().manual_seed(seed)
        som.init_weights(data, g)
        som.train_online(data, 200, g)
        runs.append(som.weights.clone())
    assert torch.equal(runs[0], runs[1])
    assert not torch.equal(runs[0], runs[2])


def test_state_dict_round_trip():
    data = torch.rand(100, 3, generator=torch.Generator().manual_seed(0))
    som = SelfOrganizingMap(SOMConfig(rows=3, cols=4, dim=3))
    som.init_weights(data)
    som.train_batch(data, 3)
    other = SelfOrganizingMap(SOMConfig(rows=3, cols=4, dim=3))
    other.load_state_dict(som.state_dict())
    assert torch.equal(other.weights, som.weights)
    assert torch.equal(other.winner(data), som.winner(data))
    assert set(som.state_dict()) == {"weights", "locations"}


def test_bad_input_raises_value_error():
    som = SelfOrganizingMap(SOMConfig(rows=2, cols=2, dim=3))
    with pytest.raises(ValueError, match="last dimension 3"):
        som.winner(torch.zeros(4, 2))
    with pytest.raises(ValueError, match="data must be"):
        som.train_batch(torch.zeros(4, 5, 3), 1)
    with pytest.raises(ValueError, match="epochs"):
        som.train_batch(torch.zeros(4, 3), 0)
    with pytest.raises(ValueError, match="num_iteration"):
        som.train_online(torch.zeros(4, 3), 0, torch.Generator())
    with pytest.raises(ValueError, match="rows, cols and dim"):
        SOMConfig(rows=0)


def test_decode_reads_the_input_back_from_the_population():
    # a hand-set 1 x 4 codebook and a gaussian width of 0.3: the response to 0.3 is exp(-(0.3 - w)^2 / 0.18)
    som = SelfOrganizingMap(SOMConfig(rows=1, cols=4, dim=1, activity_sigma=0.3))
    som.weights.copy_(torch.tensor([[0.0], [0.4], [0.8], [1.2]]))
    a = som.activity(torch.tensor([[0.3], [0.65]]))
    assert torch.allclose(a[0], torch.exp(-(0.3 - som.weights[:, 0]) ** 2 / 0.18))
    assert som.decode(a)[:, 0].tolist() == pytest.approx([0.3, 0.65], abs=1e-5)    # the winner alone: 0.4, 0.8
    assert som.decode(0.2 * a)[:, 0].tolist() == pytest.approx([0.3, 0.65], abs=1e-5)   # a scaled copy reads the same
    # 2-d inputs on a hand-set 2 x 2 map
    som2 = SelfOrganizingMap(SOMConfig(rows=2, cols=2, dim=2, activity_sigma=0.5))
    som2.weights.copy_(torch.tensor([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]]))
    x = torch.tensor([[0.2, 0.7]])
    assert som2.decode(som2.activity(x)).tolist()[0] == pytest.approx([0.2, 0.7], abs=1e-5)
    # a single active unit (the others below the floor): its codebook vector; silence: NaN
    one = torch.tensor([[0.0, 1.0, 0.0, 0.0]])
    assert som.decode(one)[0, 0].item() == pytest.approx(0.4)
    assert torch.isnan(som.decode(torch.zeros(1, 4))).all()
