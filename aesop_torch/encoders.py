"""The sensory layer: world measurements -> inputs of the property maps, and the maps' developmental training.

The agent never sees labels, only what the world measures about an object (a dict of tensors, leading batch dim):
  rgb (B, 3) mean pixel colour in 0..1, extent_cm (B, 3) the object's extents, fill (B,) object volume over
  bounding-box volume (cube/box 1, cylinder pi/4, sphere pi/6), mass_g (B,) felt when lifting, and optionally
  words: a teacher's phrase per object (a str, or a list of B str).
Each measurement is turned into the input of one map:
  color  = rgb                                                    (3-d)
  shape  = [fill, extent[1] / extent[0], extent[2] / extent[0]]   (3-d, extents sorted descending: size-invariant)
  size   = log(cube root of the bounding-box volume) normalised to [0, 1] over size_min_cm..size_max_cm   (1-d):
           one length for how big the object is, as the paper's size; the largest extent alone would call a thin
           rod as big as a cube of the same height (EncoderConfig.size_from "largest" reads it so, as an option)
  weight = log(mass) normalised to [0, 1] over mass_min_g..mass_max_g               (1-d)
  word   = bag of words over a fixed vocabulary, scaled to unit length              (22-d); the word map hears
           the words one at a time: its activity for a phrase is the sum of each word's own activity pattern, each
           scaled to unit length (`word_activity`), so every word of a name counts once however many units it has
Log scales because perception of size and weight is roughly logarithmic (Weber's law) and the objects span more
than an order of magnitude in both: on a log scale 14 g vs 90 g is as distinct as 90 g vs 580 g.

Before the experiment the maps are trained on the infant's prior visual and haptic experience
(`developmental_samples`): colours all over the RGB cube, the four shape kinds with random proportions, sizes and
masses log-uniform over the ranges above, and single words of the vocabulary (heard one at a time). The maps
therefore know the *space* of properties and the words, never the experiment's objects or names.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import nn

from .names import OBJECT_PROPERTIES, PROPERTIES, object_properties  # noqa: F401  (torch-free, aesop_torch/names.py)
from .som import SOMConfig, SelfOrganizingMap

# the object's properties judged one by one: the paper's "shape" split into what decides a sinker's volume (fill:
# volume over bounding box) and what does not (elongation: the two shorter extents over the longest)
SPLIT_PROPERTIES = ("color", "fill", "elongation", "size", "weight")
WORD_MAP = "word"
MAP_NAMES = PROPERTIES + (WORD_MAP,)

COLOR_WORDS = ("red", "green", "blue", "yellow", "orange", "purple", "white", "black", "grey")
SHAPE_WORDS = ("cylinder", "cube", "sphere", "box")
ADJECTIVES = ("large", "small", "heavy", "light", "medium", "tall", "short")
# the teacher's goal, "reach the green ball": its verb and its object join the vocabulary, so a goal is heard through
# the word map like a name (agent.GOAL_WORDS binds them to the body hub's goal state)
GOAL_WORDS = ("reach", "ball")
VOCABULARY = COLOR_WORDS + SHAPE_WORDS + ADJECTIVES + GOAL_WORDS
# heard and let pass: they name nothing, so they have no place on the word map
FUNCTION_WORDS = ("the", "a")
SIZE_FROM = ("cube_root", "largest")   # EncoderConfig.size_from
SHAPE_FILL = {"cylinder": math.pi / 4, "cube": 1.0, "sphere": math.pi / 6, "box": 1.0}  # volume / bounding box


@dataclass
class EncoderConfig:
    # size and weight are normalised over the ranges an infant handles (and the jar admits): 1..30 cm, 1..2000 g.
    size_min_cm: float = 1.0
    size_max_cm: float = 30.0
    mass_min_g: float = 1.0
    mass_max_g: float = 2000.0
    # developmental shapes: a cylinder's height / diameter is log-uniform in [1/max_aspect, max_aspect] and a box's
    # two shorter sides over its longest in [1/max_aspect, 1]: from a disc or slab to a rod, up to a factor 4.
    max_aspect: float = 4.0
    # the object's properties, each perceived on a map of its own: the paper's four (PROPERTIES), or shape split
    # into fill and elongation (SPLIT_PROPERTIES)
    properties: tuple = PROPERTIES
    # how size is read from the three extents: "cube_root", the cube root of the bounding box's volume (the
    # default: one length for how big the object is; it carries a trace of the law, since log volume is then exactly
    # log fill + 3 log size), or "largest", the largest extent (what a hand spans; a thin rod is then as big as a cube
    # of its length), to measure what the model owes to that choice (docs/model.md)
    size_from: str = "cube_root"
    # extra context properties perceived with the object (e.g. an apparatus' tube width or water level), each a 1-d
    # value in 0..1 given as measurement["context"][name], each on a SOM map of its own; none by default, so the
    # default agent has exactly the paper's four property maps and the word map
    context: tuple = ()

    def __post_init__(self):
        self.properties, self.context = tuple(self.properties), tuple(self.context)
        if self.size_from not in SIZE_FROM:
            raise ValueError(f"EncoderConfig.size_from must be one of {', '.join(SIZE_FROM)}, got {self.size_from!r}")
        if self.properties not in (PROPERTIES, SPLIT_PROPERTIES):
            raise ValueError(f"EncoderConfig.properties must be {PROPERTIES} or {SPLIT_PROPERTIES}, "
                             f"got {self.properties}")


def _log_unit(x: torch.Tensor, lo: float, hi: float) -> torch.Tensor:
    return (x.log() - math.log(lo)) / (math.log(hi) - math.log(lo))


def _log_uniform(g: torch.Generator, lo: float, hi: float, shape: tuple) -> torch.Tensor:
    return torch.exp(math.log(lo) + torch.rand(shape, generator=g) * math.log(hi / lo))


def _batched(v, name: str, tail: tuple) -> torch.Tensor:
    """A measurement field as a float tensor with a leading batch dim; ValueError if its shape is wrong."""
    t = torch.as_tensor(v, dtype=torch.float32)
    if t.shape == tail:
        t = t.unsqueeze(0)
    if t.ndim != len(tail) + 1 or t.shape[1:] != tail:
        raise ValueError(f"measurement '{name}' must have shape (B, {', '.join(map(str, tail))}) or "
                         f"({', '.join(map(str, tail))}), got {tuple(t.shape)}")
    if not torch.isfinite(t).all():
        raise ValueError(f"measurement '{name}' has non-finite values")
    return t


def word_activity(som, words: torch.Tensor) -> torch.Tensor:
    """(B, V) bags of words (encode_words) -> (B, n_units) the word map's activity for each phrase: the sum over its
    words of the map's response to that word alone, each scaled to unit length. A name then binds, and a phrase
    matches, word by word: "red heavy cylinder" and "red light cylinder" share two of three words' patterns (cosine
    2/3), whatever the map's layout. A phrase with no known word gives zeros."""
    V = words.shape[-1]
    table = som.activity(torch.eye(V, device=words.device))                       # (V, U): each word alone
    table = table / table.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    return (words > 0).to(table.dtype) @ table


