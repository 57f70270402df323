"""Sensory encoding by hand; words; developmental samples; the trained maps resolve what the experiment needs."""

import math

import pytest
import torch

from aesop_torch.encoders import (COLOR_WORDS, MAP_NAMES, PROPERTIES, SHAPE_WORDS, VOCABULARY, WORD_MAP,
                                  EncoderConfig, SensoryEncoder, developmental_samples, encode_words, word_activity,
                                  train_property_maps)

# the project's palette (sim/objects.py), repeated here so the model's tests do not import the simulator
RED, GREEN, BLUE = (0.85, 0.10, 0.10), (0.10, 0.70, 0.20), (0.10, 0.25, 0.85)


def measure(rgb, extent, fill, mass, **extra):
    return {"rgb": torch.tensor(rgb), "extent_cm": torch.tensor(extent), "fill": torch.tensor(fill),
            "mass_g": torch.tensor(mass), **extra}


def test_shape_size_weight_by_hand():
    enc = SensoryEncoder()
    out = enc(measure([RED, RED, RED], [[11.5, 6.36, 6.36], [5.0, 5.0, 5.0], [7.0, 7.0, 7.0]],
                      [math.pi / 4, 1.0, math.pi / 6], [420.0, 90.0, 14.0]))
    assert out["color"].flatten().tolist() == pytest.approx(list(RED) * 3)
    r = 6.36 / 11.5
    assert out["shape"].flatten().tolist() == pytest.approx([math.pi / 4, r, r, 1, 1, 1, math.pi / 6, 1, 1], rel=1e-6)
    # size: the side of the cube with the same bounding-box volume, log-scaled over 1..30 cm
    side = (11.5 * 6.36 * 6.36) ** (1 / 3)
    assert out["size"][:, 0].tolist() == pytest.approx([math.log(x) / math.log(30) for x in (side, 5, 7)], rel=1e-5)
    assert out["weight"][:, 0].tolist() == pytest.approx([math.log(m) / math.log(2000) for m in (420, 90, 14)],
                                                         rel=1e-6)


def test_unbatched_and_unsorted_measurements():
    enc = SensoryEncoder()
    a = enc(measure(BLUE, [6.36, 11.5, 6.36], math.pi / 4, 420.0))
    b = enc(measure([BLUE], [[11.5, 6.36, 6.36]], [math.pi / 4], [420.0]))
    assert set(a) == set(PROPERTIES)
    for k in a:
        assert a[k].shape[0] == 1 and torch.equal(a[k], b[k])


def test_shape_is_size_invariant():
    enc = SensoryEncoder()
    out = enc(measure([RED, RED], [[11.5, 6.36, 6.36], [23.0, 12.72, 12.72]], [math.pi / 4] * 2, [420.0, 420.0]))
    assert torch.allclose(out["shape"][0], out["shape"][1])
    assert out["size"][1] > out["size"][0]


def test_missing_measurements_give_no_input():
    enc = SensoryEncoder()
    out = enc({"rgb": torch.tensor(RED), "extent_cm": torch.tensor([5.0, 5.0, 5.0]), "fill": torch.tensor(1.0)})
    assert set(out) == {"color", "shape", "size"}         # not lifted yet: no weight
    out = enc({"mass_g": torch.tensor([14.0, 420.0]), "words": ["red cylinder", "blue cube"]})
    assert set(out) == {"weight", WORD_MAP} and out[WORD_MAP].shape == (2, len(VOCABULARY))


def test_words_bag_of_words():
    v = encode_words("blue cylinder")
    expected = torch.zeros(len(VOCABULARY))
    expected[VOCABULARY.index("blue")] = expected[VOCABULARY.index("cylinder")] = 1 / math.sqrt(2)
    assert torch.allclose(v, expected)
    name = encode_words("Red_heavy_cylinder")
    assert name.nonzero().flatten().tolist() == sorted(VOCABULARY.index(w) for w in ("red", "heavy", "cylinder"))
    assert name.norm() == pytest.approx(1.0)
    # unknown words are ignored; a phrase of only unknown words is silent
    assert torch.equal(encode_words("pink cylinder"), encode_words("cylinder"))
    assert encode_words("xyzzy").abs().sum() == 0
    assert encode_words(["blue cylinder", "red cube"]).shape == (2, len(VOCABULARY))


@pytest.mark.parametrize("field,value,msg", [
    ("mass_g", [0.0], "mass_g"),
    ("rgb", [[0.5, 0.5]], "rgb"),
    ("rgb", [[1.5, 0.0, 0.0]], "rgb"),
    ("fill", [1.2], "fill"),
    ("extent_cm", [[5.0, -1.0, 5.0]], "extent_cm"),
])
def test_bad_measurements_raise(field, value, msg):
    m = measure([RED], [[5.0, 5.0, 5.0]], [1.0], [90.0])
    m[field] = torch.tensor(value)
    with pytest.raises(ValueError, match=msg):
        SensoryEncoder()(m)


def test_batch_sizes_must_agree():
    with pytest.raises(ValueError, match="batch size"):
        SensoryEncoder()(measure([RED, RED], [[5.0, 5.0, 5.0]], [1.0], [90.0]))


def test_developmental_samples():
    g = torch.Generator().manual_seed(0)
    s = developmental_samples(2000, g)
    assert set(s) == set(MAP_NAMES)
    assert {k: tuple(v.shape) for k, v in s.items()} == {"color": (2000, 3), "shape": (2000, 3), "size": (2000, 1),
                                                         "weight": (2000, 1), "word": (2000, len(VOCABULARY))}
    # the four kinds, identified by fill; cube and sphere have equal extents, boxes and cylinders vary
    fills = s["shape"][:, 0]
    for f in (math.pi / 4, 1.0, math.pi / 6):
        assert ((fills - f).abs() < 1e-6).sum() > 300
    assert (s["shape"][:, 1:] <= 1 + 1e-6).all() and (s["shape"][:, 1:] >= 1 / 4 - 1e-6).all()
    # log-uniform: the normalised size and weight fill [0, 1] evenly
    for k in ("size", "weight"):
        assert 0 <= s[k].min() < 0.02 and 0.98 < s[k].max() <= 1
        assert s[k].mean() == pytest.approx(0.5, abs=0.03)
    # words: one word of the vocabulary each, every word heard (2000 draws of 20 words: ~100 each)
    words = s[WORD_MAP]
    assert ((words == 0) | (words == 1)).all() and (words.sum(-1) == 1).all()
    assert (words.sum(0) > 50).all()
    again = developmental_samples(2000, torch.Generator().manual_seed(0))
    assert all(torch.equal(s[k], again[k]) for k in s)


@pytest.fixture(scope="module")
def maps():
    return train_property_maps(4000, torch.Generator().manual_seed(0))


# the experiment's distinctions: (map, measurements of objects that must land on different units)
EXPERIMENT = {
    "weight": dict(mass_g=[14.0, 90.0, 420.0]),
    "color": dict(rgb=[RED, GREEN, BLUE]),
    # cylinder 6.36 x 11.5, cube 6, sphere 7, box 4 x 5 x 7
    "shape": dict(extent_cm=[[11.5, 6.36, 6.36], [6.0, 6.0, 6.0], [7.0, 7.0, 7.0], [7.0, 5.0, 4.0]],
                  fill=[math.pi / 4, 1.0, math.pi / 6, 1.0]),
    # the heavy cylinder and the same at half scale (the default set's size pair)
    "size": dict(extent_cm=[[11.5, 6.36, 6.36], [5.75, 3.18, 3.18]], fill=[math.pi / 4, math.pi / 4]),
}