def unknown_words(phrase: str) -> list[str]:
    """The words of a phrase (split on spaces and underscores) that are neither in VOCABULARY nor FUNCTION_WORDS."""
    return [w for w in phrase.lower().replace("_", " ").split() if w not in VOCABULARY + FUNCTION_WORDS]


def encode_words(text, vocabulary: tuple = VOCABULARY) -> torch.Tensor:
    """A phrase (or a list of B phrases) -> (dim,) or (B, dim) bag-of-words vector of unit length.

    Words are split on spaces and underscores, so object names like "red_heavy_cylinder" read as phrases.
    Unknown words are ignored: the vector has a dimension only for each vocabulary word, and a name may hold
    words outside it ("pink_light_cylinder", "grey_mid_cube") - its known words still say what they say. A phrase
    with no known word gives the zero vector. Scaling to unit length keeps a three-word name and a two-word phrase
    on the same scale, so "blue heavy cylinder" stays closest to "blue cylinder".
    """
    single = isinstance(text, str)
    texts = [text] if single else list(text)
    index = {w: i for i, w in enumerate(vocabulary)}
    out = torch.zeros(len(texts), len(vocabulary))
    for b, phrase in enumerate(texts):
        if not isinstance(phrase, str):
            raise ValueError(f"words must be str or a list of str, got {type(phrase).__name__}")
        for w in phrase.lower().replace("_", " ").split():
            if w in index:
                out[b, index[w]] = 1.0
    out = out / out.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    return out[0] if single else out


class SensoryEncoder(nn.Module):
    """Measurements -> map inputs. No learned state: a fixed transduction, like a retina or a skin."""

    def __init__(self, config: EncoderConfig | None = None):
        super().__init__()
        self.config = config or EncoderConfig()

    def forward(self, measurement: dict) -> dict:
        """dict of measurements -> dict map name -> (B, dim) input. Only maps whose measurement is present get
        an input (weight is unknown until the object is lifted; words only when a teacher speaks)."""
        c, out = self.config, {}
        if "rgb" in measurement:
            rgb = _batched(measurement["rgb"], "rgb", (3,))
            if (rgb < 0).any() or (rgb > 1).any():
                raise ValueError("measurement 'rgb' must be in 0..1")
            out["color"] = rgb
        if "extent_cm" in measurement or "fill" in measurement:
            if "extent_cm" not in measurement or "fill" not in measurement:
                raise ValueError("measurement needs both 'extent_cm' and 'fill' for shape (or neither)")
            ext = _batched(measurement["extent_cm"], "extent_cm", (3,))
            fill = _batched(measurement["fill"], "fill", ())
            if (ext <= 0).any():
                raise ValueError("measurement 'extent_cm' must be > 0")
            if (fill <= 0).any() or (fill > 1).any():
                raise ValueError("measurement 'fill' must be in (0, 1]")
            ext = ext.sort(dim=-1, descending=True).values  # robust to an unsorted caller
            ratios = torch.stack([ext[:, 1] / ext[:, 0], ext[:, 2] / ext[:, 0]], -1)
            if "shape" in c.properties:
                out["shape"] = torch.cat([fill[:, None], ratios], -1)
            if "fill" in c.properties:
                out["fill"], out["elongation"] = fill[:, None], ratios
            length = ext[:, :1] if c.size_from == "largest" else ext.prod(-1, keepdim=True) ** (1.0 / 3.0)
            out["size"] = _log_unit(length, c.size_min_cm, c.size_max_cm)
        if "mass_g" in measurement:
            mass = _batched(measurement["mass_g"], "mass_g", ())
            if (mass <= 0).any():
                raise ValueError("measurement 'mass_g' must be > 0")
            out["weight"] = _log_unit(mass[:, None], c.mass_min_g, c.mass_max_g)
        if "context" in measurement:
            ctx = measurement["context"]
            unknown = sorted(set(ctx) - set(c.context)) if isinstance(ctx, dict) else None
            if unknown is None or unknown:
                raise ValueError(f"measurement 'context' must be a dict over EncoderConfig.context "
                                 f"{tuple(c.context)}, got {unknown if unknown else type(ctx).__name__}")
            for name, v in ctx.items():
                t = _batched(v, name, ())
                if (t < 0).any() or (t > 1).any():
                    raise ValueError(f"context '{name}' must be in 0..1")
                out[name] = t[:, None]
        if "words" in measurement:
            w = measurement["words"]
            out[WORD_MAP] = encode_words([w] if isinstance(w, str) else w)
        sizes = {k: v.shape[0] for k, v in out.items()}
        if len(set(sizes.values())) > 1:
            raise ValueError(f"measurement fields disagree on the batch size: {sizes}")
        return out

    def encode(self, measurement: dict) -> dict:
        return self(measurement)


def developmental_samples(n: int, generator: torch.Generator, config: EncoderConfig | None = None) -> dict:
    """n random prior experiences -> dict map name -> (n, dim) map inputs, through the same encoding as the
    experiment's measurements (colour uniform in the RGB cube; shape kind uniform over the four, with random
    proportions; size and mass log-uniform over the config ranges; one word of the vocabulary each, uniformly:
    the word map learns the words, and a phrase is heard word by word, `word_activity`)."""
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    encoder = SensoryEncoder(config)
    c, g = encoder.config, generator
    rgb = torch.rand(n, 3, generator=g)
    kind = torch.randint(len(SHAPE_WORDS), (n,), generator=g)
    # extents relative to the largest: cylinder (d, d, h), box (1, b, c), cube and sphere all equal
    aspect = _log_uniform(g, 1.0 / c.max_aspect, c.max_aspect, (n,))     # cylinder height / diameter
    sides = _log_uniform(g, 1.0 / c.max_aspect, 1.0, (n, 2))              # box sides / its longest side
    props = torch.ones(n, 3)
    cyl, box = kind == SHAPE_WORDS.index("cylinder"), kind == SHAPE_WORDS.index("box")
    props[cyl, 2] = aspect[cyl]
    props[box, 1:] = sides[box]
    props = props / props.prod(-1, keepdim=True) ** (1.0 / 3.0)  # unit bounding-box volume, then scaled by size
    size = _log_uniform(g, c.size_min_cm, c.size_max_cm, (n, 1))
    fill = torch.tensor([SHAPE_FILL[s] for s in SHAPE_WORDS])[kind]
    mass = _log_uniform(g, c.mass_min_g, c.mass_max_g, (n,))
    out = encoder({"rgb": rgb, "extent_cm": props * size, "fill": fill, "mass_g": mass})
    out[WORD_MAP] = torch.eye(len(VOCABULARY))[torch.randint(len(VOCABULARY), (n,), generator=g)]
    for name in c.context:   # drawn last: without context the draws above, and so the maps, are unchanged
        out[name] = torch.rand(n, 1, generator=g)
    if "fill" in c.properties:
        # a map of its own for fill learns it from every object an infant handles, hollow, irregular or solid, not
        # from the four kinds' three values alone (on those, its units sat at 0.52, 0.79 and 1 and a cylinder's
        # fill decoded 0.69); uniform over 0.2..1, drawn last
        out["fill"] = 0.2 + 0.8 * torch.rand(n, 1, generator=g)
    return out