@pytest.mark.parametrize("name", list(EXPERIMENT))
def test_maps_resolve_the_experiment(maps, name):
    x = SensoryEncoder()({k: torch.tensor(v) for k, v in EXPERIMENT[name].items()})[name]
    som = maps[name]
    winners = som.winner(x)
    assert len(winners.unique()) == len(winners), f"{name}: objects share a unit {winners.tolist()}"
    act = som.activity(x)[:, winners]           # [i, j]: object i's activity on object j's unit
    n = len(winners)
    assert (act.diagonal() > 0.8).all(), f"{name}: own-unit activity {act.diagonal().tolist()}"
    off = act[~torch.eye(n, dtype=torch.bool)]
    assert (off < 0.05).all(), f"{name}: a clearly different object activates another's unit: {act.tolist()}"


def test_word_map_gives_every_word_its_own_unit_and_reads_phrases_word_by_word(maps):
    som = maps[WORD_MAP]
    words = torch.eye(len(VOCABULARY))
    winners = som.winner(words)
    assert len(winners.unique()) == len(VOCABULARY)
    act = som.activity(words)[:, winners]       # [i, j]: word i on word j's unit
    assert (act.diagonal() > 0.95).all() and (act[~torch.eye(len(VOCABULARY), dtype=torch.bool)] < 0.01).all()
    # a phrase is the sum of its words' unit-length patterns: the cosine of two names is the fraction of shared
    # words (red heavy cylinder vs red light cylinder: 2 of 3), whatever order the words come in
    cos = lambda a, b: float(torch.nn.functional.cosine_similarity(a, b, dim=-1))
    rhc, rlc = (word_activity(som, encode_words([p]))[0] for p in ("red_heavy_cylinder", "red light cylinder"))
    assert cos(rhc, word_activity(som, encode_words(["cylinder heavy red"]))[0]) == pytest.approx(1.0, abs=1e-6)
    assert cos(rhc, rlc) == pytest.approx(2 / 3, abs=0.02)
    assert word_activity(som, encode_words(["xyzzy"])).abs().sum() == 0


def test_train_property_maps_is_ordered_and_deterministic(maps):
    assert tuple(maps) == MAP_NAMES
    a, b, c = (train_property_maps(300, torch.Generator().manual_seed(s), epochs=3) for s in (1, 1, 2))
    assert all(torch.equal(a[k].weights, b[k].weights) for k in MAP_NAMES)
    assert not any(torch.equal(a[k].weights, c[k].weights) for k in MAP_NAMES)


def test_encoder_config_ranges_are_used():
    enc = SensoryEncoder(EncoderConfig(mass_min_g=10.0, mass_max_g=1000.0))
    w = enc({"mass_g": torch.tensor([10.0, 100.0, 1000.0])})["weight"][:, 0]
    assert w.tolist() == pytest.approx([0.0, 0.5, 1.0], abs=1e-6)


def test_size_is_read_from_the_volume_or_from_the_largest_extent_as_configured():
    """A 2 x 2 x 16 cm rod and a 4 cm cube have one bounding-box volume (64 cm^3): the same size read as its cube
    root (the default), the rod 4x larger read as the largest extent (EncoderConfig.size_from "largest")."""
    from aesop_torch.encoders import EncoderConfig, SensoryEncoder
    m = {"rgb": torch.tensor([[0.5] * 3] * 2), "extent_cm": torch.tensor([[16.0, 2.0, 2.0], [4.0, 4.0, 4.0]]),
         "fill": torch.tensor([1.0, 1.0]), "mass_g": torch.tensor([50.0, 50.0])}
    unit = math.log(30.0)   # size_min_cm 1 .. size_max_cm 30
    root = SensoryEncoder(EncoderConfig())(m)["size"][:, 0]
    assert torch.allclose(root, torch.tensor([math.log(4.0) / unit] * 2))
    largest = SensoryEncoder(EncoderConfig(size_from="largest"))(m)["size"][:, 0]
    assert torch.allclose(largest, torch.tensor([math.log(16.0) / unit, math.log(4.0) / unit]))
    with pytest.raises(ValueError, match="size_from must be one of cube_root, largest"):
        EncoderConfig(size_from="mean")