def default_map_configs(config: EncoderConfig | None = None) -> dict[str, SOMConfig]:
    """One SOM per map, sized to resolve what the experiment must tell apart.

    activity_sigma is about the spacing between neighbouring codebook vectors (in input units, measured on the
    trained maps): the same input activates its own unit near 1, a value two or more units away barely
    (tests/test_encoders.py checks the experiment's objects: own unit > 0.8, a clearly different object < 0.05).
    - color 10x10 over the RGB cube: neighbours ~0.16-0.18 apart, sigma 0.2. A 2-d sheet folded through a 3-d
      cube quantizes coarsely (QE 0.11 here, 0.12 with 8x8), so a palette colour activates its own unit at only
      0.6-1.0 (the hub reads activity relative to the map's peak, see hub.HubConfig). Red, green and blue are
      >= 0.9 apart: ~0 on each other's units; red vs orange (0.41 apart) 0.08.
    - shape 8x8 over [fill, ratio, ratio]: cube and sphere are points, cylinders two lines, boxes a triangle;
      neighbours ~0.07-0.12 apart, sigma 0.1. (6x6 left boxes and short cylinders at 0.65-0.75 of their unit.)
    - size 1x20 over log size: a unit per 1/20 of the log range (a factor 1.19 in size), sigma = the spacing;
      11.5 vs 5 cm are 5 units apart.
    - weight 1x30 over log mass: a unit per factor 1.29 in mass, sigma = the spacing; 14, 90, 420 g are 7 and
      6 units apart.
    - word 8x8 over the 22 words (one-hot): every word gets units of its own (22 distinct winners in seeds 0-5),
      ~3 each; two words are 1.41 apart, so sigma 0.4 gives a word ~0.002 on another's units (the ordering
      phase is what separates them). Phrases are read word by word (`word_activity`).
    - each context property of config.context: 1x20 over 0..1, like size (a unit per 1/20, sigma the spacing).
    1-d data get 1-d maps (a line cannot fold). The radius starts at about a quarter of the map's longest side.
    - fill 1x20 over 0..1 (a unit per 0.05, sigma the spacing) and elongation 6x6 over the two extent ratios,
      sigma 0.1 (neighbours ~0.1-0.15 apart), when shape is split (EncoderConfig.properties = SPLIT_PROPERTIES).
    """
    config = config or EncoderConfig()
    context = {name: SOMConfig(rows=1, cols=20, dim=1, sigma=5.0, sigma_end=0.5, activity_sigma=0.05)
               for name in config.context}
    shape = ({"shape": SOMConfig(rows=8, cols=8, dim=3, sigma=2.0, sigma_end=0.5, activity_sigma=0.1)}
             if "shape" in config.properties else
             {"fill": SOMConfig(rows=1, cols=20, dim=1, sigma=5.0, sigma_end=0.5, activity_sigma=0.05),
              "elongation": SOMConfig(rows=6, cols=6, dim=2, sigma=1.5, sigma_end=0.5, activity_sigma=0.1)})
    return {
        "color": SOMConfig(rows=10, cols=10, dim=3, sigma=2.5, sigma_end=0.5, activity_sigma=0.2),
        **shape,
        "size": SOMConfig(rows=1, cols=20, dim=1, sigma=5.0, sigma_end=0.5, activity_sigma=0.05),
        "weight": SOMConfig(rows=1, cols=30, dim=1, sigma=7.5, sigma_end=0.5, activity_sigma=0.033),
        WORD_MAP: SOMConfig(rows=8, cols=8, dim=len(VOCABULARY), sigma=1.5, sigma_end=0.3, activity_sigma=0.4,
                            ordering_iterations=4000),
        **context,
    }


@torch.no_grad()
def train_property_maps(n_samples: int, generator: torch.Generator, epochs: int = 30,
                        config: EncoderConfig | None = None) -> nn.ModuleDict:
    """The maps in MAP_NAMES order, each `fit` (SelfOrganizingMap.fit) on n_samples developmental samples.

    epochs=30: QE improves by < 2 % between 20 and 50 epochs on these data (the radius schedule spans them all).
    """
    samples = developmental_samples(n_samples, generator, config)
    maps = nn.ModuleDict()
    for name, cfg in default_map_configs(config).items():
        som = SelfOrganizingMap(cfg)
        som.fit(samples[name], epochs, generator)
        maps[name] = som
    return maps
